import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float


def _is_concrete(x) -> bool:
    return not isinstance(x, jax.core.Tracer)


# The fields of a Cable, in order (one place to list them for checks and batching).
CABLE_FIELDS = ("length", "diameter", "speed", "breaking_load", "temperature")

# Kelvin at 0 °C: data files record temperature in °C, Cable holds kelvin.
ZERO_CELSIUS = 273.15


class Cable(eqx.Module):
    """One cable (or a batch of cables, for `jax.vmap`) and the speed it is stretched at.

    All fields are in SI units. Batching: give arrays of equal leading shape and
    `jax.vmap` over the `Cable`, e.g. `jax.vmap(simulate, in_axes=(None, 0, None))`.

    **Arguments:**

    - `length`: free length L0 of the cable, m. Strain is elongation / L0.
    - `diameter`: nominal diameter d, m (default 3 mm, Park's Dyneema SK78). The
        cross-section A = pi d^2 / 4 is held constant (Park, Section 2.1).
    - `speed`: crosshead (or winch) speed v at which the cable is stretched, m/s
        (default 3 mm/min). The strain rate v / L0 sets the loading time of a
        rate-driven test (Park Eq. 6) and the long-term retardation time (Park Eq. 8).
    - `breaking_load`: force above which inputs are rejected, N (default 2000 N, the
        rated load of the 3 mm SK78 cable in Park Section 2.1).
    - `temperature`: temperature of the cable, K (default 293.15 K = 20 °C). Only
        temperature-dependent models read it (e.g. [`jaxcable.TemperatureShift`][]);
        the fit and the drivers set it per sample from a test's temperature record.
    """

    length: Float[Array, "*batch"] = eqx.field(converter=jnp.asarray)
    diameter: Float[Array, "*batch"] = eqx.field(converter=jnp.asarray, default=3e-3)
    speed: Float[Array, "*batch"] = eqx.field(converter=jnp.asarray, default=3e-3 / 60)
    breaking_load: Float[Array, "*batch"] = eqx.field(
        converter=jnp.asarray, default=2000.0
    )
    temperature: Float[Array, "*batch"] = eqx.field(
        converter=jnp.asarray, default=293.15
    )

    def __check_init__(self):
        for name in CABLE_FIELDS:
            value = getattr(self, name)
            if not _is_concrete(value):
                continue
            v = np.asarray(value)
            if not np.all(np.isfinite(v)):
                raise ValueError(f"Cable `{name}` must be finite, got {v}.")
            if not np.all(v > 0):
                raise ValueError(
                    f"Cable `{name}` must be positive (SI units), got {v}."
                )

    @property
    def area(self) -> Float[Array, "*batch"]:
        """Cross-sectional area pi d^2 / 4, m^2."""
        return (math.pi / 4) * self.diameter**2

    @property
    def strain_rate(self) -> Float[Array, "*batch"]:
        """Strain rate v / L0 of the crosshead, 1/s (MODEL_NOTES point 5)."""
        return self.speed / self.length


def check_scalar_cable(cable: Cable) -> None:
    """Raise `ValueError` unless every field of `cable` is a scalar (one cable)."""
    for name in CABLE_FIELDS:
        shape = jnp.shape(getattr(cable, name))
        if shape != ():
            raise ValueError(
                f"`cable.{name}` has shape {shape}; the kernels simulate one cable. "
                "For a batch, `jax.vmap` over the Cable (or use the batched front ends)."
            )
