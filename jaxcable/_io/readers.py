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
map (file column -> canonical quantity and unit factor) and numeric rows, which
[`jaxcable.read_test`][] reuses for raw tensile-tester exports: other separators and
encodings, preamble and unit rows, quoted numbers, columns named by the caller, and
slack detection (`_slack.py`).
"""

import csv
import dataclasses
import math
import os
import re
from collections.abc import Mapping, Sequence
from typing import NamedTuple

import numpy as np

from .._cable import ZERO_CELSIUS, Cable
from . import slack as _slack
from .slack import SlackReport as SlackReport, SlackStretch as SlackStretch


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
# The `columns` name of a file column to skip (not parsed).
_IGNORE = "-"


def _written_name(quantity: str) -> str:
    return next(name for name, unit in _COLUMNS.items() if unit.quantity == quantity)


def _accepted_names(quantity: str) -> list[str]:
    return [name for name, unit in _COLUMNS.items() if unit.quantity == quantity]


def _where(path, line=None, column=None, position=None) -> str:
    """The location prefix of every error message: file, 1-based line, column (its
    1-based position in the row when known, and its name)."""
    parts = [str(path)]
    if line is not None:
        parts.append(f"line {line}")
    if column is not None:
        number = "" if position is None else f"{position} "
        parts.append(f"column {number}'{column}'")
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
    - `mask`: per sample, True where it is to be fitted, False where it is not (a
        slack stretch, see [`jaxcable.mask_slack`][]). All True unless set. It weights
        residuals only: the whole history, masked samples included, still drives a
        simulation (with `force` there, which is never negative).
    - `force_raw`: the force as measured, N, where `force` differs from it (negative
        readings clipped to 0 by [`jaxcable.mask_slack`][]); `None` when `force` is
        the measured force.
    - `slack_report`: what [`jaxcable.mask_slack`][] found (a
        [`jaxcable.SlackReport`][]), or `None` when it has not run (e.g.
        [`jaxcable.read_csv`][]).

    Also available as `jaxcable.Test`.
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
    mask: np.ndarray | None = None
    force_raw: np.ndarray | None = None
    slack_report: SlackReport | None = None

    def __post_init__(self):
        arrays = {"time": self.time, "force": self.force}
        for name in ("elongation", "temperature", "force_raw"):
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
        for name in (*_QUANTITIES, "force_raw"):
            if name in converted:
                object.__setattr__(self, name, converted[name])
        if self.mask is None:
            mask = np.ones(lengths["time"], dtype=bool)
        else:
            mask = np.asarray(self.mask, dtype=bool)
            if mask.shape != (lengths["time"],):
                raise ValueError(
                    f"TestData `mask` must have shape ({lengths['time']},) like "
                    f"`time`, got {mask.shape}."
                )
        object.__setattr__(self, "mask", mask)
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
        (the crosshead speed) to 3 mm/min, Park's Dyneema SK78 test. The temperature
        is the metadata's `temperature_C`, else the mean of the temperature column,
        else the `Cable` default (20 °C); the breaking load is `breaking_load_N` when
        given, else the `Cable` default.

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
        kwargs = {}
        if "breaking_load_N" in self.metadata:
            kwargs["breaking_load"] = float(self.metadata["breaking_load_N"])
        if "temperature_C" in self.metadata:
            kwargs["temperature"] = float(self.metadata["temperature_C"]) + ZERO_CELSIUS
        elif self.temperature is not None:
            kwargs["temperature"] = float(np.mean(self.temperature)) + ZERO_CELSIUS
        return Cable(
            length=length_mm * 1e-3,
            diameter=diameter_mm * 1e-3,
            speed=rate * 1e-3 / 60,
            **kwargs,
        )

    def locate(self, index: int, column: str | None = None) -> str:
        """Where sample `index` came from: `file, line N, column 'name'` (for errors)."""
        if self.lines is None:
            where = _where(self.source or "<TestData>", column=column)
            return f"{where}, sample {index}"
        return _where(self.source, int(self.lines[index]), column)


# The name issue 3 gives an experiment.
Test = TestData


# ----------------------------------------------------------------------------------
# Reading

# Tried in order when no encoding is given. utf-8-sig: spreadsheet programs prepend a
# byte-order mark. gb18030 (a superset of GBK): Chinese tensile testers' headers.
# latin-1 decodes any bytes, so a header in an unknown encoding never stops a file
# whose numbers are ASCII.
_ENCODINGS = ("utf-8-sig", "gb18030", "latin-1")


def _read_text(path, encoding: str | None = None) -> str:
    """The file's text, decoded with `encoding` or the first of `_ENCODINGS` that
    decodes it."""
    with open(path, "rb") as f:
        raw = f.read()
    if encoding is None:
        for candidate in _ENCODINGS[:-1]:
            try:
                return raw.decode(candidate)
            except UnicodeDecodeError:
                continue
        return raw.decode(_ENCODINGS[-1])
    try:
        text = raw.decode(encoding)
    except LookupError:
        raise ValueError(f"{path}: unknown encoding {encoding!r}.") from None
    except UnicodeDecodeError as e:
        line = raw.count(b"\n", 0, e.start) + 1
        raise ValueError(
            f"{_where(path, line)}: cannot be decoded as {encoding} ({e.reason} at "
            f"byte {e.start}); leave the encoding out to have it detected."
        ) from None
    return text.removeprefix("\ufeff")


def _read_lines(path, encoding: str | None = None) -> list[str]:
    # Split on CR, LF and CRLF only: str.splitlines also splits on characters such as
    # U+0085, which a header decoded as latin-1 may hold, and would shift the line
    # numbers of error messages.
    lines = re.split(r"\r\n|\r|\n", _read_text(path, encoding))
    if lines and lines[-1] == "":
        lines.pop()
    return lines


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
        where = f"{_where(path, index + 1)}, metadata '{key}'"
        if not key:
            raise ValueError(f"{_where(path, index + 1)}: metadata line has no key.")
        if key in first_seen:
            raise ValueError(
                f"{where}: repeated (first given on line {first_seen[key]})."
            )
        first_seen[key] = index + 1
        metadata[key] = _metadata_value(key, value, where)
    return metadata, len(lines)


class _ColumnMap(NamedTuple):
    name: str  # as in the file (or in `columns`)
    quantity: str | None  # canonical quantity, None for an extra column, or _IGNORE
    to_si: float
    position: int | None = None  # 1-based, shown in error messages when set


def _map_columns(
    names: list[str], path, line: int, positions: bool = False
) -> list[_ColumnMap]:
    """Map the header's column names to canonical quantities and unit factors.

    **Arguments:**

    - `names`: the header cells, stripped.
    - `path`, `line`: file and 1-based line number of the header, for errors.
    - `positions`: whether error messages about the rows give column positions.

    **Returns:**

    One `_ColumnMap` per column, in file order. Unknown names are extra columns.
    """
    mapped: list[_ColumnMap] = []
    seen: dict[str, str] = {}
    for position, name in enumerate(names, start=1):
        shown = position if positions else None
        if not name:
            raise ValueError(
                f"{_where(path, line)}: column {position} of the header has no name."
            )
        if any(m.name == name for m in mapped):
            raise ValueError(f"{_where(path, line, name)}: repeated in the header.")
        unit = _COLUMNS.get(name)
        if unit is None:
            mapped.append(_ColumnMap(name, None, 1.0, shown))
            continue
        if unit.quantity in seen:
            raise ValueError(
                f"{_where(path, line, name)}: a second {unit.quantity} column (the "
                f"first is '{seen[unit.quantity]}')."
            )
        seen[unit.quantity] = name
        mapped.append(_ColumnMap(name, unit.quantity, unit.to_si, shown))
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
    # swallow the following lines and shift the line numbers in error messages. A
    # line without quotes splits the same way by str.split, several times faster.
    if '"' not in line:
        return line.split(sep)
    return next(csv.reader([line], delimiter=sep), [])


def _cells(line: str, sep: str) -> list[str]:
    """The stripped cells of a line, trailing empty cells (a trailing separator, as
    spreadsheet programs write) removed."""
    cells = [cell.strip() for cell in _split(line, sep)]
    while cells and not cells[-1]:
        cells.pop()
    return cells


def _number(cell: str, decimal_comma: bool) -> float:
    """`float(cell)`, reading `1,5` as 1.5 when the file uses decimal commas."""
    if decimal_comma:
        cell = cell.replace(",", ".")
    return float(cell)


def _parse_rows(
    lines: list[str],
    start: int,
    columns: list[_ColumnMap],
    path,
    sep: str = ",",
    decimal_comma: bool = False,
    named_by: str = "the header",
) -> tuple[np.ndarray, np.ndarray]:
    """Parse the numeric rows after the header.

    **Arguments:**

    - `lines`: the lines of the file.
    - `start`: 0-based index of the first data line.
    - `columns`: the column map; `_IGNORE` columns are not parsed.
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
            f"{_where(path, max(start, 1))}: no data rows after the header."
        )
    fast = _parse_rows_fast(lines, numbers, columns, sep, decimal_comma)
    if fast is not None:
        return fast
    parsed = [(i, c) for i, c in enumerate(columns) if c.quantity != _IGNORE]
    rows = []
    for line in numbers:
        text = lines[line - 1]
        cells = _split(text, sep)
        while len(cells) > len(columns) and not cells[-1].strip():
            cells.pop()  # a trailing separator
        if len(cells) > len(columns):
            raise ValueError(
                f"{_where(path, line)}: {len(cells)} cells but {named_by} names "
                f"{len(columns)} columns."
            )
        row = [math.nan] * len(columns)
        for position, column in parsed:
            where = _where(path, line, column.name, column.position)
            if position >= len(cells):
                raise ValueError(
                    f"{where}: missing cell (the row has {len(cells)} of "
                    f"{len(columns)} cells)."
                )
            cell = cells[position].strip()
            try:
                value = _number(cell, decimal_comma)
            except ValueError:
                what = "empty cell" if not cell else f"{cell!r} is not a number"
                raise ValueError(f"{where}: {what}.") from None
            if not math.isfinite(value):
                raise ValueError(f"{where}: {cell!r} is not a finite number.")
            row[position] = value
        rows.append(row)
    return np.asarray(rows, dtype=float), np.asarray(numbers, dtype=int)


def _parse_rows_fast(
    lines: list[str],
    numbers: list[int],
    columns: list[_ColumnMap],
    sep: str,
    decimal_comma: bool,
) -> tuple[np.ndarray, np.ndarray] | None:
    """`_parse_rows`'s result by numpy's C parser (ten times faster on 90 000-row
    exports), or None wherever it might differ: then the exact, line-by-line parser
    runs and names the line and column of the problem."""
    if decimal_comma:
        return None
    texts = [lines[n - 1] for n in numbers]
    # More separators than columns: extra cells, a trailing separator or a separator
    # inside quotes, which the exact parser tells apart.
    if max(text.count(sep) for text in texts) >= len(columns):
        return None
    used = [i for i, c in enumerate(columns) if c.quantity != _IGNORE]
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


def _require_increasing_time(time, line_numbers, column: _ColumnMap, path) -> None:
    steps = np.diff(time)
    bad = np.flatnonzero(steps <= 0)
    if bad.size:
        i = int(bad[0]) + 1
        what = "a repeated time stamp" if time[i] == time[i - 1] else "time goes back"
        raise ValueError(
            f"{_where(path, int(line_numbers[i]), column.name, column.position)}: "
            f"time must be strictly increasing, but {time[i]:g} follows "
            f"{time[i - 1]:g} (line {int(line_numbers[i - 1])}): {what}."
        )


def _assemble(
    path,
    columns: list[_ColumnMap],
    values: np.ndarray,
    line_numbers: np.ndarray,
    metadata: dict[str, float | str],
    header_line: int | None,
) -> TestData:
    """Build the [`jaxcable.TestData`][] of parsed rows: unit conversion, time and
    metadata checks."""
    fields: dict[str, np.ndarray] = {}
    extra: dict[str, np.ndarray] = {}
    for position, column in enumerate(columns):
        if column.quantity == _IGNORE:
            continue
        if column.quantity is None:
            extra[column.name] = values[:, position]
        else:
            fields[column.quantity] = values[:, position] * column.to_si
            if column.quantity == "time":
                _require_increasing_time(
                    values[:, position], line_numbers, column, path
                )
    if "length_mm" not in metadata:
        raise ValueError(
            f"{_where(path, header_line)}, metadata 'length_mm': missing (the free "
            "length of the cable, mm); add a line '# length_mm: ...' above the header "
            "or pass length_mm=... (--length-mm on the command line)."
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


def read_csv(path: str | os.PathLike, **overrides: float | str) -> TestData:
    """Read a test history in the canonical CSV format.

    The file starts with `# key: value` lines (`length_mm` required; `diameter_mm`,
    `rate_mm_per_min`, `temperature_C`, `material`, `id` and any other keys optional),
    then a header line naming the columns with their units (`time_s` and `force_N`
    required; `elongation_mm` and `temperature_C` optional; also accepted: `time_ms`,
    `time_min`, `time_h`, `force_kN`, `elongation_m`; any other column is kept as an
    extra column), then one row of numbers per sample. Time must increase strictly.
    The file is read exactly as written: no slack detection (that is
    [`jaxcable.read_test`][], which reads canonical files too).

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
    if header == len(lines):
        raise ValueError(
            f"{_where(path, len(lines) + 1)}: no header line (expected e.g. "
            "'time_s,force_N' after the '# key: value' lines)."
        )
    for key, value in overrides.items():
        metadata[key] = _metadata_value(key, value, f"{path}, argument {key}")
    header_line = header + 1
    names = [cell.strip() for cell in _split(lines[header], ",")]
    columns = _map_columns(names, path, header_line)
    values, line_numbers = _parse_rows(lines, header + 1, columns, path)
    return _assemble(path, columns, values, line_numbers, metadata, header_line)


# ----------------------------------------------------------------------------------
# Raw exports

_SEPARATORS = {",": "comma", ";": "semicolon", "\t": "tab"}
_COLUMNS_HINT = (
    "pass columns=... (--columns on the command line) naming the file's columns in "
    "order with their units, e.g. 'time_s,elongation_mm,force_N' ('-' for a column "
    "to ignore)"
)
# Header words (lower case) for each quantity, for the best-effort header match. A
# crosshead displacement is the cable's elongation when it starts at zero with the
# test, as tensile testers zero it.
_HEADER_WORDS = {
    "time": ("time", "zeit", "temps", "tiempo", "时间", "時間"),
    "force": ("force", "load", "kraft", "力", "负荷", "負荷", "载荷", "荷重"),
    "elongation": (
        "elongation",
        "extension",
        "displacement",
        "stroke",
        "crosshead",
        "deformation",
        "weg",
        "位移",
        "伸长",
        "变形",
        "行程",
    ),
    "temperature": ("temperature", "temp", "temperatur", "温度"),
}
# (quantity, unit as written, lower case) -> canonical column name.
_HEADER_UNITS = {
    **{("time", u): "time_s" for u in ("s", "sec", "secs", "second", "seconds", "秒")},
    ("time", "ms"): "time_ms",
    **{("time", u): "time_min" for u in ("min", "mins", "minute", "minutes", "分钟")},
    **{("time", u): "time_h" for u in ("h", "hr", "hrs", "hour", "hours", "小时")},
    ("force", "n"): "force_N",
    ("force", "kn"): "force_kN",
    ("elongation", "mm"): "elongation_mm",
    ("elongation", "m"): "elongation_m",
    **{
        ("temperature", u): "temperature_C"
        for u in ("c", "°c", "℃", "degc", "deg c", "celsius")
    },
}
_ALL_UNITS = {unit for _, unit in _HEADER_UNITS}
# `Name (unit)`, `Name [unit]`, also with full-width brackets.
_BRACKETED_UNIT = re.compile(r"^(.*?)\s*[(\[（【]\s*([^)\]）】]*?)\s*[)\]）】]$")
_NON_NUMBER_WORD = re.compile(r"[^\W\d_]", re.UNICODE)  # any letter


def _parse_columns_spec(columns: str | Sequence[str], path) -> list[_ColumnMap]:
    """The column map named by `columns` (`"time_s,elongation_mm,force_N,-"`)."""
    tokens = (
        [t.strip() for t in columns.split(",")]
        if isinstance(columns, str)
        else [str(t).strip() for t in columns]
    )
    shown = ",".join(tokens)
    accepted = ", ".join(_COLUMNS)
    mapped: list[_ColumnMap] = []
    seen: dict[str, str] = {}
    for position, token in enumerate(tokens, start=1):
        if token == _IGNORE:
            mapped.append(_ColumnMap(_IGNORE, _IGNORE, 1.0, position))
            continue
        unit = _COLUMNS.get(token)
        if unit is None:
            raise ValueError(
                f"{path}: columns '{shown}': column {position} '{token}' is not a "
                f"column name (accepted: {accepted}, or '-' to ignore a column)."
            )
        if unit.quantity in seen:
            raise ValueError(
                f"{path}: columns '{shown}': '{token}' is a second {unit.quantity} "
                f"column (the first is '{seen[unit.quantity]}')."
            )
        seen[unit.quantity] = token
        mapped.append(_ColumnMap(token, unit.quantity, unit.to_si, position))
    for quantity in _REQUIRED:
        if quantity not in seen:
            names = " or ".join(f"'{n}'" for n in _accepted_names(quantity))
            raise ValueError(
                f"{path}: columns '{shown}' names no {quantity} column ({names})."
            )
    return mapped


def _is_number(cell: str, decimal_comma: bool) -> bool:
    try:
        _number(cell, decimal_comma)
    except ValueError:
        return False
    return True


def _all_numbers(cells: list[str], decimal_comma: bool) -> bool:
    """Whether `cells` is a row of at least 2 numbers (for sniffing the separator)."""
    return len(cells) >= 2 and all(_is_number(c, decimal_comma) for c in cells)


def _sniff_separator(lines: list[str], first: int) -> tuple[str, bool]:
    """The separator (`,`, `;` or tab) and decimal-comma flag under which most of the
    first 200 content lines are rows of numbers; `,` when none is."""
    sample = []
    for text in lines[first:]:
        if text.strip() and not text.lstrip().startswith("#"):
            sample.append(text)
            if len(sample) == 200:
                break
    best = (0, ",", False)
    for sep in _SEPARATORS:
        # A decimal comma is only possible where the comma does not separate cells.
        for decimal_comma in (False, True) if sep != "," else (False,):
            count = sum(_all_numbers(_cells(t, sep), decimal_comma) for t in sample)
            if count > best[0]:
                best = (count, sep, decimal_comma)
    return best[1], best[2]


def _looks_like_data(
    cells: list[str], decimal_comma: bool, spec: list[_ColumnMap] | None
) -> bool:
    """Whether a row is the first data row: numbers, without words.

    A row with a bad number but no letters (`12..5`, an empty cell) counts as data,
    so that it is reported as an error rather than skipped as preamble; `nan` and
    `inf` count as numbers for the same reason.
    """
    if spec is not None:
        positions = [i for i, c in enumerate(spec) if c.quantity != _IGNORE]
        if len(cells) <= max(positions):
            return False
        cells = [cells[i] for i in positions]
    elif len(cells) < 2:
        return False
    numbers = 0
    for cell in cells:
        if _is_number(cell, decimal_comma):
            numbers += 1
        elif _NON_NUMBER_WORD.search(cell):
            return False
    return numbers > 0


def _split_unit(cell: str) -> tuple[str, str | None]:
    """`("Force", "kN")` from `Force (kN)`, `Force [kN]`, `Force/kN` or `Force_kN`."""
    match = _BRACKETED_UNIT.match(cell)
    if match:
        return match.group(1).strip(), match.group(2).strip()
    for mark in ("/", "_", " "):
        if mark in cell:
            name, unit = cell.rsplit(mark, 1)
            if unit.strip().lower() in _ALL_UNITS:
                return name.strip(), unit.strip()
    return cell, None


def _unit_cell(cell: str) -> str | None:
    """The unit of a units-row cell (`(mm)`, `[s]`, `N`), or None if it is not one."""
    bare = cell.strip().strip("()[]（）【】").strip()
    return bare if bare.lower() in _ALL_UNITS else None


def _header_quantity(name: str) -> str | None:
    lowered = name.lower()
    words = set(re.split(r"[\W_]+", lowered))
    for quantity, vocabulary in _HEADER_WORDS.items():
        for word in vocabulary:
            if (word.isascii() and word in words) or (
                not word.isascii() and word in lowered
            ):
                return quantity
    return None


def _match_header(
    names: list[str], units: list[str] | None
) -> tuple[list[_ColumnMap] | None, str]:
    """Best-effort column map of a non-canonical header (and units row).

    **Returns:**

    `(columns, why)`: the column map (unmatched columns ignored), or `None` and why
    the header does not do.
    """
    mapped: list[_ColumnMap] = []
    seen: dict[str, str] = {}
    for position, cell in enumerate(names, start=1):
        name, unit = _split_unit(cell)
        if unit is None and units is not None and position <= len(units):
            unit = _unit_cell(units[position - 1])
        quantity = _header_quantity(name)
        token = None
        if quantity is not None and unit is not None:
            token = _HEADER_UNITS.get((quantity, unit.lower()))
        if token is None:
            mapped.append(_ColumnMap(cell or _IGNORE, _IGNORE, 1.0, position))
            continue
        if quantity in seen:
            return None, f"two {quantity} columns ('{seen[quantity]}' and '{cell}')"
        seen[quantity] = cell
        unit_info = _COLUMNS[token]
        mapped.append(_ColumnMap(token, quantity, unit_info.to_si, position))
    missing = [q for q in _REQUIRED if q not in seen]
    if missing:
        return None, f"no {' and no '.join(missing)} column with a known unit"
    return mapped, ""


def _header_columns(
    lines: list[str], first: int, start: int, sep: str, path
) -> tuple[list[_ColumnMap], int]:
    """The column map from the rows above the data (`lines[first:start]`).

    A row with a canonical name (`time_s`, ...) is the canonical header. Otherwise,
    from the bottom up, the first row whose names match a time and a force column
    (`Time (s)`, `时间` over a units row `(s)`, ...) is used, its other columns
    ignored.

    **Returns:**

    `(columns, header_line)`: the column map and the 1-based line of the header.
    """
    rows = [
        (index, _cells(lines[index], sep))
        for index in range(first, start)
        if lines[index].strip() and not lines[index].lstrip().startswith("#")
    ]
    if not rows:
        raise ValueError(
            f"{_where(path, start + 1)}: no header above the first data row; "
            f"{_COLUMNS_HINT}."
        )
    for index, names in rows:
        if any(name in _COLUMNS for name in names):
            return _map_columns(names, path, index + 1, positions=True), index + 1
    unit_rows = {index for index, cells in rows if all(map(_unit_cell, cells))}
    reasons = []
    for k in range(len(rows) - 1, -1, -1):
        index, names = rows[k]
        if index in unit_rows:
            continue
        below = [cells for i, cells in rows[k + 1 :] if i in unit_rows]
        columns, why = _match_header(names, below[0] if below else None)
        if columns is not None:
            return columns, index + 1
        reasons.append((index, names, why))
    index, names, why = reasons[0] if reasons else (rows[-1][0], rows[-1][1], "")
    raise ValueError(
        f"{_where(path, index + 1)}: cannot tell the columns from the header "
        f"{_SEPARATORS[sep]}-separated {names}{f' ({why})' if why else ''}; "
        f"{_COLUMNS_HINT}."
    )


def _find_data_start(
    lines: list[str],
    first: int,
    sep: str,
    decimal_comma: bool,
    spec: list[_ColumnMap] | None,
    path,
) -> int:
    """0-based index of the first data row at or after `first`."""
    for index in range(first, len(lines)):
        text = lines[index]
        if not text.strip() or text.lstrip().startswith("#"):
            continue
        if _looks_like_data(_cells(text, sep), decimal_comma, spec):
            return index
    raise ValueError(
        f"{path}: no data rows found (rows of numbers separated by "
        f"{_SEPARATORS.get(sep, repr(sep))}s)."
    )


def read_test(
    path: str | os.PathLike,
    *,
    columns: str | Sequence[str] | None = None,
    skip_rows: int | None = None,
    length_mm: float | None = None,
    diameter_mm: float | None = None,
    rate_mm_per_min: float | None = None,
    temperature_C: float | None = None,
    material: str | None = None,
    id: str | None = None,
    encoding: str | None = None,
    delimiter: str | None = None,
    detect_slack: bool = True,
    slack_threshold_N: float | None = None,
) -> TestData:
    """Read one test from a canonical CSV file or a raw tensile-tester export.

    The file may start with the canonical `# key: value` metadata lines. Then:

    - *Separator*: comma, semicolon or tab, whichever splits most of the first lines
        into numbers (a semicolon or tab file may write decimal commas, `1,5`).
    - *Encoding*: UTF-8 (with or without byte-order mark), else GB18030 (GBK), else
        latin-1, so a header in any encoding reads.
    - *Rows to skip* (`skip_rows`): the lines before the first data row, found as the
        first row of numbers (blank lines, preamble, header and unit rows skipped).
        Quoted numbers and CRLF line ends are read as such.
    - *Columns*: `columns` names every column of the file in order with its unit;
        without it, a canonical header (`time_s,force_N,...`) is used, else a header
        matched best-effort: names such as `Time`, `Force`/`Load`,
        `Elongation`/`Extension`/`Displacement`, `Temperature` (also in Chinese,
        e.g. 时间, 力, 位移), with units in the name (`Force (kN)`, `Time/s`) or in a
        units row below (`(s),(mm),(N)`); a crosshead displacement is read as the
        elongation, and unmatched columns are ignored. Otherwise it is an error
        asking for `columns` (`--columns`).
    - *Slack* (`detect_slack`): stretches where the force is about zero while the
        crosshead moves are masked, and negative forces clipped to 0; see
        [`jaxcable.mask_slack`][] for the rule. The result is in `mask`,
        `force_raw` and `slack_report`.

    **Arguments:**

    - `path`: the file.
    - `columns`: the file's columns in order, e.g. `"time_s,elongation_mm,force_N"`
        (a string or a sequence of names). Accepted: `time_s`, `time_ms`, `time_min`,
        `time_h`, `force_N`, `force_kN`, `elongation_mm`, `elongation_m`,
        `temperature_C`, and `-` for a column to ignore (not parsed). Time and force
        are required.
    - `skip_rows`: the number of lines before the first data row, counted from the
        top of the file (blank, metadata, preamble, header and unit lines alike);
        `None` to detect it.
    - `length_mm`, `diameter_mm`, `rate_mm_per_min`, `temperature_C`, `material`,
        `id`: metadata that replace the file's (mm, mm, mm/min, °C). `length_mm` is
        required, from the file or here.
    - `encoding`: the file's encoding, or `None` to detect it.
    - `delimiter`: the cell separator, or `None` to detect it.
    - `detect_slack`: whether to detect and mask slack stretches.
    - `slack_threshold_N`: the slack force threshold, N, or `None` for the default
        rule.

    **Returns:**

    A [`jaxcable.TestData`][] in SI units (s, N, m; temperature in °C).

    **Raises:**

    `ValueError` naming the file, the 1-based line and the column (its position and
    name) of the first problem: a missing column or cell, a non-numeric, empty, NaN
    or infinite cell, time not strictly increasing (repeated time stamps included:
    remove them from the file), a header that names no time and force column, or
    no `length_mm`.
    """
    lines = _read_lines(path, encoding)
    metadata, first = _parse_metadata(lines, path)
    overrides = {
        "length_mm": length_mm,
        "diameter_mm": diameter_mm,
        "rate_mm_per_min": rate_mm_per_min,
        "temperature_C": temperature_C,
        "material": material,
        "id": id,
    }
    for key, value in overrides.items():
        if value is not None:
            metadata[key] = _metadata_value(key, value, f"{path}, argument {key}")
    if delimiter is None:
        sep, decimal_comma = _sniff_separator(lines, first)
    else:
        if (
            not isinstance(delimiter, str)
            or len(delimiter) != 1
            or delimiter in '"\r\n'
        ):
            raise ValueError(
                f"{path}: delimiter must be one character (not a quote or line "
                f"break), got {delimiter!r}."
            )
        sep = delimiter
        decimal_comma = sep != "," and _sniff_separator(lines, first) == (sep, True)
    spec = None if columns is None else _parse_columns_spec(columns, path)
    if skip_rows is None:
        start = _find_data_start(lines, first, sep, decimal_comma, spec, path)
    else:
        if isinstance(skip_rows, bool) or not isinstance(skip_rows, int | np.integer):
            raise ValueError(
                f"{path}: skip_rows must be an integer, got {skip_rows!r}."
            )
        if not 0 <= skip_rows < len(lines):
            raise ValueError(
                f"{path}: skip_rows={skip_rows} is outside the file's {len(lines)} "
                "lines."
            )
        start = int(skip_rows)
    if spec is None:
        column_map, header_line = _header_columns(lines, first, start, sep, path)
        named_by = "the header"
    else:
        column_map, header_line = spec, None
        named_by = "columns"
    values, line_numbers = _parse_rows(
        lines, start, column_map, path, sep, decimal_comma, named_by
    )
    data = _assemble(path, column_map, values, line_numbers, metadata, header_line)
    if detect_slack:
        data = mask_slack(data, threshold_N=slack_threshold_N)
    return data


def mask_slack(data: TestData, *, threshold_N: float | None = None) -> TestData:
    """Detect the slack stretches of a test, mask them and clip negative forces.

    A slack stretch is a run of samples with the force below a threshold while the
    crosshead keeps moving (the elongation changes at the test's speed and by at
    least 2 % of the test's range). The threshold is `max(0.5 % of the peak force,
    3 x the force noise)`, capped at 5 % of the peak; the noise is the robust
    standard deviation of the force's second differences. Samples in slack
    stretches, and any sample with the force below minus the threshold, are masked
    (`mask` False): they are not fitted. Every negative force is set to 0 in `force`
    (the kernels reject negative forces, and a slack cable carries none); the
    measured force is kept in `force_raw`. The full rule and its constants are in
    `jaxcable/_slack.py`.

    **Arguments:**

    - `data`: a [`jaxcable.TestData`][]; detection reads `force_raw` when set (so it
        can be re-run) and the crosshead speed from `rate_mm_per_min` when the
        metadata has it (else it is estimated from the elongation).
    - `threshold_N`: the force threshold, N, or `None` for the rule above.

    **Returns:**

    A new [`jaxcable.TestData`][] with `mask`, `force`, `force_raw` and
    `slack_report` (a [`jaxcable.SlackReport`][]) set; any previous mask is replaced.
    """
    measured = data.force if data.force_raw is None else data.force_raw
    rate = data.metadata.get("rate_mm_per_min")
    speed = None if rate is None else float(rate) * 1e-3 / 60
    mask, force, report = _slack.detect_slack(
        data.time,
        measured,
        data.elongation,
        speed=speed,
        threshold=threshold_N,
        lines=data.lines,
    )
    return dataclasses.replace(
        data,
        force=force,
        force_raw=measured if report.clipped else None,
        mask=mask,
        slack_report=report,
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
    its order. `force` is written (after [`jaxcable.mask_slack`][], the clipped
    force); `mask`, `force_raw` and `slack_report` are not: reading the file with
    [`jaxcable.read_test`][] detects the slack again. Numbers are written with full precision (`repr`), so reading the file
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
