"""The parser shared by [`jaxcable.read_csv`][] and [`jaxcable.read_test`][]: a file's
`# key: value` metadata block, the column map (file column -> canonical quantity and
unit factor), the numeric rows, and their assembly into a [`jaxcable.TestData`][] in
SI (the lines come from `text.py`). Every error names the file, line and column."""

import csv
import math
from collections.abc import Callable, Sequence
from typing import NamedTuple

import numpy as np

from .control import control_name
from .testdata import TestData, where
from .units import (
    COLUMNS,
    IGNORE,
    NUMERIC_METADATA,
    accepted_names,
    missing_quantities,
    written_name,
)


def _show(cell, limit: int = 40) -> str:
    """A cell as quoted in an error message, cut to `limit` characters."""
    text = str(cell)
    return (
        repr(text)
        if len(text) <= limit
        else repr(text[:limit]) + f"... ({len(text)} characters)"
    )


def metadata_value(key: str, value, place: str) -> float | str:
    """Parse one metadata value: a float for the numeric keys, the canonical name
    for `control` (`"force"` or `"elongation"`), else a string."""
    if key == "control":
        return control_name(value, place)
    if key not in NUMERIC_METADATA:
        return str(value)
    if isinstance(value, bool):
        raise ValueError(f"{place}: {_show(value)} is not a number.")
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{place}: {_show(value)} is not a number.") from None
    bound = NUMERIC_METADATA[key]
    if not (math.isfinite(number) or (bound.infinite and number == math.inf)):
        raise ValueError(f"{place}: {_show(value)} is not a finite number.")
    if number <= bound.minimum:
        what = "positive" if bound.minimum == 0 else f"above {bound.minimum:g}"
        raise ValueError(f"{place}: must be {what}, got {number:g}.")
    if not (number - bound.minimum) * bound.to_si > 0:
        raise ValueError(f"{place}: {number:g} is too small (0 in SI units).")
    return number


def parse_metadata(lines: list[str], path) -> tuple[dict[str, float | str], int]:
    """Parse the leading `# key: value` block.

    **Arguments:**

    - `lines`: the lines of the file.
    - `path`: the file name, for error messages.

    **Returns:**

    `(metadata, header)`: the metadata and the 0-based index of the first line that is
    neither blank nor a comment (the header; `len(lines)` when there is none). `#`
    lines without a colon are free comments and are skipped.
    """
    metadata: dict[str, float | str] = {}
    first_seen: dict[str, int] = {}
    for index, line in enumerate(lines):
        stripped = line.strip()
        if not stripped:
            continue
        if not stripped.startswith("#"):
            return metadata, index
        body = stripped[1:]
        if ":" not in body:
            continue
        key, value = (s.strip() for s in body.split(":", 1))
        place = f"{where(path, index + 1)}, metadata '{key}'"
        if not key:
            raise ValueError(f"{where(path, index + 1)}: metadata line has no key.")
        if key in first_seen:
            raise ValueError(
                f"{place}: repeated (first given on line {first_seen[key]})."
            )
        first_seen[key] = index + 1
        metadata[key] = metadata_value(key, value, place)
    return metadata, len(lines)


class ColumnMap(NamedTuple):
    """One file column: its name and what it is read as."""

    name: str  # as in the file (or in `columns`)
    quantity: str | None  # canonical quantity, None for an extra column, or IGNORE
    to_si: float
    position: int | None = None  # 1-based, shown in error messages when set
    # Added to the file's value before `to_si`: a stretch ratio (lambda) is the
    # elongation (lambda - 1) L0.
    offset: float = 0.0


def map_names(
    names: Sequence[str],
    *,
    unknown: Callable[[int, str], ColumnMap],
    repeated: Callable[[str, str, str], str],
    missing: Callable[[str], str],
    required: tuple[str, ...] = ("time", "force"),
    check: Callable[[int, str], None] | None = None,
    positions: bool = True,
) -> list[ColumnMap]:
    """Map column names to canonical quantities and unit factors by `COLUMNS`: the
    one mapping behind a file's header and a `columns` value.

    **Arguments:**

    - `names`: the column names, in file order.
    - `unknown`: `unknown(position, name)` is the `ColumnMap` of a name that is not
        in `COLUMNS` (it may raise instead).
    - `repeated`: `repeated(name, quantity, first)`, the error message for a second
        column of `quantity` (`first`: the name of the first).
    - `missing`: `missing(quantity)`, the error message for the first `required`
        quantity that no column reads.
    - `required`: the quantities that must have a column.
    - `check`: called as `check(position, name)` before a name is mapped (it raises
        on a name the caller refuses).
    - `positions`: whether the `ColumnMap`s keep their 1-based positions.

    **Returns:**

    One `ColumnMap` per name, in order.
    """
    mapped: list[ColumnMap] = []
    seen: dict[str, str] = {}
    for position, name in enumerate(names, start=1):
        if check is not None:
            check(position, name)
        unit = COLUMNS.get(name)
        if unit is None:
            mapped.append(unknown(position, name))
            continue
        if unit.quantity in seen:
            raise ValueError(repeated(name, unit.quantity, seen[unit.quantity]))
        seen[unit.quantity] = name
        shown = position if positions else None
        mapped.append(ColumnMap(name, unit.quantity, unit.to_si, shown))
    lacking = missing_quantities(seen, required)
    if lacking:
        raise ValueError(missing(lacking[0]))
    return mapped


def map_columns(
    names: list[str],
    path,
    line: int,
    positions: bool = False,
    required: tuple[str, ...] = ("time", "force"),
) -> list[ColumnMap]:
    """Map the header's column names to canonical quantities and unit factors.

    **Arguments:**

    - `names`: the header cells, stripped.
    - `path`, `line`: file and 1-based line number of the header, for errors.
    - `positions`: whether error messages about the rows give column positions.
    - `required`: the quantities that must have a column.

    **Returns:**

    One `ColumnMap` per column, in file order. Unknown names are extra columns.
    """

    def check(position: int, name: str) -> None:
        if not name:
            raise ValueError(
                f"{where(path, line)}: column {position} of the header has no name."
            )
        # The earlier names are those of the columns mapped so far.
        if name in names[: position - 1]:
            raise ValueError(f"{where(path, line, name)}: repeated in the header.")

    return map_names(
        names,
        unknown=lambda position, name: ColumnMap(
            name, None, 1.0, position if positions else None
        ),
        repeated=lambda name, quantity, first: (
            f"{where(path, line, name)}: a second {quantity} column (the first is "
            f"'{first}')."
        ),
        missing=lambda quantity: (
            f"{where(path, line, written_name(quantity))}: required column is "
            f"missing (the header has {', '.join(names)}; {quantity} is read from "
            f"{accepted_names(quantity)})."
        ),
        required=required,
        check=check,
        positions=positions,
    )


def split_cells(line: str, sep: str) -> list[str]:
    """The cells of a line, as written (quotes removed)."""
    # csv handles quoted cells. One line at a time, so that an unbalanced quote cannot
    # swallow the following lines and shift the line numbers in error messages. A
    # line without quotes splits the same way by str.split, several times faster.
    if '"' not in line:
        return line.split(sep)
    try:
        return next(csv.reader([line], delimiter=sep), [])
    except csv.Error:
        # A cell over csv's field size limit (128 KiB): the same rules, in Python.
        return _split_quoted(line, sep)


def _split_quoted(line: str, sep: str) -> list[str]:
    """`split_cells` of a line that `csv` refuses, by `csv`'s rules for its default
    dialect: a cell that starts with a quote runs to the next lone quote (`""` is
    a quote in it); anything after that quote up to the separator is kept."""
    cells: list[str] = []
    cell: list[str] = []
    quoted, at_start = False, True
    i = 0
    while i < len(line):
        char = line[i]
        if quoted:
            if char == '"' and line.startswith('""', i):
                cell.append('"')
                i += 1
            elif char == '"':
                quoted = False
            else:
                cell.append(char)
        elif char == sep:
            cells.append("".join(cell))
            cell, at_start = [], True
            i += 1
            continue
        elif char == '"' and at_start:
            quoted = True
        else:
            cell.append(char)
        at_start = False
        i += 1
    cells.append("".join(cell))
    return cells


def row_cells(line: str, sep: str) -> list[str]:
    """The stripped cells of a line, trailing empty cells (a trailing separator, as
    spreadsheet programs write) removed."""
    cells = [cell.strip() for cell in split_cells(line, sep)]
    while cells and not cells[-1]:
        cells.pop()
    return cells


def parse_number(cell: str, decimal_comma: bool) -> float:
    """`float(cell)`, reading `1,5` as 1.5 when the file uses decimal commas."""
    # float() reads `1_5` as 15 (Python's digit grouping), which no tester writes: a
    # typo, to be reported rather than read as a number ten times too large.
    if "_" in cell:
        raise ValueError(f"{_show(cell)} is not a number")
    if decimal_comma:
        cell = cell.replace(",", ".")
    return float(cell)


def parse_rows(
    lines: list[str],
    start: int,
    columns: list[ColumnMap],
    path,
    sep: str = ",",
    decimal_comma: bool = False,
    named_by: str = "the header",
) -> tuple[np.ndarray, np.ndarray]:
    """Parse the numeric rows after the header.

    **Arguments:**

    - `lines`: the lines of the file.
    - `start`: 0-based index of the first data line.
    - `columns`: the column map; `IGNORE` columns are not parsed.
    - `path`: the file name, for error messages.
    - `sep`: the cell separator.
    - `decimal_comma`: whether numbers are written `1,5`.
    - `named_by`: what named the columns, for error messages.

    **Returns:**

    `(values, line_numbers)`: a `(rows, columns)` float array in the file's units (NaN
    in ignored columns) and the 1-based line number of each row. Blank lines are
    skipped.
    """
    numbers = [start + k + 1 for k, text in enumerate(lines[start:]) if text.strip()]
    if not numbers:
        raise ValueError(
            f"{where(path, max(start, 1))}: no data rows after the header."
        )
    fast = _parse_rows_fast(lines, numbers, columns, sep, decimal_comma)
    if fast is not None:
        return fast
    parsed = [(i, c) for i, c in enumerate(columns) if c.quantity != IGNORE]
    rows = []
    for line in numbers:
        text = lines[line - 1]
        cells = split_cells(text, sep)
        while len(cells) > len(columns) and not cells[-1].strip():
            cells.pop()  # a trailing separator
        if len(cells) > len(columns):
            raise ValueError(
                f"{where(path, line)}: {len(cells)} cells but {named_by} names "
                f"{len(columns)} columns."
            )
        row = [math.nan] * len(columns)
        for position, column in parsed:
            place = where(path, line, column.name, column.position)
            if position >= len(cells):
                raise ValueError(
                    f"{place}: missing cell (the row has {len(cells)} of "
                    f"{len(columns)} cells)."
                )
            cell = cells[position].strip()
            try:
                value = parse_number(cell, decimal_comma)
            except ValueError:
                what = "empty cell" if not cell else f"{_show(cell)} is not a number"
                raise ValueError(f"{place}: {what}.") from None
            if not math.isfinite(value):
                raise ValueError(f"{place}: {_show(cell)} is not a finite number.")
            row[position] = value
        rows.append(row)
    return np.asarray(rows, dtype=float), np.asarray(numbers, dtype=int)


def _parse_rows_fast(
    lines: list[str],
    numbers: list[int],
    columns: list[ColumnMap],
    sep: str,
    decimal_comma: bool,
) -> tuple[np.ndarray, np.ndarray] | None:
    """`parse_rows`'s result by numpy's C parser (far faster on exports of many
    thousand rows), or None wherever it might differ: then the exact, line-by-line
    parser runs and names the line and column of the problem."""
    if decimal_comma:
        return None
    texts = [lines[n - 1] for n in numbers]
    # More separators than columns: extra cells, a trailing separator or a separator
    # inside quotes, which the exact parser tells apart.
    if max(text.count(sep) for text in texts) >= len(columns):
        return None
    used = [i for i, c in enumerate(columns) if c.quantity != IGNORE]
    try:
        parsed = np.loadtxt(
            texts,
            delimiter=sep,
            quotechar='"',
            usecols=used,
            comments=None,
            ndmin=2,
            dtype=float,
        )
    except ValueError:
        return None
    if not np.all(np.isfinite(parsed)):
        return None
    values = np.full((len(texts), len(columns)), math.nan)
    values[:, used] = parsed
    return values, np.asarray(numbers, dtype=int)


def _require_increasing_time(
    time, line_numbers, column: ColumnMap, path, converted: bool = False
) -> None:
    """Raise `ValueError` at the first time stamp that does not follow the one
    before (`converted`: the stamps in seconds, where distinct stamps in the file's
    unit may have become equal)."""
    with np.errstate(over="ignore", invalid="ignore"):
        steps = np.diff(time)
    bad = np.flatnonzero(~(steps > 0))
    if bad.size:
        i = int(bad[0]) + 1
        what = "a repeated time stamp" if time[i] == time[i - 1] else "time goes back"
        if converted:
            what += f" after the conversion from {column.name} to seconds"
        raise ValueError(
            f"{where(path, int(line_numbers[i]), column.name, column.position)}: "
            f"time must be strictly increasing, but {time[i]:g} follows "
            f"{time[i - 1]:g} (line {int(line_numbers[i - 1])}): {what}."
        )


def _to_si(values, line_numbers, column: ColumnMap, path) -> np.ndarray:
    """A column in SI units, checked finite: a value near the largest float may
    overflow (`1e306` h is `inf` s)."""
    with np.errstate(over="ignore"):
        converted = (values + column.offset) * column.to_si
    bad = np.flatnonzero(~np.isfinite(converted))
    if bad.size:
        i = int(bad[0])
        raise ValueError(
            f"{where(path, int(line_numbers[i]), column.name, column.position)}: "
            f"{values[i]:g} is out of range ({converted[i]:g} in SI units)."
        )
    if column.quantity == "time" and column.to_si != 1.0:
        _require_increasing_time(converted, line_numbers, column, path, True)
    return converted


def assemble(
    path,
    columns: list[ColumnMap],
    values: np.ndarray,
    line_numbers: np.ndarray,
    metadata: dict[str, float | str],
    header_line: int | None,
) -> TestData:
    """Build the [`jaxcable.TestData`][] of parsed rows: unit conversion, time and
    metadata checks (time strictly increasing in the file's unit and in seconds,
    every value finite in SI units). A file without a force column (an elongation
    history to simulate) gets NaN forces."""
    fields: dict[str, np.ndarray] = {}
    extra: dict[str, np.ndarray] = {}
    for position, column in enumerate(columns):
        if column.quantity == IGNORE:
            continue
        if column.quantity is None:
            extra[column.name] = values[:, position]
        else:
            if column.quantity == "time":
                _require_increasing_time(
                    values[:, position], line_numbers, column, path
                )
            fields[column.quantity] = _to_si(
                values[:, position], line_numbers, column, path
            )
    if "length_mm" not in metadata:
        raise ValueError(
            f"{where(path, header_line)}, metadata 'length_mm': missing (the free "
            "length of the cable, mm); add a line '# length_mm: ...' above the header "
            "or pass metadata={'length_mm': ...} (--length-mm on the command line)."
        )
    names = {c.quantity: c.name for c in columns if c.quantity in fields}
    return TestData(
        time=fields["time"],
        force=fields.get("force", np.full(line_numbers.shape, np.nan)),
        elongation=fields.get("elongation"),
        temperature=fields.get("temperature"),
        extra=extra,
        metadata=metadata,
        source=str(path),
        lines=line_numbers,
        column_names=names,
    )
