"""[`jaxcable.read_test`][]: one test from a canonical CSV file or a raw tensile-tester
export, whose layout `sniff.py` detects, with the slack stretches masked."""

import dataclasses
import os
from collections.abc import Mapping, Sequence
from typing import NamedTuple

import numpy as np

from .arguments import (
    check_read_arguments,
    column_notes,
    derive_channels,
    derived_notes,
)
from .columns import columns_by_name, parse_columns_spec
from .cycles import cycles_to_time
from .loadcell import check_force_sign, correct_load_cell
from .options import METADATA_KEYS, ReadOptions
from .parsing import (
    ColumnMap,
    assemble,
    metadata_value,
    parse_metadata,
    parse_number,
    parse_rows,
    row_cells,
)
from .preamble import merge, read_block
from .sniff import (
    data_above,
    data_below_header,
    find_data_start,
    header_columns,
    sniff_separator,
    text_columns,
)
from .testdata import TestData, mask_slack
from .text import read_lines
from .units import QUANTITIES


def _header_names(header: str, sep: str, columns: list[ColumnMap]) -> dict:
    """Per quantity read, the name of its column in the `header` line."""
    cells = [cell.strip() for cell in row_cells(header, sep)]
    return {
        c.quantity: cells[c.position - 1]
        for c in columns
        if c.quantity in QUANTITIES
        and c.position is not None
        and c.position <= len(cells)
        and cells[c.position - 1]
    }


def _text_examples(lines, start: int, sep: str, decimal_comma: bool) -> dict[int, str]:
    """Per text column of the data rows from `lines[start]` on (1-based position,
    see `text_columns`), its first cell that is not a number."""
    positions = text_columns(lines, start, sep, decimal_comma)
    found: dict[int, str] = {}
    for line in lines[start : start + 200]:
        cells = row_cells(line, sep)
        for position in positions - {p - 1 for p in found}:
            if position < len(cells):
                try:
                    parse_number(cells[position], decimal_comma)
                except ValueError:
                    found[position + 1] = cells[position]
        if len(found) == len(positions):
            break
    return found


class _Layout(NamedTuple):
    """Where a file's data are: its columns, the header line they were read from
    (None: `columns` named them), and the first data row (0-based)."""

    columns: list[ColumnMap]
    header_line: int | None
    named_by: str  # "the header" or "columns", for the messages
    start: int
    spec: list[ColumnMap] | None  # the columns as given (None: from the header)
    by_name: bool  # `columns` named header names (`Load=force_kN`)


def _separator(lines, first: int, delimiter, path) -> tuple[str, bool]:
    """The cell separator and whether numbers write a decimal comma: detected, or
    the `delimiter` given (a decimal comma then detected)."""
    if delimiter is None:
        return sniff_separator(lines, first)
    if not isinstance(delimiter, str) or len(delimiter) != 1 or delimiter in '"\r\n':
        raise ValueError(
            f"{path}: delimiter must be one character (not a quote or line "
            f"break), got {delimiter!r}."
        )
    decimal_comma = delimiter != "," and sniff_separator(lines, first) == (
        delimiter,
        True,
    )
    return delimiter, decimal_comma


def _skip_rows(skip_rows: int, lines, path) -> int:
    if not 0 <= skip_rows < len(lines):
        raise ValueError(
            f"{path}: skip_rows={skip_rows} is outside the file's {len(lines)} lines."
        )
    return int(skip_rows)


def _layout(lines, first: int, cells: tuple[str, bool], columns, options, path):
    """The file's [`_Layout`][]: from `columns` (file order, or header names), else
    from its header; the first data row given (`options.skip_rows`) or detected."""
    sep, decimal_comma = cells
    skip_rows = options.skip_rows
    required = ("time", "force") if options.require_force else ("time",)
    spec = None if columns is None else parse_columns_spec(columns, path, required)
    by_name, search = None, first
    if isinstance(spec, dict):
        # Columns named by their header names: the header is the row holding them,
        # the data below it.
        by_name = columns_by_name(lines, first, sep, spec, path)
        spec, search = by_name[0], by_name[1]
    if skip_rows is None:
        start = find_data_start(lines, search, sep, decimal_comma, spec, path)
    else:
        start = _skip_rows(skip_rows, lines, path)
    if by_name is not None:
        column_map, header_line = by_name
        named_by = "the header"
        if skip_rows is None:
            start = data_below_header(lines, header_line, start, sep)
    elif spec is None:
        column_map, header_line = header_columns(
            lines, first, start, sep, path, required
        )
        named_by = "the header"
        if skip_rows is None:
            start = data_below_header(lines, header_line, start, sep)
    else:
        column_map, header_line = spec, None
        named_by = "columns"
        if skip_rows is None:
            start = data_above(lines, first, start, sep, decimal_comma, spec)
    return _Layout(column_map, header_line, named_by, start, spec, by_name is not None)


def _assemble(lines, layout: _Layout, cells, metadata: dict, options, path):
    """The [`jaxcable.TestData`][] of the data rows of `layout`, with its notes
    (columns not read, channels derived, time from cycles), before the load-cell
    corrections and the slack detection."""
    sep, decimal_comma = cells
    start, named_by, spec = layout.start, layout.named_by, layout.spec
    values, line_numbers = parse_rows(
        lines, start, layout.columns, path, sep, decimal_comma, named_by
    )
    values, line_numbers, column_map, timed = cycles_to_time(
        values, line_numbers, layout.columns, options.frequency_hz, path
    )
    text = _text_examples(lines, start, sep, decimal_comma) if spec is None else None
    notes = () if layout.by_name else column_notes(column_map, named_by, text)
    notes += derived_notes(column_map, metadata) if spec is not None else ()
    notes += timed
    header_line = layout.header_line
    column_map = derive_channels(column_map, metadata, path, header_line)
    data = assemble(path, column_map, values, line_numbers, metadata, header_line)
    if header_line is not None:
        # Errors about the data name the columns as the header does (`Load`).
        data = dataclasses.replace(
            data, column_names=_header_names(lines[header_line - 1], sep, column_map)
        )
    if notes:
        data = dataclasses.replace(data, notes=notes)
    return data


def read_test(
    path: str | os.PathLike,
    columns: str | Sequence[str] | None = None,
    *,
    metadata: Mapping[str, float | str | None] | None = None,
    options: ReadOptions | None = None,
) -> TestData:
    """Read one test from a canonical CSV file or a raw tensile-tester export.

    The file may start with the canonical `# key: value` metadata lines. Then:

    - *Separator*: comma, semicolon or tab, whichever splits most of the first lines
        into numbers (a semicolon or tab file may write decimal commas, `1,5`).
    - *Encoding*: UTF-8 (with or without byte-order mark), else GB18030 (GBK), else
        latin-1, so a header in any encoding reads.
    - *Rows to skip* (`options.skip_rows`): the lines before the first data row. Detected:
        every row under the header is data (blank and comment lines and a units row
        right under the header aside), so a typo in the first rows (`N/A`, `O.5`, a
        stray separator) is an error, as further down; without a header (`columns`
        given), the rows above the first row of numbers are preamble, but for those
        right above it that look like data with a typo (digits and no word, or as
        many cells as `columns` with a number among them), which are errors too.
        Quoted numbers and CRLF line ends are read as such.
    - *Columns*: `columns` names every column of the file in order with its unit;
        without it, a canonical header (`time_s,force_N,...`) is used, else a header
        matched best-effort: names such as `Time`, `Force`/`Load`,
        `Elongation`/`Extension`/`Displacement`/`Position`, `Temperature` (also in
        Chinese, e.g. 时间, 力, 位移), with units in the name (`Force (kN)`,
        `Time/s`) or in a units row below (`(s),(mm),(N)`, empty cells for columns
        without a unit, any unit such as `(N/tex)` or `(mm/mm)`: a units row is
        never the header); a crosshead displacement is read as the elongation. Of
        two columns of one quantity the one with fewer words is read (`Extension`,
        not `Tensile extension`; `Total Time`, not `Cycle Elapsed Time`; two with as
        many are an error). A file with a stress column but no force column
        (`Tensile stress` in MPa, N/mm², kPa, psi...) is read with the force = the
        stress x the area of a circle of `diameter_mm` (from the file or given;
        without it, an error saying to pass it), a strain column (mm/mm, %) without
        an elongation column with the elongation = strain x `length_mm`. The other
        columns are not read; `notes` names them in one line. Otherwise it is an
        error naming the columns found and what each was read as, asking for
        `columns` (`--columns`).
    - *Instrument exports* read as they come (header words, units, metadata labels
        in `jaxcable/_io/vocabulary.py`; real exports in `tests/data/exports/`):
        Instron Bluehill (`Specimen properties : Length,"14.33000",mm`, `Test :
        Rate 1,"5.00000",mm/min`, `Specimen properties : Specimen label,"s1"` read
        as `id`, `Extension,Load,Tensile stress,Time,PIP count,...` over
        `(mm),(N),(MPa),(s),,...`), Instron WaveMatrix (`Total Time (s),...,
        Position (mm),Force (kN)`), Walter+Bai (`C_1_Temps[s];C_1_Force[kN];
        C_1_Déplacement[mm]`), Zwick testXpert
        (`;`-separated, decimal commas, `Einspannlänge;100,0;mm`,
        `Standardkraft;Standardweg;Prüfzeit` or `Standard force;Grip to grip
        separation;Test time` over `N;mm;s`), MTS TestSuite (tab-separated `Time`,
        `Axial Displacement`/`Crosshead`, `Axial Force`/`Load` over `sec mm N`),
        Shimadzu Trapezium (`Time,Force,Stroke` over `sec,N,mm`). Units: s, ms, min,
        h; N, kN, lbf, kgf; mm, cm, m, in. The metadata lines above the header
        (label, number, unit, in any order) give `length_mm`, `diameter_mm` and
        `rate_mm_per_min` (from m, cm, mm, in; mm/min, mm/s, m/min, m/s, in/min);
        a line stating the control mode (`Position control`, `Control mode,Load`,
        `Kraftregelung`) sets `control` to "elongation" or "force".
    - *Slack* (`options.detect_slack`): stretches where the force is about zero while the
        crosshead moves are masked, and negative forces clipped to 0; see
        [`jaxcable.mask_slack`][] for the rule. The result is in `mask`,
        `force_raw` and `slack_report`. A reading below zero within the load
        cell's noise (the slack threshold, from the file's own force noise) is
        then a 0 N reading; one below minus the threshold is masked, and the
        command line refuses it where the force drives the model.

    **Arguments:**

    - `path`: the file.
    - `columns`: the file's columns in order, e.g. `"time_s,elongation_mm,force_N"`
        (a string or a sequence of names). Accepted: `time_s`, `time_ms`, `time_min`,
        `time_h`, `force_N`, `force_kN`, `force_lbf`, `force_kgf`,
        `elongation_mm`, `elongation_cm`, `elongation_m`, `elongation_in`,
        `temperature_C`, and `-` for a column to ignore (not parsed). Time and force
        are required. Also read: `stress_MPa`, `stress_kPa`, `stress_Pa` (the force
        = the stress x the area of a circle of `diameter_mm`: a stress record reads
        with any consistent area), `strain`, `strain_percent` (the elongation = the
        strain x `length_mm`), `stretch_ratio` (lambda: the elongation = (lambda -
        1) x `length_mm`) and `cycles` (a cycle count: the time is N /
        `options.frequency_hz`, a burst of samples at one count read as one sample, its
        mean; see `jaxcable/_io/cycles.py` for why). Or some columns by their
        header names, `"Machine_Load=force_kN,Machine_N_cycles=cycles"`: the first
        row holding every name is the header, its other columns are not read.
    - `metadata`: facts about the test that replace or complete the file's, by
        their names in the `# key: value` block: `length_mm`, `diameter_mm`,
        `rate_mm_per_min`, `temperature_C`, `material`, `id`, `breaking_strain`
        (mm, mm, mm/min, °C; the breaking strain dimensionless, `math.inf` for a
        material that does not break, see [`jaxcable.TestData.cable`][]); a value
        `None` is not given. Where one differs from the file's by more than
        rounding (0.1 %), a [`jaxcable.MetadataConflictWarning`][] names both (the
        command line prints it as one line). `length_mm` is required, from the
        file or here.
    - `options`: how the file is read, a [`jaxcable.ReadOptions`][] (rows to skip,
        encoding, delimiter, slack detection, load-cell corrections, the
        frequency of a file timed by cycles); `None` for the defaults.

    **Returns:**

    A [`jaxcable.TestData`][] in SI units (s, N, m; temperature in °C).

    **Raises:**

    `TypeError` or `ValueError` naming the argument (or the `metadata` key) of a
    value of the wrong type or value (`columns=3`, `metadata={"length_mm": [1]}`);
    `ValueError` naming the
    file, the 1-based line and the column (its position and name) of the first
    problem: a missing column or cell, a non-numeric, empty, NaN
    or infinite cell, a value out of range in SI units (`1e306` h), time not
    strictly increasing in the file's unit or in seconds (repeated time stamps
    included: remove them from the file), a header that names no time and force
    column, a numeric metadata value (`length_mm`, `diameter_mm`,
    `rate_mm_per_min`, `temperature_C`, `breaking_load_N`, `breaking_strain`) that
    is not a finite number the [`jaxcable.Cable`][] accepts, or no `length_mm`; an
    instrument metadata line without a known unit, unless its value is given here.
    """
    if options is None:
        options = ReadOptions()
    given = check_read_arguments(path, columns, metadata, METADATA_KEYS)
    if not isinstance(options, ReadOptions):
        raise TypeError(
            "`options` must be a jaxcable.ReadOptions or None, got "
            f"{type(options).__name__}."
        )
    lines = read_lines(path, options.encoding)
    file_metadata, first = parse_metadata(lines, path)
    given = {
        key: metadata_value(key, value, f"{path}, argument {key}")
        for key, value in given.items()
    }
    sep, decimal_comma = _separator(lines, first, options.delimiter, path)
    layout = _layout(lines, first, (sep, decimal_comma), columns, options, path)
    block = read_block(lines, first, layout.start, sep, decimal_comma)
    merged = merge(path, lines, first, file_metadata, block, given)
    data = _assemble(lines, layout, (sep, decimal_comma), merged, options, path)
    data = correct_load_cell(data, check_force_sign(options.force_sign), options.tare)
    if options.detect_slack and np.all(np.isfinite(data.force)):
        data = mask_slack(data, threshold_N=options.slack_threshold_N)
    return data
