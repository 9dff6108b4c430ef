"""Differentiating through the robot's closed loop: the mean squared position error
as a function of the compensation gain and the controller's parameters
([`jaxcable.cdpr.position_loss`][]), the errors' Jacobian
([`jaxcable.cdpr.errors_and_jacobian`][]) and Gauss-Newton tuning of the gains
([`jaxcable.cdpr.tune_gain`][])."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._checks import require_int, require_number
from .._models import AbstractCableModel
from .robot import Robot
from .run import simulate_robot
from .scenario import Scenario


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
        run = simulate_robot(robot, scenario, real, controller, gain)
        return run.error.reshape(-1)

    def with_residuals(flat):
        r = residuals(flat.reshape(gain.shape))
        return r, r

    # One differentiated run gives both: the residuals are its primal.
    J, r = jax.jacfwd(with_residuals, has_aux=True)(gain.reshape(-1))
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


class GainTuning(eqx.Module):
    """How [`jaxcable.cdpr.tune_gain`][] tunes: Gauss-Newton steps with a ridge.

    **Fields:**

    - `steps`: Gauss-Newton steps (default 2), >= 0.
    - `ridge`: the weight of the pull towards a gain of 1, relative to the mean
        curvature (default 0.03), >= 0.
    """

    steps: int = eqx.field(default=2, static=True)
    ridge: float = eqx.field(default=0.03, static=True)

    def __check_init__(self):
        require_int("steps", self.steps, low=0)
        require_number("ridge", self.ridge, low=0)


def tune_gain(
    robot: Robot,
    scenario: Scenario,
    real: AbstractCableModel,
    controller: AbstractCableModel,
    gain: Float[ArrayLike, "*n"] = 1.0,
    method: "GainTuning | None" = None,
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
        [`jaxcable.cdpr.simulate_robot`][] (the scenario is the training run).
    - `gain`: the starting gain, a scalar or shape `(n,)` (one per cable).
    - `method`: a [`jaxcable.cdpr.GainTuning`][] (default `GainTuning()`: 2 steps,
        ridge 0.03).

    **Returns:**

    `(gain, history)`: the tuned gain (the shape of `gain`) and, per step, a dict with
    the `gain` (NumPy) and the run's `rms_mm` at it.
    """
    method = GainTuning() if method is None else method
    if not isinstance(method, GainTuning):
        raise TypeError(
            f"`method` must be a jaxcable.cdpr.GainTuning, got {type(method).__name__}."
        )
    steps, ridge = method.steps, method.ridge
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
