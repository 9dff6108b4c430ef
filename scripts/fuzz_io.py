"""Fuzz `jaxcable.read_test` with generated malformed test files.

    python scripts/fuzz_io.py [--files 10000] [--seed 0] [--out DIR]

Each file is a small test (canonical header with metadata, a header matched
best-effort, with or without a units row, or no header and `columns=...`) in one of
the separators, decimal marks, encodings and line ends the reader accepts, with one to
three corruptions: typos in the first, a middle or the last row (`N/A`, `O.5`, `1_0`,
an empty cell), stray separators, one-cell rows, units and text rows, huge and tiny
numbers, non-finite numbers, time stamps out of order, long cells (up to 200 kB), bytes
of another encoding, bad metadata; and harmless changes (blank lines, quotes, spaces,
a trailing separator, a units row right under the header) that must not change what
is read.

Every file goes through `read_test`, and the outcome is counted:

- `silently_wrong`: read without an error, but the rows differ from the file's data
    rows (one dropped, added or changed), or the file holds a row or value the reader
    must refuse (a malformed row, a value out of range in SI units).
- `crashes`: an exception other than `ValueError`, or a `ValueError` that does not
    name the file.
- `over_2s`: read (or refused) in more than 2 s.

The counts are printed as JSON and as a table. The generator (`make_case`) is also
the one of the suite's fuzz test.
"""

import argparse
import dataclasses
import json
import os
import pathlib
import re
import sys
import tempfile
import time
import warnings

import numpy as np


TIME_UNITS = {"time_s": 1.0, "time_ms": 1e-3, "time_min": 60.0, "time_h": 3600.0}
FORCE_UNITS = {"force_N": 1.0, "force_kN": 1e3}
ELONGATION_UNITS = {"elongation_mm": 1e-3, "elongation_m": 1.0}
# Headers matched best-effort: (name, unit as written) per canonical token.
MATCHED_NAMES = {
    "time": ("Time", "时间", "Zeit"),
    "force": ("Force", "Load", "力", "Kraft"),
    "elongation": ("Extension", "Crosshead", "位移", "Weg"),
}
MATCHED_UNITS = {
    "time_s": "s",
    "time_ms": "ms",
    "time_min": "min",
    "time_h": "h",
    "force_N": "N",
    "force_kN": "kN",
    "elongation_mm": "mm",
    "elongation_m": "m",
}
TYPOS = ("N/A", "O.5", "1..5", "abc", "-", "1_0", "--", "1e5x", "?", "0.5.1", "l0")
NON_FINITE = ("nan", "NaN", "inf", "-inf", "Infinity", "1e999")
EXTREMES = ("1e308", "-1e308", "1.7976931348623157e308", "1e-320", "5e-324", "-0")
# Typos count twice: the commonest corruption.
CORRUPTIONS = (
    *("typo", "typo", "empty-cell", "stray-separator", "one-cell", "units-row"),
    *("text-row", "time-back", "non-finite", "extreme", "long-cell", "bytes"),
    *("blank", "comment", "quotes", "spaces", "trailing-separator", "nul"),
)
PREAMBLE = ("Test report", "Operator: A. N. Other", "Machine: Zwick Z010")
TEXT_ROWS = ("End of test", "Pause", "Sample broke", "*** STOP ***")
# Kinds of line: data rows, rows the reader must refuse, rows it may skip or
# refuse, and lines that are not rows at all (metadata, header, preamble).
DATA, BAD, EITHER, OTHER = "data", "bad", "either", "other"


@dataclasses.dataclass
class Case:
    """A generated file and what reading it must give.

    - `text`: the file's bytes.
    - `kwargs`: the arguments of `read_test` besides the path, by their names in
        the file or `jaxcable.ReadOptions` (`length_mm`, `detect_slack`, ...; see
        [`read`][]).
    - `time`, `force`, `elongation`, `lines`: the data rows in SI units and their
        1-based lines, as a correct reader reads them.
    - `must_fail`: whether the file holds something the reader must refuse.
    - `what`: the corruptions, for the report.
    """

    text: bytes
    kwargs: dict
    time: np.ndarray
    force: np.ndarray
    elongation: np.ndarray
    lines: np.ndarray
    must_fail: bool
    what: list[str]


class Row:
    """One line of the file being built: its cells (or raw text) and its kind."""

    def __init__(self, cells=None, kind=DATA, text=None, values=None):
        self.cells = cells
        self.kind = kind
        self.text = text  # a line written as it is (not a data row's cells)
        self.values = values  # the numbers of a data row, in the file's units
        self.stray = None  # where a stray separator goes in the line
        self.trailing = False  # whether the line ends with a separator

    def render(self, sep: str) -> str:
        if self.text is not None:
            return self.text
        text = sep.join(self.cells)
        if self.stray is not None:
            cut = min(self.stray, len(text))
            text = text[:cut] + sep + text[cut:]
        return text + sep if self.trailing else text


def _number(rng, magnitude: str) -> float:
    if magnitude == "huge":
        return rng.choice((1.0, -1.0)) * 10 ** rng.uniform(290, 308)
    if magnitude == "tiny":
        return rng.choice((1.0, -1.0)) * 10 ** rng.uniform(-323, -300)
    return round(rng.uniform(-5, 100), rng.choice((0, 1, 3, 6, 12)))


def _format(value: float, decimal_comma: bool) -> str:
    text = repr(float(value))
    return text.replace(".", ",") if decimal_comma else text


def make_case(rng) -> Case:
    """A random malformed (or harmless) test file; `rng` is a `random.Random` or any
    object with its `choice`, `randint`, `uniform`, `random` and `sample`."""
    layout = rng.choice(("canonical", "matched", "matched-units", "columns"))
    sep, decimal_comma = rng.choice(
        ((",", False), (";", False), (";", True), ("\t", False), ("\t", True))
    )
    tokens = [
        rng.choice(tuple(TIME_UNITS)),
        rng.choice(tuple(FORCE_UNITS)),
        rng.choice(tuple(ELONGATION_UNITS)),
    ]
    tokens = rng.sample(tokens, 3)  # any column order
    factors = [{**TIME_UNITS, **FORCE_UNITS, **ELONGATION_UNITS}[t] for t in tokens]
    time_col = next(i for i, t in enumerate(tokens) if t.startswith("time"))
    magnitude = rng.choice(("normal", "normal", "normal", "huge", "tiny"))

    rows = []
    n = rng.randint(1, 25)
    t = _number(rng, magnitude) if magnitude != "normal" else rng.uniform(0, 10)
    for _ in range(n):
        values = [_number(rng, magnitude) for _ in tokens]
        values[time_col] = t
        rows.append(Row(values=values))
        step = abs(t) * rng.uniform(1e-3, 1.0) if magnitude != "normal" else 0
        t = t + max(step, rng.uniform(0.01, 5.0))
    for row in rows:
        row.cells = [_format(v, decimal_comma) for v in row.values]

    what = []
    kwargs: dict = {}
    for _ in range(rng.randint(1, 3)):
        what.append(_corrupt(rng, rows, sep, decimal_comma, tokens, time_col, layout))

    # The lines above the data.
    head: list[str] = []
    if layout == "canonical":
        head.append("# length_mm: 100")
        if rng.random() < 0.3:
            key, value, good = rng.choice(
                (
                    ("breaking_load_N", "abc", False),
                    ("breaking_load_N", "-5", False),
                    ("diameter_mm", "5e-324", False),
                    ("temperature_C", "-300", False),
                    ("rate_mm_per_min", "inf", False),
                    ("breaking_load_N", "2000", True),
                    ("material", "Dyneema SK78", True),
                )
            )
            head.append(f"# {key}: {value}")
            what.append(f"metadata {key}={value}")
            bad_metadata = not good
        else:
            bad_metadata = False
        head += rng.sample(PREAMBLE, rng.randint(0, 1))
        head.append(sep.join(tokens))
    else:
        bad_metadata = False
        kwargs["length_mm"] = 100
        head += rng.sample(PREAMBLE, rng.randint(0, 2))
        if layout == "matched":
            head.append(
                sep.join(
                    f"{rng.choice(MATCHED_NAMES[_quantity(t)])} ({MATCHED_UNITS[t]})"
                    for t in tokens
                )
            )
        elif layout == "matched-units":
            head.append(
                sep.join(rng.choice(MATCHED_NAMES[_quantity(t)]) for t in tokens)
            )
            head.append(sep.join(f"({MATCHED_UNITS[t]})" for t in tokens))
        else:
            kwargs["columns"] = ",".join(tokens)
    if rng.random() < 0.2:
        kwargs["delimiter"] = sep
    if rng.random() < 0.2:
        kwargs["detect_slack"] = False

    _classify(rows, layout, sep, decimal_comma, len(tokens))
    newline = rng.choice(("\n", "\n", "\r\n", "\r"))
    texts = head + [row.render(sep) for row in rows]
    encoding = rng.choice(("utf-8", "utf-8", "utf-8-sig", "gbk", "gb18030", "latin-1"))
    body = newline.join(texts) + rng.choice((newline, ""))
    try:
        raw = body.encode(encoding)
    except UnicodeEncodeError:
        raw = body.encode("utf-8")
    if any(row.kind == "bytes" for row in rows):
        raw = raw.replace(b"@@", b"\xb5\xff")  # bytes of no encoding the file has

    data_rows = [(k, row) for k, row in enumerate(rows, start=len(head) + 1)]
    good = [
        (k, row) for k, row in data_rows if row.kind in (DATA, EITHER) and row.values
    ]
    lines = np.array([k for k, _ in good], dtype=int)
    values = np.array([row.values for _, row in good], dtype=float).reshape(-1, 3)
    must_fail = bad_metadata or any(row.kind in (BAD, "bytes") for row in rows)
    with np.errstate(all="ignore"):
        si = values * np.array(factors)
        steps = np.diff(si[:, time_col])
        raw_steps = np.diff(values[:, time_col])
    if (
        not np.all(np.isfinite(si))
        or not np.all(steps > 0)
        or not np.all(raw_steps > 0)
    ):
        must_fail = True
    if not good:
        must_fail = True
    order = [tokens.index(next(t for t in tokens if t.startswith(q))) for q in QS]
    return Case(
        text=raw,
        kwargs=kwargs,
        time=si[:, order[0]],
        force=si[:, order[1]],
        elongation=si[:, order[2]],
        lines=lines,
        must_fail=must_fail,
        what=what,
    )


QS = ("time", "force", "elongation")


def _quantity(token: str) -> str:
    return token.split("_")[0]


def _corrupt(rng, rows, sep, decimal_comma, tokens, time_col, layout) -> str:
    """Apply one corruption to `rows` (in place); return its name."""
    data = [k for k, row in enumerate(rows) if row.kind == DATA and row.values]
    if not data:
        rows.append(Row(text="", kind=OTHER))
        return "blank"
    place = rng.choice(("first", "middle", "last"))
    index = {"first": data[0], "last": data[-1]}.get(place, rng.choice(data))
    row = rows[index]
    column = rng.randint(0, len(row.cells) - 1)
    kind = rng.choice(CORRUPTIONS)
    name = f"{kind}@{place}"
    if kind == "typo":
        row.cells[column] = rng.choice(TYPOS)
        row.kind = BAD
    elif kind == "empty-cell":
        row.cells[column] = ""
        row.kind = BAD
    elif kind == "stray-separator":
        row.stray = rng.randint(0, max(0, len(sep.join(row.cells)) - 1))
        row.kind = BAD
    elif kind == "one-cell":
        row.cells = row.cells[:1]
        row.kind = BAD
    elif kind in ("units-row", "text-row", "blank", "comment"):
        if kind == "units-row":
            text = sep.join(MATCHED_UNITS[t] for t in tokens)
        elif kind == "text-row":
            text = rng.choice(TEXT_ROWS)
        elif kind == "blank":
            text = rng.choice(("", "   ", "\t"))
        else:
            text = "# note"
        at = index if place != "last" else index + 1
        rows.insert(at, Row(text=text, kind=kind))
    elif kind == "time-back":
        if index == data[0]:
            index = data[-1]
            row = rows[index]
        previous = [k for k in data if k < index]
        if previous:
            earlier = rows[previous[-1]]
            row.values[time_col] = earlier.values[time_col] - rng.choice((0, 1e-3, 1))
            row.cells[time_col] = _format(row.values[time_col], decimal_comma)
        else:
            name = "none"
    elif kind == "non-finite":
        row.cells[column] = rng.choice(NON_FINITE)
        row.kind = BAD
    elif kind == "extreme":
        row.cells[column] = rng.choice(EXTREMES)
        row.values[column] = float(row.cells[column])
        row.cells[column] = _format(row.values[column], decimal_comma)
    elif kind == "long-cell":
        size = rng.choice((100, 2_000, 20_000, 200_000))
        style = rng.choice(("spaces", "digits", "letters", "quoted"))
        if style == "spaces":
            row.cells[column] = " " * size + row.cells[column]
        elif style == "digits":
            row.cells[column] = "1" * size  # a number, infinite from 309 digits
            row.values[column] = float(row.cells[column])
        elif style == "letters":
            row.cells[column] = "x" * size
            row.kind = BAD
        else:
            row.cells[column] = '"' + "1" * size + '"'
            row.values[column] = float("1" * size)
    elif kind == "bytes":
        row.cells[column] = row.cells[column][:1] + "@@" + row.cells[column][1:]
        row.kind = "bytes"
    elif kind == "quotes":
        quote = rng.choice(('"{}"', '"{}', "{}"))
        row.cells[column] = quote.format(row.cells[column])
        if quote == '"{}':
            row.kind = EITHER
    elif kind == "spaces":
        row.cells[column] = " " + row.cells[column] + "  "
    elif kind == "trailing-separator":
        row.trailing = True
    elif kind == "nul":
        row.cells[column] = row.cells[column] + "\0"
        row.kind = BAD
    return name


def _classify(rows, layout, sep, decimal_comma, width) -> None:
    """Set the kind of the inserted lines by the reader's documented rule: under a
    header, blank and comment lines and the units rows right under it are skipped
    and every other line is a row; without a header (`columns`), the lines above
    the first row of numbers that hold no digit are preamble."""
    seen_row = False
    for row in rows:
        if row.kind in ("blank",):
            row.kind = OTHER
            continue
        if row.kind == "comment":
            row.kind = OTHER if not seen_row else EITHER
            continue
        if row.kind == "units-row":
            row.kind = OTHER if not seen_row else BAD
            continue
        if row.kind == "text-row":
            row.kind = OTHER if (layout == "columns" and not seen_row) else BAD
            continue
        seen_row = True
    if layout == "columns":
        # Without a header, the rows right above the first good row that hold
        # digits are rows; from the first line above them without a digit (or a
        # comment) up, the lines are preamble.
        first = next((k for k, row in enumerate(rows) if row.kind == DATA), None)
        if first is None:
            return
        preamble = False
        for row in rows[first - 1 :: -1] if first else ():
            text = row.render(sep)
            if not preamble and not text.strip():
                continue
            if text.lstrip().startswith("#") or not any(c.isdigit() for c in text):
                preamble = True
            if preamble:
                row.kind = OTHER


def read(read_test, path, kwargs: dict):
    """`read_test(path, ...)` with one flat mapping of `columns`, the fields of
    `jaxcable.ReadOptions` and metadata keys (the others) as its arguments."""
    from jaxcable import ReadOptions

    fields = {f.name for f in dataclasses.fields(ReadOptions)}
    options = {k: v for k, v in kwargs.items() if k in fields}
    metadata = {k: v for k, v in kwargs.items() if k not in fields | {"columns"}}
    return read_test(
        path,
        kwargs.get("columns"),
        metadata=metadata or None,
        options=ReadOptions(**options),
    )


def check(case: Case, path: pathlib.Path, read_test) -> tuple[str, float, str]:
    """Read `path` (holding `case.text`) and judge the outcome.

    **Returns:**

    `(outcome, seconds, detail)`, the outcome one of `ok`, `refused` (an error where
    none was needed), `silently_wrong`, `crash`; the detail says what went wrong and
    which warnings were raised (`warned: ...`).
    """
    start = time.perf_counter()
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            data = read(read_test, path, case.kwargs)
    except ValueError as e:
        seconds = time.perf_counter() - start
        if str(path) not in str(e):
            return "crash", seconds, f"ValueError without the file: {e}"
        return ("ok" if case.must_fail else "refused"), seconds, str(e)[:300]
    except Exception as e:  # noqa: BLE001 (counted as a crash)
        return "crash", time.perf_counter() - start, f"{type(e).__name__}: {e}"[:300]
    seconds = time.perf_counter() - start
    if case.must_fail:
        return "silently_wrong", seconds, "read a file holding a bad row or value"
    force = data.force if data.force_raw is None else data.force_raw
    got = (data.time, force, data.elongation, data.lines)
    want = (case.time, case.force, case.elongation, case.lines)
    for name, a, b in zip(("time", "force", "elongation", "lines"), got, want):
        if a is None or a.shape != b.shape or not np.array_equal(a, b):
            return "silently_wrong", seconds, f"{name} differs"
    if caught:
        # Read right, but a warning escaped: counted apart.
        return "ok", seconds, f"warned: {caught[0].message}"
    return "ok", seconds, ""


# ----------------------------------------------------------------------------------
# Mutations of the real exports of `tests/data/exports/`: columns reordered, added,
# renamed; units moved between the header and a units row; blank and comment lines
# between header and data; other encodings and line ends.

KN, LBF, IN = 1e3, 4.4482216152605, 0.0254
# file, separator, header line, units line (None: units in the names), first data
# line, (column, factor to SI, unit as written) of time, force, elongation, length_mm.
CORPUS = [
    *(
        (
            f"TensileDataAnalysis/Specimen_RawData_{k}.csv",
            ",",
            5,
            6,
            7,
            ((0, 1.0, "s"), (2, LBF, "lbf"), (1, IN, "in")),
            50.0,
        )
        for k in range(1, 6)
    ),
    (
        "bluer/vero_clear_ccyclic_Specimen_RawData_6.csv",
        ",",
        4,
        5,
        6,
        ((0, 1.0, "sec"), (2, 1.0, "N"), (1, 1e-3, "mm")),
        20.0,
    ),
    (
        "instron_data_processing/silicone_30a_Test1.steps.tracking.csv",
        ",",
        1,
        None,
        2,
        ((0, 1.0, "s"), (8, KN, "kN"), (7, 1e-3, "mm")),
        30.0,
    ),
    (
        "instron_data_processing/silicone_10a_Test7.steps.tracking.csv",
        ",",
        1,
        None,
        2,
        ((0, 1.0, "s"), (8, KN, "kN"), (7, 1e-3, "mm")),
        30.0,
    ),
    (
        "instron_data_processing/silicone_30a_20251029_145648_1.csv",
        ",",
        1,
        2,
        3,
        ((1, 1.0, "s"), (3, KN, "kN"), (2, 1e-3, "mm")),
        30.0,
    ),
    (
        "tensile_test_analyzer/Exemple_Shimadzu_Tract_L100_D2.csv",
        ",",
        2,
        3,
        4,
        ((0, 1.0, "sec"), (1, 1.0, "N"), (2, 1e-3, "mm")),
        100.0,
    ),
    (
        "tensile_test_analyzer/Exemple_WB100kN_Tract_L100_D2.csv",
        ";",
        1,
        None,
        2,
        ((1, 1.0, "s"), (2, KN, "kN"), (9, 1e-3, "mm")),
        100.0,
    ),
    (
        "tensile_test_analyzer/Exemple_WB100kN_2_Tract_L100_D2.csv",
        ";",
        1,
        None,
        2,
        ((1, 1.0, "s"), (2, KN, "kN"), (4, 1e-3, "mm")),
        100.0,
    ),
    (
        "tensile_test_analyzer/Exemple_WB100kN_Mod_Young.csv",
        ";",
        1,
        None,
        2,
        ((1, 1.0, "s"), (2, KN, "kN"), (9, 1e-3, "mm")),
        100.0,
    ),
]
SYNONYMS = (
    ("Time", "Test time", "Zeit", "Temps", "Prüfzeit"),
    ("Load", "Force", "Standard force", "Kraft"),
    ("Extension", "Crosshead", "Displacement", "Stroke", "Standardweg"),
)
ADDED = (
    ("Tensile stress", "MPa"),
    ("Tenacity", "N/tex"),
    ("PIP count", ""),
    ("Strain gauge", "V"),
    ("Humidity", "%"),
    ("Cycle count", ""),
    ("Remark", ""),
)
CORPUS_MUTATIONS = (
    "reorder",
    "add-column",
    "rename",
    "units-to-names",
    "units-row",
    "blank-lines",
    "comment-lines",
    "encoding",
    "line-ends",
)


@dataclasses.dataclass
class Export:
    """A corpus file split into preamble lines, header, units and data cells."""

    name: str
    sep: str
    preamble: list[str]
    header: list[str]
    units: list[str] | None
    rows: list[list[str]]
    quoted: bool
    spec: tuple
    length_mm: float


def load_corpus(root: pathlib.Path) -> list[Export]:
    import csv

    out = []
    for name, sep, header, units, first, spec, length_mm in CORPUS:
        text = (root / name).read_bytes().decode("utf-8-sig")
        lines = re.split(r"\r\n|\r|\n", text)
        while lines and not lines[-1]:
            lines.pop()

        def cells(line):
            return next(csv.reader([line], delimiter=sep))

        rows = [cells(line) for line in lines[first - 1 :] if line.strip()]
        head = cells(lines[header - 1])
        unit_cells = None if units is None else cells(lines[units - 1])
        width = max(len(head), *(len(r) for r in rows))
        # Trailing columns that are empty everywhere (a trailing separator) go.
        while width and not head[width - 1 :] and all(len(r) < width for r in rows):
            width -= 1
        while width and all(
            (len(r) < width or not r[width - 1]) for r in [head, *rows]
        ):
            width -= 1

        def fit(r):
            return (r + [""] * width)[:width]

        out.append(
            Export(
                name,
                sep,
                lines[: header - 1],
                fit(head),
                None if unit_cells is None else fit(unit_cells),
                [fit(r) for r in rows],
                '"' in lines[first - 1],
                spec,
                length_mm,
            )
        )
    return out


def make_corpus_case(rng, corpus: list[Export]) -> Case:
    """A mutated corpus file and the values it holds (read without slack
    detection, with its length)."""
    export = rng.choice(corpus)
    what = [export.name.split("/")[-1]]
    kinds = rng.sample(CORPUS_MUTATIONS, rng.randint(1, 4))
    width = len(export.header)
    header, units = (
        list(export.header),
        (None if export.units is None else list(export.units)),
    )
    keep = rng.randint(20, min(len(export.rows), 300))
    rows = [list(r) for r in export.rows[:keep]]
    known = [column for column, _, _ in export.spec]
    expected = [np.array([float(r[c]) for r in rows]) * f for c, f, _ in export.spec]
    if "rename" in kinds:
        k = rng.randrange(3)
        column, _, unit = export.spec[k]
        new = rng.choice(SYNONYMS[k])
        header[column] = new if units is not None else f"{new} ({unit})"
        what.append(f"rename {export.header[column]!r}->{header[column]!r}")
    if "units-to-names" in kinds and units is not None:
        header = [
            f"{h} {u}" if u.startswith("(") else (f"{h} ({u})" if u else h)
            for h, u in zip(header, units)
        ]
        units = None
        what.append("units-to-names")
    elif "units-row" in kinds and units is None:
        units = [""] * width
        for column, _, unit in export.spec:
            units[column] = f"({unit})"
        what.append("units-row")
    if "add-column" in kinds:
        name, unit = rng.choice(ADDED)
        at = rng.randint(0, width)
        if units is not None:
            units.insert(at, f"({unit})" if unit else "")
            header.insert(at, name)
        else:
            header.insert(at, f"{name} ({unit})" if unit else name)
        for r in rows:
            r.insert(at, f"{rng.uniform(-5, 5):.4f}")
        known = [c + (c >= at) for c in known]
        width += 1
        what.append(f"add {name!r} at {at}")
    if "reorder" in kinds:
        order = list(range(width))
        rng.shuffle(order)
        header = [header[i] for i in order]
        units = None if units is None else [units[i] for i in order]
        rows = [[r[i] for i in order] for r in rows]
        what.append("reorder")

    def join(cells):
        if export.quoted:
            return export.sep.join(f'"{c}"' for c in cells)
        return export.sep.join(cells)

    lines = [*export.preamble, join(header)]
    gaps = []
    if "blank-lines" in kinds:
        gaps.append([""] * rng.randint(1, 3))
    if "comment-lines" in kinds:
        gaps.append(["# " + rng.choice(("note", "re-zeroed", "x,y", "1,2,3"))])
    if units is not None:
        if gaps and rng.random() < 0.5:
            lines += gaps.pop(0)
        lines.append(join(units))
    for gap in gaps:
        lines += gap
    what += [k for k in kinds if k in ("blank-lines", "comment-lines")]
    first = len(lines) + 1
    lines += [join(r) for r in rows]
    end = "\n"
    if "line-ends" in kinds:
        end = rng.choice(("\r\n", "\r"))
        what.append(f"line ends {end!r}")
    encoding = "utf-8"
    if "encoding" in kinds:
        encoding = rng.choice(("utf-8-sig", "cp1252", "latin-1"))
        what.append(encoding)
    text = end.join(lines) + end
    try:
        raw = text.encode(encoding)
    except UnicodeEncodeError:
        raw = text.encode("utf-8")
    return Case(
        text=raw,
        kwargs={"length_mm": export.length_mm, "detect_slack": False},
        time=expected[0],
        force=expected[1],
        elongation=expected[2],
        lines=np.arange(first, first + len(rows)),
        must_fail=False,
        what=what,
    )


def keyword_sweep(jc, folder: pathlib.Path) -> dict:
    """Call every public reader and writer with a wrong value for each keyword
    argument; count the errors that are no `TypeError`/`ValueError` naming it."""
    path = folder / "ok.csv"
    path.write_text("# length_mm: 10\ntime_s,force_N,elongation_mm\n0,0,0\n1,1,1\n")
    data = jc.read_csv(path)
    bad = (5, -1, "", "x", None, [1], {}, float("nan"), True, b"s", 1e309, object())
    calls = {
        **{
            f"read_test({k}=)": (lambda v, k=k: read(jc.read_test, path, {k: v}))
            for k in (
                "columns",
                "skip_rows",
                "length_mm",
                "diameter_mm",
                "rate_mm_per_min",
                "temperature_C",
                "material",
                "id",
                "encoding",
                "delimiter",
                "detect_slack",
                "slack_threshold_N",
            )
        },
        "read_test(path)": lambda v: jc.read_test(v),
        "read_csv(path)": lambda v: jc.read_csv(v),
        "read_csv(length_mm=)": lambda v: jc.read_csv(path, metadata={"length_mm": v}),
        "write_csv(path)": lambda v: jc.write_csv(v, data),
        "write_csv(data)": lambda v: jc.write_csv(folder / "w.csv", v),
        "mask_slack(data)": lambda v: jc.mask_slack(v),
        "mask_slack(threshold_N=)": lambda v: jc.mask_slack(data, threshold_N=v),
        "detect_control(time)": lambda v: jc.detect_control(v, data.force, data.time),
        "detect_control(force)": lambda v: jc.detect_control(data.time, v, data.time),
    }
    counts = {"calls": 0, "accepted": 0, "named": 0, "not_named": 0}
    examples, accepted = [], []
    for label, call in calls.items():
        argument = label.split("(")[1].rstrip("=)")
        for value in bad:
            counts["calls"] += 1
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    call(value)
            except FileNotFoundError:
                counts["named"] += argument == "path"  # no such file: as it must
                counts["not_named"] += argument != "path"
            except (TypeError, ValueError) as e:
                if argument in str(e):
                    counts["named"] += 1
                    continue
                counts["not_named"] += 1
                examples.append(f"{label} {value!r}: {type(e).__name__}: {e}"[:200])
            except Exception as e:  # noqa: BLE001 (counted)
                counts["not_named"] += 1
                examples.append(f"{label} {value!r}: {type(e).__name__}: {e}"[:200])
            else:
                counts["accepted"] += 1
                accepted.append(f"{label} {value!r}")
    counts["accepted_values"] = accepted
    return {"counts": counts, "examples": examples[:10]}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--files", type=int, default=10_000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=pathlib.Path, default=None, help="keep failures")
    parser.add_argument(
        "--corpus-share",
        type=float,
        default=0.5,
        help="the share of files that are mutated real exports (tests/data/exports)",
    )
    args = parser.parse_args(argv)

    import random

    root = pathlib.Path(__file__).resolve().parent.parent
    sys.path.insert(0, str(root))
    import jaxcable as jc

    rng = random.Random(args.seed)
    corpus = load_corpus(root / "tests" / "data" / "exports")
    counts = {"files": 0, "silently_wrong": 0, "crashes": 0, "over_2s": 0}
    counts |= {"ok": 0, "refused_harmless": 0, "warned": 0, "corpus": 0}
    examples: dict[str, list] = {
        "silently_wrong": [],
        "crashes": [],
        "over_2s": [],
        "warned": [],
        "refused_harmless": [],
    }
    slowest = 0.0
    started = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(args.files):
            from_corpus = rng.random() < args.corpus_share
            case = make_corpus_case(rng, corpus) if from_corpus else make_case(rng)
            counts["corpus"] += from_corpus
            path = pathlib.Path(tmp) / f"case{i:06d}.csv"
            path.write_bytes(case.text)
            outcome, seconds, detail = check(case, path, jc.read_test)
            counts["files"] += 1
            slowest = max(slowest, seconds)
            key = {"crash": "crashes", "refused": "refused_harmless"}.get(
                outcome, outcome
            )
            counts[key] += 1
            if detail.startswith("warned"):
                counts["warned"] += 1
                key = "warned"
            if seconds > 2:
                counts["over_2s"] += 1
                key = "over_2s"
            if key in examples and len(examples[key]) < 5:
                examples[key].append({"case": i, "what": case.what, "detail": detail})
                if args.out is not None:
                    args.out.mkdir(parents=True, exist_ok=True)
                    (args.out / path.name).write_bytes(case.text)
            path.unlink()
        here = pathlib.Path.cwd()
        os.chdir(tmp)  # a bad file name such as 'x' is written there
        try:
            sweep = keyword_sweep(jc, pathlib.Path(tmp))
        finally:
            os.chdir(here)
    counts["slowest_s"] = round(slowest, 3)
    counts["total_s"] = round(time.perf_counter() - started, 1)
    print(
        json.dumps(
            {"counts": counts, "examples": examples, "keywords": sweep}, indent=1
        )
    )
    print()
    print(f"{'outcome':<36}{'files':>8}")
    rows = (
        ("silently wrong (dropped/changed)", "silently_wrong"),
        ("crashes (not a located ValueError)", "crashes"),
        ("over 2 s", "over_2s"),
        ("read or refused as they must be", "ok"),
        ("harmless files refused", "refused_harmless"),
        ("read right, with a numpy warning", "warned"),
        ("files", "files"),
        ("of them mutated real exports", "corpus"),
    )
    for label, key in rows:
        print(f"{label:<36}{counts[key]:>8}")
    for key, value in sweep["counts"].items():
        if isinstance(value, list):
            continue
        print(f"{'bad keyword arguments: ' + key:<36}{value:>8}")
    bad = counts["silently_wrong"] + counts["crashes"] + counts["over_2s"]
    bad += sweep["counts"]["not_named"]
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
