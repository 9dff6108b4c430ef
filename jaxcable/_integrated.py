import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float, Int

from . import _checks
from ._abstract import AbstractCableModel, StrainParts, positive_result
from ._cable import Cable
from ._results import RESULTS


def _safe_pow(base, exponent):
    """`base**exponent` for `base >= 0`, with finite gradients at `base == 0`."""
    positive = base > 0
    safe = jnp.where(positive, base, 1.0)
    return jnp.where(positive, jnp.exp(exponent * jnp.log(safe)), 0.0)


def _relaxation_average(t, tau):
    """(1 - exp(-t / tau)) / t, continued by 1 / tau at t = 0 (finite gradients)."""
    positive = t > 0
    t_safe = jnp.where(positive, t, 1.0)
    return jnp.where(positive, -jnp.expm1(-t_safe / tau) / t_safe, 1.0 / tau)


class IntegratedState(eqx.Module):
    """Scan carry of [`jaxcable.IntegratedModel`][] for one cable (all SI).

    **Fields:**

    - `force`: force of the previous sample, N.
    - `strain`: total strain of the previous sample (the epsilon_{i-1} of Park Eq. 2).
    - `impulse`: integral of F dt since the first loading, N s (MODEL_NOTES point 6).
    - `t_total`: time under tension since the first loading, s.
    - `branch`: +1 loading, -1 unloading.
    - `force_reversal`: force where the current branch began, N (F_f of Park Eq. 9
        on an unloading branch).
    - `force_peak`: force where the last unloading began, N (0 before any).
    - `inst_reversal`: instantaneous strain where the current branch began.
    - `tau`: time since the current branch began, s.
    - `short_reversal`, `long_reversal`: short- and long-term recovery strains where
        the current branch began.
    - `parts`: the [`jaxcable.StrainParts`][] of the previous sample.
    """

    force: Float[Array, ""]
    strain: Float[Array, ""]
    impulse: Float[Array, ""]
    t_total: Float[Array, ""]
    branch: Int[Array, ""]
    force_reversal: Float[Array, ""]
    force_peak: Float[Array, ""]
    inst_reversal: Float[Array, ""]
    tau: Float[Array, ""]
    short_reversal: Float[Array, ""]
    long_reversal: Float[Array, ""]
    parts: StrainParts


# Parameters that must be finite and > 0 (moduli, viscosity, time constants).
_POSITIVE = ("E1c", "E1r", "E2c", "t_c", "eta0", "E2r", "t_r1", "E3r", "lambda1")


class IntegratedModel(AbstractCableModel[IntegratedState]):
    r"""Park et al.'s integrated nonlinear dynamic model of a polymer cable.

    Strain (dimensionless) of sample i, with A the cross-section, I = \int F dt and
    T the time under tension since the first loading (MODEL_NOTES points 2-7):

    - loading (Park Eq. 9, first case, with the creep sign read as + and the dashpot
      term as I / (eta0 A)):
      eps = (F / (E1c A))**h + (I / T) (1 - exp(-T / t_c)) / (E2c A) + I / (eta0 A),
      with the hardening exponent h = 1 + beta * eps_{i-1}**gamma (Park Eq. 1-2);
    - unloading (Park Eq. 9, second case), from the force F_f where unloading began and
      the time tau since then: the instantaneous strain falls by (F_f - F) / (E1r A),
      creep keeps its equivalent-force form (Eq. 5), and two recoveries are removed:
      short-term (I / T) (1 - exp(-tau / t_r1)) / (E2r A) (Eq. 4-5) and long-term
      (F_f - F) (1 - exp(-tau / t_r2)) / (E3r A) (Eq. 7) with the rate-dependent
      retardation time t_r2 = lambda1 / (v / L0)**2 - lambda2 (Eq. 8).

    Beyond the paper's paths (one loading, one unloading, a rest), any force history
    needs a reading of what a reversal does; this one keeps the strain continuous and
    bounded, and reduces to Eq. 1-9 exactly on Park's paths:

    - the recoveries are state variables. On an unloading branch each relaxes from its
      value q0 at the reversal towards its Eq. 4 / Eq. 7 amplitude:
      q = amplitude (1 - exp(-tau / t_r)) + q0 exp(-tau / t_r) (q0 = 0 on the first
      unloading: Eq. 7 as printed); on a loading branch the load takes them back,
      q = q0 exp(-tau / t_r). Repeated small unloadings therefore never add up to more
      recovery than one large one (a frozen-recovery reading drifts without bound
      under a robot's thousands of load changes);
    - the instantaneous strain on reloading starts where unloading left it and
      rejoins the loading curve (F / (E1c A))**h at the force where the last
      unloading began (Masing-like), so the elastic part forms a closed loop and does
      not ratchet; creep alone accumulates, as in Park Fig. 2 (arrow 3).

    Hysteresis is not modelled separately: it emerges from creep, hardening and
    recovery (Park Section 3.3).

    The equivalent force I / T replaces the hereditary integral of the Kelvin-Voigt
    creep (MODEL_NOTES point 4); this is the paper's model, kept as printed.

    The default parameters are a Dyneema SK78 3 mm set obtained as MODEL_NOTES point 9
    describes: `jaxcable.calibrate_sk78()` (Levenberg-Marquardt on the errors, in %, of
    the numbers Park prints: creep ratio, residual elongations, Table 3; all < 5 %),
    rounded to 4 digits, under physical constraints (gamma >= 1, an instantaneous set
    >= 0, a short-term recovery slower than the crosshead, no rest ending shorter than
    new); see `jaxcable._sk78` and `notebooks/01_papers.ipynb`.

    **Fields (SI):**

    - `E1c`: static (instantaneous) loading modulus, Pa (Eq. 1).
    - `beta`, `gamma`: hardening parameters, dimensionless (Eq. 2).
    - `E1r`: instantaneous unloading modulus, Pa (Eq. 9).
    - `E2c`: Kelvin-Voigt creep modulus, Pa; `t_c`: creep retardation time, s (Eq. 3).
    - `eta0`: dashpot viscosity, Pa s (Eq. 3).
    - `E2r`: short-term recovery modulus, Pa; `t_r1`: its retardation time, s (Eq. 4).
    - `E3r`: long-term recovery modulus, Pa (Eq. 7).
    - `lambda1` (1/s), `lambda2` (s): long-term retardation time law (Eq. 8).
    """

    E1c: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=2.566e9)
    beta: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=0.08153)
    gamma: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=1.344)
    E1r: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=2.670e9)
    E2c: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=3.799e8)
    t_c: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=8.632)
    eta0: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=4.794e11)
    E2r: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=3.191e9)
    t_r1: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=53.11)
    E3r: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=7.989e8)
    lambda1: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=2.883e-3)
    lambda2: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=-99.73)

    def __check_init__(self):
        _checks.check_parameters("IntegratedModel", self, _POSITIVE)
        _checks.check_parameters("IntegratedModel", self, ("lambda2",), positive=False)
        _checks.check_parameters(
            "IntegratedModel",
            self,
            ("beta", "gamma"),
            allow_zero=True,
            reason="(h = 1 + beta eps**gamma >= 1 hardens, Park Eq. 2).",
        )

    def retardation_time_long(self, cable: Cable) -> Float[Array, ""]:
        """Long-term retardation time t_r2 = lambda1 (L0 / v)^2 - lambda2, s (Eq. 8)."""
        return self.lambda1 / cable.strain_rate**2 - self.lambda2

    def check(self, cable: Cable) -> RESULTS:
        result = positive_result(
            *(getattr(self, n) for n in _POSITIVE), self.retardation_time_long(cable)
        )
        # Eq. 1 stiffens only while F < E1c A; above it h > 1 would soften the cable.
        ok = (
            (self.beta >= 0)
            & (self.gamma >= 0)
            & (self.E1c * cable.area > cable.breaking_load)
        )
        return RESULTS.where(ok, result, RESULTS.parameter_out_of_domain)

    def init(self, cable: Cable) -> IntegratedState:
        zero = jnp.zeros((), jnp.result_type(float, self.E1c, cable.length))
        parts = StrainParts(zero, zero, zero, zero)
        return IntegratedState(
            force=zero,
            strain=zero,
            impulse=zero,
            t_total=zero,
            branch=jnp.array(1, jnp.int32),
            force_reversal=zero,
            force_peak=zero,
            inst_reversal=zero,
            tau=zero,
            short_reversal=zero,
            long_reversal=zero,
            parts=parts,
        )

    def advance(
        self,
        state: IntegratedState,
        cable: Cable,
        dt: Float[Array, ""],
        force: Float[Array, ""],
        direction: Int[Array, ""],
    ) -> tuple[IntegratedState, StrainParts]:
        # Written for the scan's per-sample cost: every sample runs this several times
        # (the Newton iterations of a rate-driven test), and on a CPU its cost is
        # mostly the number of separate array operations. So each transcendental is
        # taken once (a decay and its complement from one expm1; one log per force
        # ratio), parameter quotients are reciprocals XLA hoists out of the scan, and
        # nothing depends on `dt` that need not (the Newton derivative is by `jvp`).
        area = cable.area
        branch = jnp.where(direction == 0, state.branch, direction).astype(jnp.int32)
        reversed_ = branch != state.branch
        loading = branch > 0

        # A reversal happens at the previous sample: the new branch starts from there.
        prev = state.parts
        force_reversal = jnp.where(reversed_, state.force, state.force_reversal)
        force_peak = jnp.where(reversed_ & ~loading, state.force, state.force_peak)
        inst_reversal = jnp.where(reversed_, prev.instantaneous, state.inst_reversal)
        short_reversal = jnp.where(reversed_, prev.recovery_short, state.short_reversal)
        long_reversal = jnp.where(reversed_, prev.recovery_long, state.long_reversal)
        tau = jnp.where(reversed_, 0.0, state.tau) + dt

        # Trapezoid impulse (MODEL_NOTES point 5); time under tension (point 6). A
        # step counts as under tension above 1e-4 of the breaking load, so that a
        # load cell's noise around 0 N during an hours-long rest does not count the
        # rest as loading (which would dilute the equivalent force I / T).
        impulse = state.impulse + 0.5 * (state.force + force) * dt
        tensioned = jnp.maximum(state.force, force) > 1e-4 * cable.breaking_load
        t_total = state.t_total + jnp.where(tensioned, dt, 0.0)

        # Park Eq. 1-2: (F / (E1c A))**h with the hardening exponent
        # h = 1 + beta eps_{i-1}**gamma from the previous sample's total strain; the
        # same h for the force where the branch began. Reloading rejoins the loading
        # curve at the last peak (Masing-like), so the instantaneous strain is
        # continuous at the reversal and cannot ratchet.
        compliance_c = 1.0 / (self.E1c * area)
        h = 1.0 + self.beta * _safe_pow(jnp.maximum(state.strain, 0.0), self.gamma)
        static = _safe_pow(force * compliance_c, h)
        static_reversal = _safe_pow(force_reversal * compliance_c, h)
        span = force_peak - force_reversal
        has_span = span > 0
        weight = jnp.clip(
            (force_peak - force) / jnp.where(has_span, span, 1.0), 0.0, 1.0
        )
        weight = jnp.where(has_span, weight, 0.0)
        loading_inst = static + (inst_reversal - static_reversal) * weight
        unloading_inst = inst_reversal - (force_reversal - force) / (self.E1r * area)
        inst = jnp.where(loading, loading_inst, unloading_inst)

        # Park Eq. 5 with MODEL_NOTES point 2: F_eq (1 - e^{-T/t_c}) / (E2c A) + I/(eta0 A).
        creep = impulse * (
            _relaxation_average(t_total, self.t_c) / (self.E2c * area)
            + 1.0 / (self.eta0 * area)
        )

        # Recoveries relax towards Park's amplitudes while unloading (Eq. 4, 7) and
        # back towards zero while loading, from their values at the reversal:
        # q = amplitude (1 - e^{-tau/t_r}) + q0 e^{-tau/t_r} = q0 + (amplitude - q0) g
        # with g = 1 - e^{-tau/t_r} = -expm1(-tau/t_r) (one transcendental each).
        f_eq = impulse / jnp.where(t_total > 0, t_total, 1.0)
        t_r2 = self.retardation_time_long(cable)
        grow_short = -jnp.expm1(-tau / self.t_r1)
        grow_long = -jnp.expm1(-tau / t_r2)
        amplitude_short = jnp.where(loading, 0.0, f_eq / (self.E2r * area))
        amplitude_long = jnp.where(
            loading, 0.0, (force_reversal - force) / (self.E3r * area)
        )
        short = short_reversal + (amplitude_short - short_reversal) * grow_short
        long = long_reversal + (amplitude_long - long_reversal) * grow_long

        parts = StrainParts(
            instantaneous=inst,
            creep=creep,
            recovery_short=short,
            recovery_long=long,
        )
        new_state = IntegratedState(
            force=force,
            strain=parts.total,
            impulse=impulse,
            t_total=t_total,
            branch=branch,
            force_reversal=force_reversal,
            force_peak=force_peak,
            inst_reversal=inst_reversal,
            tau=tau,
            short_reversal=short_reversal,
            long_reversal=long_reversal,
            parts=parts,
        )
        return new_state, parts
