r"""Extensions for what a test shows besides the cable's own creep: the terminations'
compliance ([`TerminationCompliance`][]), the constructional stretch of a new braid
([`BeddingIn`][]) and a drift of the elongation signal ([`SensorDrift`][])."""

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float, Int, PyTree

from ..._cable import Cable
from ..base import (
    AbstractExtension,
    StrainParts,
    add_parts,
    state_zero,
)
from ..fields import parameter, setting, signed_effect


# ----------------------------------------------------------------------------------
# termination_compliance


class TerminationCompliance(AbstractExtension[PyTree]):
    r"""A length-independent series compliance: splices, knots, grips and pulleys.

    A termination adds the same extra millimetres at a given force whatever the
    cable's length, so its strain contribution scales as 1 / L0 — which is how it is
    told apart from the cable's own (strain-proportional) compliance when tests of
    several lengths are fitted together:

    delta(F) = `compliance` * F  (m),   eps_extra = delta(F) / L0,

    added to the instantaneous strain of the wrapped model. The state is the base
    model's (the termination has no memory).

    **Continuity.** Linear in the force, no memory: a perturbation d of the force
    moves the extra strain by `compliance` d / L0.

    **Fields:**

    - `base`: the wrapped model.
    - `compliance`: series compliance of the terminations, m/N (>= 0; 0 is the base).

    `wrap(base)` starts a fit at `compliance = 1e-6 m/N` (0.1 mm at 100 N).
    """

    CLI_NAME = "termination-compliance"

    compliance: Float[Array, ""] = parameter(
        0.0, unit="m/N", domain="nonnegative", stiffness=-1.0, null=0.0, start=1e-6
    )

    def init(self, cable: Cable) -> PyTree:
        return self.base.init(cable)

    def advance(
        self,
        state: PyTree,
        cable: Cable,
        dt: Float[Array, ""],
        force: Float[Array, ""],
        direction: Int[Array, ""],
    ) -> tuple[PyTree, StrainParts]:
        state, parts = self.base.advance(state, cable, dt, force, direction)
        extra = self.compliance * force / cable.length
        return state, add_parts(parts, instantaneous=extra)


# ----------------------------------------------------------------------------------
# bedding_in


class BeddingInState(eqx.Module):
    """Scan carry of [`jaxcable.BeddingIn`][].

    **Fields:**

    - `base`: the wrapped model's state.
    - `force_max`: the (smoothed) largest force seen so far, N.
    """

    base: PyTree
    force_max: Float[Array, ""]


def smooth_relu(x, width):
    """max(x, 0) with a quadratic blend over [0, width]: 0 for x <= 0, x^2 / (2 width)
    up to `width`, x - width / 2 beyond (continuously differentiable)."""
    clipped = jnp.clip(x, 0.0, width)
    return clipped**2 / (2 * width) + jnp.maximum(x - width, 0.0)


class BeddingIn(AbstractExtension[BeddingInState]):
    r"""Constructional stretch of a new braided rope (bedding-in).

    The strands of a new braid settle into each other the first time the rope is
    loaded: a permanent strain set by the largest force seen so far,

        eps_b = s_b (1 - exp(-F_max / F_b)),

    added to the instantaneous part: it grows only when the force exceeds its
    previous maximum and never recovers, so it depends on the history only through
    F_max. For Newton solves in force, F_max is updated with a continuously
    differentiable max, F_max <- F_max + r(F - F_max), r the ramp max(x, 0) blended
    quadratically over [0, `smoothing`] (it never grows while F <= F_max, and lags
    a rising force by at most `smoothing` / 2).

    **Continuity.** The update F_max + r(F - F_max) has partial derivatives in F_max
    and in F that are >= 0 and sum to 1, so it is non-expansive: a perturbation d of
    every force sample moves F_max by at most d, for any number of samples, and
    eps_b by at most s_b d / F_b. Noise at the largest force raises F_max towards the
    largest perturbed force, never beyond it (r(x) <= max(x, 0)): no drift with the
    total variation of the noise.

    **Fields:**

    - `base`: the wrapped model.
    - `s_b`: the saturated bedding-in strain, dimensionless (>= 0; 0 is the base).
    - `F_b`: the force scale of the bedding-in, N (> 0).
    - `smoothing`: width of the smooth max, N (> 0; default 0.01 N; not fitted).

    `wrap(base)` starts a fit at `s_b = 1e-4` (0.03 mm on a 300 mm cable) and
    `F_b = 50 N`.
    """

    CLI_NAME = "bedding-in"

    s_b: Float[Array, ""] = parameter(
        0.0, unit="-", domain="nonnegative", stiffness=-1.0, null=0.0, start=1e-4
    )
    F_b: Float[Array, ""] = parameter(50.0, unit="N", start=50.0)
    smoothing: Float[Array, ""] = setting(0.01, unit="N")

    def init(self, cable: Cable) -> BeddingInState:
        return BeddingInState(self.base.init(cable), state_zero(cable, self.s_b))

    def advance(
        self,
        state: BeddingInState,
        cable: Cable,
        dt: Float[Array, ""],
        force: Float[Array, ""],
        direction: Int[Array, ""],
    ) -> tuple[BeddingInState, StrainParts]:
        base_state, parts = self.base.advance(state.base, cable, dt, force, direction)
        force_max = state.force_max + smooth_relu(
            force - state.force_max, self.smoothing
        )
        bedding = self.s_b * -jnp.expm1(-force_max / self.F_b)
        new = BeddingInState(base_state, force_max)
        return new, add_parts(parts, instantaneous=bedding)


# ----------------------------------------------------------------------------------
# sensor_drift


class SensorDriftState(eqx.Module):
    """Scan carry of [`jaxcable.SensorDrift`][].

    **Fields:**

    - `base`: the wrapped model's state.
    - `elapsed`: time since the start of the record, s.
    """

    base: PyTree
    elapsed: Float[Array, ""]


class SensorDrift(AbstractExtension[SensorDriftState]):
    r"""A slow linear drift of the elongation signal (extensometer, encoder, load frame
    temperature): not a property of the cable, but what a long record shows.

        delta(t) = r (t - t0)  (m),   eps_drift = delta / L0,

    with t0 the start of the record (the state's elapsed time starts at 0 and adds
    every step's dt). It is the apparatus part of the strain (the instrument's, not
    the cable's: an extension of the material never scales it, wherever it is
    nested). r takes either sign; 0 is the base exactly. It depends on time only, not
    on the force.

    **Fields:**

    - `base`: the wrapped model.
    - `drift_rate`: r, m/s (finite, either sign).

    `wrap(base)` starts a fit at `drift_rate = 1e-9 m/s` (3.6 um per hour; a linear
    transform scaled by that start).
    """

    CLI_NAME = "sensor-drift"

    drift_rate: Float[Array, ""] = signed_effect("m/s", start=1e-9)

    def init(self, cable: Cable) -> SensorDriftState:
        return SensorDriftState(
            self.base.init(cable), state_zero(cable, self.drift_rate)
        )

    def advance(
        self,
        state: SensorDriftState,
        cable: Cable,
        dt: Float[Array, ""],
        force: Float[Array, ""],
        direction: Int[Array, ""],
    ) -> tuple[SensorDriftState, StrainParts]:
        base_state, parts = self.base.advance(state.base, cable, dt, force, direction)
        elapsed = state.elapsed + dt
        drift = self.drift_rate * elapsed / cable.length
        return SensorDriftState(base_state, elapsed), add_parts(parts, apparatus=drift)
