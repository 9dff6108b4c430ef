"""One least-squares solve as a value that can stop and go on: optimistix's iteration
(`optx.least_squares`) split into `lane_init`, `lane_advance` and `lane_finish`.

A solve of `jaxcable.fit` runs the three in one program (`solve`). `jaxcable.fit_each`
runs many solves as the lanes of one vmapped loop, one step at a time: after each
step, a lane whose solve has stopped takes the next solve waiting (`_fit/queue.py`,
which finishes a stored solve with `finish_at`), so that solves that converged in 20
steps do not wait, lane by lane, for the one that takes 256. Each lane's iterates are those of its own solve,
step for step: the same state, the same steps, the same test of termination as
optimistix's `iterative_solve` (its cond, body and the max-steps result).
"""

from collections.abc import Callable
from typing import Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Bool, Float, Int, PyTree

from .problem import ResidualProblem


# The solver's residuals are r / sqrt(DAMPING * sum(e_measured^2)). A modulus that
# carries all the elongation has |dr / dlog E|^2 ~ sum(e^2), the largest curvature
# scale of the problem, so Levenberg-Marquardt's initial damping (lambda = 1 in the
# solver's units) is DAMPING times it: nearly a Gauss-Newton step, which the trust
# region shortens where the model is not yet linear (Marquardt's lambda_0 = tau max
# diag(J^T J), with a small tau for a start believed close; 1e-4 took the fewest
# steps over the recovery tests' models).
DAMPING = 1e-4


class Lane(eqx.Module):
    """A least-squares solve between steps: what optimistix's loop carries.

    **Fields:**

    - `y`: the current iterate, in u.
    - `num_steps`: the solver steps taken.
    - `state`: the solver's state, its arrays only (the rest is rebuilt, the same,
        by `solver.init` wherever the lane goes on).
    - `terminate`: whether the solver said to stop.
    - `result`: the solver's result so far.
    """

    y: Float[Array, " p"]
    num_steps: Int[Array, ""]
    state: PyTree
    terminate: Bool[Array, ""]
    result: optx.RESULTS

    @property
    def final_result(self) -> optx.RESULTS:
        """The solve's result once it stopped: `nonlinear_max_steps_reached` where
        it ran out of steps (optimistix's `iterative_solve`)."""
        return optx.RESULTS.where(
            (self.result == optx.RESULTS.successful) & ~self.terminate,
            optx.RESULTS.nonlinear_max_steps_reached,
            self.result,
        )

    def running(self, max_steps: int) -> Bool[Array, ""]:
        """Whether the solve takes another step (optimistix's loop condition)."""
        going = ~self.terminate & (self.result == optx.RESULTS.successful)
        return going & (self.num_steps < max_steps)


def residuals_and_jacobian(
    problem: ResidualProblem, u: Float[Array, " p"], jac: Literal["fwd", "bwd"]
) -> tuple[Float[Array, " residuals"], Float[Array, "residuals p"]]:
    """The flat residuals (m) and their Jacobian in u, in one differentiated scan:
    forward mode carries the p tangents through the scan together, reverse mode one
    cotangent per residual."""

    jacobian, r, _ = _differentiated(
        lambda u: (jnp.ravel(problem.residuals(u)), None), u, jac
    )
    return r, jacobian


def _differentiated(residuals, u, jac: Literal["fwd", "bwd"]):
    """`(jacobian, r, aux)` of `residuals(u) -> (r, aux)`: the Jacobian of r in u,
    with r and aux from the same differentiated pass (no second simulation)."""

    def flat(u):
        r, aux = residuals(u)
        return r, (r, aux)

    differentiate = jax.jacfwd if jac == "fwd" else jax.jacrev
    jacobian, (r, aux) = differentiate(flat, has_aux=True)(u)
    return jacobian, r, aux


def _zero_tangent(x):
    x = jnp.asarray(x)
    if jnp.issubdtype(x.dtype, jnp.inexact):
        return jnp.zeros_like(x)
    return np.zeros(x.shape, dtype=jax.dtypes.float0)


def with_jacobian_jvp(
    residuals: Callable[[Float[Array, " p"]], tuple[Float[Array, " n"], PyTree]],
    jac: Literal["fwd", "bwd"] = "fwd",
    scale: float | Float[Array, ""] = 1.0,
) -> Callable[[Float[Array, " p"]], tuple[Float[Array, " n"], PyTree]]:
    """Wrap `residuals(u) -> (r, aux)` for an optimistix least-squares solver: the
    wrapped function returns `(r / scale, aux)`, and its JVP is a product with the
    Jacobian computed together with r, in one differentiated pass.

    Optimistix linearises the residual function and then materialises, transposes
    and applies the linearisation. Through a simulation's scan each of those is its
    own copy of the scan in the compiled program (a compile time about twice as long
    for the calibration's program); with this rule they are products with one dense
    (n, p) matrix, and the scan is differentiated once per step. `aux` (anything the
    residuals computed on the way, e.g. the simulated values) has a zero tangent:
    a solver's state then holds it at the returned point without a further
    simulation.

    **Arguments:**

    - `residuals`: u (shape (p,)) -> (flat residuals (n,), aux).
    - `jac`: the Jacobian's mode, `"fwd"` (p tangents through the scan together) or
        `"bwd"` (one cotangent per residual).
    - `scale`: the residuals and the Jacobian are divided by it.

    **Returns:**

    The wrapped function u -> `(r / scale, aux)`.
    """

    @jax.custom_jvp
    def wrapped(u):
        r, aux = residuals(u)
        return r / scale, aux

    @wrapped.defjvp
    def _(primals, tangents):
        (u,), (du,) = primals, tangents
        jacobian, r, aux = _differentiated(residuals, u, jac)
        tangent_aux = jax.tree.map(_zero_tangent, aux)
        return (r / scale, aux), ((jacobian @ du) / scale, tangent_aux)

    return wrapped


# A finished solve: `(u, result, steps, residuals, jacobian)`.
Solved = tuple[
    Float[Array, " p"],
    optx.RESULTS,
    Int[Array, ""],
    Float[Array, " residuals"],
    Float[Array, "residuals p"],
]


def _residual_fn(problem: ResidualProblem, jac: Literal["fwd", "bwd"]):
    """fn(u, args) -> (scaled residuals, None) for the solver, and the scale."""
    data = problem.data
    scale = jnp.sqrt(DAMPING * jnp.sum((data.measured / data.scale[:, None]) ** 2))
    fn = with_jacobian_jvp(
        lambda u: (jnp.ravel(problem.residuals(u)), None), jac, scale
    )
    return (lambda u, args: (fn(u)[0], None)), scale


def _solver_state(fn, solver: optx.AbstractGaussNewton, y):
    """The solver's initial state at y, and its static part."""
    f_struct = jax.eval_shape(lambda u: fn(u, None)[0], y)
    state = solver.init(fn, y, None, {}, f_struct, None, frozenset())
    return state, eqx.partition(state, eqx.is_array)[1]


def _stop_and_result(fn, solver, y, state):
    terminate, result = solver.terminate(fn, y, None, {}, state, frozenset())
    finite = jnp.all(jnp.isfinite(y))
    return terminate, optx.RESULTS.where(finite, result, optx.RESULTS.nonfinite)


def lane_init(
    problem: ResidualProblem,
    u0: Float[Array, " p"],
    solver: optx.AbstractGaussNewton,
    jac: Literal["fwd", "bwd"],
) -> Lane:
    """A solve from `u0`, before its first step (no residual is evaluated)."""
    fn, _ = _residual_fn(problem, jac)
    y = jnp.asarray(u0, jnp.result_type(u0, float))
    state, _ = _solver_state(fn, solver, y)
    terminate, result = _stop_and_result(fn, solver, y, state)
    dynamic = eqx.partition(state, eqx.is_array)[0]
    return Lane(y, jnp.array(0), dynamic, terminate, result)


def lane_advance(
    problem: ResidualProblem,
    lane: Lane,
    solver: optx.AbstractGaussNewton,
    jac: Literal["fwd", "bwd"],
    max_steps: int,
    chunk: int | None = None,
) -> Lane:
    """`lane` after at most `chunk` more steps (None: to its end), never beyond
    `max_steps` in all."""
    fn, _ = _residual_fn(problem, jac)
    _, static = _solver_state(fn, solver, lane.y)
    limit = (
        max_steps if chunk is None else jnp.minimum(lane.num_steps + chunk, max_steps)
    )

    def body(lane: Lane) -> Lane:
        state = eqx.combine(lane.state, static)
        y, state, _ = solver.step(fn, lane.y, None, {}, state, frozenset())
        # optimistix tests termination at the iterate before the step's.
        terminate, result = _stop_and_result(fn, solver, lane.y, state)
        dynamic = eqx.partition(state, eqx.is_array)[0]
        return Lane(y, lane.num_steps + 1, dynamic, terminate, result)

    return jax.lax.while_loop(
        lambda lane: lane.running(max_steps) & (lane.num_steps < limit), body, lane
    )


def lane_finish(
    problem: ResidualProblem,
    lane: Lane,
    solver: optx.AbstractGaussNewton,
    jac: Literal["fwd", "bwd"],
    max_steps: int,
) -> Solved:
    """The end of a solve: `(u, result, steps, residuals, jacobian)`, the solution,
    the solver's result (`nonlinear_max_steps_reached` where it ran out of steps),
    its steps, and the flat residuals (m) and their Jacobian in u at the solution,
    from the solver's state (no further simulation)."""
    fn, scale = _residual_fn(problem, jac)
    _, static = _solver_state(fn, solver, lane.y)
    state = eqx.combine(lane.state, static)
    result = lane.final_result
    y, _, _ = solver.postprocess(fn, lane.y, None, None, {}, state, frozenset(), result)
    # A Gauss-Newton-type solver's state holds the residuals and the linearised
    # residual function at the returned (last accepted) point; with the rule of
    # `solver.with_jacobian_jvp` its matrix is the Jacobian, with no further scan.
    f_info = state.f_info
    return (
        y,
        result,
        lane.num_steps,
        f_info.residual * scale,
        f_info.jac.as_matrix() * scale,
    )


def finish_at(
    problem: ResidualProblem, lane: Lane, jac: Literal["fwd", "bwd"]
) -> Solved:
    """`lane_finish` of a lane whose solver state was not kept: the residuals and
    their Jacobian evaluated again at its iterate (where the state held them: the
    last accepted point is the iterate; before any step, zeros, as the state's)."""
    result = lane.final_result
    r, jacobian = residuals_and_jacobian(problem, lane.y, jac)
    stepped = lane.num_steps > 0
    return (
        lane.y,
        result,
        lane.num_steps,
        jnp.where(stepped, r, 0.0),
        jnp.where(stepped, jacobian, 0.0),
    )


def solve(
    problem: ResidualProblem,
    u0: Float[Array, " p"],
    solver: optx.AbstractGaussNewton,
    max_steps: int,
    jac: Literal["fwd", "bwd"],
) -> Solved:
    """One least-squares solve from `u0` to its end (traceable; `fit_kernel` maps it
    over the starts, `benchmarks/fit.py` times it alone).

    **Arguments:**

    - `problem`: the least-squares problem.
    - `u0`: the start in u.
    - `solver`: an optimistix Gauss-Newton-type solver.
    - `max_steps`: solver steps.
    - `jac`: the Jacobian's mode, `"fwd"` or `"bwd"`.

    **Returns:**

    `(u, result, steps, residuals, jacobian)`: the solution, the solver's result, its
    steps, and the flat residuals (m) and their Jacobian in u at the solution.
    """
    lane = lane_init(problem, u0, solver, jac)
    lane = lane_advance(problem, lane, solver, jac, max_steps)
    return lane_finish(problem, lane, solver, jac, max_steps)
