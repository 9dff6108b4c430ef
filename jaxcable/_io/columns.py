"""The `columns` argument of [`jaxcable.read_test`][] (`--columns`): the file's
columns in order (`"time_s,elongation_mm,force_N,-"`), or some of them by their
header names (`"Machine_N_cycles=cycles,Machine_Load=force_kN"`, the others not
read), each named by a canonical column name (`units.COLUMNS`) or a derived one
(`units.DERIVED_COLUMNS`: a stress, strain, stretch ratio or cycle count)."""

from collections.abc import Sequence

from .parsing import ColumnMap, row_cells
from .testdata import where
from .units import (
    COLUMNS,
    DERIVED_COLUMNS,
    DERIVED_QUANTITY,
    IGNORE,
    accepted_names,
)


_ACCEPTED = ", ".join((*COLUMNS, *DERIVED_COLUMNS))
# How far down a file the header named by `NAME=unit` pairs is looked for.
_HEADER_SEARCH_LINES = 200


def _tokens(columns: str | Sequence[str]) -> list[str]:
    if isinstance(columns, str):
        return [t.strip() for t in columns.split(",")]
    return [str(t).strip() for t in columns]


def _check_quantities(
    mapped: list[ColumnMap], shown: str, path, required: tuple[str, ...]
) -> None:
    """A derived column counts for the quantity it is read as: one column per
    quantity, and the `required` ones named."""
    seen: dict[str, str] = {}
    for column in mapped:
        if column.quantity in (IGNORE, None):
            continue
        quantity = DERIVED_QUANTITY.get(column.quantity, column.quantity)
        if quantity in seen:
            raise ValueError(
                f"{path}: columns '{shown}': '{column.name}' is a second "
                f"{quantity} column (the first is '{seen[quantity]}')."
            )
        seen[quantity] = column.name
    for quantity in required:
        if quantity not in seen:
            derived = [
                n
                for n, u in DERIVED_COLUMNS.items()
                if DERIVED_QUANTITY[u.quantity] == quantity
            ]
            also = f" or {' or '.join(repr(n) for n in derived)}" if derived else ""
            raise ValueError(
                f"{path}: columns '{shown}' names no {quantity} column "
                f"({accepted_names(quantity)}{also})."
            )


def _map_token(token: str, position: int, name: str | None, path, shown: str):
    """The `ColumnMap` of one name of `columns` (`name`: the header's, by name)."""
    unit = COLUMNS.get(token) or DERIVED_COLUMNS.get(token)
    if unit is None:
        if token == IGNORE:
            return ColumnMap(IGNORE, IGNORE, 1.0, position)
        which = position if name is None else repr(name)
        raise ValueError(
            f"{path}: columns '{shown}': column {which} '{token}' is not a column name (accepted: {_ACCEPTED}, or '-' to "
            "ignore a column)."
        )
    return ColumnMap(
        token if name is None else name, unit.quantity, unit.to_si, position
    )


def parse_columns_spec(
    columns: str | Sequence[str], path, required: tuple[str, ...]
) -> list[ColumnMap] | dict[str, str]:
    """The column map named by a positional `columns` value, or, for `NAME=unit`
    pairs, the header names and their units (mapped by [`columns_by_name`][])."""
    tokens = _tokens(columns)
    shown = ",".join(tokens)
    pairs = ["=" in t for t in tokens]
    if any(pairs):
        if not all(pairs):
            raise ValueError(
                f"{path}: columns '{shown}': name every column in order "
                "('time_s,force_N,-') or some by their header names "
                "('Time=time_s,Load=force_N'), not both."
            )
        named: dict[str, str] = {}
        for token in tokens:
            name, unit = (s.strip() for s in token.rsplit("=", 1))
            if name in named:
                raise ValueError(f"{path}: columns '{shown}': '{name}' is named twice.")
            _map_token(unit, 1, name, path, shown)  # an unknown unit: refused here
            named[name] = unit
        mapped = [_map_token(u, 1, n, path, shown) for n, u in named.items()]
        _check_quantities(mapped, shown, path, required)
        return named
    mapped = [_map_token(t, i, None, path, shown) for i, t in enumerate(tokens, 1)]
    _check_quantities(mapped, shown, path, required)
    return mapped


def columns_by_name(
    lines: list[str], first: int, sep: str, named: dict[str, str], path
) -> tuple[list[ColumnMap], int]:
    """The column map of a file whose columns `named` names by their header names:
    the first row (from `lines[first]` on) holding every name is the header; its
    other columns are not read.

    **Returns:**

    `(columns, header_line)`: the column map, one entry per header cell, and the
    1-based line of the header.
    """
    shown = ",".join(f"{n}={u}" for n, u in named.items())
    for index in range(first, min(len(lines), first + _HEADER_SEARCH_LINES)):
        cells = row_cells(lines[index], sep)
        if not set(named) <= set(cells):
            continue
        mapped = []
        for position, cell in enumerate(cells, start=1):
            if cell in named:
                mapped.append(_map_token(named[cell], position, cell, path, shown))
            else:
                mapped.append(ColumnMap(cell or IGNORE, IGNORE, 1.0, position))
        return mapped, index + 1
    raise ValueError(
        f"{where(path)}: columns '{shown}': no header line in the first "
        f"{_HEADER_SEARCH_LINES} lines holds every name "
        f"({', '.join(repr(n) for n in named)})."
    )
