"""Piao et al.'s parameter surfaces: a model parameter as a cubic polynomial of payload
and cable length (Eq. 5, [`ParameterSurface`][]), the printed coefficients (Table 3,
whose parameter and unit did not survive, read as E_L1 in Pa: [`PIAO_TABLE3`][]) and
the five-element model they give ([`piao_five_element`][])."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .. import _checks
from .._arrays import field_array
from .piao import PIAO_TABLE1, FiveElementModel


def _coefficients(x: ArrayLike) -> Array | np.ndarray:
    # A NumPy array stays on the host until the surface is evaluated: the preset
    # below is built when jaxcable is imported, and a JAX array there would start
    # JAX's backend, after which XLA_FLAGS are no longer read (a user's flags set
    # after the import, or another threshold `jaxcable.enable_cpu_loop_kernels`
    # chooses, would do nothing).
    if isinstance(x, np.ndarray) and np.issubdtype(x.dtype, np.floating):
        return x
    return field_array(x)


class ParameterSurface(eqx.Module):
    """A model parameter as a cubic polynomial of payload mass and cable length (Piao
    Eq. 5).

        P = p00 + p10 x + p01 y + p20 x^2 + p11 x y + p02 y^2
            + p30 x^3 + p21 x^2 y + p12 x y^2,

    with (x, y) = (mass, length) as Eq. 5 prints it (`first="mass"`), or
    (x, y) = (length, mass) (`first="length"`). Mass in kg, length in m; the value is
    in the unit of the parameter it stands for (Pa for a modulus). Payload and length
    are used instead of stress and strain because a cable robot measures them directly
    (force sensor and winch encoder, Piao Section 3.3).

    A pure function of its inputs: `jax.jit`, `jax.vmap` (over masses, lengths or a
    leading batch axis of `coefficients`) and `jax.grad` apply.

    **Arguments:**

    - `coefficients`: shape `(9,)` (or `(*batch, 9)`), in the order
        p00, p10, p01, p20, p11, p02, p30, p21, p12 (Piao Table 3).
    - `first`: which variable is x, `"mass"` or `"length"` (static).
    """

    coefficients: Float[Array | np.ndarray, "*batch 9"] = eqx.field(
        converter=_coefficients
    )
    first: str = eqx.field(static=True, default="mass")

    def __check_init__(self):
        if self.first not in ("mass", "length"):
            raise ValueError(
                f"ParameterSurface `first` must be 'mass' or 'length', got "
                f"{self.first!r}."
            )
        shape = jnp.shape(self.coefficients)
        if len(shape) == 0 or shape[-1] != 9:
            raise ValueError(
                f"ParameterSurface `coefficients` must have shape (9,) (p00, p10, p01, "
                f"p20, p11, p02, p30, p21, p12), got shape {shape}."
            )
        if _checks.is_concrete(self.coefficients):
            _checks.require_finite("ParameterSurface.coefficients", self.coefficients)

    def __call__(
        self, mass_kg: Float[ArrayLike, "*shape"], length_m: Float[ArrayLike, "*shape"]
    ) -> Float[Array, "*shape"]:
        """Piao Eq. 5: the surface at a payload `mass_kg` (kg) and a cable length
        `length_m` (m); arrays broadcast.

        **Returns:**

        P(x, y) in the unit of the parameter (Pa for a modulus).
        """
        mass = jnp.asarray(mass_kg)
        length = jnp.asarray(length_m)
        x, y = (mass, length) if self.first == "mass" else (length, mass)
        coefficients = jnp.asarray(self.coefficients)  # a preset's are NumPy
        p = [coefficients[..., i] for i in range(9)]
        # Grouped in powers of x (Horner in x) to limit cancellation.
        return (
            p[0]
            + y * (p[2] + p[5] * y)
            + x * (p[1] + p[4] * y + p[8] * y**2 + x * (p[3] + p[7] * y + p[6] * x))
        )


_TABLE3 = np.array(
    [2.803e12, -1.993e11, -7.127e11, 2.543e9, 5.164e10, 8.817e10, -2.286e7, 5.996e7]
    + [-4.337e9]
)

PIAO_TABLE3 = ParameterSurface(_TABLE3, first="length")
"""Piao Table 3, coefficients of unknown identity, read as the loading spring modulus
E_L1(m, l) in Pa (an illustrative preset, not a measured spring).

**What survives.** Table 3 prints nine coefficients, in the order p00, p10, p01, p20,
p11, p02, p30, p21, p12, without a unit and without the parameter they belong to: Eq. 5
lists P = E_L1, E_UL1, E_UL3 or eta_UL3 "and all values are listed in Table 3", but
only one set of nine survives.

**The reading chosen.** E_L1, in Pa (the unit Table 1 gives E_L1), with the variables
swapped, `first="length"` (x = length in m, y = mass in kg). The text says E_L1
"increases with high payload and short cable length" (Sections 3.3 and 4). Evaluated
as printed (x = mass in kg) the surface *rises* with cable length over most of the
tested range; swapped, it rises with payload and falls with length over the
experiments' range (payloads up to about 100 kg, lengths 5.4-8.4 m; tested for
10-110 kg, and the rise holds from about 4 kg).

**Magnitudes.** Over 10-100 kg and 5.4-8.4 m this reading spans 3.7e12 Pa (10 kg,
8.4 m) to 6.1e14 Pa (100 kg, 5.4 m), 31-37 to 5,000-6,100 times the UHMWPE fibre
modulus (100-120 GPa), which no rope made of the fibre can exceed; at 65 kg on 7.4 m
(the default E_L1, 2.2e14 Pa) it is about 2,000 times. As printed it spans 1.3e12 to
5.4e12 Pa, 11-54 times. Either way it is not the spring of this rope: taken as printed
the spring is practically rigid (strain below 1e-6 on the paper's 6 mm rope) and the
elongation is carried by the Kelvin-Voigt elements. The values are of the order of
Table 1's eta_L3 = 1e13 Pa s, so they may be eta_UL3's (Pa s; the text gives it the
same trend as E_L1), which the trend cannot tell apart.

No rescaling is applied on purpose: the surface grows about as m^2, so any factor
making the spring compliant would make the instantaneous elongation *fall* with
payload (sigma / E_L1 ~ 1/m); taken as printed the model's elongation rises with
payload. A different scale is a one-liner:
`ParameterSurface(PIAO_TABLE3.coefficients * s, first="length")`.
`docs/model_notes.md` point 12 records the reading; `tests/test_five_element.py`
checks the trend and the span of both variable orders.
"""


def piao_five_element(
    mass_kg: Float[ArrayLike, ""],
    length_m: Float[ArrayLike, ""],
    *,
    surface: ParameterSurface = PIAO_TABLE3,
) -> FiveElementModel:
    """The five-element model of Piao et al. for a payload and a cable length.

    E_L1 = `surface(mass_kg, length_m)` (Piao Table 3, coefficients of unknown
    identity read as E_L1 in Pa, 31-6,100 times the UHMWPE fibre modulus over the
    paper's range: see [`jaxcable.PIAO_TABLE3`][]); E_L2, E_L3, eta_L2, eta_L3 from
    Table 1. The unloading
    parameters (Table 2 and their surfaces) are lost: E_UL1 follows the same surface
    (the paper: "E_UL1 ... has the similar trend with E_L1") and E_UL2, E_UL3, eta_UL2,
    eta_UL3 equal the loading values, so the preset is the linear five-element solid
    (full recovery after unloading). An illustrative preset, not a calibrated cable.

    Traceable: `jax.jit`, `jax.vmap` over payloads and lengths and `jax.grad` with
    respect to them apply, so a controller can rebuild the model as the payload and
    the cable length change.

    **Arguments:**

    - `mass_kg`: payload mass, kg (the experiments used up to about 100 kg).
    - `length_m`: free cable length, m (the experiments used 5.4, 7.4 and 8.4 m).
    - `surface`: the E_L1 surface (default [`jaxcable.PIAO_TABLE3`][]).

    **Returns:**

    A [`jaxcable.FiveElementModel`][]. With concrete inputs outside the surface's
    domain (E_L1 <= 0) it raises `ValueError`; traced, `model.check` flags it.
    """
    if _checks.is_concrete(mass_kg, length_m):
        _checks.require_positive("mass_kg", mass_kg, allow_zero=True)
        _checks.require_positive("length_m", length_m)
    E_1 = surface(mass_kg, length_m)
    # The fields convert numbers (`field_array`), which pyright does not see through
    # `fields.parameter`.
    return FiveElementModel(E_L1=E_1, E_UL1=E_1, **PIAO_TABLE1)  # pyright: ignore[reportArgumentType]
