"""The vocabulary of the canonical test-data format: the column names with the quantity
and unit each stands for, and the metadata keys read as numbers."""

from typing import NamedTuple

from .._cable import M_PER_MM, ZERO_CELSIUS


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
    "force_lbf": Unit("force", 4.4482216152605),  # the pound-force, exactly
    "force_kgf": Unit("force", 9.80665),  # the kilogram-force, exactly
    "elongation_mm": Unit("elongation", 1e-3),
    "elongation_cm": Unit("elongation", 1e-2),
    "elongation_m": Unit("elongation", 1.0),
    "elongation_in": Unit("elongation", 0.0254),
    "temperature_C": Unit("temperature", 1.0),
}
QUANTITIES = ("time", "force", "elongation", "temperature")
# Names `columns` (`--columns`) also accepts, for columns that hold another quantity
# from which a canonical one follows (never a canonical file's header): a stress
# (factor to MPa; the force is the stress x the area of a circle of `diameter_mm`),
# a strain (factor to mm/mm; the elongation is the strain x `length_mm`), a stretch
# ratio lambda (the elongation is (lambda - 1) x `length_mm`), a cycle count (the
# time follows from the test frequency, `frequency_hz`).
DERIVED_COLUMNS: dict[str, Unit] = {
    "stress_MPa": Unit("stress", 1.0),
    "stress_kPa": Unit("stress", 1e-3),
    "stress_Pa": Unit("stress", 1e-6),
    "strain": Unit("strain", 1.0),
    "strain_percent": Unit("strain", 0.01),
    "stretch_ratio": Unit("stretch", 1.0),
    "cycles": Unit("cycles", 1.0),
}
# The canonical quantity each derived one is read as.
DERIVED_QUANTITY = {
    "stress": "force",
    "strain": "elongation",
    "stretch": "elongation",
    "cycles": "time",
}
_REQUIRED = ("time", "force")
# The `columns` name of a file column to skip (not parsed).
IGNORE = "-"


class Bound(NamedTuple):
    """The values a numeric metadata key may take: those above `minimum` that stay
    above it in the [`jaxcable.Cable`][]'s SI units, where `(value - minimum) *
    to_si` is positive (a length of 1e-320 mm is not: it is 0 m); finite, unless
    `infinite` (then `inf` too)."""

    minimum: float
    to_si: float
    infinite: bool = False


# Metadata keys parsed as numbers, with the values the Cable accepts. Other keys are
# kept as strings.
NUMERIC_METADATA = {
    "length_mm": Bound(0.0, M_PER_MM),
    "diameter_mm": Bound(0.0, M_PER_MM),
    "rate_mm_per_min": Bound(0.0, M_PER_MM / 60),
    "temperature_C": Bound(-ZERO_CELSIUS, 1.0),  # above absolute zero
    "breaking_load_N": Bound(0.0, 1.0),
    # Dimensionless (elongation / L0 at break); `inf` for a material that does not
    # break, as the Cable accepts.
    "breaking_strain": Bound(0.0, 1.0, infinite=True),
}


def written_name(quantity: str) -> str:
    """The column name `quantity` is written under."""
    return next(name for name, unit in COLUMNS.items() if unit.quantity == quantity)


def missing_quantities(seen, required: tuple[str, ...] = _REQUIRED) -> list[str]:
    """The `required` quantities (default time and force) that are not keys of
    `seen`, the quantities some column reads."""
    return [quantity for quantity in required if quantity not in seen]


def accepted_names(quantity: str) -> str:
    """The column names `quantity` is read from, for error messages:
    `'time_s' or 'time_ms' or ...`."""
    return " or ".join(
        f"'{name}'" for name, unit in COLUMNS.items() if unit.quantity == quantity
    )
