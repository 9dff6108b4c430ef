"""The one JSON reader: a file's text parsed, every error naming the file and place.

Only numbers a float can hold are accepted: `NaN`, `Infinity` (which Python's `json`
reads, though JSON has no such values), a literal beyond the float range (`1e999`,
read as infinity) and an integer of more digits than a float can hold are refused
with their line and column, so that no reader downstream meets an infinity or an
integer it cannot convert.
"""

import json
import math
import pathlib
import re


# 10**300 is still a float (max about 1.8e308); a longer integer literal is refused
# before Python converts it (past 4300 digits, `int` itself refuses).
_MAX_INT_DIGITS = 300


class _BadNumber(Exception):
    """A number literal that is refused: the literal and why."""

    def __init__(self, literal: str, why: str):
        super().__init__(literal)
        self.literal = literal
        self.why = why


def _parse_float(literal: str) -> float:
    value = float(literal)
    if not math.isfinite(value):
        raise _BadNumber(literal, "is beyond the range of a float (about 1.8e308)")
    return value


def _parse_int(literal: str) -> int:
    if len(literal.lstrip("-")) > _MAX_INT_DIGITS:
        raise _BadNumber(
            literal,
            f"is an integer of {len(literal.lstrip('-'))} digits, beyond the range of "
            "a float (about 1.8e308)",
        )
    return int(literal)


def _parse_constant(literal: str):
    raise _BadNumber(literal, "is not a JSON number (JSON has no NaN or infinity)")


def _locate(text: str, literal: str) -> tuple[int, int] | None:
    """(line, column) of the first number token `literal` in `text`, or None."""
    token = re.compile(r"(?<![\w.+\-])" + re.escape(literal) + r"(?![\w.+\-])")
    match = token.search(text)
    if match is None:
        return None
    start = match.start()
    line = text.count("\n", 0, start) + 1
    return line, start - (text.rfind("\n", 0, start) + 1) + 1


def _short(literal: str) -> str:
    return literal if len(literal) <= 24 else f"{literal[:10]}...{literal[-6:]}"


def read_json(path, what: str):
    """The parsed content of the JSON file at `path`.

    **Arguments:**

    - `path`: the file.
    - `what`: what the file should hold (e.g. `"a parameter file"`), for the errors.

    **Returns:**

    The decoded JSON value.

    **Raises:**

    `ValueError` naming the file, and the line and column of invalid JSON or of a
    number a float cannot hold; naming the file when it cannot be read or is not
    UTF-8 text.
    """
    where = str(path)
    try:
        raw = pathlib.Path(path).read_bytes()
    except OSError as e:
        raise ValueError(f"{where}: cannot read {what}: {e.strerror}.") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as e:
        line = raw.count(b"\n", 0, e.start) + 1
        column = e.start - (raw.rfind(b"\n", 0, e.start) + 1) + 1
        raise ValueError(
            f"{where}, line {line}, column {column}: {what} must be UTF-8 text "
            f"(byte 0x{raw[e.start]:02x}: {e.reason})."
        ) from None
    return parse_json(text, where)


def parse_json(text: str, where: str):
    """`text` decoded as JSON; a `ValueError` naming `where`, the line and column of
    invalid JSON or of a number a float cannot hold (see the module's docstring)."""
    try:
        return json.loads(
            text,
            parse_float=_parse_float,
            parse_int=_parse_int,
            parse_constant=_parse_constant,
        )
    except _BadNumber as e:
        place = _locate(text, e.literal)
        at = f", line {place[0]}, column {place[1]}" if place else ""
        raise ValueError(f"{where}{at}: {_short(e.literal)} {e.why}.") from None
    except json.JSONDecodeError as e:
        raise ValueError(
            f"{where}, line {e.lineno}, column {e.colno}: invalid JSON: {e.msg}."
        ) from None
    except RecursionError:
        raise ValueError(f"{where}: invalid JSON: nested too deeply.") from None
