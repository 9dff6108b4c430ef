"""Least squares over records of any length in bounded memory: the normal equations
accumulated sample by sample ([`jaxcable.StreamingLeastSquares`][]).

`jaxcable.fit` with [`jaxcable.LeastSquares`][] holds the Jacobian of every residual
(n samples x p parameters): for a robot's day at 100 Hz (8.6 million samples) that
is 8.6e6 x p floats per Jacobian, several of them alive at once. Levenberg-Marquardt
needs only J^T J (p x p), J^T r (p) and r^T r: here one forward scan of each test
carries the cable's state and its p tangents in u (forward mode, so no history is
kept), and adds each sample's residual and its gradient into those sums. Memory is
the record itself plus O(p^2): constant in the number of samples, and the time
linear in it.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Float

from .._drive import CableState, init_state, step
from .._problem import StreamingLeastSquares
from .._results import RESULTS
from .blocks import blocked_scan
from .problem import ResidualProblem, _at_sample
from .solver import KernelMethod, KernelOut, kernel_starts


# `kernel_starts` of one start: the data-scaled one (the solver is not used).
_ONE_START = KernelMethod(None, 1, "fwd", 1, 0.0)  # pyright: ignore[reportArgumentType]


class Normal(eqx.Module):
    """The normal equations of the residuals r(u), summed over every fitted sample.

    **Fields:**

    - `gram`: J^T J, shape (p, p).
    - `gradient`: J^T r, shape (p,).
    - `ssr`: r^T r (NaN where a test's simulation failed).
    """

    gram: Float[Array, "p p"]
    gradient: Float[Array, " p"]
    ssr: Float[Array, ""]


class _Carry(eqx.Module):
    state: CableState
    tangent: CableState  # d state / d u: each inexact leaf with a leading p axis
    normal: Normal


def _split(state: CableState):
    return eqx.partition(state, eqx.is_inexact_array)


def _model(problem: ResidualProblem, u):
    return eqx.combine(problem.params(u), problem.static)


def _test_normal(problem: ResidualProblem, u, index: int) -> Normal:
    """The normal equations of test `index` (force-driven) at u."""
    data = problem.data
    take = lambda x: x[index]  # noqa: E731
    cable = jax.tree_util.tree_map(take, data.cable)
    time = take(data.time)
    p = u.shape[0]
    basis = jnp.eye(p, dtype=u.dtype)
    scale = take(data.scale)

    def start(u):
        return _split(init_state(_model(problem, u), cable, time[0]))[0]

    first, rest = _split(init_state(_model(problem, u), cable, time[0]))
    tangent = jax.vmap(lambda du: jax.jvp(start, (u,), (du,))[1])(basis)

    def body(carry: _Carry, x):
        t, f, simulate, weight, measured, temp, cov = x
        here = _at_sample(cable, temp, cov)
        inexact, other = _split(carry.state)

        def advance(u, inexact):
            state = eqx.combine(inexact, other)
            new, _ = step(_model(problem, u), here, state, t, f)
            new = jax.tree_util.tree_map(
                lambda a, b: jnp.where(simulate, a, b), new, state
            )
            new_inexact, new_other = _split(new)
            return (new_inexact, new.strain * cable.length), new_other

        def along(du, ds):
            return jax.jvp(advance, (u, inexact), (du, ds), has_aux=True)

        (new_inexact, e), (d_inexact, de), new_other = jax.vmap(
            along, out_axes=(None, 0, None)
        )(basis, _split(carry.tangent)[0])
        fitted = weight > 0
        r = jnp.where(fitted, e - measured, 0.0) / scale
        dr = jnp.where(fitted, de, 0.0) / scale
        n = carry.normal
        normal = Normal(n.gram + jnp.outer(dr, dr), n.gradient + dr * r, n.ssr + r**2)
        state = eqx.combine(new_inexact, new_other)
        return _Carry(state, eqx.combine(d_inexact, new_other), normal), None

    zero = Normal(
        jnp.zeros((p, p), u.dtype), jnp.zeros((p,), u.dtype), jnp.zeros((), u.dtype)
    )
    init = _Carry(eqx.combine(first, rest), eqx.combine(tangent, rest), zero)
    xs = tuple(
        take(x)
        for x in (
            data.time,
            data.force,
            data.simulate,
            data.weight,
            data.elongation,
            data.temperature,
            data.covariate,
        )
    )
    final, _ = blocked_scan(body, init, xs, off=(2, 3))
    ok = final.state.result == RESULTS.successful
    return eqx.tree_at(
        lambda n: n.ssr, final.normal, jnp.where(ok, final.normal.ssr, jnp.nan)
    )


@eqx.filter_jit
def normal_equations(problem: ResidualProblem, u: Float[Array, " p"]) -> Normal:
    """The normal equations of every test of `problem` at u, summed (the tests must
    be force-driven: their elongation is scored)."""
    parts = [_test_normal(problem, u, i) for i in range(problem.data.num_tests)]
    return jax.tree_util.tree_map(lambda *xs: sum(xs), *parts)


class StreamOut(eqx.Module):
    """Where a streaming solve ended: `u`, its normal equations, the steps taken and
    whether it converged."""

    u: Float[Array, " p"]
    normal: Normal
    steps: int
    converged: bool


def _small(normal: Normal, u: np.ndarray, method: StreamingLeastSquares) -> bool:
    """Whether the Gauss-Newton step from `normal` is below `atol + rtol |u|` in
    every coordinate."""
    gram, gradient = np.asarray(normal.gram), np.asarray(normal.gradient)
    try:
        step = np.linalg.lstsq(gram, -gradient, rcond=None)[0]
    except np.linalg.LinAlgError:
        return False
    return bool(np.all(np.abs(step) <= method.atol + method.rtol * np.abs(u)))


def solve_streaming(
    problem: ResidualProblem, u0: Float[Array, " p"], method: StreamingLeastSquares
) -> StreamOut:
    """Levenberg-Marquardt on the accumulated normal equations from u0 (Marquardt's
    diagonal scaling; a rejected step raises the damping by 4, an accepted one lowers
    it by 3), until the step in u is below `atol + rtol |u|` in every coordinate."""
    u = jnp.asarray(u0)
    normal = normal_equations(problem, u)
    if not np.isfinite(float(normal.ssr)):
        return StreamOut(u, normal, 0, False)
    damping = method.damping
    for steps in range(1, method.max_steps + 1):
        gram, gradient = np.asarray(normal.gram), np.asarray(normal.gradient)
        diagonal = np.maximum(np.diag(gram), 1e-300)
        try:
            delta = np.linalg.solve(gram + damping * np.diag(diagonal), -gradient)
        except np.linalg.LinAlgError:
            return StreamOut(u, normal, steps, False)
        trial = u + jnp.asarray(delta, u.dtype)
        candidate = normal_equations(problem, trial)
        ssr = float(candidate.ssr)
        if np.isfinite(ssr) and ssr <= float(normal.ssr):
            u, normal = trial, candidate
            damping = max(damping / 3.0, 1e-12)
            # Converged where the next undamped (Gauss-Newton) step is small: a
            # damped step is small also far from the optimum when the damping is
            # large.
            if _small(normal, np.asarray(u), method):
                return StreamOut(u, normal, steps, True)
        else:
            damping *= 4.0
            if damping > 1e16:
                return StreamOut(u, normal, steps, False)
    return StreamOut(u, normal, method.max_steps, False)


def streaming_kernel(
    problem: ResidualProblem, u_user: Float[Array, " p"], method: StreamingLeastSquares
) -> KernelOut:
    """The fit of `problem` by `solve_streaming` from the data-scaled start, as the
    `KernelOut` of one start (its residuals from one forward scan, no Jacobian)."""
    starts, start_ok = _starts(problem, u_user)
    if not np.all(np.asarray(start_ok)):
        u = starts[0]
        return _kernel_out(
            problem, starts, start_ok, StreamOut(u, _failed(u), 0, False)
        )
    return _kernel_out(
        problem, starts, start_ok, solve_streaming(problem, starts[0], method)
    )


@eqx.filter_jit
def _starts(problem: ResidualProblem, u_user):
    return kernel_starts(problem, u_user, jax.random.key(0), _ONE_START)


def _failed(u) -> Normal:
    p = u.shape[0]
    nan = jnp.asarray(jnp.nan, u.dtype)
    return Normal(jnp.full((p, p), nan), jnp.full((p,), nan), nan)


@eqx.filter_jit
def _finish(problem: ResidualProblem, u):
    residuals = problem.residuals(u)
    return (
        residuals,
        problem.natural_flat(u),
        problem.params(u),
        jax.jacfwd(problem.natural_flat)(u),
    )


def _kernel_out(problem, starts, start_ok, end: StreamOut) -> KernelOut:
    residuals, natural, params, natural_jacobian = _finish(problem, end.u)
    ssr = jnp.sum(residuals**2)
    finite = bool(jnp.isfinite(ssr))
    result = (
        optx.RESULTS.successful
        if end.converged
        else optx.RESULTS.nonlinear_max_steps_reached
    )
    results = jax.tree_util.tree_map(lambda x: jnp.reshape(x, (1,)), result)
    return KernelOut(
        starts=starts,
        values=end.u[None],
        results=results,
        best_result=result,
        converged=jnp.asarray([end.converged and finite]),
        steps=jnp.asarray([end.steps]),
        ssr=jnp.asarray([ssr if finite else jnp.inf]),
        best=jnp.asarray(0),
        residuals=residuals,
        gram=end.normal.gram,
        natural=natural,
        params=params,
        natural_jacobian=natural_jacobian,
        start_ok=start_ok,
    )
