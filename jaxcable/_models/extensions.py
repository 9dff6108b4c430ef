r"""Model extensions: physical effects a base model lacks, each a wrapper around any
[`jaxcable.AbstractCableModel`][] (wrap, don't subclass), composable by nesting, e.g.
`SensorDrift(BeddingIn(IntegratedModel()))`.

Each extension has a stable id (`EXTENSION_ID`) used by the diagnosis workflow, and
the same class-level interface:

- `EXTENSION_ID`: the stable id (a key of [`jaxcable.EXTENSIONS`][]);
- `EFFECT_FIELDS`: the extension's own parameters that a diagnosis fits together with
    the base model's;
- `SIZE_FIELD`, `SIZE_UNIT`: the one field reported as the size of the effect, and its
    unit;
- `FIT_INFO`: `{field: (transform, unit[, stiffness])}` for each fitted field, with
    transform `"log"` (positive) or `"linear"` (either sign, scaled by |start|), and
    the optional power with which the field follows a stiffness scaling of the model;
- `wrap(base)`: the extension around `base` with small but nonzero start values for a
    fit (so that a log transform works and the gradient is informative).

At the null value of its effect parameter (`weight = 0`, `E_k = inf`, `n = 0`,
`activation_energy = 0`, `compliance = 0`, `s_b = 0`, `drift_rate = 0`) every
extension reproduces its base model exactly.

Every extension is continuous in the force history (issue 10): none switches on the
sign of a force change, on a threshold of the force or through a division guard that
jumps, so a perturbation d of every force sample moves its own contribution by at most
a stated multiple of d, which does not grow with the total variation of the noise (each
docstring says how). They receive `direction` only to pass it on to the base.
"""

import math
from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int, PyTree

from .. import _checks
from .._cable import Cable
from .._results import RESULTS
from .base import AbstractCableModel, StrainParts
from .kernels import (
    ramp_factor,
    relaxation_average,
    running_max,
    safe_pow,
    tension_time_step,
)
from .park import IntegratedModel


# Gas constant, J/(mol K).
GAS_CONSTANT = 8.314462618
_LN10 = math.log(10.0)


def _validate(owner: str, module, name: str, predicate, requirement: str) -> None:
    """Raise `ValueError` naming `owner.name` unless the concrete value satisfies
    `predicate` (elementwise). Traced values are skipped: `check` flags them."""
    value = getattr(module, name)
    if not _checks.is_concrete(value):
        return
    v = np.asarray(value)
    if v.dtype == object:
        raise ValueError(f"{owner} `{name}` must be a number, got {value!r}.")
    v = v.astype(float)
    with np.errstate(invalid="ignore"):
        ok = np.all(predicate(v))
    if not ok:
        raise ValueError(f"{owner} `{name}` must be {requirement}, got {v}.")


def _finite(v):
    return np.isfinite(v)


def _nonnegative(v):
    return np.isfinite(v) & (v >= 0)


def _positive(v):
    return np.isfinite(v) & (v > 0)


def _ok(*conditions) -> Array:
    ok = jnp.array(True)
    for c in conditions:
        ok = ok & jnp.all(c)
    return ok


def _combine(ok, base_result: RESULTS) -> RESULTS:
    return RESULTS.where(ok, base_result, RESULTS.parameter_out_of_domain)


def _add(parts: StrainParts, *, instantaneous=None, creep=None) -> StrainParts:
    if instantaneous is not None:
        parts = eqx.tree_at(
            lambda p: p.instantaneous, parts, parts.instantaneous + instantaneous
        )
    if creep is not None:
        parts = eqx.tree_at(lambda p: p.creep, parts, parts.creep + creep)
    return parts


def _zero(cable: Cable, *like) -> Float[Array, ""]:
    return jnp.zeros((), jnp.result_type(float, cable.length, *like))


def innermost_integrated(model: AbstractCableModel) -> IntegratedModel | None:
    """The first [`jaxcable.IntegratedModel`][] found by following `.base` from
    `model` (the model itself included), or None."""
    seen = model
    while True:
        if isinstance(seen, IntegratedModel):
            return seen
        seen = getattr(seen, "base", None)
        if not isinstance(seen, AbstractCableModel):
            return None


# ----------------------------------------------------------------------------------
# termination_compliance


class TerminationCompliance(AbstractCableModel[PyTree]):
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

    EXTENSION_ID: ClassVar[str] = "termination_compliance"
    EFFECT_FIELDS: ClassVar[tuple[str, ...]] = ("compliance",)
    SIZE_FIELD: ClassVar[str] = "compliance"
    SIZE_UNIT: ClassVar[str] = "m/N"
    FIT_INFO: ClassVar[dict[str, tuple]] = {"compliance": ("log", "m/N", -1.0)}

    base: AbstractCableModel
    compliance: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=0.0)

    def __check_init__(self):
        _validate(
            "TerminationCompliance",
            self,
            "compliance",
            _nonnegative,
            "finite and >= 0 (m/N)",
        )

    @classmethod
    def wrap(cls, base: AbstractCableModel) -> "TerminationCompliance":
        """`base` with a fit's start value `compliance = 1e-6` m/N."""
        return cls(base, compliance=1e-6)

    def init(self, cable: Cable) -> PyTree:
        return self.base.init(cable)

    def check(self, cable: Cable) -> RESULTS:
        ok = _ok(jnp.isfinite(self.compliance), self.compliance >= 0)
        return _combine(ok, self.base.check(cable))

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
        return state, _add(parts, instantaneous=extra)


# ----------------------------------------------------------------------------------
# hereditary


class HereditaryState(eqx.Module):
    """Scan carry of [`jaxcable.Hereditary`][] (SI).

    **Fields:**

    - `base`: the wrapped model's state.
    - `force`: force of the previous sample, N.
    - `impulse`: integral of F dt since the first loading, N s.
    - `t_total`: time under tension since the first loading, s (the base's clock,
        `jaxcable._memory.tension_time_step`).
    - `force_max`: the largest force so far, N (sets the clock's ramp).
    - `kelvin_voigt`: the exact (hereditary) Kelvin-Voigt creep strain.
    """

    base: PyTree
    force: Float[Array, ""]
    impulse: Float[Array, ""]
    t_total: Float[Array, ""]
    force_max: Float[Array, ""]
    kelvin_voigt: Float[Array, ""]


class Hereditary(AbstractCableModel[HereditaryState]):
    r"""Exact Boltzmann superposition of the Kelvin-Voigt creep of Park's model.

    Park's Eq. 5 replaces the hereditary integral of the Kelvin-Voigt creep compliance
    J(t) = (1 - exp(-t / t_c)) / (E2c A) by the equivalent force (MODEL_NOTES point 4):

        eps_eq = (I / T) (1 - exp(-T / t_c)) / (E2c A),   I = \int F dt,

    where the exact superposition is

        eps_ex(T) = \int_0^T J(T - s) dF(s),

    i.e. the strain of a Kelvin-Voigt element eps' = (F / (E2c A) - eps) / t_c. Under
    a ramp F = k t the two are k [t - t_c (1 - e^(-t/t_c))] / (E2c A) and
    (k t / 2)(1 - e^(-t/t_c)) / (E2c A): the same while t << t_c, a factor 2 apart
    for t >> t_c. This extension adds the difference, weighted:

        eps = eps_base + w (eps_ex - eps_eq)   (added to the creep part),

    w = 0 is the base (the paper's model), w = 1 the fully hereditary Kelvin-Voigt
    creep; w > 1 is accepted (a fit may overshoot) and extrapolates.

    E2c and t_c are read from the innermost [`jaxcable.IntegratedModel`][] (following
    `.base`), so they are fitted with the base. The extension keeps its own I and T
    with the base's counting rule (MODEL_NOTES point 6: I by the trapezoid rule over
    every step; T by `jaxcable._memory.tension_time_step`, the same continuous clock
    as the base: time counts in proportion to the force below F_on, fully above,
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

    EXTENSION_ID: ClassVar[str] = "hereditary"
    EFFECT_FIELDS: ClassVar[tuple[str, ...]] = ("weight",)
    SIZE_FIELD: ClassVar[str] = "weight"
    SIZE_UNIT: ClassVar[str] = "-"
    FIT_INFO: ClassVar[dict[str, tuple]] = {"weight": ("log", "-")}

    base: AbstractCableModel
    weight: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=1.0)

    def __check_init__(self):
        _validate("Hereditary", self, "weight", _nonnegative, "finite and >= 0")
        if innermost_integrated(self.base) is None:
            raise ValueError(
                f"Hereditary needs a base containing an IntegratedModel (its "
                f"equivalent-force creep is what it corrects); for "
                f"{type(self.base).__name__} the Boltzmann superposition is already "
                "exact."
            )

    @classmethod
    def wrap(cls, base: AbstractCableModel) -> "Hereditary":
        """`base` with a fit's start value `weight = 0.1`."""
        return cls(base, weight=0.1)

    def init(self, cable: Cable) -> HereditaryState:
        zero = _zero(cable, self.weight)
        return HereditaryState(self.base.init(cable), zero, zero, zero, zero, zero)

    def check(self, cable: Cable) -> RESULTS:
        ok = _ok(jnp.isfinite(self.weight), self.weight >= 0)
        return _combine(ok, self.base.check(cable))

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
        area = cable.area
        impulse = state.impulse + 0.5 * (state.force + force) * dt
        # The base's clock (continuous in the force, no threshold switch).
        force_max = running_max(state.force_max, force)
        dt_tension = tension_time_step(state.force, force, dt, cable, force_max)
        t_total = state.t_total + dt_tension
        # Exact Kelvin-Voigt update for a force linear over the step (x = dt / t_c).
        x = dt_tension / inner.t_c
        compliance = 1.0 / (inner.E2c * area)
        kelvin_voigt = jnp.exp(-x) * state.kelvin_voigt + compliance * (
            -state.force * jnp.expm1(-x) + (force - state.force) * ramp_factor(x)
        )
        equivalent = impulse * relaxation_average(t_total, inner.t_c) * compliance
        parts = _add(parts, creep=self.weight * (kelvin_voigt - equivalent))
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


class SecondRetardation(AbstractCableModel[SecondRetardationState]):
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

    EXTENSION_ID: ClassVar[str] = "second_retardation"
    EFFECT_FIELDS: ClassVar[tuple[str, ...]] = ("E_k", "tau_k")
    SIZE_FIELD: ClassVar[str] = "E_k"
    SIZE_UNIT: ClassVar[str] = "Pa"
    FIT_INFO: ClassVar[dict[str, tuple]] = {
        "E_k": ("log", "Pa", 1.0),
        "tau_k": ("log", "s"),
    }

    base: AbstractCableModel
    E_k: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=jnp.inf)
    tau_k: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=1000.0)

    def __check_init__(self):
        _validate(
            "SecondRetardation",
            self,
            "E_k",
            lambda v: (v > 0) & ~np.isnan(v),
            "positive, Pa (inf switches the element off)",
        )
        _validate("SecondRetardation", self, "tau_k", _positive, "finite and > 0 (s)")

    @classmethod
    def wrap(cls, base: AbstractCableModel) -> "SecondRetardation":
        """`base` with a fit's start values `E_k = 1e10` Pa, `tau_k = 1000` s."""
        return cls(base, E_k=1e10, tau_k=1000.0)

    def init(self, cable: Cable) -> SecondRetardationState:
        zero = _zero(cable, self.E_k)
        return SecondRetardationState(self.base.init(cable), zero, zero)

    def check(self, cable: Cable) -> RESULTS:
        ok = _ok(
            self.E_k > 0,
            ~jnp.isnan(self.E_k),
            jnp.isfinite(self.tau_k),
            self.tau_k > 0,
        )
        return _combine(ok, self.base.check(cable))

    def advance(
        self,
        state: SecondRetardationState,
        cable: Cable,
        dt: Float[Array, ""],
        force: Float[Array, ""],
        direction: Int[Array, ""],
    ) -> tuple[SecondRetardationState, StrainParts]:
        base_state, parts = self.base.advance(state.base, cable, dt, force, direction)
        x = dt / self.tau_k
        compliance = 1.0 / (self.E_k * cable.area)  # 0 for E_k = inf
        strain = jnp.exp(-x) * state.strain + compliance * (
            -state.force * jnp.expm1(-x) + (force - state.force) * ramp_factor(x)
        )
        parts = _add(parts, creep=strain)
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


class StressNonlinearCreep(AbstractCableModel[StressNonlinearCreepState]):
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

    EXTENSION_ID: ClassVar[str] = "stress_nonlinear_creep"
    EFFECT_FIELDS: ClassVar[tuple[str, ...]] = ("n",)
    SIZE_FIELD: ClassVar[str] = "n"
    SIZE_UNIT: ClassVar[str] = "-"
    FIT_INFO: ClassVar[dict[str, tuple]] = {"n": ("log", "-")}

    base: AbstractCableModel
    n: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=0.0)
    stress_ref: Float[Array, ""] = eqx.field(
        converter=jnp.asarray, default=DEFAULT_STRESS_REF
    )

    def __check_init__(self):
        _validate("StressNonlinearCreep", self, "n", _nonnegative, "finite and >= 0")
        _validate(
            "StressNonlinearCreep",
            self,
            "stress_ref",
            _positive,
            "finite and > 0 (Pa)",
        )

    @classmethod
    def wrap(cls, base: AbstractCableModel) -> "StressNonlinearCreep":
        """`base` with a fit's start value `n = 0.1` (default `stress_ref`)."""
        return cls(base, n=0.1)

    def init(self, cable: Cable) -> StressNonlinearCreepState:
        zero = _zero(cable, self.n)
        return StressNonlinearCreepState(self.base.init(cable), zero, zero, zero)

    def check(self, cable: Cable) -> RESULTS:
        ok = _ok(
            jnp.isfinite(self.n),
            self.n >= 0,
            jnp.isfinite(self.stress_ref),
            self.stress_ref > 0,
        )
        return _combine(ok, self.base.check(cable))

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
        return new, _add(parts, creep=share * parts.creep)


# ----------------------------------------------------------------------------------
# temperature


def log_shift_arrhenius(
    temperature, activation_energy, reference_temperature
) -> Float[Array, "*shape"]:
    r"""log10 of the Arrhenius time-temperature shift factor,

        log10 a_T = E_a / (R ln 10) (1 / T - 1 / T_ref),

    with T, T_ref in K and E_a in J/mol (R = 8.314 J/(mol K)). a_T < 1 above T_ref:
    processes run faster.
    """
    return (
        activation_energy
        / (GAS_CONSTANT * _LN10)
        * (1.0 / temperature - 1.0 / reference_temperature)
    )


def log_shift_wlf(temperature, c1, c2, reference_temperature) -> Float[Array, "*shape"]:
    r"""log10 of the Williams-Landel-Ferry shift factor,

        log10 a_T = -C1 (T - T_ref) / (C2 + T - T_ref),

    with T, T_ref and C2 in K (or all in °C: only differences enter), C1 dimensionless.
    Valid while C2 + T - T_ref > 0.
    """
    d = temperature - reference_temperature
    return -c1 * d / (c2 + d)


def _reduced(cable: Cable, dt, log_a):
    """The reduced time step dt / a_T and the cable as the base sees it on reduced
    time (crosshead speed per reduced second v a_T)."""
    a_t = 10.0**log_a
    cable_reduced = eqx.tree_at(lambda c: c.speed, cable, cable.speed * a_t)
    return dt / a_t, cable_reduced


class TemperatureShift(AbstractCableModel[PyTree]):
    r"""Thermally activated creep by time-temperature superposition (Arrhenius).

    Every time-dependent process of the base runs on reduced time,

        dt_eff = dt / a_T(T),   log10 a_T = E_a / (R ln 10) (1 / T - 1 / T_ref),

    with T = `cable.temperature` (K) read at each step (the fit sets it per sample
    from a test's temperature record), so a hotter cable creeps and recovers faster
    (a_T < 1) and a colder one slower. The base model gets dt_eff and a cable whose
    crosshead speed is v a_T (the same strain per reduced second: e.g. Park's
    rate-dependent long-term retardation time, Eq. 8, is evaluated on reduced time);
    instantaneous (time-independent) strains are unchanged. The state is the base's.
    `activation_energy = 0` (a_T = 1) is the base exactly. For the WLF law see
    [`jaxcable.TemperatureShiftWLF`][].

    **Continuity.** a_T depends on the temperature, not on the force: the extension
    is as continuous in the force history as the base on reduced time.

    **Fields:**

    - `base`: the wrapped model.
    - `activation_energy`: E_a, J/mol (>= 0).
    - `T_ref`: the reference temperature, K (> 0; default 293.15 K, the default
        `Cable.temperature`), at which a_T = 1.

    `wrap(base)` starts a fit at `activation_energy = 1e4 J/mol` (a_T ~ 0.87 at 10 K
    above T_ref; thermally activated creep of UHMWPE is ~ 1e5 J/mol).
    """

    EXTENSION_ID: ClassVar[str] = "temperature"
    EFFECT_FIELDS: ClassVar[tuple[str, ...]] = ("activation_energy",)
    SIZE_FIELD: ClassVar[str] = "activation_energy"
    SIZE_UNIT: ClassVar[str] = "J/mol"
    FIT_INFO: ClassVar[dict[str, tuple]] = {"activation_energy": ("log", "J/mol")}

    base: AbstractCableModel
    activation_energy: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=0.0)
    T_ref: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=293.15)

    def __check_init__(self):
        _validate(
            "TemperatureShift",
            self,
            "activation_energy",
            _nonnegative,
            "finite and >= 0 (J/mol)",
        )
        _validate("TemperatureShift", self, "T_ref", _positive, "finite and > 0 (K)")

    @classmethod
    def wrap(cls, base: AbstractCableModel) -> "TemperatureShift":
        """`base` with a fit's start value `activation_energy = 1e4` J/mol."""
        return cls(base, activation_energy=1e4)

    def log_shift(self, temperature) -> Float[Array, "*shape"]:
        """log10 a_T at `temperature` (K)."""
        return log_shift_arrhenius(temperature, self.activation_energy, self.T_ref)

    def init(self, cable: Cable) -> PyTree:
        return self.base.init(cable)

    def check(self, cable: Cable) -> RESULTS:
        ok = _ok(
            jnp.isfinite(self.activation_energy),
            self.activation_energy >= 0,
            jnp.isfinite(self.T_ref),
            self.T_ref > 0,
            jnp.isfinite(self.log_shift(cable.temperature)),
        )
        _, reduced = _reduced(cable, 0.0, self.log_shift(cable.temperature))
        return _combine(ok, self.base.check(reduced))

    def advance(
        self,
        state: PyTree,
        cable: Cable,
        dt: Float[Array, ""],
        force: Float[Array, ""],
        direction: Int[Array, ""],
    ) -> tuple[PyTree, StrainParts]:
        dt_eff, reduced = _reduced(cable, dt, self.log_shift(cable.temperature))
        return self.base.advance(state, reduced, dt_eff, force, direction)


class TemperatureShiftWLF(AbstractCableModel[PyTree]):
    r"""Time-temperature superposition with the Williams-Landel-Ferry shift factor,

        dt_eff = dt / a_T(T),   log10 a_T = -C1 (T - T_ref) / (C2 + T - T_ref),

    otherwise as [`jaxcable.TemperatureShift`][] (reduced time for every
    time-dependent process of the base, T = `cable.temperature`, K). WLF suits
    amorphous polymers above their glass transition; `c1 = 0` is the base exactly.
    Like it, continuous in the force history as the base is (a_T does not depend on
    the force).
    Not a diagnosis candidate of its own (`EXTENSIONS["temperature"]` is the
    Arrhenius form, one parameter); its id is `temperature_wlf`.

    **Fields:**

    - `base`: the wrapped model.
    - `c1`: C1, dimensionless (>= 0).
    - `c2`: C2, K (> 0; C2 + T - T_ref must stay > 0).
    - `T_ref`: the reference temperature, K (> 0; default 293.15 K).

    `wrap(base)` starts a fit at the "universal" C2 = 51.6 K and a small C1 = 1.
    """

    EXTENSION_ID: ClassVar[str] = "temperature_wlf"
    EFFECT_FIELDS: ClassVar[tuple[str, ...]] = ("c1", "c2")
    SIZE_FIELD: ClassVar[str] = "c1"
    SIZE_UNIT: ClassVar[str] = "-"
    FIT_INFO: ClassVar[dict[str, tuple]] = {"c1": ("log", "-"), "c2": ("log", "K")}

    base: AbstractCableModel
    c1: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=0.0)
    c2: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=51.6)
    T_ref: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=293.15)

    def __check_init__(self):
        _validate("TemperatureShiftWLF", self, "c1", _nonnegative, "finite and >= 0")
        _validate("TemperatureShiftWLF", self, "c2", _positive, "finite and > 0 (K)")
        _validate("TemperatureShiftWLF", self, "T_ref", _positive, "finite and > 0 (K)")

    @classmethod
    def wrap(cls, base: AbstractCableModel) -> "TemperatureShiftWLF":
        """`base` with a fit's start values `c1 = 1`, `c2 = 51.6` K."""
        return cls(base, c1=1.0, c2=51.6)

    def log_shift(self, temperature) -> Float[Array, "*shape"]:
        """log10 a_T at `temperature` (K)."""
        return log_shift_wlf(temperature, self.c1, self.c2, self.T_ref)

    def init(self, cable: Cable) -> PyTree:
        return self.base.init(cable)

    def check(self, cable: Cable) -> RESULTS:
        ok = _ok(
            jnp.isfinite(self.c1),
            self.c1 >= 0,
            jnp.isfinite(self.c2),
            self.c2 > 0,
            jnp.isfinite(self.T_ref),
            self.T_ref > 0,
            self.c2 + cable.temperature - self.T_ref > 0,
        )
        log_a = jnp.where(ok, self.log_shift(cable.temperature), 0.0)
        _, reduced = _reduced(cable, 0.0, log_a)
        return _combine(ok, self.base.check(reduced))

    def advance(
        self,
        state: PyTree,
        cable: Cable,
        dt: Float[Array, ""],
        force: Float[Array, ""],
        direction: Int[Array, ""],
    ) -> tuple[PyTree, StrainParts]:
        dt_eff, reduced = _reduced(cable, dt, self.log_shift(cable.temperature))
        return self.base.advance(state, reduced, dt_eff, force, direction)


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


def _smooth_relu(x, width):
    """max(x, 0) with a quadratic blend over [0, width]: 0 for x <= 0, x^2 / (2 width)
    up to `width`, x - width / 2 beyond (continuously differentiable)."""
    clipped = jnp.clip(x, 0.0, width)
    return clipped**2 / (2 * width) + jnp.maximum(x - width, 0.0)


class BeddingIn(AbstractCableModel[BeddingInState]):
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

    EXTENSION_ID: ClassVar[str] = "bedding_in"
    EFFECT_FIELDS: ClassVar[tuple[str, ...]] = ("s_b", "F_b")
    SIZE_FIELD: ClassVar[str] = "s_b"
    SIZE_UNIT: ClassVar[str] = "-"
    FIT_INFO: ClassVar[dict[str, tuple]] = {
        "s_b": ("log", "-", -1.0),
        "F_b": ("log", "N"),
    }

    base: AbstractCableModel
    s_b: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=0.0)
    F_b: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=50.0)
    smoothing: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=0.01)

    def __check_init__(self):
        _validate("BeddingIn", self, "s_b", _nonnegative, "finite and >= 0 (strain)")
        _validate("BeddingIn", self, "F_b", _positive, "finite and > 0 (N)")
        _validate("BeddingIn", self, "smoothing", _positive, "finite and > 0 (N)")

    @classmethod
    def wrap(cls, base: AbstractCableModel) -> "BeddingIn":
        """`base` with a fit's start values `s_b = 1e-4`, `F_b = 50` N."""
        return cls(base, s_b=1e-4, F_b=50.0)

    def init(self, cable: Cable) -> BeddingInState:
        return BeddingInState(self.base.init(cable), _zero(cable, self.s_b))

    def check(self, cable: Cable) -> RESULTS:
        ok = _ok(
            jnp.isfinite(self.s_b),
            self.s_b >= 0,
            jnp.isfinite(self.F_b),
            self.F_b > 0,
            jnp.isfinite(self.smoothing),
            self.smoothing > 0,
        )
        return _combine(ok, self.base.check(cable))

    def advance(
        self,
        state: BeddingInState,
        cable: Cable,
        dt: Float[Array, ""],
        force: Float[Array, ""],
        direction: Int[Array, ""],
    ) -> tuple[BeddingInState, StrainParts]:
        base_state, parts = self.base.advance(state.base, cable, dt, force, direction)
        force_max = state.force_max + _smooth_relu(
            force - state.force_max, self.smoothing
        )
        bedding = self.s_b * -jnp.expm1(-force_max / self.F_b)
        return BeddingInState(base_state, force_max), _add(parts, instantaneous=bedding)


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


class SensorDrift(AbstractCableModel[SensorDriftState]):
    r"""A slow linear drift of the elongation signal (extensometer, encoder, load frame
    temperature): not a property of the cable, but what a long record shows.

        delta(t) = r (t - t0)  (m),   eps_drift = delta / L0,

    with t0 the start of the record (the state's elapsed time starts at 0 and adds
    every step's dt). It is added to the creep part (the time-dependent part it is
    confused with). r takes either sign; 0 is the base exactly. It depends on time
    only, not on the force.

    **Fields:**

    - `base`: the wrapped model.
    - `drift_rate`: r, m/s (finite, either sign).

    `wrap(base)` starts a fit at `drift_rate = 1e-9 m/s` (3.6 um per hour; a linear
    transform scaled by that start).
    """

    EXTENSION_ID: ClassVar[str] = "sensor_drift"
    EFFECT_FIELDS: ClassVar[tuple[str, ...]] = ("drift_rate",)
    SIZE_FIELD: ClassVar[str] = "drift_rate"
    SIZE_UNIT: ClassVar[str] = "m/s"
    FIT_INFO: ClassVar[dict[str, tuple]] = {"drift_rate": ("linear", "m/s")}

    base: AbstractCableModel
    drift_rate: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=0.0)

    def __check_init__(self):
        _validate("SensorDrift", self, "drift_rate", _finite, "finite (m/s)")

    @classmethod
    def wrap(cls, base: AbstractCableModel) -> "SensorDrift":
        """`base` with a fit's start value `drift_rate = 1e-9` m/s."""
        return cls(base, drift_rate=1e-9)

    def init(self, cable: Cable) -> SensorDriftState:
        return SensorDriftState(self.base.init(cable), _zero(cable, self.drift_rate))

    def check(self, cable: Cable) -> RESULTS:
        return _combine(jnp.isfinite(self.drift_rate), self.base.check(cable))

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
        return SensorDriftState(base_state, elapsed), _add(parts, creep=drift)


# ----------------------------------------------------------------------------------

EXTENSIONS: dict[str, type] = {
    cls.EXTENSION_ID: cls
    for cls in (
        Hereditary,
        SecondRetardation,
        StressNonlinearCreep,
        TemperatureShift,
        TerminationCompliance,
        BeddingIn,
        SensorDrift,
    )
}
"""The candidate extensions of the diagnosis, id -> class, in the issue's order."""
