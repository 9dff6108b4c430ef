"""The cable a model is run on, in SI units, and the one conversion from the units of
data files (mm, mm/min, °C) to it."""

import math

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from . import _checks
from ._arrays import field_array, optional_field_array


# The fields of a Cable, in order (one place to list them for checks and batching).
CABLE_FIELDS = (
    "length",
    "diameter",
    "speed",
    "breaking_load",
    "breaking_strain",
    "temperature",
    "covariate",
)

# The fields that must be positive (a covariate may take any sign).
_POSITIVE_FIELDS = CABLE_FIELDS[:-1]
# The positive fields that may be +inf (a material that never breaks).
_MAY_BE_INFINITE = ("breaking_strain",)

# Kelvin at 0 °C: data files record temperature in °C, Cable holds kelvin.
ZERO_CELSIUS = 273.15

# Metres per millimetre: data files give lengths in mm and speeds in mm/min, Cable
# holds m and m/s.
M_PER_MM = 1e-3

# Park's Dyneema SK78 test (Park, Section 2.1): the diameter and crosshead speed of a
# cable whose file leaves them out.
DEFAULT_DIAMETER_MM = 3.0
DEFAULT_RATE_MM_PER_MIN = 3.0

# The breaking strain (elongation / L0 at break) of a cable that does not give its own,
# for the 3 mm braided Dyneema SK78 rope of Park et al.: an estimate, not a measured
# value. A rope breaks when its fibres do (SK75/SK78: 3-4 %, DSM fact sheet CIS YA100),
# and its strain adds the braid's constructional elongation, large for Park's rope
# (2.8 % at 100 N after a 3-minute ramp, 3.9 % at 150 N): 3.5 % + 3.5 %.
# docs/model_notes.md ("Breaking strain") gives the sources.
DEFAULT_BREAKING_STRAIN = 0.07

# The rated breaking load of Park's 3 mm SK78 cable (Park, Section 2.1), N: the
# `Cable` default, and the scale of `default_breaking_load` for other diameters.
DEFAULT_BREAKING_LOAD_N = 2000.0


def default_breaking_load(diameter_mm):
    """The breaking load of a cable that does not give its own, N: the 3 mm rope's
    `DEFAULT_BREAKING_LOAD_N` scaled with the cross-section, `2000 N x (d / 3 mm)^2`
    (a rope's nominal strength, 283 MPa, held at any diameter), so that a thin
    fibre does not inherit the 3 mm rope's load nor a thick rope a 3 mm limit.

    **Arguments:**

    - `diameter_mm`: the nominal diameter, mm.

    **Returns:**

    The breaking load, N.
    """
    return DEFAULT_BREAKING_LOAD_N * (diameter_mm / DEFAULT_DIAMETER_MM) ** 2


def speed_from_mm_per_min(rate_mm_per_min):
    """The crosshead speed in m/s of a rate in mm/min (the unit of data files)."""
    return rate_mm_per_min * M_PER_MM / 60


class Cable(eqx.Module):
    """One cable (or a batch of cables, for `jax.vmap`) and the speed it is stretched at.

    All fields are in SI units; [`jaxcable.Cable.from_mm`][] builds one from the units
    of data files (mm, mm/min, °C). Batching: give arrays of equal leading shape and
    `jax.vmap` over the `Cable`, e.g. `jax.vmap(simulate, in_axes=(None, 0, None))`.

    **Arguments:**

    - `length`: free length L0 of the cable, m. Strain is elongation / L0.
    - `diameter`: nominal diameter d, m (default 3 mm, Park's Dyneema SK78). The
        cross-section A = pi d^2 / 4 is held constant (Park, Section 2.1).
    - `speed`: crosshead (or winch) speed v at which the cable is stretched, m/s
        (default 3 mm/min). The strain rate v / L0 sets the loading time of a
        rate-driven test (Park Eq. 6) and the long-term retardation time (Park Eq. 8).
    - `breaking_load`: force above which inputs are rejected, N (default 2000 N, the
        rated load of the 3 mm SK78 cable in Park Section 2.1; a cable built by
        [`jaxcable.Cable.from_mm`][] without one gets it scaled with its
        cross-section, [`jaxcable.default_breaking_load`][]).
    - `breaking_strain`: strain (elongation / L0) at which the cable breaks,
        dimensionless (default `jaxcable.DEFAULT_BREAKING_STRAIN`, for the 3 mm
        braided Dyneema SK78 rope). Every simulation reports a strain above it as
        [`jaxcable.RESULTS`][]`.strain_beyond_break` (raised with `throw=True`):
        the model has been run past the point where the cable is in one piece.
        `math.inf` for a material with no meaningful break (e.g. an elastomer with
        the linear baselines): never flagged.
    - `temperature`: temperature of the cable, K (default 293.15 K = 20 °C). Only
        temperature-dependent models read it (e.g. [`jaxcable.TemperatureShift`][]);
        the fit and the drivers set it per sample from a test's temperature record.
    - `covariate`: the value of one recorded covariate column at this sample, in the
        unit of that column (default None, read as 0): humidity, moisture content, a second
        thermocouple, ... Only covariate-dependent models read it (e.g.
        `jaxcable.DiscoveredTerm`); the fit sets it per sample from the column named
        by its `covariate` argument (see [`jaxcable.pad_tests`][]). Any sign.
    """

    length: Float[Array, "*batch"] = eqx.field(converter=field_array)
    diameter: Float[Array, "*batch"] = eqx.field(
        converter=field_array, default=DEFAULT_DIAMETER_MM * M_PER_MM
    )
    speed: Float[Array, "*batch"] = eqx.field(
        converter=field_array, default=speed_from_mm_per_min(DEFAULT_RATE_MM_PER_MIN)
    )
    breaking_load: Float[Array, "*batch"] = eqx.field(
        converter=field_array, default=DEFAULT_BREAKING_LOAD_N
    )
    breaking_strain: Float[Array, "*batch"] = eqx.field(
        converter=field_array, default=DEFAULT_BREAKING_STRAIN
    )
    temperature: Float[Array, "*batch"] = eqx.field(
        converter=field_array, default=293.15
    )
    # None unless set: a batch of cables built without it still vmaps (None has no
    # leaves to map), and models read None as 0.
    covariate: Float[Array, "*batch"] | None = eqx.field(
        converter=optional_field_array, default=None
    )

    def __check_init__(self):
        for name in _POSITIVE_FIELDS:
            value = getattr(self, name)
            if not _checks.is_concrete(value):
                continue
            try:
                _checks.require_positive(
                    name, value, allow_inf=name in _MAY_BE_INFINITE
                )
            except ValueError as e:
                raise ValueError(f"Cable {str(e).rstrip('.')}, SI units.") from None

    @classmethod
    def from_mm(
        cls,
        *,
        length_mm: Float[ArrayLike, "*batch"],
        diameter_mm: Float[ArrayLike, "*batch"] = DEFAULT_DIAMETER_MM,
        rate_mm_per_min: Float[ArrayLike, "*batch"] = DEFAULT_RATE_MM_PER_MIN,
        temperature_C: Float[ArrayLike, "*batch"] | None = None,
        breaking_load_N: Float[ArrayLike, "*batch"] | None = None,
        breaking_strain: Float[ArrayLike, "*batch"] | None = None,
    ) -> "Cable":
        """The cable described in the units of data files and their metadata.

        The arguments are named as the metadata keys of a test file (and of a
        protocol file), so that a file's metadata can be passed as it is.

        **Arguments:**

        - `length_mm`: free length, mm.
        - `diameter_mm`: nominal diameter, mm (default 3 mm).
        - `rate_mm_per_min`: crosshead speed, mm/min (default 3 mm/min).
        - `temperature_C`: temperature, °C, or `None` for the `Cable` default (20 °C).
        - `breaking_load_N`: breaking load, N, or `None` for the 3 mm rope's 2000 N
            scaled with the cross-section ([`jaxcable.default_breaking_load`][]): a
            thin fibre does not inherit the 3 mm rope's load.
        - `breaking_strain`: breaking strain (elongation / L0, dimensionless), or
            `None` for the `Cable` default.

        **Returns:**

        A `Cable` in SI: `length` and `diameter` in m, `speed` in m/s, `temperature`
        in K (`breaking_strain` is dimensionless, as given).
        """
        kwargs = {}
        if temperature_C is not None:
            kwargs["temperature"] = temperature_C + ZERO_CELSIUS
        if breaking_load_N is None:
            breaking_load_N = default_breaking_load(diameter_mm)
        kwargs["breaking_load"] = breaking_load_N
        if breaking_strain is not None:
            kwargs["breaking_strain"] = breaking_strain
        return cls(
            length=length_mm * M_PER_MM,
            diameter=diameter_mm * M_PER_MM,
            speed=speed_from_mm_per_min(rate_mm_per_min),
            **kwargs,
        )

    @property
    def area(self) -> Float[Array, "*batch"]:
        """Cross-sectional area pi d^2 / 4, m^2."""
        return (math.pi / 4) * self.diameter**2

    @property
    def strain_rate(self) -> Float[Array, "*batch"]:
        """Strain rate v / L0 of the crosshead, 1/s: the rate a rate-driven test
        strains the cable at (Park Eq. 6 and 8 read it)."""
        return self.speed / self.length


def check_scalar_cable(cable: Cable) -> None:
    """Raise `ValueError` unless every field of `cable` is a scalar (one cable)."""
    for name in CABLE_FIELDS:
        if getattr(cable, name) is None:
            continue
        shape = jnp.shape(getattr(cable, name))
        if shape != ():
            raise ValueError(
                f"`cable.{name}` has shape {shape}; the kernels simulate one cable. "
                "For a batch, `jax.vmap` over the Cable (or use the batched front ends)."
            )
