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
[`jaxcable.TestData`][] holds SI. The parser is split into a metadata block, a column
map (file column -> canonical quantity and unit factor) and numeric rows, so that raw
tensile-tester exports (other separators, encodings, column names) can reuse it.
"""

import csv
import dataclasses
import math
import os
from collections.abc import Mapping
from typing import NamedTuple

import numpy as np

from ._cable import Cable


DEFAULT_DIAMETER_MM = 3.0
DEFAULT_RATE_MM_PER_MIN = 3.0

# Metadata keys parsed as numbers, with whether they must be strictly positive. Other
# keys are kept as strings.
_NUMERIC_METADATA = {
    "length_mm": True,
    "diameter_mm": True,
    "rate_mm_per_min": True,
    "temperature_C": False,
}


class _Unit(NamedTuple):
    quantity: str
    to_si: float  # file value * to_si = value in the TestData field's unit


# Column names a file may use for each canonical quantity. The first listed for a
# quantity is the one written.
_COLUMNS: dict[str, _Unit] = {
    "time_s": _Unit("time", 1.0),
    "time_ms": _Unit("time", 1e-3),
    "time_min": _Unit("time", 60.0),
    "time_h": _Unit("time", 3600.0),
    "force_N": _Unit("force", 1.0),
    "force_kN": _Unit("force", 1e3),
    "elongation_mm": _Unit("elongation", 1e-3),
    "elongation_m": _Unit("elongation", 1.0),
    "temperature_C": _Unit("temperature", 1.0),
}
_QUANTITIES = ("time", "force", "elongation", "temperature")
_REQUIRED = ("time", "force")


def _written_name(quantity: str) -> str:
    return next(name for name, unit in _COLUMNS.items() if unit.quantity == quantity)


def _accepted_names(quantity: str) -> list[str]:
    return [name for name, unit in _COLUMNS.items() if unit.quantity == quantity]


def _where(path, line=None, column=None) -> str:
    """The location prefix of every error message: file, 1-based line, column."""
    parts = [str(path)]
    if line is not None:
        parts.append(f"line {line}")
    if column is not None:
        parts.append(f"column '{column}'")
    return ", ".join(parts)


@dataclasses.dataclass(frozen=True, eq=False)
class TestData:
    """One measured or simulated cable test: a time-stamped force (and elongation)
    history with its metadata, as read from or written to the canonical CSV file.

    **Fields:**

    - `time`: sample times, s.
    - `force`: cable force, N.
    - `elongation`: elongation, m, or `None` when the file has no elongation column.
    - `temperature`: temperature at each sample, °C, or `None`.
    - `extra`: any other columns, by their name in the file, values as in the file
        (not converted); carried through on write.
    - `metadata`: the `# key: value` block. `length_mm`, `diameter_mm`,
        `rate_mm_per_min` and `temperature_C` are floats in the units their names say;
        every other key (`material`, `id`, ...) is a string.
    - `source`: the file the data were read from (for error messages), or `None`.
    - `lines`: the 1-based line number of each sample in `source`, or `None`.
    """

    # pytest would otherwise try to collect this class wherever it is imported.
    __test__ = False

    time: np.ndarray
    force: np.ndarray
    elongation: np.ndarray | None = None
    temperature: np.ndarray | None = None
    extra: dict[str, np.ndarray] = dataclasses.field(default_factory=dict)
    metadata: dict[str, float | str] = dataclasses.field(default_factory=dict)
    source: str | None = None
    lines: np.ndarray | None = None

    def __post_init__(self):
        arrays = {"time": self.time, "force": self.force}
        for name in ("elongation", "temperature"):
            if getattr(self, name) is not None:
                arrays[name] = getattr(self, name)
        for name, value in self.extra.items():
            arrays[f"extra[{name!r}]"] = value
        converted = {}
        for name, value in arrays.items():
            v = np.asarray(value, dtype=float)
            if v.ndim != 1:
                raise ValueError(
                    f"TestData `{name}` must be 1-dimensional, got shape {v.shape}."
                )
            converted[name] = v
        lengths = {name: v.shape[0] for name, v in converted.items()}
        if len(set(lengths.values())) != 1:
            raise ValueError(f"TestData columns differ in length: {lengths}.")
        if lengths["time"] == 0:
            raise ValueError("TestData needs at least one sample.")
        for name in _QUANTITIES:
            if name in converted:
                object.__setattr__(self, name, converted[name])
        canonical = set(_COLUMNS)
        extra = {}
        for name in self.extra:
            if name in canonical:
                raise ValueError(
                    f"TestData extra column '{name}' is a canonical column; set the "
                    f"`{_COLUMNS[name].quantity}` field instead."
                )
            extra[name] = converted[f"extra[{name!r}]"]
        object.__setattr__(self, "extra", extra)
        object.__setattr__(self, "metadata", dict(self.metadata))
        if self.lines is not None:
            object.__setattr__(self, "lines", np.asarray(self.lines, dtype=int))

    @property
    def num_samples(self) -> int:
        """The number of samples (rows)."""
        return int(self.time.shape[0])

    def cable(self) -> Cable:
        """The [`jaxcable.Cable`][] described by the metadata, in SI.

        `length_mm` is required; `diameter_mm` defaults to 3 mm and `rate_mm_per_min`
        (the crosshead speed) to 3 mm/min, Park's Dyneema SK78 test.

        **Returns:**

        A [`jaxcable.Cable`][] with `length` and `diameter` in m and `speed` in m/s.
        """
        if "length_mm" not in self.metadata:
            raise ValueError(
                f"{_where(self.source or '<TestData>')}: metadata has no 'length_mm' "
                "(the free length of the cable, mm)."
            )
        length_mm = float(self.metadata["length_mm"])
        diameter_mm = float(self.metadata.get("diameter_mm", DEFAULT_DIAMETER_MM))
        rate = float(self.metadata.get("rate_mm_per_min", DEFAULT_RATE_MM_PER_MIN))
        return Cable(
            length=length_mm * 1e-3, diameter=diameter_mm * 1e-3, speed=rate * 1e-3 / 60
        )

    def locate(self, index: int, column: str | None = None) -> str:
        """Where sample `index` came from: `file, line N, column 'name'` (for errors)."""
        if self.lines is None:
            where = _where(self.source or "<TestData>", column=column)
            return f"{where}, sample {index}"
        return _where(self.source, int(self.lines[index]), column)


# ----------------------------------------------------------------------------------
# Reading


def _read_lines(path) -> list[str]:
    # utf-8-sig: spreadsheet programs prepend a byte-order mark.
    with open(path, encoding="utf-8-sig", newline="") as f:
        return f.read().splitlines()


def _metadata_value(key: str, value, where: str) -> float | str:
    """Parse one metadata value: a float for the numeric keys, else a string."""
    if key not in _NUMERIC_METADATA:
        return str(value)
    if isinstance(value, bool):
        raise ValueError(f"{where}: {value!r} is not a number.")
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{where}: {str(value)!r} is not a number.") from None
    if not math.isfinite(number):
        raise ValueError(f"{where}: {str(value)!r} is not a finite number.")
    if _NUMERIC_METADATA[key] and number <= 0:
        raise ValueError(f"{where}: must be positive, got {number:g}.")
    return number


def _parse_metadata(lines: list[str], path) -> tuple[dict[str, float | str], int]:
    """Parse the leading `# key: value` block.

    **Arguments:**

    - `lines`: the lines of the file.
    - `path`: the file name, for error messages.

    **Returns:**

    `(metadata, header)`: the metadata and the 0-based index of the first line that is
    neither blank nor a comment (the header). `#` lines without a colon are free
    comments and are skipped.
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
        where = f"{_where(path, index + 1)}, metadata '{key}'"
        if not key:
            raise ValueError(f"{_where(path, index + 1)}: metadata line has no key.")
        if key in first_seen:
            raise ValueError(
                f"{where}: repeated (first given on line {first_seen[key]})."
            )
        first_seen[key] = index + 1
        metadata[key] = _metadata_value(key, value, where)
    raise ValueError(
        f"{_where(path, len(lines) + 1)}: no header line (expected e.g. "
        "'time_s,force_N' after the '# key: value' lines)."
    )


class _ColumnMap(NamedTuple):
    name: str  # as in the file
    quantity: str | None  # canonical quantity, or None for an extra column
    to_si: float


def _map_columns(names: list[str], path, line: int) -> list[_ColumnMap]:
    """Map the header's column names to canonical quantities and unit factors.

    **Arguments:**

    - `names`: the header cells, stripped.
    - `path`, `line`: file and 1-based line number of the header, for errors.

    **Returns:**

    One `_ColumnMap` per column, in file order. Unknown names are extra columns.
    """
    mapped: list[_ColumnMap] = []
    seen: dict[str, str] = {}
    for position, name in enumerate(names, start=1):
        if not name:
            raise ValueError(
                f"{_where(path, line)}: column {position} of the header has no name."
            )
        if any(m.name == name for m in mapped):
            raise ValueError(f"{_where(path, line, name)}: repeated in the header.")
        unit = _COLUMNS.get(name)
        if unit is None:
            mapped.append(_ColumnMap(name, None, 1.0))
            continue
        if unit.quantity in seen:
            raise ValueError(
                f"{_where(path, line, name)}: a second {unit.quantity} column (the "
                f"first is '{seen[unit.quantity]}')."
            )
        seen[unit.quantity] = name
        mapped.append(_ColumnMap(name, unit.quantity, unit.to_si))
    for quantity in _REQUIRED:
        if quantity not in seen:
            accepted = " or ".join(f"'{n}'" for n in _accepted_names(quantity))
            raise ValueError(
                f"{_where(path, line, _written_name(quantity))}: required column is "
                f"missing (the header has {', '.join(names)}; {quantity} is read "
                f"from {accepted})."
            )
    return mapped


def _split(line: str, sep: str) -> list[str]:
    # csv handles quoted cells. One line at a time, so that an unbalanced quote cannot
    # swallow the following lines and shift the line numbers in error messages.
    return next(csv.reader([line], delimiter=sep), [])


def _parse_rows(
    lines: list[str], start: int, columns: list[_ColumnMap], path, sep: str = ","
) -> tuple[np.ndarray, np.ndarray]:
    """Parse the numeric rows after the header.

    **Arguments:**

    - `lines`: the lines of the file.
    - `start`: 0-based index of the first line after the header.
    - `columns`: the header's column map.
    - `path`: the file name, for error messages.

    **Returns:**

    `(values, line_numbers)`: a `(rows, columns)` float array in the file's units and
    the 1-based line number of each row. Blank lines are skipped.
    """
    rows = []
    numbers = []
    for offset, text in enumerate(lines[start:]):
        line = start + offset + 1
        if not text.strip():
            continue
        cells = _split(text, sep)
        if len(cells) > len(columns):
            raise ValueError(
                f"{_where(path, line)}: {len(cells)} cells but the header names "
                f"{len(columns)} columns."
            )
        row = []
        for position, column in enumerate(columns):
            if position >= len(cells):
                raise ValueError(
                    f"{_where(path, line, column.name)}: missing cell (the row has "
                    f"{len(cells)} of {len(columns)} cells)."
                )
            cell = cells[position].strip()
            try:
                value = float(cell)
            except ValueError:
                what = "empty cell" if not cell else f"{cell!r} is not a number"
                raise ValueError(
                    f"{_where(path, line, column.name)}: {what}."
                ) from None
            if not math.isfinite(value):
                raise ValueError(
                    f"{_where(path, line, column.name)}: {cell!r} is not a finite "
                    "number."
                )
            row.append(value)
        rows.append(row)
        numbers.append(line)
    if not rows:
        raise ValueError(f"{_where(path, start)}: no data rows after the header.")
    return np.asarray(rows, dtype=float), np.asarray(numbers, dtype=int)


def _require_increasing_time(time, line_numbers, name: str, path) -> None:
    steps = np.diff(time)
    bad = np.flatnonzero(steps <= 0)
    if bad.size:
        i = int(bad[0]) + 1
        raise ValueError(
            f"{_where(path, int(line_numbers[i]), name)}: time must be strictly "
            f"increasing, but {time[i]:g} follows {time[i - 1]:g} (line "
            f"{int(line_numbers[i - 1])})."
        )


def read_csv(path: str | os.PathLike, **overrides: float | str) -> TestData:
    """Read a test history in the canonical CSV format.

    The file starts with `# key: value` lines (`length_mm` required; `diameter_mm`,
    `rate_mm_per_min`, `temperature_C`, `material`, `id` and any other keys optional),
    then a header line naming the columns with their units (`time_s` and `force_N`
    required; `elongation_mm` and `temperature_C` optional; also accepted: `time_ms`,
    `time_min`, `time_h`, `force_kN`, `elongation_m`; any other column is kept as an
    extra column), then one row of numbers per sample. Time must increase strictly.

    **Arguments:**

    - `path`: the file.
    - `**overrides`: metadata values that replace or add to the file's, e.g.
        `length_mm=300`.

    **Returns:**

    A [`jaxcable.TestData`][] in SI units (s, N, m; temperature in °C).

    **Raises:**

    `ValueError` naming the file, the 1-based line and the column (or metadata key) of
    the first problem: a missing required column, a non-numeric, empty, NaN or
    infinite cell, time not strictly increasing, or no `length_mm` metadata.
    """
    lines = _read_lines(path)
    metadata, header = _parse_metadata(lines, path)
    for key, value in overrides.items():
        metadata[key] = _metadata_value(key, value, f"{path}, argument {key}")
    header_line = header + 1
    names = [cell.strip() for cell in _split(lines[header], ",")]
    columns = _map_columns(names, path, header_line)
    values, line_numbers = _parse_rows(lines, header + 1, columns, path)

    fields: dict[str, np.ndarray] = {}
    extra: dict[str, np.ndarray] = {}
    for position, column in enumerate(columns):
        if column.quantity is None:
            extra[column.name] = values[:, position]
        else:
            fields[column.quantity] = values[:, position] * column.to_si
            if column.quantity == "time":
                _require_increasing_time(
                    values[:, position], line_numbers, column.name, path
                )
    if "length_mm" not in metadata:
        raise ValueError(
            f"{_where(path, header_line)}, metadata 'length_mm': missing (the free "
            "length of the cable, mm); add a line '# length_mm: ...' above the header "
            "or pass length_mm=..."
        )
    return TestData(
        time=fields["time"],
        force=fields["force"],
        elongation=fields.get("elongation"),
        temperature=fields.get("temperature"),
        extra=extra,
        metadata=metadata,
        source=str(path),
        lines=line_numbers,
    )


# ----------------------------------------------------------------------------------
# Writing


def _format_metadata(value: float | str) -> str:
    if isinstance(value, str):
        return value
    value = float(value)
    if value.is_integer() and abs(value) < 1e15:
        return str(int(value))
    return repr(value)


def _check_metadata_for_writing(metadata: Mapping[str, float | str]) -> None:
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
    its order. Numbers are written with full precision (`repr`), so reading the file
    back gives the same values up to the mm <-> m conversion (1 ulp).

    **Arguments:**

    - `path`: the file to (over)write.
    - `data`: a [`jaxcable.TestData`][]; its metadata must have `length_mm`.

    **Returns:**

    Nothing.
    """
    _check_metadata_for_writing(data.metadata)
    names = []
    columns = []
    for quantity in _QUANTITIES:
        value = getattr(data, quantity)
        if value is None:
            continue
        name = _written_name(quantity)
        names.append(name)
        columns.append(np.asarray(value, dtype=float) / _COLUMNS[name].to_si)
    for name, value in data.extra.items():
        if any(c in name for c in ',"\n\r'):
            raise ValueError(f"Extra column name {name!r} cannot be written.")
        names.append(name)
        columns.append(np.asarray(value, dtype=float))
    out = [f"# {key}: {_format_metadata(v)}" for key, v in data.metadata.items()]
    out.append(",".join(names))
    table = np.stack(columns, axis=1).tolist()
    out.extend(",".join(map(repr, row)) for row in table)
    with open(path, "w", encoding="utf-8", newline="\n") as f:
        f.write("\n".join(out) + "\n")
