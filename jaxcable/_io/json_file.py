"""The one JSON reader: a file's text parsed, every error naming the file and place."""

import json
import pathlib


def read_json(path, what: str):
    """The parsed content of the JSON file at `path`.

    **Arguments:**

    - `path`: the file.
    - `what`: what the file should hold (e.g. `"a parameter file"`), for the errors.

    **Returns:**

    The decoded JSON value.

    **Raises:**

    `ValueError` naming the file, and the line and column of invalid JSON; naming the
    file when it cannot be read or is not UTF-8 text.
    """
    where = str(path)
    try:
        text = pathlib.Path(path).read_text(encoding="utf-8")
    except UnicodeDecodeError as e:
        raise ValueError(f"{where}: {what} must be UTF-8 text ({e.reason}).") from None
    except OSError as e:
        raise ValueError(f"{where}: cannot read {what}: {e.strerror}.") from None
    return parse_json(text, where)


def parse_json(text: str, where: str):
    """`text` decoded as JSON; a `ValueError` naming `where`, the line and column."""
    try:
        return json.loads(text)
    except json.JSONDecodeError as e:
        raise ValueError(
            f"{where}, line {e.lineno}, column {e.colno}: invalid JSON: {e.msg}."
        ) from None
    except RecursionError:
        raise ValueError(f"{where}: invalid JSON: nested too deeply.") from None
