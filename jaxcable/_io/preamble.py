"""An instrument's metadata block: the lines above the header of a tester export
(`Specimen properties : Length,"14.33000",mm`, `Einspannlänge;100,0;mm`) read into
the canonical metadata keys in their units, the control mode the file states, and
the merge with the caller's values, which win (a [`MetadataConflictWarning`][] says
so where they differ from the file's). The labels and units are in
`vocabulary.py`."""

import math
import re
import warnings
from typing import NamedTuple

from .parsing import metadata_value, parse_number, row_cells
from .testdata import where
from .vocabulary import (
    CONTROL_MARKS,
    CONTROL_WORDS,
    METADATA_LABELS,
    METADATA_UNITS,
    STRING_LABELS,
)


class MetadataConflictWarning(UserWarning):
    """A value given to [`jaxcable.read_test`][] (`length_mm=...`, `--length-mm`)
    differs from the file's by more than rounding (0.1 %); the given value is used."""


# Values within this relative difference agree: the file's and the caller's may be
# rounded differently (`14.33000` mm and `14.33`, `0.5` in and `12.7` mm).
_ROUNDING = 1e-3
# Longer lines hold no metadata (a metadata line is a label, a number and a unit):
# skipped, so that a long cell costs no pattern matching.
_LONGEST = 300
_NUMBER_THEN_UNIT = re.compile(r"\s*(\S+)\s+(\S.{0,15})\s*")
_WORDS = re.compile(r"[^\W\d_]+", re.UNICODE)
_LABEL_INDEX = {
    label: (key, rank)
    for key, labels in METADATA_LABELS.items()
    for rank, label in enumerate(labels)
}
_STRING_INDEX = {
    label: (key, rank)
    for key, labels in STRING_LABELS.items()
    for rank, label in enumerate(labels)
}


class Found(NamedTuple):
    """A metadata value of the instrument's block."""

    value: float | str | None  # in the key's unit (mm, mm/min), a string for `id`;
    # None when unreadable
    line: int  # 1-based
    text: str  # as written, for messages: `'Specimen properties : Length' 14.33 mm`
    rank: int  # the label's place in `METADATA_LABELS` (0 is the most specific)
    problem: str = ""  # why `value` is None


def _label_key(cell: str, index=_LABEL_INDEX) -> tuple[str, int] | None:
    """The metadata key and rank a label names (`Test : Rate 1` -> rate), or None."""
    label = cell.strip().rstrip(":=").rsplit(":", 1)[-1].strip().lower()
    label = re.sub(r"\s*[(\[][^)\]]{0,16}[)\]]$", "", label)  # `Length (mm)`
    label = re.sub(r"\s+\d+$", "", label)  # `Rate 1`
    return index.get(" ".join(label.split()))


def _bracket_unit(cell: str) -> str | None:
    """`mm` of a label `Length (mm)` or `Length [mm]`."""
    match = re.search(r"[(\[]([^)\]]{1,16})[)\]]\s*:?\s*$", cell)
    return match.group(1).strip() if match else None


def _cells(text: str, sep: str) -> list[str]:
    """`[label, value, unit...]` of a metadata line: its cells, or a single cell's
    `Label: value unit` split."""
    cells = row_cells(text, sep)
    if len(cells) == 1 and (":" in cells[0] or "=" in cells[0]):
        cut = max(cells[0].rfind(":"), cells[0].rfind("="))
        cells = [cells[0][:cut], cells[0][cut + 1 :].strip()]
    if len(cells) >= 2:
        match = _NUMBER_THEN_UNIT.fullmatch(cells[1])
        if match:  # `14.33 mm` in one cell
            cells = [cells[0], match.group(1), match.group(2), *cells[2:]]
    return cells


def _read_line(
    text: str, line: int, sep: str, decimal_comma: bool
) -> tuple[str, Found] | None:
    """The metadata of one line of the block, or None if it holds none."""
    cells = _cells(text, sep)
    if len(cells) < 2:
        return None
    named = _label_key(cells[0])
    if named is None:
        named = _label_key(cells[0], _STRING_INDEX)
        if named is None or not cells[1]:
            return None
        key, rank = named  # a name (`Specimen label,"sample1"`), kept as written
        return key, Found(cells[1], line, f"{cells[0]!r} {cells[1]!r}", rank)
    key, rank = named
    try:
        # A `;` or tab file may write a decimal comma in its block only.
        number = parse_number(cells[1], decimal_comma or sep != ",")
    except ValueError:
        return None  # a label followed by words: no value of ours (`Length, short`)
    unit = cells[2] if len(cells) > 2 and cells[2] else _bracket_unit(cells[0])
    shown = f"{cells[0]!r} {cells[1]}{f' {unit}' if unit else ''}"
    units = METADATA_UNITS[key]
    factor = None if unit is None else units.get(unit.strip("()[] ").lower())
    if factor is None:
        what = "no unit" if unit is None else f"unit {unit!r} unknown"
        problem = f"{what} (accepted: {', '.join(units)})"
        return key, Found(None, line, shown, rank, problem)
    return key, Found(number * factor, line, shown, rank)


def _control(text: str) -> str | None:
    """The control mode a line states (`Control mode,Position`, `Kraftregelung`):
    "elongation" or "force", or None if it states none or both."""
    lowered = text.lower()
    marks = [mark for mark in CONTROL_MARKS if mark in lowered]
    if not marks:
        return None
    words = _WORDS.findall(lowered)
    modes = set()
    for mode, vocabulary in CONTROL_WORDS.items():
        for word in vocabulary:
            if not word.isascii():
                hit = word in lowered
            else:
                # Whole words, or German compounds (`Wegregelung`, `kraftgeregelt`).
                hit = any(
                    w == word
                    or (w.startswith(word) and any(w.endswith(m) for m in marks))
                    for w in words
                )
            if hit:
                modes.add(mode)
                break
    return modes.pop() if len(modes) == 1 else None


def read_block(
    lines: list[str], first: int, stop: int, sep: str, decimal_comma: bool
) -> tuple[dict[str, Found], str | None]:
    """The instrument's metadata in `lines[first:stop]` (the rows above the data).

    **Returns:**

    `(found, control)`: per canonical key the value of its most specific label
    (the first line of it where one label is repeated with other values, whose
    `problem` then says so), and the control mode the block states ("elongation",
    "force") or None.
    """
    found: dict[str, Found] = {}
    modes = set()
    for index in range(first, stop):
        text = lines[index]
        if not text.strip() or text.lstrip().startswith("#") or len(text) > _LONGEST:
            continue
        mode = _control(text)
        if mode is not None:
            modes.add(mode)
        read = _read_line(text, index + 1, sep, decimal_comma)
        if read is None:
            continue
        key, new = read
        old = found.get(key)
        if old is None or new.rank < old.rank:
            found[key] = new
        elif new.rank == old.rank and new.value != old.value and not old.problem:
            problem = f"given again on line {new.line} as {new.text}"
            found[key] = old._replace(value=None, problem=problem)
    return found, modes.pop() if len(modes) == 1 else None


def _file_line(lines: list[str], first: int, key: str) -> int | None:
    """The 1-based line of the `# key: value` line of the canonical block."""
    for index in range(first):
        body = lines[index].strip()
        if body.startswith("#") and body[1:].split(":", 1)[0].strip() == key:
            return index + 1
    return None


def _differ(given, value) -> bool:
    if isinstance(given, float) and isinstance(value, float):
        return not math.isclose(given, value, rel_tol=_ROUNDING)
    return str(given).strip() != str(value).strip()


def _show(value) -> str:
    return f"{value:g}" if isinstance(value, float) else repr(value)


def merge(
    path,
    lines: list[str],
    first: int,
    metadata: dict[str, float | str],
    block: tuple[dict[str, Found], str | None],
    given: dict[str, float | str],
) -> dict[str, float | str]:
    """The test's metadata: the caller's values (`given`, checked), else the
    canonical `# key: value` block's (`metadata`, lines before `first`), else the
    instrument block's (`block`, from [`read_block`][]).

    Where a given value differs from the file's by more than rounding, a
    [`MetadataConflictWarning`][] names both; the given value is used.

    **Raises:**

    `ValueError` naming the file and line of an instrument value that is needed (not
    given) and cannot be read: no or an unknown unit, a label repeated with
    another value, a value the [`jaxcable.Cable`][] refuses.
    """
    found, control = block
    merged = dict(metadata)
    origin = {key: _file_line(lines, first, key) for key in metadata}
    shown = {key: _show(value) for key, value in metadata.items()}
    for key, item in found.items():
        if key in merged:
            continue
        place = f"{where(path, item.line)}, metadata {item.text}"
        if item.problem:
            if key in given:
                continue  # the caller's value replaces it
            raise ValueError(
                f"{place}: {item.problem}; or pass metadata={{'{key}': ...}} (--"
                f"{key.replace('_', '-')} on the command line)."
            )
        try:
            merged[key] = metadata_value(key, item.value, f"{place} ({key})")
        except ValueError:
            if key in given:
                continue
            raise
        origin[key] = item.line
        shown[key] = f"{_show(merged[key])} ({item.text})"
    if control is not None and "control" not in merged:
        merged["control"] = control
    for key, value in given.items():
        if key in merged and _differ(value, merged[key]):
            warnings.warn(
                f"{where(path, origin.get(key))}: {key}={_show(value)} given, the "
                f"file says {shown[key]}; the given value is used.",
                MetadataConflictWarning,
                stacklevel=3,
            )
        merged[key] = value
    return merged
