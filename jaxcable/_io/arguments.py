"""The keyword arguments of the public readers and writers, checked at the boundary
(a wrong type or value is a `TypeError` or `ValueError` naming the argument), and the
columns a raw export records in place of force and elongation: a stress column read
as the force times the cross-section, a strain column as the elongation times the
length, from the file's or the caller's metadata."""

import math
import os
from collections.abc import Mapping, Sequence

import numpy as np

from .._checks import is_number, require_number
from .parsing import ColumnMap
from .testdata import where
from .units import IGNORE


def check_path(path, argument: str = "path") -> None:
    """`TypeError` unless `path` is a file name (`str` or `os.PathLike`)."""
    if not isinstance(path, str | os.PathLike):
        raise TypeError(
            f"`{argument}` must be a file name (str or os.PathLike), got "
            f"{type(path).__name__}."
        )
    if not os.fspath(path):
        raise ValueError(f"`{argument}` must be a file name, got ''.")


def check_optional_text(value, argument: str) -> None:
    """`TypeError` unless `value` is `None` or a string."""
    if value is not None and not isinstance(value, str):
        raise TypeError(
            f"`{argument}` must be a string or None, got {type(value).__name__}."
        )


def check_flag(value, argument: str) -> None:
    """`TypeError` unless `value` is a bool."""
    if not isinstance(value, bool | np.bool_):
        raise TypeError(f"`{argument}` must be True or False, got {value!r}.")


def check_threshold(value, argument: str, *, positive: bool = False) -> None:
    """`TypeError`/`ValueError` unless `value` is `None` or a finite number >= 0
    (> 0 with `positive`)."""
    if value is None:
        return
    if not is_number(value):
        raise TypeError(
            f"`{argument}` must be a number or None, got {type(value).__name__}."
        )
    require_number(argument, value, 0, strict=positive)


def check_metadata(metadata, keys: Sequence[str] | None = None) -> dict:
    """The `metadata` argument of a reader: a mapping (or None) of the `keys` (any
    key when None), its values numbers or strings (`material` and `id` strings);
    returned as a dict without its `None` values (not given)."""
    if metadata is None:
        return {}
    if not isinstance(metadata, Mapping):
        raise TypeError(
            "`metadata` must be a mapping such as {'length_mm': 300} or None, got "
            f"{type(metadata).__name__}."
        )
    for key in metadata:
        if keys is not None and key not in keys:
            raise ValueError(
                f"`metadata` names {key!r}, which is not one of {', '.join(keys)}."
            )
        if not isinstance(key, str):
            raise TypeError(f"`metadata` keys must be strings, got {key!r}.")
    given = {key: value for key, value in metadata.items() if value is not None}
    for key, value in given.items():
        if key in ("material", "id"):
            if not isinstance(value, str):
                raise TypeError(
                    f"`{key}` must be a string or None, got {type(value).__name__}."
                )
        # A string is parsed as the file's values are (`"14.33"`).
        elif not (is_number(value) or isinstance(value, str)):
            raise TypeError(
                f"`{key}` must be a number or None, got {type(value).__name__}."
            )
    return given


def check_read_arguments(path, columns, metadata, keys: Sequence[str]) -> dict:
    """Check the arguments of [`jaxcable.read_test`][] whose checks need no file
    (the metadata values are checked against the file's by `merge`); return the
    given metadata (`keys` only, `None` values left out)."""
    check_path(path)
    if columns is not None:
        if isinstance(columns, str):
            pass
        elif not isinstance(columns, Sequence) or not all(
            isinstance(c, str) for c in columns
        ):
            raise TypeError(
                "`columns` must be a string ('time_s,force_N,...') or a sequence of "
                f"column names, got {columns!r}."
            )
        if not columns or (isinstance(columns, str) and not columns.strip()):
            raise ValueError("`columns` must name the file's columns, got none.")
    return check_metadata(metadata, keys)


def _area_mm2(metadata: dict) -> float | None:
    diameter = metadata.get("diameter_mm")
    return None if diameter is None else math.pi * float(diameter) ** 2 / 4.0


def derive_channels(
    columns: list[ColumnMap], metadata: dict, path, header_line: int | None
) -> list[ColumnMap]:
    """The column map with a stress column read as the force (MPa x the area of a
    circle of `diameter_mm`, N) and a strain column as the elongation (x
    `length_mm`), where the file has no force or elongation column.

    **Raises:**

    `ValueError` naming the file, header line and column of a stress column when
    the metadata have no `diameter_mm`, saying what to pass.
    """
    out = []
    for column in columns:
        if column.quantity == "stress":
            area = _area_mm2(metadata)
            if area is None:
                raise ValueError(
                    f"{where(path, header_line, column.name, column.position)}: the "
                    "file records stress but no force; pass metadata={'diameter_mm': "
                    "...} (--diameter-mm on the command line) to read the force as the "
                    "stress times the cross-section (pi d^2 / 4), or columns=... "
                    "(--columns) naming a force column."
                )
            column = column._replace(quantity="force", to_si=column.to_si * area)
        elif column.quantity in ("strain", "stretch"):
            length = metadata.get("length_mm")
            if length is None:
                column = column._replace(quantity=IGNORE)  # assemble asks for it
            else:
                # A stretch ratio lambda is the strain lambda - 1.
                offset = -1.0 if column.quantity == "stretch" else 0.0
                to_m = column.to_si * float(length) * 1e-3
                column = column._replace(
                    quantity="elongation", to_si=to_m, offset=offset
                )
        out.append(column)
    return out


def derived_notes(columns: list[ColumnMap], metadata: dict) -> tuple[str, ...]:
    """One line per channel of a `columns` value read from another quantity (a
    stress, strain or stretch column; `columns` before `derive_channels`), saying
    how it was read."""
    notes = []
    for column in columns:
        if column.quantity == "stress" and metadata.get("diameter_mm") is not None:
            area = _area_mm2(metadata)
            notes.append(
                f"force = the stress '{column.name}' x the area of a "
                f"{float(metadata['diameter_mm']):g} mm circle ({area:.6g} mm^2): "
                "a stress record is read with any consistent area (the model works "
                "in force over the cable's area)"
            )
        elif column.quantity in ("strain", "stretch") and "length_mm" in metadata:
            how = "(lambda - 1)" if column.quantity == "stretch" else "the strain"
            notes.append(
                f"elongation = {how} of '{column.name}' x length_mm "
                f"({float(metadata['length_mm']):g} mm)"
            )
    return tuple(notes)


def column_notes(
    columns: list[ColumnMap], named_by: str, text: dict[int, str] | None = None
) -> tuple[str, ...]:
    """One line naming the columns of a header that are not read (none for a
    `columns` value, which names them itself), and one per derived channel; a text
    column (`text`: 1-based position -> a cell of it, `Dy_auto`) shown with its
    text."""
    if named_by != "the header":
        return ()
    text = text or {}
    notes = []
    skipped = [
        repr(c.name) + (f" (text: {text[c.position]!r})" if c.position in text else "")
        for c in columns
        if c.quantity == IGNORE and c.name != IGNORE
    ]
    if skipped:
        notes.append(f"columns not read: {', '.join(skipped)}")
    return tuple(notes)
