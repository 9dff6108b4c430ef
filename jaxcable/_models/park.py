"""Park et al.'s integrated nonlinear dynamic model of a polymer cable
([`IntegratedModel`][]), one function per mechanism:

- Eq. 1, the static strain under hardening: [`static_strain`][];
- Eq. 2, the hardening exponent: [`hardening_exponent`][];
- Eq. 3, 4 and 7, the creep and its short- and long-term recoveries: three
  delayed-elastic elements that creep fast under load and recover slowly at rest,
  `delayed_elastic`;
- Eq. 3's dashpot, over the hours and days a robot runs: a stress-activated (Eyring)
  flow, `eyring_rate`;
- Eq. 8, the long-term retardation time: `IntegratedModel.retardation_time_long`;
- Eq. 9, the strain from its terms: `IntegratedModel.advance`.

Eq. 5-6 (the equivalent force and the crosshead's strain) are the constraint with
which the rate-driven simulation solves for the loading time, not part of the model:
`docs/model_notes.md` says why the equivalent force is no longer a state.
"""

import dataclasses
from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float, Int

from .. import _checks
from .._cable import Cable
from .._results import RESULTS
from .base import AbstractCableModel, StrainParts, state_zero
from .fields import MODULUS, VISCOSITY, declared_ok, parameter
from .kernels import retarded, running_max, safe_pow


# Park's hardening parameters (Eq. 2), dimensionless and >= 0; not identified by
# cyclic tests. beta is fitted on a linear scale: its default, 0 (no hardening), is
# a start a fit can leave (a log scale would need it positive).
_HARDENING = {
    "unit": "-",
    "domain": "nonnegative",
    "fitted": False,
    "note": "(h = 1 + beta eps**gamma >= 1 hardens, Park Eq. 2).",
}
# The default activation stress of the flow, Pa, anchored on published HMPE creep
# rates for the default 3 mm rope (`docs/model_notes.md`); the model holds it as an
# activation strain, this stress over the default E1c.
_SIGMA_A = 4e7
_E1C = 2.591e9


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


def delayed_elastic(
    previous: Float[Array, ""],
    target_previous: Float[Array, ""],
    target: Float[Array, ""],
    dt: Float[Array, ""],
    creep_time: Float[Array, ""],
    recovery_time: Float[Array, ""] | None,
) -> Float[Array, ""]:
    """One delayed-elastic (Kelvin-Voigt) element that creeps towards its target
    strain with retardation time `creep_time` and recovers from above it with
    `recovery_time` (Park Eq. 3-4 and 7 with separate creep and recovery times).

    The element obeys q' = (q_target - q) / tau, tau = `creep_time` while
    q < q_target and `recovery_time` while q > q_target: the rate is continuous
    (0 at q = q_target) and non-decreasing in q_target, so the element keeps the
    order of its inputs (more load never leaves it shorter). Over a step with the
    target linear from `target_previous` to `target`, the two exact updates
    ([`jaxcable._models.kernels.retarded`][]) are combined by the larger (creep
    faster than recovery) or the smaller, whichever follows the target faster:
    exact while the target stays on one side of q, continuous and order-keeping
    where it crosses (both updates are non-decreasing in q and in both targets).

    **Arguments:**

    - `previous`, `target_previous`: q and q_target at the previous sample.
    - `target`: q_target at this sample.
    - `dt`: the step, s.
    - `creep_time`, `recovery_time`: the retardation times, s; `recovery_time`
        None: the element never recovers (a permanent creep that saturates).

    **Returns:**

    q at this sample, dimensionless.
    """
    creep = retarded(previous, target_previous, target, dt, creep_time)
    if recovery_time is None:
        return jnp.maximum(creep, previous)
    recover = retarded(previous, target_previous, target, dt, recovery_time)
    faster_creep = creep_time <= recovery_time
    return jnp.where(
        faster_creep, jnp.maximum(creep, recover), jnp.minimum(creep, recover)
    )


# sinh's argument is capped here (far beyond any rope's breaking stress) so that the
# rate stays finite: a strain beyond break is reported, not an overflow.
_EYRING_CAP = 60.0


def eyring_rate(
    stress: Float[Array, ""],
    viscosity: Float[Array, ""],
    activation_stress: Float[Array, ""],
) -> Float[Array, ""]:
    """The plastic flow rate of a stress-activated (Eyring) process,
    (sigma_a / eta0) sinh(sigma / sigma_a), 1/s: Park's dashpot sigma / eta0
    (Eq. 3) at stresses well below sigma_a, growing exponentially above it, as the
    plateau creep rate of HMPE fibres does (`docs/model_notes.md` cites the data).

    **Arguments:**

    - `stress`: sigma = F / A, Pa (>= 0).
    - `viscosity`: eta0, Pa s.
    - `activation_stress`: sigma_a, Pa.

    **Returns:**

    The strain rate, 1/s.
    """
    x = jnp.minimum(stress / activation_stress, _EYRING_CAP)
    return activation_stress / viscosity * jnp.sinh(x)


class IntegratedState(eqx.Module):
    """Scan carry of [`jaxcable.IntegratedModel`][] for one cable (all SI).

    Every field is a continuous function of the force history (no branch flag, no
    clock restarted at a reversal), and a non-decreasing one: see the model's
    docstring.

    **Fields:**

    - `force`: force of the previous sample, N.
    - `strain`: total strain of the previous sample (the epsilon_{i-1} of Park Eq. 2).
    - `force_max`: the largest force so far, N (F_f of Park Eq. 9).
    - `permanent`: the creep that does not recover (Park Eq. 3's Kelvin-Voigt
        element, E2c), strain.
    - `short`, `long`: the creep that recovers in minutes (E2r, Park Eq. 4) and in
        hours (E3r, Park Eq. 7), strains.
    - `short_max`, `long_max`: the largest `short` and `long` so far (their recovery
        is reported as the distance below them).
    - `flow`: the Eyring flow strain (Park Eq. 3's dashpot).
    """

    force: Float[Array, ""]
    strain: Float[Array, ""]
    force_max: Float[Array, ""]
    permanent: Float[Array, ""]
    short: Float[Array, ""]
    long: Float[Array, ""]
    short_max: Float[Array, ""]
    long_max: Float[Array, ""]
    flow: Float[Array, ""]


class IntegratedModel(AbstractCableModel[IntegratedState]):
    r"""Park et al.'s integrated nonlinear dynamic model of a polymer cable, in a
    reading that holds on his experiments as he ran them and over the hours and days
    a robot runs.

    Strain (dimensionless) of sample i, with A the cross-section, sigma = F / A and
    F_m the largest force so far (`docs/model_notes.md` derives the reading and cites
    its sources):

    - instantaneous (Park Eq. 1-2 and the first terms of Eq. 9):
      e_i = max((F_m / (E1c A))**h - (F_m - F) / (E1r A), (F / (E1c A))**h),
      with h = 1 + beta eps_{i-1}**gamma (Eq. 2). On the first loading F = F_m and
      this is the loading curve; below F_m it is Eq. 9's unloading line from the peak,
      on which the cable also reloads (the bedding-in of a braid: the first loading
      sets a permanent constructional elongation F_m (1/E1c - 1/E1r) / A);
    - creep (Park Eq. 3, 4 and 7): three delayed-elastic elements q_k, each relaxing
      towards F / (E_k A) (`delayed_elastic`), fast while below it (creep, or
      re-extension after a rest) and slowly while above it (recovery):
      permanent (E2c): creeps with t_c, never recovers;
      short-term (E2r): creeps with t_e, recovers with t_r1 (Eq. 4);
      long-term (E3r): creeps with t_e, recovers with t_r2 = lambda1 (L0 / v)**2 -
      lambda2 (Eq. 7-8).
      Each saturates at F / (E_k A): the primary creep of HMPE is bounded;
    - flow (Park Eq. 3's dashpot): eps_p' = (sigma_a / eta0) sinh(sigma / sigma_a),
      Park's sigma / eta0 at low stress, the stress-activated plateau creep of HMPE
      fibres above (an Eyring process, `eyring_rate`);
    - eps = e + q_permanent + q_short + q_long + eps_p.

    **Properties** (each tested): the strain is continuous in the force history (no
    state switches on the sign of a force change); it is never negative (every term
    is >= 0); more load never makes the cable shorter (with beta = 0: every memory
    is non-decreasing in the force and in the other memories, the strain is
    non-decreasing in each, and the update of a sample keeps that order; with
    beta > 0 the hardening of Eq. 2 lowers the static strain as the previous strain
    grows); a rested cable stretches back on reloading (the elements re-extend with
    t_e, as Park's second tensile tests measured, Table 3); and a long hold stays
    bounded (the elements saturate, the flow is the slow plateau creep).

    The reported parts: `instantaneous` e; `creep` q_permanent + max q_short +
    max q_long + eps_p (the largest creep each element reached); `recovery_short`
    and `recovery_long` how far q_short and q_long are below their largest values.

    **Defaults.** A Dyneema SK78 3 mm set: [`jaxcable.papers.calibrate_sk78`][]
    fitted to every number Park prints, each computed by simulating the test he ran
    ([`jaxcable.papers.sk78_targets_report`][]), with the flow (eta0, sigma_a)
    anchored on published HMPE creep rates; beta = 0: Park's tests do not identify
    the hardening (see `docs/model_notes.md`).

    **Fields (SI):**

    - `E1c`: static (instantaneous) loading modulus, Pa (Eq. 1).
    - `beta`, `gamma`: hardening parameters, dimensionless (Eq. 2).
    - `E1r`: instantaneous unloading modulus, Pa (Eq. 9).
    - `E2c`: modulus of the creep that does not recover, Pa; `t_c`: its creep
        retardation time, s (Eq. 3).
    - `eta0`: the flow's viscosity at low stress, Pa s (Eq. 3).
    - `E2r`: modulus of the short-term recoverable creep, Pa; `t_r1`: its recovery
        time, s (Eq. 4).
    - `E3r`: modulus of the long-term recoverable creep, Pa (Eq. 7).
    - `lambda1` (1/s), `lambda2` (s): its recovery time law (Eq. 8).
    - `t_e`: creep (and re-extension) time of the recoverable creep, s.
    - `strain_a`: the flow's activation strain, dimensionless: its activation
        stress sigma_a = `strain_a` E1c (the property `sigma_a`, Pa; default
        40 MPa / 2.591 GPa = 0.0154). Measured against the rope's own stiffness,
        it carries over between ropes of one fibre: a thin braid whose E1c (per
        nominal area) is 37 times the 3 mm rope's has a sigma_a 37 times larger,
        and a start scaled to its data ([`jaxcable.scaled_start`][]) flows as the
        3 mm rope does at the same strain.

    **Checks.** Every declared field in its domain, t_r2 > 0 (Eq. 8) and Eq. 1
    hardening within the cable's domain (`hardening_ok`).
    """

    # The drives solve a time or force only up to this strain (see
    # `jaxcable._drive.state.strain_limit`): beyond it the hardening law (Eq. 2,
    # eps**gamma) makes the strain almost independent of the force.
    SOLVED_STRAIN_LIMIT: ClassVar[float] = 1.0

    CLI_NAME = "integrated"

    # Fitted by default: the parameters that cyclic tests identify. Hardening (beta,
    # gamma; 0 by default) and the long-term recovery law (lambda1, lambda2) are
    # nearly degenerate on them, the flow (eta0, sigma_a) is a plateau creep of
    # ~1e-9 /s, invisible in tests of minutes, and the permanent element (E2c,
    # t_c = 0.9 s) is one compliance with the spring on ramps of seconds or more: a
    # fit with all of them free wanders along flat valleys (correlations > 0.999)
    # and does not converge, so these six are what the fit, the diagnosis, the demo
    # and the synthetic generators vary by default.
    E1c: Float[Array, ""] = parameter(_E1C, **MODULUS)
    beta: Float[Array, ""] = parameter(0.0, **_HARDENING, transform="linear")
    gamma: Float[Array, ""] = parameter(2.0, **_HARDENING)
    E1r: Float[Array, ""] = parameter(2.594e9, **MODULUS)
    E2c: Float[Array, ""] = parameter(6.838e9, **MODULUS, fitted=False)
    t_c: Float[Array, ""] = parameter(0.8772, unit="s", fitted=False, time=1.0)
    eta0: Float[Array, ""] = parameter(1.2e16, **VISCOSITY, fitted=False)
    E2r: Float[Array, ""] = parameter(6.032e9, **MODULUS)
    t_r1: Float[Array, ""] = parameter(6.4, unit="s", time=1.0)
    E3r: Float[Array, ""] = parameter(8.045e8, **MODULUS)
    # t_r2 = lambda1 (L0/v)^2 - lambda2 (Park Eq. 8), either sign: both terms
    # follow a time scaling of the start (the strain rate v / L0 is the data's).
    lambda1: Float[Array, ""] = parameter(0.003322, unit="1/s", fitted=False, time=1.0)
    lambda2: Float[Array, ""] = parameter(
        -157.2, unit="s", transform="linear", fitted=False, time=1.0
    )
    t_e: Float[Array, ""] = parameter(4.241, unit="s", time=1.0)
    # The flow's activation stress over E1c: a strain, so that it follows the rope's
    # own stiffness (a thin braid of the same fibre, a fitted E1c).
    strain_a: Float[Array, ""] = parameter(_SIGMA_A / _E1C, unit="-", fitted=False)

    @property
    def sigma_a(self) -> Float[Array, ""]:
        """The flow's activation stress sigma_a = `strain_a` E1c, Pa."""
        return self.strain_a * self.E1c

    def retardation_time_long(self, cable: Cable) -> Float[Array, ""]:
        """Park Eq. 8: the long-term recovery time t_r2 = lambda1 (L0 / v)^2 -
        lambda2, s, at the strain rate v / L0 of `cable`. It must be positive: `check`
        flags a cable whose strain rate makes it not."""
        return self.lambda1 / cable.strain_rate**2 - self.lambda2

    def hardening_ok(self, cable: Cable):
        """Traced: whether Eq. 1 hardens wherever the cable is in one piece.

        (F / (E1c A))**h with h > 1 is below F / (E1c A) (stiffer) only while
        F < E1c A, a static strain below 1. The static strain never exceeds the
        total, which every simulation keeps below the breaking strain (else
        `RESULTS.strain_beyond_break`), so a breaking strain <= 1 keeps every
        accepted sample there; so does a breaking load below E1c A. Without
        hardening (beta = 0) nothing is required. Measured as a strain, the check
        holds for a thin braid of any diameter, and is well-defined for a cable
        with no breaking load or strain (inf): it then fails only when beta > 0.
        """
        return (
            (self.beta == 0)
            | (cable.breaking_strain <= 1.0)
            | (self.E1c * cable.area > cable.breaking_load)
        )

    def check(self, cable: Cable) -> RESULTS:
        t_r2 = self.retardation_time_long(cable)
        ok = _checks.all_ok(
            declared_ok(self, "positive"),
            jnp.isfinite(t_r2) & (t_r2 > 0),
            self.beta >= 0,
            self.gamma >= 0,
            self.hardening_ok(cable),
        )
        return _checks.domain_result(ok)

    def init(self, cable: Cable) -> IntegratedState:
        # The unloaded cable: every field of the state is zero.
        zero = state_zero(cable, self.E1c)
        names = (f.name for f in dataclasses.fields(IntegratedState))
        return IntegratedState(**dict.fromkeys(names, zero))

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
        force_max = running_max(state.force_max, force)

        # Eq. 1-2 with h from the previous sample's total strain, at F and at F_m;
        # Eq. 9's unloading line from F_m, never below the loading curve.
        compliance_c = 1.0 / (self.E1c * area)
        h = hardening_exponent(state.strain, self.beta, self.gamma)
        static = static_strain(force, compliance_c, h)
        static_max = static_strain(force_max, compliance_c, h)
        inst = jnp.maximum(static_max - (force_max - force) / (self.E1r * area), static)

        def element(q, modulus, creep_time, recovery_time):
            ca = 1.0 / (modulus * area)
            return delayed_elastic(
                q, state.force * ca, force * ca, dt, creep_time, recovery_time
            )

        permanent = element(state.permanent, self.E2c, self.t_c, None)
        short = element(state.short, self.E2r, self.t_e, self.t_r1)
        long = element(
            state.long, self.E3r, self.t_e, self.retardation_time_long(cable)
        )
        # Trapezoid rule over the step: exact for a rate linear in time.
        sigma_a = self.sigma_a
        rate0 = eyring_rate(state.force / area, self.eta0, sigma_a)
        rate1 = eyring_rate(force / area, self.eta0, sigma_a)
        flow = state.flow + 0.5 * (rate0 + rate1) * dt

        short_max = jnp.maximum(state.short_max, short)
        long_max = jnp.maximum(state.long_max, long)
        parts = StrainParts(
            instantaneous=inst,
            creep=permanent + short_max + long_max + flow,
            recovery_short=short_max - short,
            recovery_long=long_max - long,
            apparatus=jnp.zeros_like(inst),
        )
        new_state = IntegratedState(
            force=force,
            strain=parts.total,
            force_max=force_max,
            permanent=permanent,
            short=short,
            long=long,
            short_max=short_max,
            long_max=long_max,
            flow=flow,
        )
        return new_state, parts
