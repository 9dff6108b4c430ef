"""The baselines the papers argue against: Hooke's law, the Burgers model and a
Bouc-Wen hysteresis loop. Kept as models so that the argument (a polymer cable creeps,
recovers and hardens, which none of them does fully) can be measured on the same
drivers and data."""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from .. import _checks
from .._cable import Cable
from .._results import RESULTS
from .base import AbstractCableModel, StrainParts, state_zero
from .fields import MODULUS, VISCOSITY, declared_ok, parameter, setting
from .kernels import kelvin_voigt_step, loading_weight, play


# ----------------------------------------------------------------------------------
# Hooke


class HookeState(eqx.Module):
    """Scan carry of [`jaxcable.HookeModel`][]: Hooke's law has no memory, so it is
    empty."""


class HookeModel(AbstractCableModel[HookeState]):
    """Hooke's law: a linear elastic cable, eps = F / (E A).

    The "static elongation" red line of Park Fig. 2 and the modified Hooke's law used by
    Schmidt and Pott and by Merlet (Park Section 1): no creep, no recovery, no
    hysteresis.

    **Fields (SI):**

    - `E`: Young's modulus, Pa (default 2.2e9 Pa, the static modulus E1c of the
        [`jaxcable.IntegratedModel`][] default set for Dyneema SK78, 3 mm).
    """

    CLI_NAME = "hooke"

    E: Float[Array, "*batch"] = parameter(2.2e9, **MODULUS)

    def init(self, cable: Cable) -> HookeState:
        return HookeState()

    def advance(
        self,
        state: HookeState,
        cable: Cable,
        dt: Float[Array, ""],
        force: Float[Array, ""],
        direction: Int[Array, ""],
    ) -> tuple[HookeState, StrainParts]:
        strain = force / (self.E * cable.area)
        zero = jnp.zeros_like(strain)
        return state, StrainParts(strain, zero, zero, zero, zero)


# ----------------------------------------------------------------------------------
# Burgers


class BurgersState(eqx.Module):
    """Scan carry of [`jaxcable.BurgersModel`][] for one cable (all SI).

    **Fields:**

    - `stress`: stress F / A at the previous sample, Pa.
    - `kelvin_voigt`: strain of the Kelvin-Voigt element (E2, eta2).
    - `dashpot`: strain of the Maxwell dashpot eta0 (permanent).
    """

    stress: Float[Array, ""]
    kelvin_voigt: Float[Array, ""]
    dashpot: Float[Array, ""]


class BurgersModel(AbstractCableModel[BurgersState]):
    """The Burgers model: a Maxwell element (spring E1, dashpot eta0) in series with a
    Kelvin-Voigt element (spring E2 parallel to dashpot eta2).

    Under a constant stress sigma = F / A applied at t = 0 (Park Eq. 3 plus the spring):

        eps(t) = sigma / E1 + sigma / E2 (1 - exp(-E2 t / eta2)) + sigma t / eta0,

    the retardation time of Park Eq. 3 being t_c = eta2 / E2. Any force history is
    handled by exact superposition: the force is linear between samples, the
    Kelvin-Voigt element takes its exact exponential update and the dashpot strain
    increment, (sigma0 + sigma1) h / (2 eta0), is exact for a linear stress (trapezoid
    rule). Unlike Park's integrated model there are no separate loading and unloading
    parameters: on unloading the Kelvin-Voigt strain recovers and the dashpot strain
    stays.

    **Strain parts.** `instantaneous` = sigma / E1; `creep` = Kelvin-Voigt + dashpot.

    **Fields (SI):**

    - `E1`: instantaneous (Maxwell) spring modulus, Pa.
    - `eta0`: Maxwell dashpot viscosity, Pa s.
    - `E2`: Kelvin-Voigt modulus, Pa.
    - `eta2`: Kelvin-Voigt viscosity, Pa s.

    The defaults are the linear part of the [`jaxcable.IntegratedModel`][] default set
    (Dyneema SK78, 3 mm): E1 = E1c = 2.591e9 Pa; one Kelvin-Voigt element with the
    compliance of its three creep elements in series, 1 / E2 = 1 / E2c + 1 / E2r +
    1 / E3r (E2 = 6.431e8 Pa), and its creep time t_e (eta2 = E2 t_e = 2.727e9 Pa s);
    the dashpot, its flow at low stress (eta0 = 1.2e16 Pa s). 10 N held 2 h on the
    3 mm rope strains it 0.27 % (0.05 % at once, 0.22 % of creep in seconds and
    1e-6 of flow). (Before, eta0 = 1.6e11 Pa s: the same hold reached 6.8 %, far from
    any rope.) [`jaxcable.scaled_start`][] scales them to a data set.
    """

    CLI_NAME = "burgers"

    E1: Float[Array, "*batch"] = parameter(2.591e9, **MODULUS)
    eta0: Float[Array, "*batch"] = parameter(1.2e16, **VISCOSITY)
    E2: Float[Array, "*batch"] = parameter(6.431e8, **MODULUS)
    eta2: Float[Array, "*batch"] = parameter(2.727e9, **VISCOSITY)

    def init(self, cable: Cable) -> BurgersState:
        zero = state_zero(cable, self.E1)
        return BurgersState(stress=zero, kelvin_voigt=zero, dashpot=zero)

    def advance(
        self,
        state: BurgersState,
        cable: Cable,
        dt: Float[Array, ""],
        force: Float[Array, ""],
        direction: Int[Array, ""],
    ) -> tuple[BurgersState, StrainParts]:
        stress = force / cable.area
        kelvin_voigt = kelvin_voigt_step(
            state.kelvin_voigt, state.stress, stress, dt, self.E2, self.eta2
        )
        dashpot = state.dashpot + 0.5 * (state.stress + stress) * dt / self.eta0
        zero = jnp.zeros_like(stress)
        parts = StrainParts(stress / self.E1, kelvin_voigt + dashpot, zero, zero, zero)
        return BurgersState(stress, kelvin_voigt, dashpot), parts


# ----------------------------------------------------------------------------------
# Bouc-Wen


def _powers(z, n):
    """(|z|^(n-1), sign(z) |z|^n, |z|^n) for n >= 1, with finite gradients (in z and n)
    at z = 0.

    Written through |z|^(n-1), continued at z = 0 by its limit (1 for n = 1, else 0),
    so that sign(z) |z|^n = z |z|^(n-1) has its true z-derivative there.
    """
    nonzero = z != 0
    magnitude = jnp.where(nonzero, jnp.abs(z), 1.0)
    at_zero = jnp.where(n == 1, 1.0, 0.0)
    factor = jnp.where(nonzero, jnp.exp((n - 1) * jnp.log(magnitude)), at_zero)
    return factor, z * factor, jnp.abs(z) * factor


# Rosenbrock ROS2 (Verwer et al. 1999) is second order for gamma = 1 -+ 1/sqrt 2 and
# L-stable for both. The smaller root has a ~20x smaller error constant on the
# saturating branch; its step stays monotone (0 < R(z) < 1) while h |d slope/d zeta| <
# 1 / (1 - 2 gamma) ~ 2.4 per substep, i.e. a sample's stress step below about
# 19 sigma_y / (beta + gamma) with 8 substeps (n = 1).
_ROS2_GAMMA = 1.0 - 2.0**-0.5

# 1 N on the 3 mm cable of Park et al. (A = 7.07e-6 m^2): ~1.41e5 Pa.
DEFAULT_BAND = 1.0 / (math.pi / 4 * 3e-3**2)


class BoucWenState(eqx.Module):
    """Scan carry of [`jaxcable.BoucWenModel`][] for one cable.

    **Fields:**

    - `stress`: stress F / A at the previous sample, Pa.
    - `zeta`: hysteretic variable, dimensionless.
    - `centre`: centre of the play band at the previous sample, Pa (the stress that
        the play operator of half-width `band` outputs; `stress` - `centre` in
        [-band, band]).
    """

    stress: Float[Array, ""]
    zeta: Float[Array, ""]
    centre: Float[Array, ""]


class BoucWenModel(AbstractCableModel[BoucWenState]):
    """A Bouc-Wen hysteresis loop driven by stress (after Miyasaka et al. 2016): the
    rate-independent baseline Park and Piao argue against.

        d zeta / d sigma = (1 / sigma_y) [A - (beta sign(d sigma zeta) + gamma) |zeta|^n],
        eps = sigma / E + z_y (A sigma / sigma_y - zeta),

    with sigma = F / A_cable. zeta is the Bouc-Wen variable in its usual role (it
    follows A sigma / sigma_y at first and saturates at (A / (beta + gamma))^(1/n));
    the hysteretic strain z_y (A sigma / sigma_y - zeta) is what it fails to follow,
    the plastic-like part that grows once zeta saturates. The tangent compliance is
    1/E at the virgin start and on each reversal (for beta = gamma), rising to
    1/E + z_y A / sigma_y on a saturated branch.

    !!! info "Sign convention"

        The form eps = sigma / E + z_y zeta, with the stress as the input, runs the
        loop anticlockwise in the force-elongation plane: the cable would return energy
        every cycle. Writing the hysteretic strain as A sigma / sigma_y - zeta (the
        force-driven counterpart of the displacement-driven Bouc-Wen, where zeta plays
        the restoring force) makes the dissipated energy per cycle positive, with the
        same zeta dynamics.

    The law is rate-independent: time enters nowhere, so under a cyclic force the loop
    closes (after the first, virgin loading the strain returns to the same value at
    the same force, up to a transient that decays geometrically) and a held force shows
    no creep. This is Park's objection (Section 1 and 3.3): a closed loop lacks the
    dynamic creep and recovery of a polymer cable.

    **Loading and unloading without a branch flag.** The classical law switches on
    sign(d sigma). Under a measured force every noise blip is a reversal: each traces a
    minor loop, whose dissipation moves zeta by about 2 beta |zeta|^n / sigma_y times
    the blip, so the strain drifts with the total variation of the noise (77 mm per N
    of noise on a 300 mm cable, `benchmarks/continuity.py`, before this reading). Here
    the stress passes through a play (backlash) operator of half-width `band`: its
    centre c follows the stress only when |sigma - c| would exceed `band`, and

        sign(d sigma) := 2 w - 1,   w = (sigma - c + band) / (2 band) in [0, 1]

    (`jaxcable._models.kernels.loading_weight`): 1 while the stress pushes the band up, -1
    while it pulls it down, and in between a function of the stress alone. Noise
    smaller than the band therefore traces no loop and leaves no drift: inside the band
    zeta obeys an ODE in sigma alone, so it returns to its value when the stress does.
    The model reduces to the classical Bouc-Wen once the stress has moved 2 `band` past
    a reversal (virgin loading is classical from the start: the band starts at its
    top). A perturbation d <= `band` of every force sample moves the strain by at
    most about (d / A_cable) (1/E + z_y (3 A + 8 beta zeta_sat^n) / sigma_y),
    zeta_sat = (A / (beta + gamma))^(1/n) (the band centre moves by at most d, the
    weight by at most d / band over the 2 (band + d) after a reversal): 0.15 mm per N
    on a 300 mm cable with the defaults, of which random histories reach up to 40 %
    (`tests/test_continuity_models.py`). Noise
    larger than the band traces genuine minor loops, which settle (shake down) rather
    than drift without bound: |zeta| stays below its saturation. The ROS2 steps are
    not exactly reversible: a blip inside the band leaves an error of third order in
    its size (3e-6 in zeta per cycle of -+0.9 `band` with the defaults, 1000 times
    less at -+0.09 `band`), where the classical flag left a first-order loop.
    `direction` is not used.

    **Integration.** The stress is linear over each sample, so zeta obeys an ODE in
    sigma. It is integrated from sigma0 to sigma1 by `substeps` steps of the L-stable
    second-order Rosenbrock method ROS2, whose linear solve keeps the saturating branch
    stable for any force step and needs no Newton iteration (smooth for `jax.grad`);
    8 substeps keep the strain within ~1e-4 (relative) of the exact loop for force
    samples up to a few sigma_y A apart. The play band is evaluated at the ends of
    each substep (exactly: the stress is monotone over a sample), and ROS2 takes the
    weight at the start of the substep in its first stage and at the end in its
    second (second order in the weight as well). ROS2 keeps its order for any matrix
    in place of the Jacobian (it is a W-method, Verwer et al. 1999), so its matrix
    takes the Jacobian with |gamma| sign(d sigma) in place of gamma sign(zeta): exact
    on the saturating branch, continuous where zeta changes sign (the exact
    Jacobian jumps there for n = 1, and the step with it), and clipped to
    h d slope / d zeta <= 0 (inside the band the slope can grow with zeta), which
    keeps the denominator >= 1. sign(zeta) |zeta|^n is evaluated with gradients that
    stay finite at zeta = 0.

    **Strain parts.** `instantaneous` = the whole strain (elastic + loop); there is no
    creep or recovery.

    **Fields (SI):**

    - `E`: elastic modulus, Pa.
    - `sigma_y`: stress scale of the loop ("yield" stress), Pa.
    - `z_y`: strain scale of the hysteretic part, dimensionless.
    - `A`: Bouc-Wen amplitude parameter, dimensionless (not the cross-section).
    - `beta`, `gamma`: loop-shape parameters, dimensionless; `beta > 0` and
        `|gamma| <= beta` (a dissipative loop, and a stable integration).
    - `n`: sharpness exponent, dimensionless, `n >= 1`.
    - `band`: half-width of the play band that reads loading and unloading, Pa
        (> 0; not fitted). Default `DEFAULT_BAND`, 1 N on Park's 3 mm cable (about
        1.41e5 Pa, 2.8 % of the default `sigma_y`): above the force noise of a load
        cell at these loads, while the energy dissipated per 0-100 N cycle stays
        within 4 % of the classical loop's (measured; 1 % for 0.35 N, 8.5 % for
        2 N, 21 % for 5 N). Noise of standard deviation 0.5-1 N (peaks of several N)
        exceeds it and traces minor loops (`benchmarks/continuity.py`).
    - `substeps`: ROS2 steps per sample (static; default 8).

    The strain must rise with the force on every branch (the elongation-driven solve
    needs it): E z_y (beta - gamma) A / (beta + gamma) < sigma_y, checked.

    The defaults are illustrative for the 3 mm SK78 cable at 100-150 N (Miyasaka's
    fitted values are for stainless-steel cables): E = 2.2e9 Pa as Hooke, z_y = 2e-3,
    sigma_y = 5e6 Pa (about 35 N), A = 1, beta = 0.6, gamma = 0.4, n = 1.
    """

    CLI_NAME = "bouc-wen"

    E: Float[Array, "*batch"] = parameter(2.2e9, **MODULUS)
    sigma_y: Float[Array, "*batch"] = parameter(5e6, unit="Pa")
    # eps = sigma / E + z_y (...): E -> c E with z_y -> z_y / c divides eps by c.
    z_y: Float[Array, "*batch"] = parameter(2e-3, unit="-", stiffness=-1.0)
    A: Float[Array, "*batch"] = parameter(1.0, unit="-")
    beta: Float[Array, "*batch"] = parameter(0.6, unit="-")
    # |gamma| <= beta (a dissipative loop) and n >= 1: checked by `check_more`.
    gamma: Float[Array, "*batch"] = parameter(0.4, unit="-", transform="tanh:beta")
    n: Float[Array, "*batch"] = parameter(1.0, unit="-", transform="log1")
    band: Float[Array, "*batch"] = setting(DEFAULT_BAND, unit="Pa")
    substeps: int = eqx.field(static=True, default=8)

    def check_more(self):
        if _checks.is_concrete(self.beta, self.gamma):
            if np.any(np.abs(self.gamma) > self.beta):
                raise ValueError(
                    f"`BoucWenModel.gamma` must satisfy |gamma| <= beta (a dissipative "
                    f"loop), got gamma={self.gamma}, beta={self.beta}."
                )
        if _checks.is_concrete(self.n) and np.any(np.asarray(self.n) < 1):
            raise ValueError(
                f"`BoucWenModel.n` must be >= 1 (|zeta|^n Lipschitz at zeta = 0), "
                f"got {self.n}."
            )
        if _checks.is_concrete(self) and not np.all(self._monotone()):
            raise ValueError(
                "`BoucWenModel.z_y` too large for `sigma_y`: the strain would fall "
                "while the force rises on unloading branches (need E z_y (beta - "
                f"gamma) A / (beta + gamma) < sigma_y), got z_y={self.z_y}, "
                f"sigma_y={self.sigma_y}."
            )
        if not isinstance(self.substeps, int) or self.substeps < 1:
            raise ValueError(
                f"`BoucWenModel.substeps` must be a positive int, got {self.substeps!r}."
            )

    def _monotone(self):
        # Smallest tangent compliance: unloading from the saturated branch,
        # 1/E - z_y (beta - gamma) |zeta_sat|^n / sigma_y, must stay positive.
        saturated = self.A / (self.beta + self.gamma)
        return self.E * self.z_y * (self.beta - self.gamma) * saturated < self.sigma_y

    def check(self, cable: Cable) -> RESULTS:
        ok = _checks.all_ok(
            declared_ok(self, "positive"),
            (jnp.abs(self.gamma) <= self.beta) & (self.n >= 1) & self._monotone(),
        )
        return _checks.domain_result(ok)

    def init(self, cable: Cable) -> BoucWenState:
        zero = state_zero(cable, self.E)
        # The band starts at its top (w = 1): the virgin loading is classical.
        return BoucWenState(stress=zero, zeta=zero, centre=zero - self.band)

    def _slope(self, zeta, sign_dsigma):
        """d zeta / d sigma (the Bouc-Wen law, 1/Pa) and |zeta|^(n-1)."""
        factor, signed, magnitude = _powers(zeta, self.n)
        # sign(d sigma zeta) |zeta|^n = sign(d sigma) sign(zeta) |zeta|^n.
        slope = self.A - self.beta * sign_dsigma * signed - self.gamma * magnitude
        return slope / self.sigma_y, factor

    def _stiffness(self, factor, sign_dsigma, h):
        """h times the zeta-derivative of the slope as ROS2's matrix takes it, <= 0.

        The exact derivative, -n |zeta|^(n-1) (beta sign(d sigma) + gamma sign(zeta)),
        jumps where zeta changes sign (n = 1); the matrix takes |gamma| sign(h) in
        place of gamma sign(zeta): exact on the saturating branch, larger elsewhere,
        continuous in zeta and in the stress."""
        hj = -self.n * factor * (self.beta * sign_dsigma * h + jnp.abs(self.gamma * h))
        return jnp.minimum(hj / self.sigma_y, 0.0)

    def advance(
        self,
        state: BoucWenState,
        cable: Cable,
        dt: Float[Array, ""],
        force: Float[Array, ""],
        direction: Int[Array, ""],
    ) -> tuple[BoucWenState, StrainParts]:
        # Rate-independent; `direction` is not used: the play band reads loading and
        # unloading from the stress alone (class docstring).
        del dt, direction
        stress = force / cable.area
        h = (stress - state.stress) / self.substeps

        def sign_dsigma(centre, sigma):
            return 2.0 * loading_weight(centre, sigma, self.band) - 1.0

        def ros2(i, carry):
            zeta, centre = carry
            sigma = state.stress + i * h
            # The stress is monotone over the sample: the play at the substep's end
            # is exact.
            centre_end = play(centre, sigma + h, self.band)
            sign_start = sign_dsigma(centre, sigma)
            slope, factor = self._slope(zeta, sign_start)
            denominator = 1.0 - _ROS2_GAMMA * self._stiffness(factor, sign_start, h)
            k1 = h * slope / denominator
            slope_end = self._slope(zeta + k1, sign_dsigma(centre_end, sigma + h))[0]
            k2 = (h * slope_end - 2.0 * k1) / denominator
            return zeta + 1.5 * k1 + 0.5 * k2, centre_end

        zeta, _ = jax.lax.fori_loop(0, self.substeps, ros2, (state.zeta, state.centre))
        centre = play(state.centre, stress, self.band)
        strain = stress / self.E + self.z_y * (self.A * stress / self.sigma_y - zeta)
        zero = jnp.zeros_like(strain)
        return BoucWenState(stress, zeta, centre), StrainParts(
            strain, zero, zero, zero, zero
        )
