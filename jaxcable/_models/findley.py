"""Findley's power-law creep (Findley, Lai & Onaran 1976, *Creep and Relaxation of
Nonlinear Viscoelastic Materials*, Ch. 5): under a constant stress sigma applied at
t = 0,

    eps(t) = eps0 + m t^n,   eps0 = sigma / E0,   m = sigma / (E_t t_ref^n),

a linear viscoelastic solid whose creep compliance J(t) = 1/E0 + (t / t_ref)^n / E_t
is a power of time. An arbitrary force history is Boltzmann's superposition of that
compliance, which needs the whole history at every sample. The model runs one
sample at a time instead, through a retardation spectrum that reproduces t^n over a
stated time range (`power_law_terms`): a spring, `elements` Kelvin-Voigt elements
with log-spaced retardation times and a dashpot, each stepped exactly for a force
linear over the sample.
"""

import math

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jax.scipy.special import gammaln
from jaxtyping import Array, Float, Int

from .. import _checks
from .._cable import Cable
from .._results import RESULTS
from .base import AbstractCableModel, StrainParts, state_zero
from .fields import MODULUS, declared_ok, parameter
from .kernels import retarded


def power_law_terms(n, t_ref, t_short, t_long, elements: int):
    """A retardation spectrum whose creep is (t / t_ref)^n for t_short << t << t_long.

    The power law is a continuous spectrum of Kelvin-Voigt elements over x = ln tau
    (for 0 < n < 1, from the integral of u^(-n-1) (1 - exp(-u)) over u > 0, which is
    Gamma(1 - n) / n):

        t^n = n / Gamma(1 - n) * integral of tau^n (1 - exp(-t / tau)) dx.

    The integral is cut at tau = t_short and t_long. Inside, the midpoint rule on
    `elements` cells of equal width dx gives each cell's element at the cell's centre
    tau_i the compliance n / Gamma(1 - n) tau_i^n dx; the integrand is analytic in x
    in a strip of half-width pi / 2, so the rule's ripple falls as exp(-pi^2 / dx)
    (1.4 % at one element per decade, 2e-4 at two). Below t_short every element has
    fully crept by the times that matter (1 - exp(-t / tau) = 1): a spring of
    compliance t_short^n / Gamma(1 - n). Above t_long none has begun to
    (1 - exp(-t / tau) = t / tau): a dashpot of fluidity n t_long^(n - 1) /
    (Gamma(1 - n) (1 - n)). The ends are exact to first order; the error is largest
    near them (measured in `tests/test_family.py`).

    **Arguments:**

    - `n`: the exponent, 0 < n < 1.
    - `t_ref`: the time at which the power law's creep compliance is 1 (its unit), s.
    - `t_short`, `t_long`: the range of retardation times, s (0 < t_short < t_long).
    - `elements`: the number of Kelvin-Voigt elements (static).

    **Returns:**

    `(spring, weights, taus, fluidity)`: the compliance of the spring, of each
    element and the dashpot's fluidity (1/s), all in units of the power law's
    compliance at t_ref; each element's retardation time, s.
    """
    log_short, log_long = jnp.log(t_short), jnp.log(t_long)
    dx = (log_long - log_short) / elements
    centres = log_short + (jnp.arange(elements) + 0.5) * dx
    taus = jnp.exp(centres)
    log_gamma = gammaln(1.0 - n)
    # Every power as exp(n ln(tau / t_ref)): finite for any n, smooth in n.
    spring = jnp.exp(n * (log_short - jnp.log(t_ref)) - log_gamma)
    weights = n * dx * jnp.exp(n * (centres - jnp.log(t_ref)) - log_gamma)
    fluidity = (
        n / (1.0 - n) * jnp.exp(n * (log_long - jnp.log(t_ref)) - log_gamma) / t_long
    )
    return spring, weights, taus, fluidity


class FindleyState(eqx.Module):
    """Scan carry of [`jaxcable.FindleyModel`][] for one cable (all SI).

    **Fields:**

    - `stress`: stress F / A at the previous sample, Pa.
    - `kelvin_voigt`: the strain of each Kelvin-Voigt element, shape `(elements,)`.
    - `dashpot`: the strain of the dashpot (the spectrum above `t_long`).
    """

    stress: Float[Array, ""]
    kelvin_voigt: Float[Array, " elements"]
    dashpot: Float[Array, ""]


class FindleyModel(AbstractCableModel[FindleyState]):
    """Findley's power-law creep: eps(t) = sigma / E0 + sigma / E_t (t / t_ref)^n under
    a constant stress sigma = F / A applied at t = 0 (Findley, Lai & Onaran 1976,
    Ch. 5; linear in the stress, so Boltzmann's superposition gives any history).

    Findley's eps0 + m t^n with eps0 = sigma / E0 and m = sigma / (E_t t_ref^n):
    `E_t` is the stress over the creep strain after `t_ref` (default one hour), a
    modulus like the others, so that it and `n` are fitted on comparable scales
    (Findley's m has the unit 1 / s^n, which moves with n).

    **Per sample.** The power law is carried by a spring, `elements` Kelvin-Voigt
    elements with retardation times log-spaced between `t_short` and `t_long`, and a
    dashpot (`power_law_terms`); each element is stepped exactly for a stress
    linear over the sample (`jaxcable._models.kernels.retarded`), so the model is
    exact for any force history in which the power law is replaced by its spectrum.
    With the defaults (20 elements over 0.01 s to 1e7 s, 2.2 per decade) the creep
    under a constant load is within 0.5 % of eps0 + m t^n from 0.1 s to 1e6 s for
    n from 0.1 to 0.5 (measured in `tests/test_family.py`). On unloading the
    elements recover (the power law's recovery, by superposition); the dashpot, the
    part of the spectrum slower than `t_long`, does not. `direction` is not used.

    **Strain parts.** `instantaneous` = sigma (1 / E0 + the spectrum's spring);
    `creep` = the elements and the dashpot.

    **Fields (SI):**

    - `E0`: instantaneous modulus, Pa.
    - `E_t`: creep modulus: the stress over the power law's creep strain after
        `t_ref`, Pa.
    - `n`: the exponent, dimensionless, 0 < n < 1 (checked).
    - `t_ref`: the reference time of `E_t`, s (static; default 3600 s).
    - `t_short`, `t_long`: the range of retardation times over which t^n is
        represented, s (static; defaults 0.01 s and 1e7 s, 116 days).
    - `elements`: the number of Kelvin-Voigt elements (static; default 20).

    The defaults are illustrative for the 3 mm SK78 cable: E0 = 2.2e9 Pa as
    [`jaxcable.HookeModel`][]; E_t = 2e10 Pa, 0.07 % of creep strain after one hour
    at 100 N; n = 0.2, in the range Findley reports for polymers (0.1-0.3).
    """

    CLI_NAME = "findley"

    E0: Float[Array, "*batch"] = parameter(2.2e9, **MODULUS)
    E_t: Float[Array, "*batch"] = parameter(2e10, **MODULUS)
    # 0 < n < 1 (Gamma(1 - n) and the spectrum): checked by `check_more`.
    n: Float[Array, "*batch"] = parameter(0.2, unit="-")
    # The power law's time scales are static settings, not array fields: a fit
    # that frees every array field of a model without a declared identifiable set
    # must not free them (t_ref is degenerate with E_t; t_short, t_long and
    # elements choose the approximation, not the material).
    t_ref: float = eqx.field(static=True, default=3600.0)
    t_short: float = eqx.field(static=True, default=0.01)
    t_long: float = eqx.field(static=True, default=1e7)
    elements: int = eqx.field(static=True, default=20)

    def check_more(self):
        if _checks.is_concrete(self.n) and np.any(np.asarray(self.n) >= 1):
            raise ValueError(
                f"`FindleyModel.n` must be < 1 (a creep that slows down), got {self.n}."
            )
        times = (self.t_ref, self.t_short, self.t_long)
        if not all(isinstance(t, (int, float)) and 0 < t < math.inf for t in times):
            raise ValueError(
                "`FindleyModel.t_ref`, `t_short` and `t_long` must be positive "
                f"finite numbers (s), got {times}."
            )
        if not self.t_short < self.t_long:
            raise ValueError(
                "`FindleyModel.t_short` must be below `t_long`, got "
                f"t_short={self.t_short}, t_long={self.t_long}."
            )
        _checks.require_int("FindleyModel.elements", self.elements, low=1)

    def check(self, cable: Cable) -> RESULTS:
        ok = _checks.all_ok(declared_ok(self), self.n < 1)
        return _checks.domain_result(ok)

    def _terms(self):
        """The spectrum (`power_law_terms`) in compliance units, 1/Pa."""
        spring, weights, taus, fluidity = power_law_terms(
            self.n, self.t_ref, self.t_short, self.t_long, self.elements
        )
        return spring / self.E_t, weights / self.E_t, taus, fluidity / self.E_t

    def init(self, cable: Cable) -> FindleyState:
        zero = state_zero(cable, self.E0, self.E_t, self.n)
        return FindleyState(
            stress=zero,
            kelvin_voigt=jnp.zeros((self.elements,), zero.dtype),
            dashpot=zero,
        )

    def advance(
        self,
        state: FindleyState,
        cable: Cable,
        dt: Float[Array, ""],
        force: Float[Array, ""],
        direction: Int[Array, ""],
    ) -> tuple[FindleyState, StrainParts]:
        del direction  # a linear viscoelastic solid: one law both ways
        stress = force / cable.area
        spring, weights, taus, fluidity = self._terms()
        # Each element relaxes towards weight x stress, the stress linear over the
        # step: exact (`retarded`).
        kelvin_voigt = retarded(
            state.kelvin_voigt, weights * state.stress, weights * stress, dt, taus
        )
        dashpot = state.dashpot + fluidity * 0.5 * (state.stress + stress) * dt
        creep = jnp.sum(kelvin_voigt) + dashpot
        zero = jnp.zeros_like(stress)
        parts = StrainParts(stress * (1.0 / self.E0 + spring), creep, zero, zero, zero)
        return FindleyState(stress, kelvin_voigt, dashpot), parts
