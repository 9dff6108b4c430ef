"""The canonical test-data file: a CSV with a `# key: value` metadata block.

```
# id: sk78-300-100N
# material: Dyneema SK78
# length_mm: 300
# diameter_mm: 3
# rate_mm_per_min: 3
time_s,force_N,elongation_mm,temperature_C
0,0,0,21.5
1.5,2.1,0.031,21.5
```

Units in the file are the ones the column and key names say (s, N, mm, mm/min, °C);
[`jaxcable.TestData`][] holds SI. This module holds the format's reader
[`jaxcable.read_csv`][] and writer [`jaxcable.write_csv`][]; the parser they share with
[`jaxcable.read_test`][] (raw tensile-tester exports) is in `parsing.py`.
"""

import os
from collections.abc import Mapping

import numpy as np

from .._files import atomic_path
from .arguments import check_metadata, check_path
from .parsing import (
    assemble,
    map_columns,
    metadata_value,
    parse_metadata,
    parse_rows,
    split_cells,
)
from .testdata import TestData, where
from .text import read_lines
from .units import COLUMNS, QUANTITIES, written_name


def read_csv(
    path: str | os.PathLike,
    *,
    metadata: Mapping[str, float | str | None] | None = None,
) -> TestData:
    """Read a test history in the canonical CSV format.

    The file starts with `# key: value` lines (`length_mm` required; `diameter_mm`,
    `rate_mm_per_min`, `temperature_C`, `breaking_load_N`, `breaking_strain`,
    `material`, `id` and any other keys optional),
    then a header line naming the columns with their units (`time_s` and `force_N`
    required; `elongation_mm` and `temperature_C` optional; also accepted: `time_ms`,
    `time_min`, `time_h`, `force_kN`, `elongation_m`; any other column is kept as an
    extra column), then one row of numbers per sample. Time must increase strictly.
    The file is read exactly as written: no slack detection (that is
    [`jaxcable.read_test`][], which reads canonical files too).

    **Arguments:**

    - `path`: the file.
    - `metadata`: values that replace or add to the file's `# key: value` block,
        e.g. `{"length_mm": 300}`; a value `None` is not given.

    **Returns:**

    A [`jaxcable.TestData`][] in SI units (s, N, m; temperature in °C).

    **Raises:**

    `TypeError` naming `metadata` (or its key) of a value of the wrong type;
    `ValueError` naming the file, the 1-based line and the column (or metadata key) of
    the first problem: a missing required column, a non-numeric, empty, NaN or
    infinite cell, a value out of range in SI units, time not strictly increasing
    (in the file's unit or in seconds), a numeric metadata value that is not a
    finite number the [`jaxcable.Cable`][] accepts, or no `length_mm` metadata.
    """
    check_path(path)
    return read_canonical(path, check_metadata(metadata), raw=False)


def read_canonical(
    path, overrides, required: tuple[str, ...] = ("time", "force"), raw: bool = True
) -> TestData:
    """[`jaxcable.read_csv`][] with the `required` quantities (an elongation
    history to simulate needs time and elongation, not force: its forces are NaN);
    with `raw`, a file whose first line after the `# key: value` block names no
    canonical column (an instrument export) is read by [`jaxcable.read_test`][],
    without slack detection (its values as written)."""
    lines = read_lines(path)
    metadata, header = parse_metadata(lines, path)
    if header == len(lines):
        raise ValueError(
            f"{where(path, len(lines) + 1)}: no header line (expected e.g. "
            "'time_s,force_N' after the '# key: value' lines)."
        )
    names = [cell.strip() for cell in split_cells(lines[header], ",")]
    if raw and not any(name in COLUMNS for name in names):
        # The raw reader builds on this module's parser.
        from .options import ReadOptions
        from .raw import read_test

        return read_test(
            path, metadata=overrides, options=ReadOptions(detect_slack=False)
        )
    for key, value in overrides.items():
        metadata[key] = metadata_value(key, value, f"{path}, argument {key}")
    header_line = header + 1
    columns = map_columns(names, path, header_line, required=required)
    values, line_numbers = parse_rows(lines, header + 1, columns, path)
    return assemble(path, columns, values, line_numbers, metadata, header_line)


def _format_metadata(value: float | str) -> str:
    """A metadata value as written: integers without a decimal point, other numbers
    with full precision."""
    if isinstance(value, str):
        return value
    value = float(value)
    if value.is_integer() and abs(value) < 1e15:
        return str(int(value))
    return repr(value)


def _check_metadata_for_writing(metadata: Mapping[str, float | str]) -> None:
    """Raise `ValueError` unless `metadata` can be written as `# key: value` lines that
    read back as the same keys."""
    for key, value in metadata.items():
        text = f"{key}{value}"
        if ":" in key or not key.strip() or key != key.strip():
            raise ValueError(f"Metadata key {key!r} cannot be written (':' or blank).")
        if "\n" in text or "\r" in text:
            raise ValueError(f"Metadata {key!r} contains a line break.")
    if "length_mm" not in metadata:
        raise ValueError(
            "Metadata has no 'length_mm' (the free length of the cable, mm), which the "
            "canonical format requires."
        )


def write_csv(path: str | os.PathLike, data: TestData) -> None:
    """Write `data` in the canonical CSV format (see [`jaxcable.read_csv`][]).

    Columns are written as `time_s`, `force_N`, then `elongation_mm` and
    `temperature_C` when present, then the extra columns by their names; metadata in
    its order. `force` is written (after [`jaxcable.mask_slack`][], the clipped
    force); `mask`, `force_raw` and `slack_report` are not: reading the file with
    [`jaxcable.read_test`][] detects the slack again. Numbers are written with full
    precision (`repr`), so reading the file back gives the same values up to the
    mm <-> m conversion (1 ulp).

    **Arguments:**

    - `path`: the file to (over)write, atomically: the text goes to a temporary file
        beside it, renamed over it once written, so a write cut short leaves `path`
        as it was.
    - `data`: a [`jaxcable.TestData`][]; its metadata must have `length_mm`.

    **Returns:**

    Nothing.
    """
    check_path(path)
    if not isinstance(data, TestData):
        raise TypeError(
            f"`data` must be a jaxcable.TestData, got {type(data).__name__}."
        )
    _check_metadata_for_writing(data.metadata)
    names = []
    columns = []
    for quantity in QUANTITIES:
        value = getattr(data, quantity)
        if value is None:
            continue
        name = written_name(quantity)
        names.append(name)
        columns.append(np.asarray(value, dtype=float) / COLUMNS[name].to_si)
    for name, value in data.extra.items():
        if any(c in name for c in ',"\n\r'):
            raise ValueError(f"Extra column name {name!r} cannot be written.")
        names.append(name)
        columns.append(np.asarray(value, dtype=float))
    out = [f"# {key}: {_format_metadata(v)}" for key, v in data.metadata.items()]
    out.append(",".join(names))
    table = np.stack(columns, axis=1).tolist()
    out.extend(",".join(map(repr, row)) for row in table)
    # Atomically: a write cut short leaves the file as it was, never truncated.
    with atomic_path(path) as tmp, open(tmp, "w", encoding="utf-8", newline="\n") as f:
        f.write("\n".join(out) + "\n")
