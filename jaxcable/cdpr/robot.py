"""An 8-cable suspended robot with creep-compensated winch lengths: the example of how
jaxcable drops into a JAX control loop (`notebooks/05_cdpr.ipynb`).

The robot is Piao et al.'s CNU high-payload CDPR as their Section 2.1 describes it: a
4 m x 4 m x 4 m frame, eight pulleys near the corners of the top frame, 6 mm Dyneema
cables (LIROS D-Pro), payloads up to 65 kg. Every function is pure JAX: a whole run
(hours of pick-and-place) is one jitted `lax.scan`, and `jax.grad` goes through it.

**One sample of the closed loop** (`simulate_robot`):

1. the end-effector, a point mass (platform + payload), hangs where the last sample
    left it; the winch torques realise a tension distribution that keeps every cable
    taut (`tension_distribution`, quasi-static); the load cells measure these forces;
2. the controller predicts each cable's elongation from its own measured force
    history ([`jaxcable.controller_step`][]) and commands the unstretched free length
    L(x_d) - gain * elongation, with L(x_d) the inverse kinematics of the desired
    position plus the fixed routing from the winch to the pulley;
3. the "real" cables stretch by their own model (other parameters, one more effect)
    under the same forces;
4. the end-effector moves to the least-squares forward kinematics of the stretched
    lengths (`forward_kinematics`): the position error is that minus x_d.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np
from jaxtyping import Array, ArrayLike, Float, PRNGKeyArray

from .._cable import Cable
from .._drive import (
    GRAVITY,
    ControllerState,
    LiveFiveElement,
    controller_init,
    controller_step,
)
from .._models import (
    AbstractCableModel,
    HookeModel,
    IntegratedModel,
    TerminationCompliance,
)
from .._montecarlo import IndependentParameters, LogNormal


# Piao Section 2.1: LIROS D-Pro 01505-0600, 6 mm. Its breaking load is not printed; it
# is taken as Park's rated load of the 3 mm SK78 cable (2000 N, Park Section 2.1)
# scaled with the cross-section (x4): the same rated stress. The manufacturer's
# breaking load of such a rope is higher, so this is conservative for the input checks.
DIAMETER = 6e-3
BREAKING_LOAD = 8000.0
# The strain rate that sets Park's long-term retardation time t_r2 (Eq. 8): that of
# Park's fastest test, 50 mm/min on 300 mm (t_r2 ~ 8 min with the default set).
# A cable's `speed` is its length times this rate.
STRAIN_RATE = (50e-3 / 60) / 0.3
# The default compensation models.
NOMINAL = IntegratedModel()
HOOKE = HookeModel(E=NOMINAL.E1c)
FIVE_ELEMENT = LiveFiveElement()


def _default_pulleys() -> np.ndarray:
    # Two pulleys per top corner of the 4 m cube (frame centred on x = y = 0, floor
    # at z = 0), 0.3 m apart along the two edges that meet there.
    rows = []
    for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
        rows.append((sx * 1.95, sy * 1.65, 4.0))
        rows.append((sx * 1.65, sy * 1.95, 4.0))
    return np.array(rows)


class Robot(eqx.Module):
    """A suspended cable robot with a point-mass end-effector.

    **Fields (SI):**

    - `pulleys`: exit points of the cables at the pulleys, m, shape `(n, 3)` (default:
        8 pulleys near the corners of the top of a 4 m cube, z up, floor at 0).
    - `routing`: unstretched cable length from each winch drum to its pulley, m
        (default 4 m: winches at the foot of the columns). It is loaded like the rest,
        so a cable's free length is routing + the pulley-to-end-effector distance
        (6.9-9.0 m over `pick_and_place`; Piao tested 5.4-8.4 m).
    - `platform_mass`: mass of the end-effector without payload, kg.
    - `min_tension`: the least tension of every cable, N (taut cables).
    - `diameter`, `breaking_load`: of every cable, m and N (6 mm Dyneema).
    - `strain_rate`: 1/s, sets each cable's `speed` = length * strain_rate.
    """

    pulleys: Float[Array, "n 3"] = eqx.field(
        converter=jnp.asarray, default_factory=_default_pulleys
    )
    routing: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=4.0)
    platform_mass: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=20.0)
    min_tension: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=10.0)
    diameter: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=DIAMETER)
    breaking_load: Float[Array, ""] = eqx.field(
        converter=jnp.asarray, default=BREAKING_LOAD
    )
    strain_rate: Float[Array, ""] = eqx.field(
        converter=jnp.asarray, default=STRAIN_RATE
    )

    def __check_init__(self):
        shape = jnp.shape(self.pulleys)
        if len(shape) != 2 or shape[1] != 3 or shape[0] < 4:
            raise ValueError(
                f"Robot `pulleys` must have shape (n, 3) with n >= 4, got {shape}."
            )

    @property
    def num_cables(self) -> int:
        return int(jnp.shape(self.pulleys)[0])

    def geometric_lengths(self, position: Float[Array, " 3"]) -> Float[Array, " n"]:
        """Inverse kinematics: pulley-to-end-effector distances, m."""
        return jnp.linalg.norm(self.pulleys - position, axis=-1)

    def free_lengths(self, position: Float[Array, " 3"]) -> Float[Array, " n"]:
        """Loaded cable lengths, winch to end-effector (routing + geometric), m."""
        return self.routing + self.geometric_lengths(position)

    def directions(self, position: Float[Array, " 3"]) -> Float[Array, "3 n"]:
        """The structure matrix: unit vectors from the end-effector to the pulleys."""
        d = self.pulleys - position
        return (d / jnp.linalg.norm(d, axis=-1, keepdims=True)).T

    def cables(self, lengths: Float[Array, " n"]) -> Cable:
        """The [`jaxcable.Cable`][] set of these free lengths (m)."""
        return Cable(
            length=lengths,
            diameter=self.diameter,
            speed=lengths * self.strain_rate,
            breaking_load=self.breaking_load,
        )


def tension_distribution(
    robot: Robot,
    position: Float[ArrayLike, " 3"],
    mass: Float[ArrayLike, ""],
    *,
    iterations: int = 12,
) -> Float[Array, " n"]:
    r"""Cable tensions that hold a point mass at `position`: the minimum-norm
    distribution above the minimum tension.

    Solves min ||t||^2 / 2 subject to A t = m g e_z and t >= t_min (A: the
    structure matrix `robot.directions`, quasi-static). Its KKT conditions give
    t = max(t_min, A^T lambda) with A max(t_min, A^T lambda) = m g e_z, three
    piecewise-linear equations in lambda, solved by a semismooth Newton method
    (`iterations` steps from the unconstrained minimum-norm solution; exact once the
    set of cables at t_min stops changing, usually after 1-3 steps). Differentiable
    (`jax.grad` through the unrolled steps). For a suspended robot the problem is
    feasible only while t_min * sum(A_z) < m g: keep `robot.min_tension` well below
    the weight per cable.

    **Arguments:**

    - `robot`: the [`jaxcable.Robot`][].
    - `position`: end-effector position, m.
    - `mass`: total suspended mass (platform + payload), kg.
    - `iterations`: Newton steps (static).

    **Returns:**

    The tensions, N, shape `(n,)`; NaN where no distribution balances the load
    (infeasible pose), so that [`jaxcable.controller_step`][] raises on it.
    """
    A = robot.directions(jnp.asarray(position))
    dtype = A.dtype
    w = jnp.zeros(3, dtype).at[2].set(jnp.asarray(mass, dtype) * GRAVITY)
    t_min = robot.min_tension
    AAt = A @ A.T
    lam = jnp.linalg.solve(AAt, w)
    # A small ridge keeps the Newton matrix invertible while fewer than three cables
    # are above t_min (that step then moves lambda towards the feasible set).
    ridge = 1e-9 * jnp.trace(AAt) * jnp.eye(3, dtype=dtype)

    def newton(_, lam):
        s = A.T @ lam
        active = (s > t_min).astype(dtype)
        residual = A @ jnp.maximum(t_min, s) - w
        J = (A * active) @ A.T + ridge
        return lam - jnp.linalg.solve(J, residual)

    # A fixed trip count: a scan, so reverse-mode differentiable (and compact to
    # compile inside the robot's scan).
    lam = jax.lax.fori_loop(0, iterations, newton, lam)
    t = jnp.maximum(t_min, A.T @ lam)
    # Infeasible (the pose is outside the workspace for this mass and t_min) or not
    # converged: NaN, which the creep models flag as a non-physical force.
    balanced = jnp.linalg.norm(A @ t - w) <= 1e-6 * jnp.linalg.norm(w)
    return jnp.where(balanced, t, jnp.nan)


def forward_kinematics(
    robot: Robot,
    lengths: Float[ArrayLike, " n"],
    guess: Float[ArrayLike, " 3"],
    *,
    iterations: int = 6,
) -> Float[Array, " 3"]:
    """Least-squares forward kinematics: the point whose distances to the pulleys best
    fit the stretched pulley-to-end-effector `lengths` (m).

    min_x sum_i (|p_i - x| - l_i)^2 by Gauss-Newton, `iterations` steps from `guess`
    (quadratic convergence from the previous sample's position; unrolled, so
    `jax.grad` applies). With 8 cables for 3 coordinates the lengths are redundant:
    where they disagree (cables stretched unequally) this is the unweighted
    least-squares compromise, not a stiffness-weighted equilibrium.
    """
    lengths = jnp.asarray(lengths)
    x = jnp.asarray(guess, lengths.dtype)

    def gauss_newton(_, x):
        d = robot.pulleys - x
        dist = jnp.linalg.norm(d, axis=-1)
        r = dist - lengths
        J = -d / dist[:, None]
        return x - jnp.linalg.solve(J.T @ J, J.T @ r)

    return jax.lax.fori_loop(0, iterations, gauss_newton, x)


# ----------------------------------------------------------------------------------
# The task.


class Scenario(eqx.Module):
    """A sampled motion: desired end-effector positions and the payload carried.

    **Fields:** `time` (s, `(T,)`), `position` (m, `(T, 3)`), `payload` (kg, `(T,)`).
    """

    time: Float[Array, " T"] = eqx.field(converter=jnp.asarray)
    position: Float[Array, "T 3"] = eqx.field(converter=jnp.asarray)
    payload: Float[Array, " T"] = eqx.field(converter=jnp.asarray)

    def __check_init__(self):
        T = jnp.shape(self.time)
        if (
            len(T) != 1
            or jnp.shape(self.position) != (*T, 3)
            or jnp.shape(self.payload) != T
        ):
            raise ValueError(
                f"Scenario: `time` (T,), `position` (T, 3), `payload` (T,) expected, "
                f"got {T}, {jnp.shape(self.position)}, {jnp.shape(self.payload)}."
            )

    def __getitem__(self, index) -> "Scenario":
        return Scenario(self.time[index], self.position[index], self.payload[index])


HOME = (0.0, 0.0, 2.2)
PICK = (-1.0, -0.9, 0.9)
PLACE = (1.0, 0.9, 1.3)
PAYLOADS = (65.0, 30.0, 50.0, 15.0, 65.0, 40.0, 55.0, 25.0)
# One cycle, s: home -> pick, dwell (grasp), pick -> place, dwell (release),
# place -> home, idle.
_SEGMENTS = (("move", 8.0), ("grasp", 6.0), ("move", 10.0), ("release", 6.0))
_SEGMENTS += (("move", 8.0), ("idle", 22.0))


def _minimum_jerk(s):
    return s**3 * (10 - 15 * s + 6 * s**2)


def pick_and_place(
    hours: float = 2.0,
    *,
    dt: float = 1.0,
    payloads=PAYLOADS,
    home=HOME,
    pick=PICK,
    place=PLACE,
) -> Scenario:
    """Hours of pick-and-place: a 60 s cycle repeated, each cycle carrying the next
    payload of `payloads` (kg, cycled).

    A cycle: home -> pick (8 s), grasp (6 s: the payload is taken over 2 s in the
    middle), pick -> place (10 s), release (6 s), place -> home (8 s), idle at home
    (22 s). Moves follow a minimum-jerk profile on straight lines.

    **Arguments:**

    - `hours`: duration, h.
    - `dt`: sample period, s (the controller and the creep models run at 1/dt).
    - `payloads`: the payload of each cycle, kg (0 to 65 kg in Piao's robot).
    - `home`, `pick`, `place`: positions, m.

    **Returns:**

    A [`jaxcable.Scenario`][].
    """
    if not (hours > 0 and dt > 0):
        raise ValueError(f"`hours` and `dt` must be positive, got {hours}, {dt}.")
    payloads = np.asarray(payloads, float)
    if payloads.ndim != 1 or payloads.size == 0 or np.any(payloads < 0):
        raise ValueError(f"`payloads` must be non-negative masses, got {payloads}.")
    home, pick, place = (np.asarray(p, float) for p in (home, pick, place))
    period = sum(d for _, d in _SEGMENTS)
    time = np.arange(0.0, hours * 3600.0 + 0.5 * dt, dt)
    cycle = np.floor(time / period).astype(int)
    phase = time - cycle * period
    mass = payloads[cycle % payloads.size]
    position = np.empty((time.size, 3))
    payload = np.empty(time.size)
    route = (home, pick, pick, place, place, home, home)
    start = 0.0
    for k, (kind, duration) in enumerate(_SEGMENTS):
        inside = (phase >= start) & (phase < start + duration)
        s = (phase[inside] - start) / duration
        a, b = route[k], route[k + 1]
        position[inside] = a + _minimum_jerk(s)[:, None] * (b - a)
        ramp = np.clip((s - 1 / 3) * 3, 0.0, 1.0)  # the middle third of the dwell
        held = {"grasp": ramp, "move": k == 2, "release": 1 - ramp, "idle": 0.0}[kind]
        payload[inside] = mass[inside] * held
        start += duration
    return Scenario(time, position, payload)


# ----------------------------------------------------------------------------------
# The "real" cables.

# The parameters drawn for the real cables: every modulus, viscosity and time of the
# integrated model (the hardening and long-term-recovery laws keep their values).
REAL_PARAMETERS = ("E1c", "E1r", "E2c", "t_c", "eta0", "E2r", "t_r1", "E3r")


def real_cables(
    key: PRNGKeyArray,
    *,
    num_cables: int = 8,
    relative_std: float = 0.05,
    compliance: float = 2e-5,
    model: IntegratedModel = NOMINAL,
) -> AbstractCableModel:
    """The cables of the simulated "real" robot: one parameter set per cable drawn
    around the controller's model, plus an effect the controller's model lacks.

    Each cable's `REAL_PARAMETERS` are drawn log-normally (median: `model`'s value,
    standard deviation of the log `relative_std`: the fit's uncertainty and the
    cable-to-cable scatter), with [`jaxcable.IndependentParameters`][]; the cables
    are then wrapped in [`jaxcable.TerminationCompliance`][], a length-independent
    series compliance (splices, the pulley and the winch drum) that none of the
    compensation models has.

    **Returns:**

    A `TerminationCompliance` whose arrays have a leading axis of `num_cables`
    (use with `per_cable=True`).
    """
    sampler = IndependentParameters(
        model,
        {n: LogNormal(getattr(model, n), relative_std) for n in REAL_PARAMETERS},
    )
    drawn = jax.vmap(sampler.draw)(jax.random.split(key, num_cables))
    broadcast = jtu.tree_map(
        lambda x: (
            jnp.broadcast_to(x, (num_cables, *jnp.shape(x)[1:]))
            if jnp.ndim(x) == 0
            else x
        ),
        drawn,
    )
    return TerminationCompliance(broadcast, jnp.full(num_cables, compliance))


# ----------------------------------------------------------------------------------
# The closed loop.


class RobotRun(eqx.Module):
    """A simulated run (all SI; `(T, ...)` arrays, one row per sample).

    **Fields:**

    - `time`: s. `desired`, `position`: desired and actual end-effector positions, m.
    - `forces`: measured cable tensions, N, `(T, n)`.
    - `elongation`: the real cables' elongations, m, `(T, n)`.
    - `predicted`: the controller's predicted elongations, m (0 without compensation).
    - `command`: commanded unstretched free lengths (winch), m.
    """

    time: Float[Array, " T"]
    desired: Float[Array, "T 3"]
    position: Float[Array, "T 3"]
    forces: Float[Array, "T n"]
    elongation: Float[Array, "T n"]
    predicted: Float[Array, "T n"]
    command: Float[Array, "T n"]

    @property
    def error(self) -> Float[Array, "T 3"]:
        """Position error, actual - desired, m."""
        return self.position - self.desired

    @property
    def error_norm(self) -> Float[Array, " T"]:
        """|actual - desired|, m."""
        return jnp.linalg.norm(self.error, axis=-1)

    def rms_error(self) -> Float[Array, ""]:
        """RMS of |actual - desired| over the samples, m."""
        return jnp.sqrt(jnp.mean(jnp.sum(self.error**2, axis=-1)))

    def max_error(self) -> Float[Array, ""]:
        """Largest |actual - desired|, m."""
        return jnp.max(self.error_norm)


class _Carry(eqx.Module):
    controller: ControllerState | None
    real: ControllerState
    position: Float[Array, " 3"]


def simulate_robot(
    robot: Robot,
    scenario: Scenario,
    real: AbstractCableModel,
    controller: AbstractCableModel | None,
    gain: Float[ArrayLike, ""] = 1.0,
) -> RobotRun:
    """Run the closed loop over a scenario (one jitted `lax.scan`).

    **Arguments:**

    - `robot`: the [`jaxcable.Robot`][].
    - `scenario`: the [`jaxcable.Scenario`][].
    - `real`: the real cables' model with one parameter set per cable (leading axis
        n, e.g. [`jaxcable.real_cables`][]).
    - `controller`: the compensation model, shared by the cables, or `None` for no
        compensation (the winches command the inverse kinematics).
    - `gain`: the share of the predicted elongation that is compensated (1: all of
        it), a scalar or one per cable; differentiable, as are the model's
        parameters.

    **Returns:**

    A [`jaxcable.RobotRun`][].
    """
    # An array, so that a new gain does not recompile (filter_jit makes Python
    # scalars static).
    # One gain per cable, always: a scalar and a per-cable gain share a compilation.
    dtype = jnp.result_type(float, scenario.position)
    gain = jnp.broadcast_to(jnp.asarray(gain, dtype), (robot.num_cables,))
    return _simulate_robot(robot, scenario, real, controller, gain)


@eqx.filter_jit
def _simulate_robot(robot, scenario, real, controller, gain) -> RobotRun:
    n = robot.num_cables
    dtype = jnp.result_type(float, scenario.position)
    x0 = scenario.position[0]
    lengths0 = robot.free_lengths(x0)
    carry = _Carry(
        controller=None
        if controller is None
        else controller_init(controller, robot.cables(lengths0), scenario.time[0]),
        real=controller_init(
            real, robot.cables(lengths0), scenario.time[0], per_cable=True
        ),
        position=x0,
    )
    mass0 = robot.platform_mass

    def body(carry: _Carry, sample):
        t, x_d, payload = sample
        # 1. The tensions that hold the end-effector where it is (load cells).
        forces = tension_distribution(robot, carry.position, mass0 + payload)
        # 2. The controller's prediction and the commanded unstretched lengths.
        lengths = robot.free_lengths(x_d)
        if controller is None:
            ctrl, predicted = None, jnp.zeros(n, dtype)
        else:
            ctrl, predicted = controller_step(
                controller, robot.cables(lengths), carry.controller, t, forces
            )
        command = lengths - gain * predicted
        # 3. The real cables stretch under the same forces.
        real_state, elongation = controller_step(
            real,
            robot.cables(command),
            carry.real,
            t,
            forces,
            per_cable=True,
        )
        # 4. Where the stretched cables put the end-effector.
        stretched = command + elongation - robot.routing
        position = forward_kinematics(robot, stretched, carry.position)
        new = _Carry(controller=ctrl, real=real_state, position=position)
        return new, (position, forces, elongation, predicted, command)

    xs = (scenario.time, scenario.position, scenario.payload)
    _, (position, forces, elongation, predicted, command) = jax.lax.scan(
        body, carry, xs
    )
    return RobotRun(
        time=scenario.time,
        desired=scenario.position,
        position=position,
        forces=forces,
        elongation=elongation,
        predicted=predicted,
        command=command,
    )


def compensation_models() -> dict[str, AbstractCableModel | None]:
    """The four compensations compared: none, Hooke's law (the static modulus of the
    nominal integrated model), Piao's five-element model with its payload/length
    surface evaluated live, and the nominal (default) integrated model."""
    return {
        "none": None,
        "Hooke": HOOKE,
        "five-element (Piao, live)": FIVE_ELEMENT,
        "integrated": NOMINAL,
    }


def compare(
    robot: Robot, scenario: Scenario, real: AbstractCableModel, models=None
) -> dict[str, dict[str, float]]:
    """RMS and max position error (mm) of every compensation model.

    **Returns:**

    `{name: {"rms_mm": ..., "max_mm": ...}}` for the models of
    [`jaxcable.compensation_models`][] (or `models`, a dict of the same form).
    """
    models = compensation_models() if models is None else models
    table = {}
    for name, model in models.items():
        run = simulate_robot(robot, scenario, real, model)
        table[name] = {
            "rms_mm": 1e3 * float(run.rms_error()),
            "max_mm": 1e3 * float(run.max_error()),
        }
    return table


def removed(table: dict[str, dict[str, float]], name: str, reference: str) -> float:
    """The share (%) of `reference`'s RMS error that `name` removes."""
    return 100.0 * (1.0 - table[name]["rms_mm"] / table[reference]["rms_mm"])


# ----------------------------------------------------------------------------------
# Differentiating through the closed loop.


def position_loss(
    gain: Float[ArrayLike, ""],
    robot: Robot,
    scenario: Scenario,
    real: AbstractCableModel,
    controller: AbstractCableModel,
) -> Float[Array, ""]:
    """Mean squared position error of a run, m^2: a differentiable function of the
    compensation `gain` and of the `controller` model's parameters (`jax.grad`,
    `eqx.filter_grad`), through the whole closed loop (tension distribution, creep
    models, forward kinematics)."""
    run = simulate_robot(robot, scenario, real, controller, gain)
    return jnp.mean(jnp.sum(run.error**2, axis=-1))


_loss_and_grad = eqx.filter_jit(jax.value_and_grad(position_loss))


def loss_and_grad(
    gain: Float[ArrayLike, ""],
    robot: Robot,
    scenario: Scenario,
    real: AbstractCableModel,
    controller: AbstractCableModel,
) -> tuple[Float[Array, ""], Float[Array, ""]]:
    """`position_loss` and its derivative with respect to the gain, jitted (one
    compilation per scenario length and controller model, whatever the gain)."""
    gain = jnp.asarray(gain, jnp.result_type(float, scenario.position))
    return _loss_and_grad(gain, robot, scenario, real, controller)


@eqx.filter_jit
def _residuals_and_jacobian(gain, robot, scenario, real, controller):
    def residuals(gain):
        run = _simulate_robot(robot, scenario, real, controller, gain)
        return run.error.reshape(-1)

    flat = gain.reshape(-1)
    unflat = lambda g: g.reshape(gain.shape)
    r = residuals(gain)
    J = jax.jacfwd(lambda g: residuals(unflat(g)))(flat)
    return r, J


def errors_and_jacobian(
    gain: Float[ArrayLike, "*n"],
    robot: Robot,
    scenario: Scenario,
    real: AbstractCableModel,
    controller: AbstractCableModel,
) -> tuple[Float[Array, " m"], Float[Array, "m p"]]:
    """The position errors of a run, flattened (m = 3 x samples, in m), and their
    Jacobian with respect to the gain (p = its size), by forward-mode
    differentiation through the whole closed loop (`jax.jacfwd`, jitted)."""
    g = jnp.asarray(gain, jnp.result_type(float, scenario.position))
    return _residuals_and_jacobian(g, robot, scenario, real, controller)


def tune_gain(
    robot: Robot,
    scenario: Scenario,
    real: AbstractCableModel,
    controller: AbstractCableModel,
    gain: Float[ArrayLike, "*n"] = 1.0,
    *,
    steps: int = 2,
    ridge: float = 0.03,
) -> tuple[Float[Array, "*n"], list[dict]]:
    """Tune the compensation gain (one for all cables, or one per cable) by the
    derivative of the position error through the closed loop.

    Gauss-Newton on the position errors of every sample, e(g): the Jacobian de/dg
    comes from forward-mode differentiation of the whole run (`jax.jacfwd`, one
    tangent per gain). The error is nearly linear in the gains (the forward
    kinematics is smooth and the forces depend on them only through small pose
    changes), so one or two steps converge. A ridge pulls the gains towards 1 (full
    compensation), `ridge` times the mean curvature: cables that pull in nearly the
    same direction (the two at a corner) otherwise trade their gains freely.

    **Arguments:**

    - `robot`, `scenario`, `real`, `controller`: as in
        [`jaxcable.simulate_robot`][] (the scenario is the training run).
    - `gain`: the starting gain, a scalar or shape `(n,)` (one per cable).
    - `steps`: Gauss-Newton steps.
    - `ridge`: the weight of the pull towards 1, relative to the mean curvature.

    **Returns:**

    `(gain, history)`: the tuned gain (the shape of `gain`) and, per step, a dict with
    the `gain` (NumPy) and the run's `rms_mm` at it.
    """
    dtype = jnp.result_type(float, scenario.position)
    g = jnp.asarray(gain, dtype)
    shape = g.shape
    history = []
    for k in range(steps + 1):
        r, J = _residuals_and_jacobian(g, robot, scenario, real, controller)
        rms = 1e3 * float(jnp.sqrt(3.0 * jnp.mean(r**2)))
        history.append({"gain": np.asarray(g), "rms_mm": rms})
        if k == steps:
            break
        flat = g.reshape(-1)
        H = J.T @ J
        mu = ridge * jnp.trace(H) / flat.size
        eye = jnp.eye(flat.size, dtype=dtype)
        flat = flat + jnp.linalg.solve(H + mu * eye, -(J.T @ r) - mu * (flat - 1.0))
        g = flat.reshape(shape)
    return g, history
