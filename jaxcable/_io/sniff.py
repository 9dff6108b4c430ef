"""The layout of a raw tensile-tester export, sniffed: its separator (and whether it
writes decimal commas), its first data row, and its columns from a free-form header
(names such as `Force (kN)` or 时间 over a units row) matched best-effort."""

import re

from .cells import (
    NON_NUMBER_WORD as _NON_NUMBER_WORD,
    is_number as _is_number,
    text_cells as _text_cells,
    text_columns_of as _text_columns,
)
from .parsing import ColumnMap, map_columns, row_cells
from .testdata import where
from .units import COLUMNS, IGNORE, missing_quantities, written_name
from .vocabulary import (
    HEADER_UNITS,
    HEADER_WORDS,
    STRAIN_UNITS,
    STRESS_UNITS,
    STRESS_WORDS,
    UNIT_SPELLINGS,
)


_SEPARATORS = {",": "comma", ";": "semicolon", "\t": "tab"}
_COLUMNS_HINT = (
    "pass columns=... (--columns on the command line) naming the file's columns in "
    "order with their units, e.g. 'time_s,elongation_mm,force_N' ('-' for a column "
    "to ignore), or some of them by their header names, e.g. "
    "'Load=force_kN,Time=time_s' (the others not read)"
)
_QUANTITY_UNITS = {unit for _, unit in HEADER_UNITS}
# The brackets of `Name (unit)`, `Name [unit]`, also full-width.
_OPENING = "([（【"
_CLOSING = ")]）】"
_WORD = re.compile(r"[^\W\d_]{2,}", re.UNICODE)  # two letters or more in a row
# What instruments write for a missing value (a whole row of these is a data row
# with no values, not preamble). Anchored, no nested repetition: linear time.
_MISSING = re.compile(r"(?:n/?a|nan|null|none|-+|\?+)", re.IGNORECASE)


def _sample(lines: list[str], first: int) -> list[str]:
    """The first 200 content lines from `lines[first]` on."""
    sample = []
    for text in lines[first:]:
        if _is_content(text):
            sample.append(text)
            if len(sample) == 200:
                break
    return sample


def sniff_separator(lines: list[str], first: int) -> tuple[str, bool]:
    """The separator (`,`, `;` or tab) and decimal-comma flag under which most of the
    first 200 content lines are rows of numbers (cells of the rows' text columns
    aside, see `jaxcable._io.cells.text_columns_of`); `,` when none is."""
    sample = _sample(lines, first)
    best = (0, ",", False)
    for sep in _SEPARATORS:
        rows = [row_cells(text, sep) for text in sample]
        # A decimal comma is only possible where the comma does not separate cells.
        for decimal_comma in (False, True) if sep != "," else (False,):
            text = _text_columns(rows, decimal_comma)
            shapes = (_text_cells(cells, decimal_comma) for cells in rows)
            count = sum(shape is not None and shape <= text for shape in shapes)
            if count > best[0]:
                best = (count, sep, decimal_comma)
    return best[1], best[2]


def text_columns(
    lines: list[str], first: int, sep: str, decimal_comma: bool
) -> frozenset[int]:
    """The 0-based positions of the text columns of the data rows (see
    `jaxcable._io.cells.text_columns_of`) among the first 200 content lines from `lines[first]` on."""
    rows = [row_cells(text, sep) for text in _sample(lines, first)]
    return _text_columns(rows, decimal_comma)


def _looks_like_data(
    cells: list[str],
    decimal_comma: bool,
    spec: list[ColumnMap] | None,
    text: frozenset[int] = frozenset(),
) -> bool:
    """Whether a row is the first data row: numbers, without words but in the `text`
    columns (see `jaxcable._io.cells.text_columns_of`).

    A row with a bad number but no letters (`12..5`, an empty cell) counts as data,
    so that it is reported as an error rather than skipped as preamble; `nan` and
    `inf` count as numbers for the same reason.
    """
    if spec is not None:
        positions = [i for i, c in enumerate(spec) if c.quantity != IGNORE]
        if len(cells) <= max(positions):
            return False
        cells = [cells[i] for i in positions]
    elif len(cells) < 2:
        return False
    else:
        cells = [cell for i, cell in enumerate(cells) if i not in text]
    numbers = 0
    for cell in cells:
        if _is_number(cell, decimal_comma):
            numbers += 1
        elif _NON_NUMBER_WORD.search(cell):
            return False
    return numbers > 0


def _split_unit(cell: str) -> tuple[str, str | None]:
    """`("Force", "kN")` from `Force (kN)`, `Force [kN]`, `Force/kN` or `Force_kN`."""
    # By string search rather than a regular expression: the natural pattern
    # (`(.*?)\s*[(]\s*([^)]*?)\s*[)]$`) backtracks in cubic time on a cell such as
    # `Remark (` followed by a few thousand spaces.
    if cell and cell[-1] in _CLOSING:
        # The unit runs from the first opening bracket after the last closing one
        # before the end, so that it holds no closing bracket.
        inner = cell[:-1]
        last_closing = max(inner.rfind(c) for c in _CLOSING)
        openings = [inner.find(c, last_closing + 1) for c in _OPENING]
        opening = min((i for i in openings if i >= 0), default=-1)
        if opening >= 0:
            return inner[:opening].strip(), inner[opening + 1 :].strip()
    for mark in ("/", "_", " "):
        if mark in cell:
            name, unit = cell.rsplit(mark, 1)
            if unit.strip().lower() in _QUANTITY_UNITS:
                return name.strip(), unit.strip()
    return cell, None


def _unit_cell(cell: str) -> str | None:
    """The unit of a units-row cell (`(mm)`, `[s]`, `N`, `(MPa)`), or None if it is
    not one: a unit spelling instruments write, or any word without digits in
    brackets (a units row names the units of columns that are not read too)."""
    cell = cell.strip()
    bare = cell.strip("()[]（）【】").strip()
    if bare.lower() in UNIT_SPELLINGS:
        return bare
    bracketed = len(bare) < len(cell) and cell[0] in _OPENING and cell[-1] in _CLOSING
    if (
        bracketed
        and len(bare) <= 16
        # Digits only beside letters, in one word: `(N/mm2)`, not `(Sample 1)`.
        and not (any(ch.isdigit() for ch in bare) and (" " in bare))
        and (_NON_NUMBER_WORD.search(bare) or "%" in bare)
    ):
        return bare
    return None


def _has_word(name: str, vocabulary) -> bool:
    """Whether `name` holds a word of `vocabulary` (an ASCII word as a whole word of
    `name`, any other anywhere in it)."""
    lowered = name.lower()
    words = set(re.split(r"[\W_]+", lowered))
    return any(
        (word.isascii() and word in words) or (not word.isascii() and word in lowered)
        for word in vocabulary
    )


def _header_quantity(name: str) -> str | None:
    for quantity, vocabulary in HEADER_WORDS.items():
        if _has_word(name, vocabulary):
            return quantity
    return None


def _derived(name: str, quantity: str | None, unit: str | None) -> ColumnMap | None:
    """The column map of a stress column (`Tensile stress` in MPa, read as "stress"
    in MPa) or a strain column (`Tensile strain` in %, read as "strain" in mm/mm),
    or None."""
    if unit is None:
        return None
    unit = unit.lower()
    if unit in STRESS_UNITS and _has_word(name, STRESS_WORDS):
        return ColumnMap(name, "stress", STRESS_UNITS[unit])
    if unit in STRAIN_UNITS and quantity == "elongation":
        return ColumnMap(name, "strain", STRAIN_UNITS[unit])
    return None


def _specificity(name: str) -> int:
    """The number of words of a column name: of two columns of one quantity, the one
    with fewer is read (`Extension` rather than `Tensile extension`, `Total Time`
    rather than `Cycle Elapsed Time`, `Position` rather than `Digital Position`)."""
    return len(_NON_NUMBER_RUN.findall(name))


_NON_NUMBER_RUN = re.compile(r"[^\W\d_]+", re.UNICODE)


def _match_header(
    names: list[str], units: list[str] | None
) -> tuple[list[ColumnMap] | None, str]:
    """Best-effort column map of a non-canonical header (and units row).

    Each column is read by its name and unit: time, force, elongation, temperature;
    of two columns of one quantity the one with fewer words in its name (two with
    as many are refused); a stress column stands for the force, and a strain column
    for the elongation, where the file has none (quantities "stress" and "strain").
    Every other column is not read (`IGNORE`, named with its unit).

    **Returns:**

    `(columns, why)`: the column map, or `None` and why the header does not do:
    what each column was read as, and a `columns` value that would read it.
    """
    mapped: list[ColumnMap] = []
    candidates: dict[str, list[tuple[int, int]]] = {}  # quantity -> (words, index)
    found: list[str] = []
    guess: list[str] = []
    for position, cell in enumerate(names, start=1):
        name, unit = _split_unit(cell)
        below = None
        if units is not None and position <= len(units):
            below = _unit_cell(units[position - 1])
        if unit is None or (unit.lower() not in UNIT_SPELLINGS and below):
            # `Tensile strain (Extension)` over `(mm/mm)`: the bracket is no unit.
            name, unit = (name, below) if unit is None else (cell, below)
        quantity = _header_quantity(name)
        token = None
        if quantity is not None and unit is not None:
            token = HEADER_UNITS.get((quantity, unit.lower()))
        shown_name = cell if not below or unit is None else f"{cell} ({unit})"
        if token is None or quantity is None:  # (a token names its quantity)
            derived = _derived(shown_name, quantity, unit)
            if derived is not None:
                kind = str(derived.quantity)  # "stress" or "strain"
                candidates.setdefault(kind, []).append(
                    (_specificity(name), len(mapped))
                )
                found.append(f"{_show(cell)} ({kind})")
                mapped.append(derived._replace(position=position))
                guess.append(IGNORE)
                continue
            found.append(f"{_show(cell)} ({_read_as(quantity, unit, token)})")
            mapped.append(ColumnMap(shown_name or IGNORE, IGNORE, 1.0, position))
            guess.append(
                written_name(quantity)
                if quantity is not None and quantity not in candidates
                else IGNORE
            )
            continue
        guess.append(token)
        candidates.setdefault(quantity, []).append((_specificity(name), len(mapped)))
        mapped.append(ColumnMap(token, quantity, COLUMNS[token].to_si, position))
    # `mapped[i]` is the column at position i + 1: one per name, in order.
    problem = ""
    for quantity, ranked in candidates.items():
        ranked.sort()
        if len(ranked) > 1 and ranked[0][0] == ranked[1][0] and not problem:
            first, second = (names[i] for _, i in ranked[:2])
            problem = f"two {quantity} columns ('{first}' and '{second}')"
        for _, i in ranked[1:]:  # the less specific: not read
            column = mapped[i]
            mapped[i] = ColumnMap(names[i], IGNORE, 1.0, column.position)
    for derived, channel in (("stress", "force"), ("strain", "elongation")):
        if derived in candidates and channel in candidates:
            for _, i in candidates.pop(derived)[:1]:
                column = mapped[i]
                mapped[i] = ColumnMap(column.name, IGNORE, 1.0, column.position)
    seen = dict(candidates)
    if "stress" in seen:
        seen["force"] = seen["stress"]
    missing = missing_quantities(seen)
    if missing and not problem:
        problem = f"no {' and no '.join(missing)} column with a known unit"
    if not problem:
        return mapped, ""
    shown = found[:_SHOWN_COLUMNS]
    if len(found) > _SHOWN_COLUMNS:
        shown.append(f"... ({len(found)} columns)")
    suggestion = ",".join(guess[:_SHOWN_COLUMNS])
    return None, (
        f"{problem}; found {', '.join(shown)}"
        + (f"; for this file perhaps columns='{suggestion}'" if seen else "")
    )


# The columns listed in the error about a header that does not do.
_SHOWN_COLUMNS = 12


def _show(cell: str) -> str:
    """A header cell as quoted in an error message, cut to 30 characters."""
    return repr(cell) if len(cell) <= 30 else repr(cell[:30] + "...")


def _read_as(quantity: str | None, unit: str | None, token: str | None) -> str:
    """What a header column was read as, for the error about the header."""
    if token is not None:
        return token
    if quantity is None:
        return "not recognised"
    if unit is None:
        return f"{quantity}, no unit"
    return f"{quantity}, unit {_show(unit)} unknown"


def header_columns(
    lines: list[str],
    first: int,
    start: int,
    sep: str,
    path,
    required: tuple[str, ...] = ("time", "force"),
) -> tuple[list[ColumnMap], int]:
    """The column map from the rows above the data (`lines[first:start]`).

    A row with a canonical name (`time_s`, ...) is the canonical header, which must
    name the `required` quantities. Otherwise, from the bottom up, the first row
    whose names match a time and a force column (`Time (s)`, `时间` over a units
    row `(s)`, ...) is used, its other columns ignored.

    **Returns:**

    `(columns, header_line)`: the column map and the 1-based line of the header.
    """
    rows = [
        (index, row_cells(lines[index], sep))
        for index in range(first, start)
        if _is_content(lines[index])
    ]
    if not rows:
        raise ValueError(
            f"{where(path, start + 1)}: no header above the first data row; "
            f"{_COLUMNS_HINT}."
        )
    for index, names in rows:
        if any(name in COLUMNS for name in names):
            columns = map_columns(
                names, path, index + 1, positions=True, required=required
            )
            return columns, index + 1
    unit_rows = {index for index, cells in rows if _is_units_row(cells)}
    reasons = []
    for k in range(len(rows) - 1, -1, -1):
        index, names = rows[k]
        if index in unit_rows or _mostly_numbers(names):
            continue
        below = [cells for i, cells in rows[k + 1 :] if i in unit_rows]
        columns, why = _match_header(names, below[0] if below else None)
        if columns is not None:
            return columns, index + 1
        reasons.append((index, names, why))
    index, names, why = reasons[0] if reasons else (rows[-1][0], rows[-1][1], "")
    raise ValueError(
        f"{where(path, index + 1)}: cannot tell the columns from this "
        f"{_SEPARATORS[sep]}-separated header{f' ({why})' if why else ''}; "
        f"{_COLUMNS_HINT}."
    )


def _mostly_numbers(cells: list[str]) -> bool:
    """Whether most filled cells of a row are numbers: a data row that carries a
    label (CCFatigue writes the specimen's name in the first data row only), never
    a header."""
    filled = [cell for cell in cells if cell.strip()]
    numbers = sum(_is_number(cell, False) for cell in filled)
    return bool(filled) and numbers > len(filled) / 2


def _is_content(text: str) -> bool:
    """Whether a line is neither blank nor a comment."""
    return bool(text.strip()) and not text.lstrip().startswith("#")


def _is_units_row(cells: list[str]) -> bool:
    """Whether a row is a units row: a unit in every cell but empty ones (a column
    without a unit, `(mm),(N),,(N/tex)`), one at least."""
    filled = [cell for cell in cells if cell.strip()]
    if len(filled) < len(cells) and all(c.strip() == "-" for c in filled):
        return False  # `,-,`: a row of missing values, not of units
    return bool(filled) and all(map(_unit_cell, filled))


def find_data_start(
    lines: list[str],
    first: int,
    sep: str,
    decimal_comma: bool,
    spec: list[ColumnMap] | None,
    path,
) -> int:
    """0-based index of the first row of numbers at or after `first`: a first guess
    at the data, which `data_below_header` or `data_above` then move up over the
    rows that are data with a typo. Without `spec`, the cells of the rows' text
    columns (`text_columns`) may hold words."""
    text_at = (
        frozenset()
        if spec is not None
        else text_columns(lines, first, sep, decimal_comma)
    )
    for index in range(first, len(lines)):
        text = lines[index]
        if not _is_content(text):
            continue
        if _looks_like_data(row_cells(text, sep), decimal_comma, spec, text_at):
            return index
    raise ValueError(
        f"{path}: no data rows found (rows of numbers separated by "
        f"{_SEPARATORS.get(sep, repr(sep))}s"
        f"{'' if sep in _SEPARATORS else ', the delimiter given'})."
    )


def data_below_header(lines: list[str], header_line: int, start: int, sep: str) -> int:
    """0-based index of the first data row under the header on 1-based line
    `header_line`, the first row of numbers being `lines[start]`.

    Every row under the header is data, but for blank and comment lines and a units
    row (`s,N,mm`, `(s),(N)`) right under it: a row with a typo (`0,0,N/A`, `O.5`)
    is then reported by the row parser instead of being skipped as preamble.
    """
    for index in range(header_line, start):
        text = lines[index]
        if _is_content(text) and not _is_units_row(row_cells(text, sep)):
            return index
    return start


def _is_data_with_typo(
    cells: list[str], decimal_comma: bool, spec: list[ColumnMap]
) -> bool:
    """Whether a row above the first row of numbers of a file without a header is
    rather a data row with a typo than preamble.

    A row of as many cells as `spec`, each a missing-value marker (`N/A,N/A,N/A`,
    `nan`, `-`), is data. Preamble is a units row, or a row without digits, or one
    with a word (two letters in a row: `Sample 12`, `Ch1`) unless it has as many
    cells as `spec` and one of the parsed columns reads as a number (`0,0,abc`).
    """
    if len(cells) == len(spec) and all(_MISSING.fullmatch(c.strip()) for c in cells):
        return True
    if _is_units_row(cells) or not any(ch.isdigit() for cell in cells for ch in cell):
        return False
    if not any(_WORD.search(c) and not _is_number(c, decimal_comma) for c in cells):
        return True
    parsed = [i for i, column in enumerate(spec) if column.quantity != IGNORE]
    return len(cells) == len(spec) and any(
        _is_number(cells[i], decimal_comma) for i in parsed
    )


def data_above(
    lines: list[str],
    first: int,
    start: int,
    sep: str,
    decimal_comma: bool,
    spec: list[ColumnMap],
) -> int:
    """0-based index of the first data row of a file read by `spec` without a header,
    the first row of numbers being `lines[start]`: the rows right above it (blank
    lines between them aside) that look like data with a typo are data too, so that
    the row parser reports them instead of their being skipped as preamble."""
    for index in range(start - 1, first - 1, -1):
        text = lines[index]
        if not text.strip():
            continue
        if not _is_content(text):
            break
        if not _is_data_with_typo(row_cells(text, sep), decimal_comma, spec):
            break
        start = index
    return start
