"""The closed loop of the robot ([`jaxcable.cdpr.simulate_robot`][], one jitted
`lax.scan`) and the comparison of compensation models over a run.

**One sample of the closed loop:**

1. the end-effector, a point mass (platform + payload), hangs where the last sample
    left it; the winch torques realise a tension distribution that keeps every cable
    taut ([`jaxcable.cdpr.tension_distribution`][], quasi-static); the load cells
    measure these forces;
2. the controller predicts each cable's elongation from its own measured force
    history ([`jaxcable.controller_step`][]) and commands the unstretched free length
    L(x_d) - gain * elongation, with L(x_d) the inverse kinematics of the desired
    position plus the fixed routing from the winch to the pulley;
3. the "real" cables stretch by their own model (other parameters, one more effect)
    under the same forces;
4. the end-effector moves to the least-squares forward kinematics of the stretched
    lengths ([`jaxcable.cdpr.forward_kinematics`][]): the position error is that minus
    x_d.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .._drive import ControllerState, LiveFiveElement, controller_init, controller_step
from .._models import AbstractCableModel, HookeModel
from .robot import NOMINAL, Robot, forward_kinematics, tension_distribution
from .scenario import Scenario


# The compensations compared besides the nominal integrated model: Hooke's law with
# its static modulus, and Piao's five-element model with its surface evaluated live.
HOOKE = HookeModel(E=NOMINAL.E1c)
FIVE_ELEMENT = LiveFiveElement()


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

    - `robot`: the [`jaxcable.cdpr.Robot`][].
    - `scenario`: the [`jaxcable.cdpr.Scenario`][].
    - `real`: the real cables' model with one parameter set per cable (leading axis
        n, e.g. [`jaxcable.cdpr.real_cables`][]).
    - `controller`: the compensation model, shared by the cables, or `None` for no
        compensation (the winches command the inverse kinematics).
    - `gain`: the share of the predicted elongation that is compensated (1: all of
        it), a scalar or one per cable; differentiable, as are the model's
        parameters.

    **Returns:**

    A [`jaxcable.cdpr.RobotRun`][].
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
            # The carry holds a controller state whenever there is a controller.
            assert carry.controller is not None
            ctrl, predicted = controller_step(
                controller, robot.cables(lengths), carry.controller, t, forces
            )
        command = lengths - gain * predicted
        # 3. The real cables stretch under the same forces.
        real_state, elongation = controller_step(
            real, robot.cables(command), carry.real, t, forces
        )
        # 4. Where the stretched cables put the end-effector.
        stretched = command + elongation - robot.routing
        position = forward_kinematics(robot, stretched, carry.position)
        new = _Carry(controller=ctrl, real=real_state, position=position)
        return new, (position, forces, elongation, predicted, command)

    xs = (scenario.time, scenario.position, scenario.payload)
    # The scan's outputs are RobotRun's fields after `time` and `desired`, in order.
    _, outputs = jax.lax.scan(body, carry, xs)
    return RobotRun(scenario.time, scenario.position, *outputs)


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
    [`jaxcable.cdpr.compensation_models`][] (or `models`, a dict of the same form).
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
