"""The compiled fit kernel: a data-derived start, multi-start Levenberg-Marquardt with
Jacobians through the simulation's scan, and the Jacobian at the optimum.
"""

import math
from collections.abc import Callable
from typing import Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.random as jr
import lineax as lx
import numpy as np
import optimistix as optx
from jaxtyping import Array, Bool, Float, PRNGKeyArray, PyTree

from .lanes import residuals_and_jacobian, solve, with_jacobian_jvp
from .problem import ResidualProblem


__all__ = ["residuals_and_jacobian", "solve", "with_jacobian_jvp"]


class LevenbergMarquardt(optx.AbstractGaussNewton):
    """Levenberg-Marquardt: optimistix's damped Newton descent in a classical trust
    region, with the textbook cut-offs (Nocedal & Wright, Algorithm 4.1: shrink the
    step by 4 below a ratio of actual to predicted reduction of 1/4, grow it above
    3/4; here by 5). `optx.LevenbergMarquardt`'s constants (grow by 3.5 only above
    0.99) took about twice the steps on the recovery tests' fits, where parameter
    correlations keep the ratio below 0.99 while the damping is still too strong.

    With `ftol > 0` (default 0: off) it also stops, as converged, after an accepted
    step that lowered the sum of squares by less than `ftol` of it (scipy's `ftol`
    test; the diagnosis's fits use it).

    The damped step is solved by Cholesky on the normal equations (J^T J + lambda I,
    p x p) rather than by QR of the tall (n + p, p) matrix: LAPACK's QR of a tall
    matrix, through a multi-threaded OpenBLAS on a loaded machine, can cost several
    Jacobians' worth per step (its threads spin).
    Squaring the condition number is harmless here: lambda > 0 bounds it, the
    parameters are log-scaled, and the fit runs in float64 (a float32 fit of a
    poorly identified problem may fail the solve; `throw=False` then reports it)."""

    rtol: float
    atol: float
    ftol: float = 0.0
    norm: Callable = optx.max_norm
    # optimistix's own solvers override its AbstractVars so; pyright wants the same type.
    descent: optx.DampedNewtonDescent = optx.DampedNewtonDescent(  # pyright: ignore[reportIncompatibleVariableOverride]
        linear_solver=lx.Normal(lx.Cholesky())
    )
    search: optx.ClassicalTrustRegion = optx.ClassicalTrustRegion(  # pyright: ignore[reportIncompatibleVariableOverride]
        high_cutoff=0.75, low_cutoff=0.25, high_constant=5.0, low_constant=0.25
    )
    verbose: Callable = lambda **kwargs: None

    def step(self, fn, y, args, options, state, tags):
        """optimistix's Gauss-Newton step, which also stops before evaluating a
        proposal that would pass its own convergence test.

        optimistix tests convergence (`optx.cauchy_termination`: the change of y and
        of the residuals both below atol + rtol |.|) on a step already taken, so a
        converged solve paid one more residual-and-Jacobian evaluation (about 2.5
        forward simulations) only to confirm it: 10-30 % of the fits' steps. Here the
        same test is also applied, right after a step is accepted, to the next
        proposal: its y change and its residuals' change as predicted by the
        Jacobian just computed (J dy). When both are below tolerance the solve stops
        at the accepted point, which is then the solution and where the returned
        residuals and Jacobian were evaluated. The proposal's damping is then at most
        that of the accepted step, so a small proposal is a small Gauss-Newton step,
        not a step shrunk by a rejection.
        """
        y, new, aux = super().step(fn, y, args, options, state, tags)
        accepted = new.num_steps_since_acceptance == 0
        # The fit's y and residuals are flat arrays.
        f = new.f_info.residual
        dy = new.y_eval - y
        df = new.f_info.jac.mv(dy)
        small_y = self.norm(jnp.abs(dy) / (self.atol + self.rtol * jnp.abs(y))) < 1
        small_f = self.norm(jnp.abs(df) / (self.atol + self.rtol * jnp.abs(f))) < 1
        stop = accepted & small_y & small_f & jnp.all(jnp.isfinite(f))
        if self.ftol > 0:
            # scipy's ftol test: an accepted step (after the start's own
            # evaluation) that lowered the SSR by less than ftol of it. A parameter
            # drifting along a flat valley (an effect the data do not show, its
            # size creeping towards 0 on a log scale) otherwise runs to max_steps.
            before = jnp.sum(state.f_info.residual**2)
            after = jnp.sum(f**2)
            stalled = (state.num_accepted_steps >= 1) & (
                before - after <= self.ftol * after
            )
            stop = stop | (accepted & stalled & jnp.all(jnp.isfinite(f)))
        return y, eqx.tree_at(lambda s: s.terminate, new, new.terminate | stop), aux


# Secant iterations of the data-derived start.
_SECANT_ITERATIONS = 4
# The data-derived stiffness factor stays within [1 / _SECANT_RANGE, _SECANT_RANGE].
_SECANT_RANGE = 30.0


class _SecantCarry(eqx.Module):
    """The secant iteration's carry: the current log stiffness factor, and the best
    one so far with its loss."""

    log_c: Float[Array, ""]
    best_log_c: Float[Array, ""]
    best_loss: Float[Array, ""]


def _data_derived_start(
    problem: ResidualProblem, u_user: Float[Array, " p"]
) -> tuple[Float[Array, " p"], Bool[Array, " tests"]]:
    """The user's start with every stiffness-like parameter scaled to fit the data.

    Every stiffness-like fitted parameter is multiplied by c**k (for the linear models
    this divides every strain by exactly c). The best c in the least-squares sense
    follows from a secant (closed-form) fit: the multiplier
    g = <e_model, e_measured> / <e_model, e_model> of the model's elongation is 1 / c
    for a linear model, and a few such updates converge for the nonlinear ones. Each
    iterate's loss is evaluated and the best kept, so the start never gets worse than
    the user's. The first iterate (c = 1) is the user's start.

    **Returns:**

    `(u_start, start_ok)`: the start, and whether the user's start simulates finitely
    on each test.
    """
    layout = problem.layout
    dtype = u_user.dtype
    power = problem.reduce(
        jnp.concatenate(
            [jnp.full((s,), k) for s, k in zip(layout.sizes, layout.stiffness)]
        ).astype(dtype)
    )
    data = problem.data
    measured = data.measured / data.scale[:, None]
    # A stiffer model lengthens less under a force (the elongation scales as 1 / c)
    # and pulls harder at an elongation (the force scales as c).
    scored_force = np.array([d.scores_force for d in data.drive])
    iterations = _SECANT_ITERATIONS if any(k != 0 for k in layout.stiffness) else 1
    limit = math.log(_SECANT_RANGE)

    def secant(carry: _SecantCarry, _) -> tuple[_SecantCarry, Bool[Array, " tests"]]:
        r = problem.residuals(u_user + power * carry.log_c)
        loss = jnp.sum(r**2)
        better = jnp.isfinite(loss) & (loss < carry.best_loss)
        model = (r + measured) * data.weight
        steps = []
        for tests, sign in ((~scored_force, -1.0), (scored_force, 1.0)):
            if tests.any():
                m, e = model[tests], measured[tests]
                g = jnp.sum(m * e) / jnp.sum(m**2)
                ok = jnp.isfinite(g) & (g > 0)
                steps.append(jnp.where(ok, sign * jnp.log(jnp.where(ok, g, 1.0)), 0.0))
        step = sum(steps) / len(steps)
        new = _SecantCarry(
            log_c=jnp.clip(carry.log_c + step, -limit, limit),
            best_log_c=jnp.where(better, carry.log_c, carry.best_log_c),
            best_loss=jnp.where(better, loss, carry.best_loss),
        )
        return new, jnp.all(jnp.isfinite(r), axis=1)

    zero = jnp.zeros((), dtype)
    init = _SecantCarry(zero, zero, jnp.asarray(jnp.inf, dtype))
    final, finite = jax.lax.scan(secant, init, None, length=iterations)
    return u_user + power * final.best_log_c, finite[0]


class KernelMethod(eqx.Module):
    """How the fit kernel solves: a `jaxcable.LeastSquares` resolved for one
    problem (its solver built, its Jacobian mode chosen).

    **Fields:**

    - `solver`: an optimistix Gauss-Newton-type solver.
    - `max_steps`: solver steps per start.
    - `jac`: the Jacobian's mode, `"fwd"` or `"bwd"`.
    - `num_starts`: the number of starts (the data-derived one, then perturbed ones).
    - `spread`: the standard deviation of the perturbations in u.
    """

    solver: optx.AbstractGaussNewton
    max_steps: int = eqx.field(static=True)
    jac: Literal["fwd", "bwd"] = eqx.field(static=True)
    num_starts: int = eqx.field(static=True)
    spread: float = eqx.field(static=True)


class KernelOut(eqx.Module):
    """What the fit kernel returns.

    **Fields:**

    - `starts`: the starts in u, the data-derived one first.
    - `values`: the solution in u of each start.
    - `results`: the solver's result of each start.
    - `best_result`: the solver's result of the chosen start.
    - `converged`: whether each start converged to finite residuals.
    - `steps`: the solver steps of each start.
    - `ssr`: the sum of squared residuals of each start, m^2 (inf where not finite).
    - `best`: the index of the chosen start.
    - `residuals`: the residuals at the chosen optimum, m.
    - `gram`: J^T J at the chosen optimum, J the Jacobian of the residuals in u.
    - `natural`: the natural values at the chosen optimum, laid out as u.
    - `params`: the model's inexact-array fields at the chosen optimum.
    - `natural_jacobian`: dx/du at the chosen optimum.
    - `start_ok`: whether the user's start simulates finitely on each test.
    """

    starts: Float[Array, "starts p"]
    values: Float[Array, "starts p"]
    results: optx.RESULTS
    best_result: optx.RESULTS
    converged: Bool[Array, " starts"]
    steps: Float[Array, " starts"]
    ssr: Float[Array, " starts"]
    best: Float[Array, ""]
    residuals: Float[Array, "tests samples"]
    gram: Float[Array, "p p"]
    natural: Float[Array, " p"]
    params: PyTree
    natural_jacobian: Float[Array, "p p"]
    start_ok: Bool[Array, " tests"]


@eqx.filter_jit
def fit_kernel(
    problem: ResidualProblem,
    u_user: Float[Array, " p"],
    key: PRNGKeyArray,
    method: KernelMethod,
) -> KernelOut:
    """The whole fit, compiled: the data-derived start, `method.num_starts` least-squares
    solves and the chosen optimum (see [`jaxcable.fit`][]).

    **Arguments:**

    - `problem`: the least-squares problem.
    - `u_user`: the user's start in u.
    - `key`: the key of the start perturbations.
    - `method`: the `KernelMethod` (solver, steps, Jacobian mode, starts, spread).

    **Returns:**

    A `KernelOut`.
    """
    starts, start_ok = kernel_starts(problem, u_user, key, method)
    solver, max_steps, jac = method.solver, method.max_steps, method.jac
    # The starts in lockstep (one vmapped solve, as long as the slowest start): the
    # scans of a fit are bound by their per-sample cost, not by the batch, so the
    # starts together take less time than one after the other (`lax.map`), for the
    # same compile time.
    solved = jax.vmap(lambda u0: solve(problem, u0, solver, max_steps, jac))(starts)
    return kernel_choose(problem, starts, start_ok, solved)


def kernel_starts(
    problem: ResidualProblem,
    u_user: Float[Array, " p"],
    key: PRNGKeyArray,
    method: KernelMethod,
) -> tuple[Float[Array, "starts p"], Bool[Array, " tests"]]:
    """The starts of a fit in u, the data-derived one first, then `num_starts - 1`
    perturbations of it; and whether the user's start simulates on each test."""
    u_start, start_ok = _data_derived_start(problem, u_user)
    shape = (method.num_starts - 1, u_user.shape[0])
    noise = method.spread * jr.normal(key, shape, u_user.dtype)
    return jnp.concatenate([u_start[None], u_start[None] + noise]), start_ok


def kernel_choose(
    problem: ResidualProblem,
    starts: Float[Array, "starts p"],
    start_ok: Bool[Array, " tests"],
    solved: tuple,
) -> KernelOut:
    """The `KernelOut` of a fit from its starts' solves (`solved`: `lanes.solve`'s
    outputs, stacked over the starts): the best converged start (else the best
    finite one) and the statistics' inputs at it."""
    values, results, steps, r, jacobian = solved
    ssr = jnp.sum(r**2, axis=1)
    ssr = jnp.where(jnp.isfinite(ssr), ssr, jnp.inf)
    converged = (results == optx.RESULTS.successful) & jnp.isfinite(ssr)
    best = jnp.where(
        jnp.any(converged),
        jnp.argmin(jnp.where(converged, ssr, jnp.inf)),
        jnp.argmin(ssr),
    )
    u_best = values[best]
    return KernelOut(
        starts=starts,
        values=values,
        results=results,
        best_result=jax.tree_util.tree_map(lambda x: x[best], results),
        converged=converged,
        steps=steps,
        ssr=ssr,
        best=best,
        residuals=jnp.reshape(r[best], problem.data.time.shape),
        gram=jacobian[best].T @ jacobian[best],
        natural=problem.natural_flat(u_best),
        params=problem.params(u_best),
        natural_jacobian=jax.jacfwd(problem.natural_flat)(u_best),
        start_ok=start_ok,
    )
