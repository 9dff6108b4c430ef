import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float, Int

from .. import _checks
from .._cable import Cable
from .._results import RESULTS
from .base import AbstractCableModel, StrainParts, positive_result
from .kernels import (
    relaxation_average,
    retarded,
    running_max,
    safe_pow,
    tension_force,
    tension_time_step,
)


class IntegratedState(eqx.Module):
    """Scan carry of [`jaxcable.IntegratedModel`][] for one cable (all SI).

    Every field is a continuous function of the force history (no branch flag, no
    clock restarted at a reversal): see the model's docstring.

    **Fields:**

    - `force`: force of the previous sample, N.
    - `strain`: total strain of the previous sample (the epsilon_{i-1} of Park Eq. 2).
    - `impulse`: integral of F dt since the first loading, N s (MODEL_NOTES point 6).
    - `t_total`: time under tension since the first loading, s (a step at a force
        below 1e-4 of the breaking load counts in proportion to the force).
    - `force_max`: the largest force so far, N (F_f of Park Eq. 7 and 9).
    - `short`, `long`: short- and long-term recovery strains before the creep bound
        (Park Eq. 4 and 7).
    - `short_target`, `long_target`: the recovery amplitudes they relax towards at
        the previous sample.
    - `parts`: the [`jaxcable.StrainParts`][] of the previous sample.
    """

    force: Float[Array, ""]
    strain: Float[Array, ""]
    impulse: Float[Array, ""]
    t_total: Float[Array, ""]
    force_max: Float[Array, ""]
    short: Float[Array, ""]
    long: Float[Array, ""]
    short_target: Float[Array, ""]
    long_target: Float[Array, ""]
    parts: StrainParts


# Parameters that must be finite and > 0 (moduli, viscosity, time constants).
_POSITIVE = ("E1c", "E1r", "E2c", "t_c", "eta0", "E2r", "t_r1", "E3r", "lambda1")


class IntegratedModel(AbstractCableModel[IntegratedState]):
    r"""Park et al.'s integrated nonlinear dynamic model of a polymer cable, in a
    reading that is continuous in the force history.

    Strain (dimensionless) of sample i, with A the cross-section, I = \int F dt, T the
    time under tension since the first loading and F_m the largest force so far
    (MODEL_NOTES points 2-7; `docs/continuity.md` derives and measures the reading):

    - instantaneous (Park Eq. 1-2 and the first terms of Eq. 9):
      e_i = max((F_m / (E1c A))**h - (F_m - F) / (E1r A), (F / (E1c A))**h),
      with the hardening exponent h = 1 + beta * eps_{i-1}**gamma (Eq. 2). On the
      first loading F = F_m and this is (F / (E1c A))**h (Eq. 9, loading); below the
      largest force it is Eq. 9's unloading line from the peak F_f = F_m, on which
      the cable also reloads (the bedding-in of a rope: the first loading sets a
      permanent constructional elongation, later cycles below it are stiffer). The
      max keeps it at or above the loading curve, so it is never negative;
    - creep (Park Eq. 5 with MODEL_NOTES point 2):
      c = (I / T) (1 - exp(-T / t_c)) / (E2c A) + I / (eta0 A);
    - recoveries (Park Eq. 4 and 7), each a Kelvin-Voigt strain q relaxing towards
      an amplitude set by how far the force has fallen below F_m,
      q' = (q_target - q) / t_r, with
      short: q_target = (I / T) ((F_m - F) / F_m) / (E2r A), t_r = t_r1 (Eq. 4-5);
      long: q_target = (F_m - F) / (E3r A), t_r = t_r2 = lambda1 / (v / L0)**2 -
      lambda2 (Eq. 7-8);
    - eps = e + c - s (q_short + q_long), with s = min(1, c / (q_short + q_long)):
      the recoveries remove at most the creep that produced them, so no history
      leaves the cable shorter than its instantaneous set (>= 0).

    **Why this reading.** Eq. 9 as printed switches on a loading/unloading flag and
    starts both recoveries, at full amplitude, on a clock restarted at the reversal.
    Under a measured force every downward noise blip is a reversal: the strain jumps
    by a share of the full short-term amplitude however small the blip (measured on
    the previous reading: 1e-6 N of noise moved a 300 mm cable by 0.95 mm). Here no
    state depends on the sign of a force change: every memory (I, T, F_m, the two
    recovery strains) is Lipschitz-continuous in the force history, and a force
    perturbation d moves the strain by at most about
    d (1/E1r + 1/E2r + 1/E3r) / A plus what d integrates to through the creep terms.
    The recovery amplitudes grow with the depth of the unloading, in proportion to
    the force drop, as Boltzmann superposition of a load decrease makes them; they
    reach Park's amplitudes (I / T) / (E2r A) and F_f / (E3r A) at 0 N, and a
    reloading takes them back at the same rates.

    **On Park's paths** (a loading, a full unloading, a rest at 0 N) the loading
    branch and the instantaneous unloading are Eq. 1-9 exactly, and so are both
    recoveries from the moment the force reaches 0 N, up to the lag built up while
    the amplitude ramps in during the unloading (Park starts the full amplitude at the
    reversal): that lag decays as exp(-tau / t_r). `docs/continuity.md` measures the
    difference on Park's protocols. Cycles reload along the unloading line instead of
    jumping back to the loading curve at 0 N.

    Hysteresis is not modelled separately: it emerges from creep, hardening and
    recovery (Park Section 3.3). The equivalent force I / T replaces the hereditary
    integral of the Kelvin-Voigt creep (MODEL_NOTES point 4); this is the paper's
    model, kept as printed.

    The default parameters are a Dyneema SK78 3 mm set obtained as MODEL_NOTES point 9
    describes: `jaxcable.calibrate_sk78()` (Levenberg-Marquardt on the errors, in %, of
    the numbers Park prints: creep ratio, residual elongations, Table 3; all < 5 %),
    rounded to 4 digits; see `jaxcable._sk78` and `notebooks/01_papers.ipynb`.

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

    E1c: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=2.597e9)
    beta: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=0.05465)
    gamma: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=2.258)
    E1r: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=2.63e9)
    E2c: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=3.888e8)
    t_c: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=8.251)
    eta0: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=4.504e11)
    E2r: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=3.709e9)
    t_r1: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=35.88)
    E3r: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=7.906e8)
    lambda1: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=0.002825)
    lambda2: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=-80.84)

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
            force_max=zero,
            short=zero,
            long=zero,
            short_target=zero,
            long_target=zero,
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
        # `direction` is not used: no state of this reading depends on the sign of a
        # force change (the class docstring says why).
        del direction
        area = cable.area
        # Trapezoid impulse (MODEL_NOTES point 5); time under tension (point 6), a
        # continuous ramp near 0 N so that noise around 0 N during a rest neither
        # counts the rest as loading nor switches it on and off.
        impulse = state.impulse + 0.5 * (state.force + force) * dt
        force_max = running_max(state.force_max, force)
        t_total = state.t_total + tension_time_step(
            state.force, force, dt, cable, force_max
        )

        # Park Eq. 1-2 with h from the previous sample's total strain; Eq. 9's
        # unloading line from the largest force, never below the loading curve.
        compliance_c = 1.0 / (self.E1c * area)
        h = 1.0 + self.beta * safe_pow(jnp.maximum(state.strain, 0.0), self.gamma)
        static = safe_pow(force * compliance_c, h)
        static_max = safe_pow(force_max * compliance_c, h)
        drop = force_max - force
        inst = jnp.maximum(static_max - drop / (self.E1r * area), static)

        # Park Eq. 5 with MODEL_NOTES point 2: F_eq (1 - e^{-T/t_c}) / (E2c A) + I/(eta0 A).
        creep = impulse * (
            relaxation_average(t_total, self.t_c) / (self.E2c * area)
            + 1.0 / (self.eta0 * area)
        )

        # Recovery amplitudes in proportion to the drop below the largest force
        # (Park Eq. 4 and 7 at F = 0); each recovery follows its amplitude with its
        # retardation time, exactly for an amplitude linear over the step.
        f_eq = impulse / jnp.where(t_total > 0, t_total, 1.0)
        # The depth's scale is at least F_on, so that before any real loading (F_m at
        # the level of the noise) the depth stays proportional to the noise.
        depth = drop / jnp.maximum(force_max, tension_force(cable, force_max))
        short_target = f_eq * depth / (self.E2r * area)
        long_target = drop / (self.E3r * area)
        short = retarded(state.short, state.short_target, short_target, dt, self.t_r1)
        long = retarded(
            state.long,
            state.long_target,
            long_target,
            dt,
            self.retardation_time_long(cable),
        )

        # The recoveries remove at most the creep that produced them.
        recovery = short + long
        excess = recovery > creep
        share = jnp.where(excess, creep / jnp.where(excess, recovery, 1.0), 1.0)
        parts = StrainParts(
            instantaneous=inst,
            creep=creep,
            recovery_short=short * share,
            recovery_long=long * share,
        )
        new_state = IntegratedState(
            force=force,
            strain=parts.total,
            impulse=impulse,
            t_total=t_total,
            force_max=force_max,
            short=short,
            long=long,
            short_target=short_target,
            long_target=long_target,
            parts=parts,
        )
        return new_state, parts
