"""The vocabulary of the canonical test-data format: the column names with the quantity
and unit each stands for, and the metadata keys read as numbers."""

from typing import NamedTuple


class Unit(NamedTuple):
    """What a column name stands for.

    - `quantity`: the [`jaxcable.TestData`][] field it fills.
    - `to_si`: file value * `to_si` = value in that field's unit.
    """

    quantity: str
    to_si: float


# Column names a file may use for each canonical quantity. The first listed for a
# quantity is the one written.
COLUMNS: dict[str, Unit] = {
    "time_s": Unit("time", 1.0),
    "time_ms": Unit("time", 1e-3),
    "time_min": Unit("time", 60.0),
    "time_h": Unit("time", 3600.0),
    "force_N": Unit("force", 1.0),
    "force_kN": Unit("force", 1e3),
    "elongation_mm": Unit("elongation", 1e-3),
    "elongation_m": Unit("elongation", 1.0),
    "temperature_C": Unit("temperature", 1.0),
}
QUANTITIES = ("time", "force", "elongation", "temperature")
_REQUIRED = ("time", "force")
# The `columns` name of a file column to skip (not parsed).
IGNORE = "-"

# Metadata keys parsed as numbers, with whether they must be strictly positive. Other
# keys are kept as strings.
NUMERIC_METADATA = {
    "length_mm": True,
    "diameter_mm": True,
    "rate_mm_per_min": True,
    "temperature_C": False,
}


def written_name(quantity: str) -> str:
    """The column name `quantity` is written under."""
    return next(name for name, unit in COLUMNS.items() if unit.quantity == quantity)


def missing_quantities(seen) -> list[str]:
    """The required quantities (time, force) that are not keys of `seen`, the
    quantities some column reads."""
    return [quantity for quantity in _REQUIRED if quantity not in seen]


def accepted_names(quantity: str) -> str:
    """The column names `quantity` is read from, for error messages:
    `'time_s' or 'time_ms' or ...`."""
    return " or ".join(
        f"'{name}'" for name, unit in COLUMNS.items() if unit.quantity == quantity
    )
