"""What the robot measures for its online estimator: the winch encoders (the
unstretched free lengths paid out), the load cells (passed to
[`jaxcable.cdpr.OnlineEstimator`][]`.step` as forces) and occasional position fixes
of the end-effector ([`jaxcable.cdpr.Fix`][]: a camera, a laser tracker, a touch
probe at the drop-off point), and the position that a set of predicted elongations
implies ([`jaxcable.cdpr.fix_prediction`][]), the measurement model of a fix."""

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float

from .._arrays import field_array
from .robot import Robot, forward_kinematics


class Fix(eqx.Module):
    """A position fix of the end-effector, taken at a control sample after the winches
    reached their commanded lengths.

    **Fields:**

    - `position`: the measured end-effector position, m, shape `(3,)`.
    - `lengths`: the encoders' unstretched free lengths (winch to end-effector) at
        the fix, m, shape `(n,)`.
    - `valid`: whether there is a fix at this sample (a scalar boolean): a robot
        passes a `Fix` at every sample, with `valid=False` between fixes, so that one
        compiled step serves both (`Fix.missing`).
    """

    position: Float[Array, " 3"] = eqx.field(converter=field_array)
    lengths: Float[Array, " n"] = eqx.field(converter=field_array)
    valid: Bool[Array, ""] = eqx.field(converter=jnp.asarray, default=True)

    @classmethod
    def missing(cls, lengths: Float[ArrayLike, " n"]) -> "Fix":
        """No fix at this sample: a `Fix` with `valid=False` (its position is
        ignored).

        **Arguments:**

        - `lengths`: the encoders' free lengths, m, shape `(n,)` (any values of this
            shape and dtype: only the shape is used).

        **Returns:**

        A [`jaxcable.cdpr.Fix`][].
        """
        lengths = jnp.asarray(lengths)
        return cls(jnp.zeros(3, lengths.dtype), lengths, jnp.asarray(False))


def fix_prediction(
    robot: Robot,
    lengths: Float[ArrayLike, " n"],
    elongation: Float[ArrayLike, " n"],
    guess: Float[ArrayLike, " 3"],
) -> tuple[Float[Array, " 3"], Float[Array, "3 n"]]:
    """The end-effector position that the encoders' lengths and a set of predicted
    elongations imply, and its derivative with respect to the elongations.

    The stretched pulley-to-end-effector lengths are `lengths + elongation -
    robot.routing`; the position is their least-squares forward kinematics
    ([`jaxcable.cdpr.forward_kinematics`][]), the same map that places the simulated
    robot's end-effector. A fix is compared with this position rather than turned into
    eight measured elongations (the geometric lengths minus the encoders'): the
    cables' stretched lengths do not close exactly on one point (unequal
    stretches), and their least-squares residual, millimetres on this robot, would
    enter such elongations as an error that no parameter explains.

    **Arguments:**

    - `robot`: the [`jaxcable.cdpr.Robot`][].
    - `lengths`: the encoders' unstretched free lengths, m, shape `(n,)`.
    - `elongation`: the predicted elongations, m, shape `(n,)`.
    - `guess`: where the Gauss-Newton iterations start, m (e.g. the fix itself).

    **Returns:**

    `(position, jacobian)`: the position, m, shape `(3,)`, and d position / d
    elongation, shape `(3, n)` (forward-mode through the iterations).
    """
    lengths = jnp.asarray(lengths)
    guess = jnp.asarray(guess, lengths.dtype)

    def position(elongation):
        stretched = lengths + elongation - robot.routing
        return forward_kinematics(robot, stretched, guess)

    elongation = jnp.asarray(elongation, lengths.dtype)
    x, linear = jax.linearize(position, elongation)
    jacobian = jax.vmap(linear, out_axes=1)(jnp.eye(lengths.shape[0], dtype=x.dtype))
    return x, jacobian
