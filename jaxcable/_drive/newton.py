"""The scalar root finder of the drives: [`jaxcable.Newton`][] and `root_scalar`, which
solves one sample's unknown (a loading time, a force) with Newton's method or any
optimistix root finder, past turning points, differentiated implicitly."""

from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx
from jax.ad_checkpoint import checkpoint_name
from jaxtyping import Array, Bool, Float

from .. import _checks
from .optimistix_root import optimistix_root
from .root_derivatives import aux_at_root, evaluate_where, implicit_root
from .root_solver import (
    BracketBisection,
    NewtonSteps,
    RootProblem,
    iterate,
    jvp_with_aux,
)


class Newton(eqx.Module):
    """Newton–Raphson for the scalar root of each sample, built for the scan.

    The per-sample problems of jaxcable (the loading time of a force sample, Park
    Eq. 6; the force of an imposed elongation) are scalar and smooth, and a good
    initial guess is known (along a ramp, the previous sample's duration), so
    Newton's method converges in two or three steps. A sample first takes
    `unrolled` Newton steps, with no loop and no branch (one kernel per step,
    vectorised across a batch); a step converges where its residual is within
    `tol`, or where the residual after it is predicted so from two contracting
    steps (`root_solver.converged`). Only where that did not happen does the robust
    path take over: Newton's method in a `lax.while_loop` up to `max_steps`, then a
    bracket search and bisection (`root_solver.BracketBisection`). Derivatives are taken by the implicit
    function theorem at each sample's root (`root_derivatives.implicit_root`),
    never through the iterations.

    Where the robust path's loops are entered is `two_pass`'s choice. In one pass
    (a CPU's default), they follow each sample's unrolled steps, entered only by
    the lanes that need them: a batch that converged passes each loop with one
    predicate. On an accelerator every loop or branch reads its predicate back to
    the host, a round trip per sample; in two passes (an accelerator's default) the
    first has no loop at all, a history in which some sample did not converge is
    solved again by the robust path (one loop for the whole history, entered only
    by the cables that need it), and a differentiated simulation replays the
    history at its roots for the derivatives (`scan.run`).

    Any optimistix root finder (e.g. `optx.Newton(rtol, atol)`) can be passed
    instead, where a simulation takes `solver=`; it runs through `optx.root_find`
    (with its `ImplicitAdjoint`) on the same relative residual, from the same
    initial guess moved past a turning point as below, and is slower inside the
    scan.

    **Arguments:**

    - `tol`: convergence when |residual| <= tol. jaxcable's residuals are relative
        strain errors (dimensionless), so `tol` is a relative accuracy of the strain;
        a few float32 epsilons at most in single precision.
    - `max_steps`: the most Newton steps in all; beyond it the sample is flagged
        `RESULTS.newton_failed` (or solved by the bracket fallback).
    - `unrolled`: the Newton steps every sample takes before any loop (>= 1);
        None (the default): in one pass, 2, or 1 for a single-precision `tol`
        (above 1e-9: the guess along a ramp is often within it already, and the
        loop then never runs); in two, 3 (a first pass that needs the robust one
        costs a whole second pass; with coarse samples, such as fewer than ~100 a
        ramp, a fourth can pay). Measured in benchmarks/README.md.
    - `two_pass`: solve a history in two passes (True) or one (False); None (the
        default): two on an accelerator, one on a CPU (`branches_are_cheap`). The
        results agree to the tolerance either way.
    """

    tol: float
    max_steps: int = 32
    unrolled: int | None = None
    two_pass: bool | None = None

    def __check_init__(self):
        _checks.require_int("max_steps", self.max_steps, 1)
        if self.unrolled is not None:
            _checks.require_int("unrolled", self.unrolled, 1)
        if self.two_pass not in (None, True, False):
            raise ValueError(
                f"Newton: `two_pass` must be None, True or False, got {self.two_pass!r}."
            )

    @property
    def in_two_passes(self) -> bool:
        """Whether a history is solved in two passes here (see `two_pass`)."""
        if self.two_pass is None:
            return not branches_are_cheap()
        return self.two_pass

    @property
    def steps_unrolled(self) -> int:
        """The unrolled Newton steps here (see `unrolled`)."""
        if self.unrolled is None:
            if self.in_two_passes:
                return 3
            return 1 if self.tol > 1e-9 else 2
        return self.unrolled


def branches_are_cheap() -> bool:
    """Whether a `lax.cond` or `lax.while_loop` inside a scan is cheap where the
    program runs: on a CPU its predicate is already on the host; on an accelerator
    every one reads its predicate back to the host, a round trip per sample. The
    default backend at trace time decides (the same choice for every sample: the
    results do not depend on it)."""
    return jax.default_backend() == "cpu"


# How `root_scalar` solves: the robust path (loops, bracket, bisection); the fixed
# steps of a first pass; or the replay of a root already known (its derivatives and
# fn's output there).
ROBUST, FAST, REPLAY = "robust", "fast", "replay"


class RootResult(eqx.Module):
    """What `root_scalar` found: the root `value`, whether the solve `converged`,
    `no_root`: where it did not converge, whether no residual it evaluated had the
    other sign (so no root was bracketed; a physical verdict on the problem, such as
    a force out of reach, rather than a numerical failure), and `aux`: with
    `has_aux`, fn's auxiliary output at the root (see `root_scalar`)."""

    value: Float[Array, ""]
    converged: Bool[Array, ""]
    no_root: Bool[Array, ""]
    aux: Any = None


def root_scalar(
    fn: Callable[[Float[Array, ""], Any], Any],
    solver: Newton | optx.AbstractRootFinder,
    guess: Float[Array, ""],
    args: Any,
    lower: Float[Array, ""],
    slope_sign: Float[Array, ""] | None = None,
    growth: Float[Array, ""] | None = None,
    active: Bool[Array, ""] | None = None,
    upper: Float[Array, ""] | None = None,
    name: str | None = None,
    has_aux: bool = False,
    how: str = ROBUST,
    known: Float[Array, ""] | None = None,
) -> RootResult:
    """Solve fn(y, args) = 0 for a scalar lower <= y <= upper.

    With jaxcable's `Newton`, two solvers with optimistix's init / step / terminate
    contract run in turn (`root_solver.NewtonSteps`, then, where it failed,
    `root_solver.BracketBisection`): `solver.steps_unrolled` steps with no loop,
    then each in a `lax.while_loop` (`root_solver.iterate`).

    `slope_sign` (+1 or -1), where known, is the sign of fn's slope at the wanted
    root. Where the slope at an iterate has the other sign (or is zero), the root
    lies beyond a turning point of fn, and a Newton step would run away from it: the
    iterate is then grown geometrically instead, y <- 2 y + `growth`. This is what
    makes the loading-time solve robust when a fast recovery briefly outruns the
    crosshead (a residual that first falls, then rises through zero). An optimistix
    solver gets the same treatment of its initial guess only: it starts from the
    first y (of guess, 2 guess + growth, ...) where the slope has `slope_sign`.

    Every residual evaluated updates a bracket of the wanted root (`Bracket`: a
    crossing in the direction of `slope_sign`). Where Newton's method has not
    converged in `max_steps`, fn is scanned for a bracket if its iterates found
    none (a scan from `lower` up to 2**60 `growth`), and the solve is finished
    by bisection on the bracket. Where the scan finds none either,
    `RootResult.no_root` is set: a problem without a root (e.g. a force that creep
    keeps out of reach), not a solver failure. `scripts/sweep_draws.py` checks the
    verdict on 10^5 random cables against a denser scan of the residual. The search
    and the bisection share one loop after Newton's, which a batch whose solves all
    converged enters for one predicate only.

    `upper` (default: none) bounds the iterates and the search: beyond it fn is
    outside the model's domain (e.g. a rate-driven strain far past the hardening
    law's limit, where its arithmetic overflows), so a sign change there is no root
    and a solve whose root lies beyond it ends with `no_root`, the same verdict on
    every platform instead of one that depends on rounding at strains of 1e8
    (measured: a force out of reach was `unreachable_force` or `newton_failed`
    depending on LLVM's optimisation level). jaxcable's `Newton` only.

    `active` (default: all) marks the lanes to solve: a lane that is not active
    (a cable that has already failed, under `vmap`) takes the unrolled steps only,
    so it never keeps the batch's loops running.

    `name` (jaxcable's `Newton` only), where given, is the `checkpoint_name` of the
    root and of the slope its derivative uses: a rematerialised backward pass that
    saves that name then never repeats the solve.

    `has_aux`: fn returns `(residual, aux)`, and `RootResult.aux` is aux at the
    root (a drive's model state after the sample). Where the last unrolled Newton
    step converged (most samples), jaxcable's `Newton` takes it from that
    evaluation, to first order in the final refinement step
    (`root_derivatives.aux_at_root`), instead of evaluating fn once more (on a CPU
    that evaluation was about a third of a rate-driven sample's time); elsewhere fn
    is evaluated at the root, in a loop that a batch of such samples only enters
    for one predicate.
    """
    if has_aux:
        fn_aux = fn
        fn = lambda y, args: fn_aux(y, args)[0]
    else:
        residual_fn = fn
        fn_aux = lambda y, args: (residual_fn(y, args), None)
    if isinstance(solver, optx.AbstractRootFinder):
        y, converged, no_root = optimistix_root(
            fn, solver, guess, args, lower, slope_sign, growth
        )
        aux = fn_aux(y, args)[1] if has_aux else None
        return RootResult(y, converged, no_root, aux)
    if not isinstance(solver, Newton):
        raise ValueError(
            "`solver` must be a jaxcable.Newton or an optimistix root finder, got "
            f"{type(solver).__name__}."
        )
    # The solve itself is never differentiated (nor are its start and bounds): the
    # root's derivatives come from the implicit function theorem
    # (`root_derivatives.implicit_root`).
    diff, static = eqx.partition(args, eqx.is_inexact_array)
    problem = RootProblem(
        fn=fn_aux,
        args=eqx.combine(jax.lax.stop_gradient(diff), static),
        lower=jax.lax.stop_gradient(lower),
        top=jnp.inf if upper is None else jax.lax.stop_gradient(upper),
        growth=None if growth is None else jax.lax.stop_gradient(growth),
        slope_sign=slope_sign,
        live=jnp.ones_like(guess, dtype=bool) if active is None else active,
    )
    if how == ROBUST:
        y, slope, ok, no_root, y_eval, aux, aux_t = _robust(
            solver, problem, jax.lax.stop_gradient(guess), has_aux
        )
    else:
        start = guess if how == FAST else known
        y, slope, ok, y_eval, aux, aux_t = (_fixed_steps if how == FAST else _at_known)(
            solver, problem, jax.lax.stop_gradient(start)
        )
        no_root = jnp.zeros_like(ok)
    if name is not None:
        y, slope = checkpoint_name((y, slope), name)
    y = implicit_root(y, slope, args, fn=fn, slope_known=how != ROBUST)
    if has_aux:
        aux = aux_at_root(y, y_eval, aux, aux_t, args, fn=fn_aux)
    return RootResult(y, ok, no_root, aux if has_aux else None)


def _fixed_steps(solver: Newton, problem: RootProblem, y0):
    """`solver.steps_unrolled` Newton steps and no loop: the first of two passes."""
    newton = NewtonSteps(solver.tol, solver.max_steps)
    state = newton.init(problem, y0)
    y_eval, aux, aux_t = y0, None, None
    for _ in range(solver.steps_unrolled):
        state, (y_eval, aux, aux_t) = newton.step_with_aux(problem, state)
    ok = state.converged & jnp.isfinite(state.y)
    return state.y, state.slope, ok, y_eval, aux, aux_t


def _at_known(solver: Newton, problem: RootProblem, y0):
    """One evaluation at the known root y0: its slope and fn's output there."""
    (r, aux), (slope, aux_t) = jvp_with_aux(problem, y0)
    ok = (jnp.abs(r) <= solver.tol) & jnp.isfinite(y0)
    return y0, slope, ok, y0, aux, aux_t


def _robust(solver: Newton, problem: RootProblem, y0, has_aux: bool):
    """The first `unrolled` Newton steps, Newton's loop, then one loop for the search
    and the bisection of the lanes that Newton's method left unconverged (one loop
    instead of two costs a batch whose solves all converge one predicate, and its
    carry, less per sample), and fn's output at the root."""
    newton = NewtonSteps(solver.tol, solver.max_steps)
    state = newton.init(problem, y0)
    for _ in range(solver.steps_unrolled - 1):
        state = newton.step(problem, state)
    state, (y_eval, aux, aux_t) = newton.step_with_aux(problem, state)
    # Where the last unrolled evaluation was within the tolerance, the root is that
    # point plus one refinement step, and fn's output there follows from the
    # evaluation's (`aux_at_root`).
    fresh = state.converged
    state = iterate(newton, problem, state)
    y = state.y
    ok = state.converged & jnp.isfinite(y)
    failed = problem.live & ~ok
    fallback = BracketBisection(solver.tol)
    state = iterate(fallback, problem, fallback.init(problem, state, failed))
    no_root = failed & ~state.bracket.found
    # A lane with a bracket has bisected it (at least one step).
    bisected = failed & state.bracket.found
    y = jnp.where(bisected, state.y_end, y)
    # A bisected root has no slope yet: `root_derivatives.implicit_root` evaluates
    # it, only where it is differentiated.
    slope = jnp.where(bisected, jnp.nan, state.slope)
    ok = ok | (bisected & (jnp.abs(state.r_end) <= solver.tol))
    # Elsewhere (the loops' roots, a lane that is not live) fn's output is evaluated
    # at y, in a loop that a batch whose roots are all fresh enters for one
    # predicate only; a lane that is not live keeps the unrolled one.
    fresh = fresh & ~bisected & jnp.isfinite(y)
    y_eval = jnp.where(fresh, y_eval, y)
    aux_t = jax.tree_util.tree_map(
        lambda t: jnp.where(fresh, t, jnp.zeros_like(t)), aux_t
    )
    if has_aux:
        aux = evaluate_where(
            ~fresh & problem.live,
            lambda y, a: problem.fn(y, a)[1],
            y,
            problem.args,
            aux,
        )
    return y, slope, ok, no_root, y_eval, aux, aux_t
