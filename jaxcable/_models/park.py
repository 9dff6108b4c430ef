"""Park et al.'s integrated nonlinear dynamic model of a polymer cable
([`IntegratedModel`][]), one function per equation of the paper:

- Eq. 1, the static strain under hardening: [`static_strain`][];
- Eq. 2, the hardening exponent: [`hardening_exponent`][];
- Eq. 3, the Burgers creep (Kelvin-Voigt element and dashpot): [`creep_strain`][];
- Eq. 4 and 7, the short- and long-term recoveries: [`recovery`][];
- Eq. 5, the equivalent force: [`equivalent_force`][];
- Eq. 8, the long-term retardation time: `IntegratedModel.retardation_time_long`;
- Eq. 9, the strain from its terms: [`combined_strain`][].

Eq. 6 (the crosshead's strain, strain rate times time) is the constraint with which
the rate-driven simulation solves for the loading time, not part of the model.
"""

from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float, Int

from .. import _checks
from .._arrays import field_array
from .._cable import Cable
from .._results import RESULTS
from .base import AbstractCableModel, StrainParts, state_zero
from .kernels import (
    relaxation_average,
    retarded,
    running_max,
    safe_pow,
    tension_force,
    tension_time_step,
)


def hardening_exponent(
    strain: Float[Array, ""], beta: Float[Array, ""], gamma: Float[Array, ""]
) -> Float[Array, ""]:
    """Park Eq. 2: the hardening exponent h = 1 + beta eps**gamma.

    eps is the total strain of the previous sample (a negative strain counts as 0):
    the exponent follows the history, which makes the model a causal recursion over
    the samples. h >= 1 stiffens the cable while F < E1c A ([`static_strain`][]).

    **Arguments:**

    - `strain`: total strain of the previous sample, dimensionless.
    - `beta`, `gamma`: the hardening parameters, dimensionless (>= 0).

    **Returns:**

    h, dimensionless.
    """
    return 1.0 + beta * safe_pow(jnp.maximum(strain, 0.0), gamma)


def static_strain(
    force: Float[Array, ""], compliance: Float[Array, ""], h: Float[Array, ""]
) -> Float[Array, ""]:
    """Park Eq. 1: the static (time-independent) strain (F / (E1c A))**h.

    **Arguments:**

    - `force`: the force, N (>= 0).
    - `compliance`: 1 / (E1c A), 1/N.
    - `h`: the hardening exponent ([`hardening_exponent`][]).

    **Returns:**

    The strain, dimensionless (0 at 0 N, with finite gradients there).
    """
    return safe_pow(force * compliance, h)


def creep_strain(
    impulse: Float[Array, ""],
    t_total: Float[Array, ""],
    t_c: Float[Array, ""],
    modulus_area: Float[Array, ""],
    viscosity_area: Float[Array, ""],
) -> Float[Array, ""]:
    r"""Park Eq. 3: the creep of the Burgers model, a Kelvin-Voigt element (E2c, t_c)
    and a dashpot eta0 in series, under the equivalent force F_eq = I / T
    ([`equivalent_force`][]) applied for the time under tension T:

        c = F_eq (1 - exp(-T / t_c)) / (E2c A) + F_eq T / (eta0 A)
          = I (1 - exp(-T / t_c)) / T / (E2c A) + I / (eta0 A).

    The dashpot term is the exact dashpot strain for any force history; the
    Kelvin-Voigt term is the paper's approximation of the hereditary integral (see
    [`jaxcable.Hereditary`][] for the exact one). Written with I = \int F dt rather
    than F_eq so that it stays finite, with finite gradients, at T = 0.

    **Arguments:**

    - `impulse`: I, N s.
    - `t_total`: T, s.
    - `t_c`: the creep retardation time, s.
    - `modulus_area`: E2c A, N.
    - `viscosity_area`: eta0 A, N s.

    **Returns:**

    The creep strain, dimensionless.
    """
    return impulse * (
        relaxation_average(t_total, t_c) / modulus_area + 1.0 / viscosity_area
    )


def recovery(
    previous: Float[Array, ""],
    previous_target: Float[Array, ""],
    force: Float[Array, ""],
    modulus_area: Float[Array, ""],
    dt: Float[Array, ""],
    retardation_time: Float[Array, ""],
) -> tuple[Float[Array, ""], Float[Array, ""]]:
    """Park Eq. 4 (short-term) and Eq. 7 (long-term): a recovery strain
    q = F / (E A) (1 - exp(-t / t_r)), a Kelvin-Voigt element (modulus E, retardation
    time t_r) that follows its amplitude q_target = F / (E A).

    The paper starts the full amplitude at the reversal; here the amplitude follows
    the force (the model's docstring says how) and q obeys q' = (q_target - q) / t_r,
    integrated exactly for an amplitude linear over the step: Eq. 4 / 7 for an
    amplitude held from t = 0. Short-term: F = F_eq depth, E = E2r, t_r = t_r1;
    long-term: F = F_m - F (the drop below the largest force), E = E3r, t_r = t_r2
    (`IntegratedModel.retardation_time_long`).

    **Arguments:**

    - `previous`, `previous_target`: q and q_target at the previous sample.
    - `force`: F at this sample, N.
    - `modulus_area`: E A, N.
    - `dt`: the step, s.
    - `retardation_time`: t_r, s.

    **Returns:**

    `(q, q_target)` at this sample, dimensionless.
    """
    target = force / modulus_area
    q = retarded(previous, previous_target, target, dt, retardation_time)
    return q, target


def equivalent_force(
    impulse: Float[Array, ""], t_total: Float[Array, ""]
) -> Float[Array, ""]:
    r"""Park Eq. 5's equivalent force F_eq = I / T: the mean force over the time under
    tension, with I = \int F dt and T counted from the first loading (carried across
    cycles, so that creep accumulates over them). It stands for the force in the
    Burgers terms ([`creep_strain`][], the short-term recovery of [`recovery`][]).

    **Arguments:**

    - `impulse`: I, N s.
    - `t_total`: T, s (I itself while T = 0: nothing has loaded the cable).

    **Returns:**

    F_eq, N.
    """
    return impulse / jnp.where(t_total > 0, t_total, 1.0)


def combined_strain(
    static: Float[Array, ""],
    static_max: Float[Array, ""],
    drop: Float[Array, ""],
    unloading_modulus_area: Float[Array, ""],
    creep: Float[Array, ""],
    short: Float[Array, ""],
    long: Float[Array, ""],
) -> StrainParts:
    """Park Eq. 9: the strain of a sample from its terms, in the reading that is
    continuous in the force history.

    - instantaneous: the loading curve (the static strain at F), or below the
        largest force F_m the unloading line from the peak, the static strain at F_m
        less (F_m - F) / (E1r A), whichever is larger, so that it is never below the
        loading curve (and never negative). On the first loading F = F_m and it is
        the loading curve;
    - plus the creep;
    - minus the two recoveries, scaled by s = min(1, creep / (short + long)): the
        recoveries remove at most the creep that produced them.

    **Arguments:**

    - `static`, `static_max`: the static strain ([`static_strain`][]) at F and at
        F_m.
    - `drop`: F_m - F, N.
    - `unloading_modulus_area`: E1r A, N.
    - `creep`: the creep strain ([`creep_strain`][]).
    - `short`, `long`: the recovery strains ([`recovery`][]).

    **Returns:**

    The [`jaxcable.StrainParts`][].
    """
    inst = jnp.maximum(static_max - drop / unloading_modulus_area, static)
    total_recovery = short + long
    excess = total_recovery > creep
    share = jnp.where(excess, creep / jnp.where(excess, total_recovery, 1.0), 1.0)
    return StrainParts(
        instantaneous=inst,
        creep=creep,
        recovery_short=short * share,
        recovery_long=long * share,
    )


class IntegratedState(eqx.Module):
    """Scan carry of [`jaxcable.IntegratedModel`][] for one cable (all SI).

    Every field is a continuous function of the force history (no branch flag, no
    clock restarted at a reversal): see the model's docstring.

    **Fields:**

    - `force`: force of the previous sample, N.
    - `strain`: total strain of the previous sample (the epsilon_{i-1} of Park Eq. 2).
    - `impulse`: integral of F dt since the first loading, N s (trapezoid rule over
        every step: exact for a force linear between samples).
    - `t_total`: time under tension since the first loading, s (a step at a force
        below F_on counts in proportion to the force; see
        `jaxcable._models.kernels.tension_time_step`).
    - `force_max`: the largest force so far, N (F_f of Park Eq. 7 and 9).
    - `short`, `long`: short- and long-term recovery strains before the creep bound
        (Park Eq. 4 and 7).
    - `short_target`, `long_target`: the recovery amplitudes they relax towards at
        the previous sample.
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


# Parameters that must be finite and > 0 (moduli, viscosity, time constants).
_POSITIVE = ("E1c", "E1r", "E2c", "t_c", "eta0", "E2r", "t_r1", "E3r", "lambda1")


class IntegratedModel(AbstractCableModel[IntegratedState]):
    r"""Park et al.'s integrated nonlinear dynamic model of a polymer cable, in a
    reading that is continuous in the force history.

    Strain (dimensionless) of sample i, with A the cross-section, I = \int F dt (from
    the first loading, trapezoid rule), T the time under tension since the first
    loading (carried across cycles) and F_m the largest force so far
    (`docs/continuity.md` derives and measures the reading):

    - instantaneous (Park Eq. 1-2 and the first terms of Eq. 9):
      e_i = max((F_m / (E1c A))**h - (F_m - F) / (E1r A), (F / (E1c A))**h),
      with the hardening exponent h = 1 + beta * eps_{i-1}**gamma (Eq. 2). On the
      first loading F = F_m and this is (F / (E1c A))**h (Eq. 9, loading); below the
      largest force it is Eq. 9's unloading line from the peak F_f = F_m, on which
      the cable also reloads (the bedding-in of a rope: the first loading sets a
      permanent constructional elongation, later cycles below it are stiffer). The
      max keeps it at or above the loading curve, so it is never negative;
    - creep (Park Eq. 3 under the equivalent force I / T of Eq. 5):
      c = (I / T) (1 - exp(-T / t_c)) / (E2c A) + I / (eta0 A). The paper prints the
      dashpot term as F_eq / (eta0 A), which is not a strain; F_eq T / (eta0 A) =
      I / (eta0 A) is the Burgers dashpot of Eq. 3, exact for any force history;
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
    integral of the Kelvin-Voigt creep (exact for the dashpot, up to a factor 2 off
    for the Kelvin-Voigt element under a long ramp; [`jaxcable.Hereditary`][] is the
    exact superposition); this is the paper's model, kept as printed.

    The default parameters are a Dyneema SK78 3 mm set fitted to the numbers Park
    prints (Table 1 of the fitted parameters is lost): [`jaxcable.papers.calibrate_sk78`][]
    (Levenberg-Marquardt on the errors, in %, of the creep ratio, the residual
    elongations and Table 3; all < 5 %), rounded to 4 digits; see
    `notebooks/01_papers.ipynb`.

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

    # The drives solve a time or force only up to this strain (see
    # `jaxcable._drive.state.strain_limit`): beyond it the hardening law (Eq. 2,
    # eps**gamma) makes the strain almost independent of the force.
    SOLVED_STRAIN_LIMIT: ClassVar[float] = 1.0

    E1c: Float[Array, ""] = eqx.field(converter=field_array, default=2.597e9)
    beta: Float[Array, ""] = eqx.field(converter=field_array, default=0.05465)
    gamma: Float[Array, ""] = eqx.field(converter=field_array, default=2.258)
    E1r: Float[Array, ""] = eqx.field(converter=field_array, default=2.63e9)
    E2c: Float[Array, ""] = eqx.field(converter=field_array, default=3.888e8)
    t_c: Float[Array, ""] = eqx.field(converter=field_array, default=8.251)
    eta0: Float[Array, ""] = eqx.field(converter=field_array, default=4.504e11)
    E2r: Float[Array, ""] = eqx.field(converter=field_array, default=3.709e9)
    t_r1: Float[Array, ""] = eqx.field(converter=field_array, default=35.88)
    E3r: Float[Array, ""] = eqx.field(converter=field_array, default=7.906e8)
    lambda1: Float[Array, ""] = eqx.field(converter=field_array, default=0.002825)
    lambda2: Float[Array, ""] = eqx.field(converter=field_array, default=-80.84)

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
        """Park Eq. 8: the long-term retardation time t_r2 = lambda1 (L0 / v)^2 -
        lambda2, s, at the strain rate v / L0 of `cable`. It must be positive: `check`
        flags a cable whose strain rate makes it not."""
        return self.lambda1 / cable.strain_rate**2 - self.lambda2

    def check(self, cable: Cable) -> RESULTS:
        t_r2 = self.retardation_time_long(cable)
        ok = _checks.all_ok(
            _checks.parameters_ok(self, _POSITIVE),
            jnp.isfinite(t_r2) & (t_r2 > 0),
            self.beta >= 0,
            self.gamma >= 0,
            # Eq. 1 stiffens only while F < E1c A; above it h > 1 would soften the
            # cable.
            self.E1c * cable.area > cable.breaking_load,
        )
        return _checks.domain_result(ok)

    def init(self, cable: Cable) -> IntegratedState:
        zero = state_zero(cable, self.E1c)
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
        # Trapezoid impulse, exact for a force linear over the step; time under
        # tension, a continuous ramp near 0 N so that noise around 0 N during a rest
        # neither counts the rest as loading nor switches it on and off.
        impulse = state.impulse + 0.5 * (state.force + force) * dt
        force_max = running_max(state.force_max, force)
        t_total = state.t_total + tension_time_step(
            state.force, force, dt, cable, force_max
        )

        # Eq. 1-2 with h from the previous sample's total strain, at F and at F_m.
        compliance_c = 1.0 / (self.E1c * area)
        h = hardening_exponent(state.strain, self.beta, self.gamma)
        static = static_strain(force, compliance_c, h)
        static_max = static_strain(force_max, compliance_c, h)
        drop = force_max - force

        creep = creep_strain(
            impulse, t_total, self.t_c, self.E2c * area, self.eta0 * area
        )

        # Recovery amplitudes in proportion to the drop below the largest force
        # (Park's amplitudes at F = 0). The depth's scale is at least F_on, so that
        # before any real loading (F_m at the level of the noise) the depth stays
        # proportional to the noise.
        depth = drop / jnp.maximum(force_max, tension_force(cable, force_max))
        short, short_target = recovery(
            state.short,
            state.short_target,
            equivalent_force(impulse, t_total) * depth,
            self.E2r * area,
            dt,
            self.t_r1,
        )
        long, long_target = recovery(
            state.long,
            state.long_target,
            drop,
            self.E3r * area,
            dt,
            self.retardation_time_long(cable),
        )

        parts = combined_strain(
            static, static_max, drop, self.E1r * area, creep, short, long
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
        )
        return new_state, parts
