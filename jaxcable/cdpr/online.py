"""The robot's closed loop compensated by its online estimator
([`jaxcable.cdpr.simulate_online`][], one jitted `lax.scan`): the loop of
[`jaxcable.cdpr.simulate_robot`][] whose predicted elongations come from a
[`jaxcable.cdpr.OnlineEstimator`][] fed with imperfect signals
([`jaxcable.cdpr.Sensors`][]: noisy or drifting load cells, a stuck one, noisy and
sparse position fixes with dropouts)."""

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float

from .._arrays import field_array
from .._drive import ControllerState, controller_init, controller_step
from .._models import AbstractCableModel
from .._results import RESULTS
from .estimator import EstimatorState, OnlineEstimator
from .robot import forward_kinematics, tension_distribution
from .run import RobotRun
from .scenario import Scenario
from .signals import Fix


class Sensors(eqx.Module):
    """What the robot's sensors get wrong, sample by sample (T samples, n cables; all
    SI). Draw the errors with one's own keys: the loop adds them.

    **Fields:**

    - `fix`: whether a position fix is taken at the end of each sample, `(T,)`
        booleans (every 10 s, with dropouts: `False`).
    - `fix_error`: the fixes' errors, m, `(T, 3)`.
    - `force_error`: the load cells' errors (noise, drift), N, `(T, n)`.
    - `stuck`: where a load cell repeats its last reading, `(T, n)` booleans.
    """

    fix: Bool[Array, " T"] = eqx.field(converter=jnp.asarray)
    fix_error: Float[Array, "T 3"] = eqx.field(converter=field_array)
    force_error: Float[Array, "T n"] = eqx.field(converter=field_array)
    stuck: Bool[Array, "T n"] = eqx.field(converter=jnp.asarray)

    @classmethod
    def exact(cls, scenario: Scenario, num_cables: int, every: int = 10) -> "Sensors":
        """Exact signals with a fix every `every` samples (none at the start).

        **Arguments:**

        - `scenario`: the [`jaxcable.cdpr.Scenario`][] (its number of samples).
        - `num_cables`: n.
        - `every`: samples between fixes (>= 1).

        **Returns:**

        A [`jaxcable.cdpr.Sensors`][].
        """
        if not (isinstance(every, int) and every >= 1):
            raise ValueError(f"`every` must be an integer >= 1, got {every!r}.")
        T = scenario.time.shape[0]
        k = jnp.arange(T)
        dtype = scenario.time.dtype
        return cls(
            fix=(k % every == 0) & (k > 0),
            fix_error=jnp.zeros((T, 3), dtype),
            force_error=jnp.zeros((T, num_cables), dtype),
            stuck=jnp.zeros((T, num_cables), bool),
        )


class OnlineRun(eqx.Module):
    """A run compensated by the online estimator.

    **Fields:**

    - `run`: the [`jaxcable.cdpr.RobotRun`][] (its `forces` are the load cells'
        readings, errors included; `predicted` the estimator's).
    - `result`: the estimator's [`jaxcable.RESULTS`][] at each sample, `(T,)`.
    - `log_parameters`: the estimates' logs at each sample, `(T, n, p)`.
    - `state`: the final [`jaxcable.cdpr.EstimatorState`][].
    """

    run: RobotRun
    result: RESULTS
    log_parameters: Float[Array, "T n p"]
    state: EstimatorState


class _Carry(eqx.Module):
    estimator: EstimatorState
    real: ControllerState
    position: Float[Array, " 3"]
    command: Float[Array, " n"]
    reading: Float[Array, " n"]


def simulate_online(
    estimator: OnlineEstimator,
    scenario: Scenario,
    real: AbstractCableModel,
    sensors: Sensors,
    gain: Float[ArrayLike, ""] = 1.0,
) -> OnlineRun:
    """Run the closed loop with the online estimator's compensation (one jitted
    `lax.scan`).

    Each sample: the tensions that hold the end-effector (the load cells read them
    with `sensors`' errors); the estimator updates with the last sample's fix (if
    any) and predicts each cable's elongation from the readings at the desired
    position's free lengths; the winches command those lengths minus `gain` times
    the prediction; the real cables stretch under the true tensions; the
    end-effector moves to the forward kinematics of the stretched lengths, where
    the fix (if any) finds it, with its error.

    **Arguments:**

    - `estimator`: the [`jaxcable.cdpr.OnlineEstimator`][] (its `robot` is the
        robot's).
    - `scenario`: the [`jaxcable.cdpr.Scenario`][].
    - `real`: the real cables' model, one parameter set per cable (leading axis n,
        e.g. [`jaxcable.cdpr.real_cables`][]).
    - `sensors`: the [`jaxcable.cdpr.Sensors`][] of this run (T samples).
    - `gain`: the share of the predicted elongation compensated.

    **Returns:**

    An [`jaxcable.cdpr.OnlineRun`][].
    """
    T, n = scenario.time.shape[0], estimator.robot.num_cables
    if sensors.force_error.shape != (T, n) or sensors.fix.shape != (T,):
        raise ValueError(
            f"`sensors` must describe {T} samples of {n} cables, got force_error "
            f"{sensors.force_error.shape} and fix {sensors.fix.shape}."
        )
    dtype = jnp.result_type(float, scenario.position)
    gain = jnp.broadcast_to(jnp.asarray(gain, dtype), (n,))
    return _simulate_online(estimator, scenario, real, sensors, gain)


@eqx.filter_jit
def _simulate_online(estimator, scenario, real, sensors, gain) -> OnlineRun:
    robot = estimator.robot
    x0, t0 = scenario.position[0], scenario.time[0]
    lengths0 = robot.free_lengths(x0)
    carry = _Carry(
        estimator=estimator.init(lengths0, x0, t0),
        real=controller_init(real, robot.cables(lengths0), t0, per_cable=True),
        position=x0,
        command=lengths0,
        reading=jnp.zeros_like(lengths0),
    )

    def body(carry: _Carry, sample):
        t, x_d, payload, fix_here, fix_error, force_error, stuck = sample
        forces = tension_distribution(
            robot, carry.position, robot.platform_mass + payload
        )
        reading = jnp.where(stuck, carry.reading, forces + force_error)
        # The fix of the end of the last sample: where its command put the robot.
        fix = Fix(carry.position + fix_error, carry.command, fix_here)
        lengths = robot.free_lengths(x_d)
        state, predicted = estimator.step(carry.estimator, t, reading, lengths, fix)
        command = lengths - gain * predicted
        real_state, elongation = controller_step(
            real, robot.cables(command), carry.real, t, forces
        )
        stretched = command + elongation - robot.routing
        position = forward_kinematics(robot, stretched, carry.position)
        new = _Carry(state, real_state, position, command, reading)
        outputs = (position, reading, elongation, predicted, command)
        return new, (outputs, state.result, state.log_parameters)

    # A fix at sample k is read by the step of sample k + 1.
    fix_next = jnp.concatenate([jnp.zeros(1, bool), sensors.fix[:-1]])
    error_next = jnp.concatenate(
        [jnp.zeros((1, 3), sensors.fix_error.dtype), sensors.fix_error[:-1]]
    )
    xs = (
        scenario.time,
        scenario.position,
        scenario.payload,
        fix_next,
        error_next,
        sensors.force_error,
        sensors.stuck,
    )
    final, (outputs, result, log_parameters) = jax.lax.scan(body, carry, xs)
    run = RobotRun(scenario.time, scenario.position, *outputs)
    return OnlineRun(run, result, log_parameters, final.estimator)
