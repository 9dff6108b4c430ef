r"""Extensions that change the material law of the base model: Park's hardening of
its instantaneous strain ([`Hardening`][]), the exact hereditary Kelvin-Voigt creep
([`Hereditary`][]), one more retardation time ([`SecondRetardation`][]) and a creep
compliance that grows with stress ([`StressNonlinearCreep`][])."""

import math

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float, Int, PyTree

from ..._cable import Cable
from ..base import (
    AbstractCableModel,
    AbstractExtension,
    StrainParts,
    add_parts,
    innermost,
    state_zero,
)
from ..fields import MODULUS, parameter, setting
from ..kernels import (
    relaxation_average,
    relaxation_terms,
    running_max,
    safe_pow,
    tension_time_step,
)
from ..park import IntegratedModel, hardening_exponent


def innermost_integrated(model: AbstractCableModel) -> IntegratedModel | None:
    """The [`jaxcable.IntegratedModel`][] at the core of the extensions around
    `model` (`model` itself included), or None."""
    core = innermost(model)
    return core if isinstance(core, IntegratedModel) else None


# ----------------------------------------------------------------------------------
# hardening


class HardeningState(eqx.Module):
    """Scan carry of [`jaxcable.Hardening`][].

    **Fields:**

    - `base`: the wrapped model's state.
    - `strain`: the total strain of the previous sample (Park Eq. 2's eps_{i-1}).
    """

    base: PyTree
    strain: Float[Array, ""]


class Hardening(AbstractExtension[HardeningState]):
    r"""Park's hardening (Eq. 1-2) applied to the base's instantaneous strain.

    Park's static strain is (F / (E1c A))**h with h = 1 + beta eps**gamma (Eq. 2),
    eps the total strain of the previous sample: the rope stiffens as it stretches
    (a braid whose strands straighten and pack). Around any base this extension
    raises the base's instantaneous strain e to the same power,

        e_h = e**h = e exp(beta eps**gamma ln e),   h = 1 + beta eps**gamma,

    which for the default [`jaxcable.IntegratedModel`][] (beta = 0) is Park's Eq. 1
    on the loading curve, F / (E1c A) raised to h, and on Eq. 9's unloading line
    the line's strain raised to h. Written as e exp(...), beta = 0 is the base
    exactly (exp(0) = 1), with a gradient in beta there. Every quantity is a strain,
    so the law carries over between ropes of any diameter and stiffness.

    e**h < e (stiffer) while e < 1, i.e. wherever a cable is in one piece; above a
    strain of 1 the power law would soften, beyond any rope's break. h > 0 keeps
    e_h increasing in e, so the strain still rises with the force (the
    elongation-driven solve needs it).

    **Continuity.** h is a continuous function of the previous total strain and e_h
    of e and h; no state switches on the sign of a force change: a perturbation of
    the force history moves e_h by at most a bounded multiple (h e**(h-1) <= h for
    e <= 1) of the base's response to it.

    **Fields:**

    - `base`: the wrapped model.
    - `beta`: Park's beta, dimensionless (>= 0; 0 is the base), fitted on a linear
        scale.
    - `gamma`: Park's gamma, dimensionless (> 0; a setting, not fitted: beta and
        gamma are nearly degenerate on one range of strain). Default 2, the
        [`jaxcable.IntegratedModel`][] default.

    `wrap(base)` starts a fit at `beta = 100` (h - 1 = 0.04 at a strain of 2 %). The
    fit's linear scale of beta is its start's size, and a smaller one leaves the
    solver's steps in beta too short to leave the start: from beta = 1 or 10 a fit
    of a braid cycled to 3 % strain stays there, with a hidden beta of 100 or none;
    from 100 it reaches 101 and 0.05.
    """

    CLI_NAME = "hardening"

    beta: Float[Array, ""] = parameter(
        0.0,
        unit="-",
        transform="linear",
        domain="nonnegative",
        null=0.0,
        start=100.0,
        note="(h = 1 + beta eps**gamma >= 1 hardens, Park Eq. 2).",
    )
    gamma: Float[Array, ""] = setting(2.0, unit="-")

    def init(self, cable: Cable) -> HardeningState:
        return HardeningState(self.base.init(cable), state_zero(cable, self.beta))

    def advance(
        self,
        state: HardeningState,
        cable: Cable,
        dt: Float[Array, ""],
        force: Float[Array, ""],
        direction: Int[Array, ""],
    ) -> tuple[HardeningState, StrainParts]:
        base_state, parts = self.base.advance(state.base, cable, dt, force, direction)
        e = parts.instantaneous
        # h - 1 = beta eps**gamma (Park Eq. 2), from the previous total strain.
        excess = hardening_exponent(state.strain, self.beta, self.gamma) - 1.0
        positive = e > 0
        log_e = jnp.log(jnp.where(positive, e, 1.0))
        hardened = e * jnp.exp(excess * log_e)
        parts = add_parts(parts, instantaneous=hardened - e)
        return HardeningState(base_state, parts.total), parts


# ----------------------------------------------------------------------------------
# hereditary


class HereditaryState(eqx.Module):
    """Scan carry of [`jaxcable.Hereditary`][] (SI).

    **Fields:**

    - `base`: the wrapped model's state.
    - `force`: force of the previous sample, N.
    - `impulse`: integral of F dt since the first loading, N s.
    - `t_total`: time under tension since the first loading, s (the base's clock,
        `jaxcable._models.kernels.tension_time_step`).
    - `force_max`: the largest force so far, N (sets the clock's ramp).
    - `kelvin_voigt`: the exact (hereditary) Kelvin-Voigt creep strain.
    """

    base: PyTree
    force: Float[Array, ""]
    impulse: Float[Array, ""]
    t_total: Float[Array, ""]
    force_max: Float[Array, ""]
    kelvin_voigt: Float[Array, ""]


class Hereditary(AbstractExtension[HereditaryState]):
    r"""The difference between the exact (hereditary) Kelvin-Voigt creep of Park's
    Eq. 3 and his equivalent-force reading of it (Eq. 5), added to the base.

    Park's Eq. 5 replaces the hereditary integral of the Kelvin-Voigt creep compliance
    J(t) = (1 - exp(-t / t_c)) / (E2c A) by the equivalent force F_eq = I / T:

        eps_eq = (I / T) (1 - exp(-T / t_c)) / (E2c A),   I = \int F dt,

    where the exact superposition is

        eps_ex(T) = \int_0^T J(T - s) dF(s),

    i.e. the strain of a Kelvin-Voigt element eps' = (F / (E2c A) - eps) / t_c. Under
    a ramp F = k t the two are k [t - t_c (1 - e^(-t/t_c))] / (E2c A) and
    (k t / 2)(1 - e^(-t/t_c)) / (E2c A): the same while t << t_c, a factor 2 apart
    for t >> t_c. This extension adds the difference, weighted:

        eps = eps_base + w (eps_ex - eps_eq)   (added to the creep part),

    w = 0 is the base. The default [`jaxcable.IntegratedModel`][] already integrates
    its delayed-elastic elements exactly (`docs/model_notes.md`, point 4), so around
    it the term is an extra creep that keeps growing along long loadings, shaped as
    that difference (Park's printed reading itself would be w = -1, outside the
    domain); it stays a candidate of the diagnosis for data whose creep grows so.

    E2c and t_c are read from the innermost [`jaxcable.IntegratedModel`][] (following
    `.base`), so they are fitted with the base. The extension keeps its own I and T
    with the base's counting rule (both from the first loading, carried across
    cycles: I by the trapezoid rule over every step; T by
    `jaxcable._models.kernels.tension_time_step`, the same continuous clock as the
    base: time counts in proportion to the force below F_on, fully above,
    F_on = max(1e-4 of the breaking load, a tenth of the largest force so far)).
    eps_ex takes the exact exponential update for a force linear over the step, on the
    same clock as T: like the base's creep term it is frozen at rest (an unloaded cable
    recovers through the base's recovery terms, E2r and E3r), so the correction
    changes the shape of the creep under load, not the recovery.

    **Continuity.** No state depends on the sign of a force change or on a threshold
    of the force: I, T and eps_ex are Lipschitz-continuous in the force history. (The
    clock used to switch on max(F0, F1) > 1e-4 of the breaking load: a force held
    near that threshold, or noise crossing it, switched whole steps of relaxation on
    and off.) Below F_on the clock counts time by F / F_on, so force noise d during a
    rest near 0 N shifts the clock by up to about d / F_on of the rest's length, and
    eps_ex relaxes by that much more: the price of freezing the element at rest,
    shared with the base's T.

    Nest it inside a time-changing extension (e.g. `TemperatureShift(Hereditary(m))`),
    not around one, so that both clocks agree.

    **Fields:**

    - `base`: the wrapped model; it must contain an `IntegratedModel` (for the linear
        models the superposition is already exact).
    - `weight`: w, dimensionless (>= 0; 0 is the base, 1 fully hereditary).

    `wrap(base)` starts a fit at `weight = 0.1`.
    """

    CLI_NAME = "hereditary"

    weight: Float[Array, ""] = parameter(
        1.0, unit="-", domain="nonnegative", null=0.0, start=0.1
    )

    def check_more(self):
        if innermost_integrated(self.base) is None:
            raise ValueError(
                f"Hereditary needs a base containing an IntegratedModel (its "
                f"equivalent-force creep is what it corrects); for "
                f"{type(self.base).__name__} the Boltzmann superposition is already "
                "exact."
            )

    def init(self, cable: Cable) -> HereditaryState:
        zero = state_zero(cable, self.weight)
        return HereditaryState(self.base.init(cable), zero, zero, zero, zero, zero)

    def advance(
        self,
        state: HereditaryState,
        cable: Cable,
        dt: Float[Array, ""],
        force: Float[Array, ""],
        direction: Int[Array, ""],
    ) -> tuple[HereditaryState, StrainParts]:
        base_state, parts = self.base.advance(state.base, cable, dt, force, direction)
        inner = innermost_integrated(self.base)
        assert inner is not None  # check_more refuses a base without one
        area = cable.area
        impulse = state.impulse + 0.5 * (state.force + force) * dt
        # The base's clock (continuous in the force, no threshold switch).
        force_max = running_max(state.force_max, force)
        dt_tension = tension_time_step(state.force, force, dt, cable, force_max)
        t_total = state.t_total + dt_tension
        # Exact Kelvin-Voigt update for a force linear over the step (x = dt / t_c).
        decay_m1, ramp = relaxation_terms(dt_tension / inner.t_c)
        compliance = 1.0 / (inner.E2c * area)
        kelvin_voigt = (
            state.kelvin_voigt
            + decay_m1 * state.kelvin_voigt
            + compliance * (-state.force * decay_m1 + (force - state.force) * ramp)
        )
        equivalent = impulse * relaxation_average(t_total, inner.t_c) * compliance
        parts = add_parts(parts, creep=self.weight * (kelvin_voigt - equivalent))
        new = HereditaryState(
            base_state, force, impulse, t_total, force_max, kelvin_voigt
        )
        return new, parts


# ----------------------------------------------------------------------------------
# second_retardation


class SecondRetardationState(eqx.Module):
    """Scan carry of [`jaxcable.SecondRetardation`][].

    **Fields:**

    - `base`: the wrapped model's state.
    - `force`: force of the previous sample, N.
    - `strain`: strain of the extra Kelvin-Voigt element.
    """

    base: PyTree
    force: Float[Array, ""]
    strain: Float[Array, ""]


class SecondRetardation(AbstractExtension[SecondRetardationState]):
    r"""One more Kelvin-Voigt element in series: another retardation time.

    A spring E_k parallel to a dashpot E_k tau_k, driven by the stress F / A:

        d eps_k / dt = (F / (A E_k) - eps_k) / tau_k,

    integrated exactly for a force linear over each step (with x = dt / tau_k,
    eps_k <- e^(-x) eps_k + [F0 (1 - e^(-x)) + (F1 - F0) (1 - (1 - e^(-x)) / x)]
    / (A E_k)). Under a constant force F applied at t = 0 it creeps as
    F (1 - exp(-t / tau_k)) / (A E_k) and recovers exponentially at rest. The strain
    is added to the creep part of the base. E_k = inf is the base exactly.

    **Continuity.** A linear element of the force: a perturbation d of every force
    sample moves its strain by at most d / (A E_k) (the exact update averages the
    stress history with positive weights summing to at most 1 / E_k), however long
    the history.

    **Fields:**

    - `base`: the wrapped model.
    - `E_k`: modulus of the element, Pa (> 0; `inf` switches it off).
    - `tau_k`: its retardation time, s (> 0).

    `wrap(base)` starts a fit at `E_k = 1e10 Pa` (a compliance ~4 % of the SK78 default
    set's Kelvin-Voigt creep) and `tau_k = 1000 s` (between the default t_c ~ 9 s and
    a day's rest).
    """

    CLI_NAME = "second-retardation"

    E_k: Float[Array, ""] = parameter(
        jnp.inf,
        **MODULUS,
        domain="positive_or_inf",
        null=math.inf,
        note="(Pa; inf switches the element off)",
        start=1e10,
    )
    tau_k: Float[Array, ""] = parameter(1000.0, unit="s", start=1000.0, time=1.0)

    def init(self, cable: Cable) -> SecondRetardationState:
        zero = state_zero(cable, self.E_k)
        return SecondRetardationState(self.base.init(cable), zero, zero)

    def advance(
        self,
        state: SecondRetardationState,
        cable: Cable,
        dt: Float[Array, ""],
        force: Float[Array, ""],
        direction: Int[Array, ""],
    ) -> tuple[SecondRetardationState, StrainParts]:
        base_state, parts = self.base.advance(state.base, cable, dt, force, direction)
        decay_m1, ramp = relaxation_terms(dt / self.tau_k)
        # 0 for E_k = inf, with tangents 0 too: inf times a zero tangent of the
        # area (the elongation drive's implicit derivative carries one) is NaN.
        off = jnp.isinf(self.E_k)
        compliance = jnp.where(
            off, 0.0, 1.0 / (jnp.where(off, 1.0, self.E_k) * cable.area)
        )
        strain = (
            state.strain
            + decay_m1 * state.strain
            + compliance * (-state.force * decay_m1 + (force - state.force) * ramp)
        )
        parts = add_parts(parts, creep=strain)
        return SecondRetardationState(base_state, force, strain), parts


# ----------------------------------------------------------------------------------
# stress_nonlinear_creep

# 100 N on the 3 mm cable of Park et al. (A = 7.07e-6 m^2): ~14.1 MPa.
DEFAULT_STRESS_REF = 100.0 / (math.pi / 4 * 3e-3**2)


class StressNonlinearCreepState(eqx.Module):
    """Scan carry of [`jaxcable.StressNonlinearCreep`][].

    **Fields:**

    - `base`: the wrapped model's state.
    - `force`: force of the previous sample, N.
    - `creep_max`: the largest creep strain of the base model so far.
    - `extra_max`: the extra creep laid down while the base's creep set new maxima,
        sum of (g(sigma) - 1) over the increments of `creep_max`.
    """

    base: PyTree
    force: Float[Array, ""]
    creep_max: Float[Array, ""]
    extra_max: Float[Array, ""]


class StressNonlinearCreep(AbstractExtension[StressNonlinearCreepState]):
    r"""Creep compliance growing with stress as a power law (Findley / Schapery-like).

    Each growth of the base model's creep part eps_c to a new largest value is scaled
    by g(sigma) = (sigma / sigma_ref)^n, with sigma = (F0 + F1) / (2 A) the step's
    mean stress, and the extra creep follows the base's creep in proportion below
    that largest value:

        M = max eps_c so far,   X = \int (g(sigma) - 1) dM,
        eps_extra = (X / M) eps_c   (0 while M = 0),

    added to the creep part. So creep accumulated at sigma > sigma_ref is larger than
    the base's (for n > 0), at sigma < sigma_ref smaller; a recovering base creep (a
    linear base at rest) takes the extra creep back in proportion, and regrowth below
    the previous largest creep takes it back again at the same proportion. Where the
    base creep only grows (a constant or rising load on Park's model) this is
    d eps_extra = (g(sigma) - 1) d eps_c. The extra creep is a state variable, so
    the strain is continuous when the force changes (no jump). n = 0 is the base
    exactly (g = 1, with 0^0 = 1).

    **Continuity.** M is the running maximum of the base creep and X a sum of g over
    its increments: both move by at most a multiple of a perturbation of the force
    history, and neither grows with the total variation of noise. (The earlier
    reading split each step's creep increment by its sign, growth scaled by g,
    recovery by the current extra/creep share, with a jump of that share where the
    base creep is 0: where the base creep is stationary, force noise flips the sign
    of every increment and the extra creep drifted with the total variation of the
    noise towards (g - 1) eps_c.) eps_extra = (X / M) eps_c with |eps_c| <= M and
    X / M between min(g) - 1 and max(g) - 1 is continuous as M -> 0.

    **Fields:**

    - `base`: the wrapped model.
    - `n`: the stress exponent, dimensionless (>= 0).
    - `stress_ref`: the reference stress sigma_ref, Pa (> 0; fixed, not fitted).
        Default ~14.1 MPa: 100 N on Park's 3 mm cable (A = 7.07e-6 m^2), the force
        level of Park's tests.

    `wrap(base)` starts a fit at `n = 0.1`.
    """

    CLI_NAME = "stress-nonlinear-creep"

    n: Float[Array, ""] = parameter(
        0.0, unit="-", domain="nonnegative", null=0.0, start=0.1
    )
    stress_ref: Float[Array, ""] = setting(DEFAULT_STRESS_REF, unit="Pa")

    def init(self, cable: Cable) -> StressNonlinearCreepState:
        zero = state_zero(cable, self.n)
        return StressNonlinearCreepState(self.base.init(cable), zero, zero, zero)

    def advance(
        self,
        state: StressNonlinearCreepState,
        cable: Cable,
        dt: Float[Array, ""],
        force: Float[Array, ""],
        direction: Int[Array, ""],
    ) -> tuple[StressNonlinearCreepState, StrainParts]:
        base_state, parts = self.base.advance(state.base, cable, dt, force, direction)
        ratio = jnp.maximum(0.5 * (state.force + force) / cable.area, 0.0) / (
            self.stress_ref
        )
        gain = jnp.where(self.n == 0, 1.0, safe_pow(ratio, self.n))
        creep_max = running_max(state.creep_max, parts.creep)
        extra_max = state.extra_max + (gain - 1.0) * (creep_max - state.creep_max)
        positive = creep_max > 0
        share = jnp.where(
            positive, extra_max / jnp.where(positive, creep_max, 1.0), 0.0
        )
        new = StressNonlinearCreepState(base_state, force, creep_max, extra_max)
        return new, add_parts(parts, creep=share * parts.creep)
