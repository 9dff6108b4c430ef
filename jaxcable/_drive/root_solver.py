"""The two solvers behind `newton.root_scalar`, each with the init / step / terminate
contract of an optimistix solver, over one sample's `RootProblem`:

- `NewtonSteps`: Newton's method, past turning points, with a bracket of every point
    it evaluated;
- `BracketBisection`: where Newton's method did not converge, a search for a bracket
    and its bisection, ending with a root or the verdict that there is none.

`iterate` runs one of them in a `lax.while_loop`, fn's arguments tied to the loop's
counter."""

import dataclasses
from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from .bracket import Bracket
from .root_derivatives import inexact, loop_tied


# Bisection halves the bracket each step: 100 steps take a bracket of 1e7 s (or N)
# to below float64 resolution.
_BISECTION_STEPS = 100
# The bracket search of a failed solve spans lower + growth * (2**k - 1) up to this
# k: 2**60 growths is 1e12 crosshead strains (a loading time) or 1e12 breaking
# loads (a force).
_SEARCH_STEPS = 60

# The phases of a lane: Newton's method, then, only where it failed, the bracket
# search (`SEARCH`) and bisection, then done.
NEWTON, SEARCH, BISECT, DONE = 0, 1, 2, 3


class RootProblem(eqx.Module):
    """One sample's scalar root problem, as the solvers see it (see
    `newton.root_scalar`).

    **Fields:**

    - `fn`: fn(y, args) -> (residual, aux).
    - `args`: fn's arguments (not differentiated here).
    - `lower`, `top`: the bounds of the iterates (`top` inf without a bound).
    - `growth`: the geometric growth past a turning point, and the step of the
        bracket search; None: no search.
    - `slope_sign`: the sign of fn's slope at the wanted root, or None.
    - `live`: whether the lane is solved at all (False: unrolled steps only).
    """

    fn: Callable[[Float[Array, ""], Any], tuple[Float[Array, ""], Any]]
    args: Any
    lower: Float[Array, ""]
    top: Float[Array, ""] | float
    growth: Float[Array, ""] | None
    slope_sign: Float[Array, ""] | None
    live: Bool[Array, ""]

    def tied(self, counter) -> "RootProblem":
        """This problem, its arguments tied to a loop's `counter` (`loop_tied`)."""
        return dataclasses.replace(self, args=loop_tied(self.args, counter))


def jvp_with_aux(problem: RootProblem, y: Float[Array, ""]):
    """fn's residual and auxiliary output at y and their derivatives in y (integer
    and boolean outputs: zeros of their own dtype): `((r, aux), (slope, aux_t))`."""
    (r, aux), (slope, aux_t) = jax.jvp(
        lambda y: problem.fn(y, problem.args), (y,), (jnp.ones_like(y),)
    )
    aux_t = jax.tree_util.tree_map(
        lambda a, t: t if inexact(a) else jnp.zeros_like(a), aux, aux_t
    )
    return (r, aux), (slope, aux_t)


class SolveState(eqx.Module):
    """The state of a lane's solve.

    Newton's method: the next iterate `y`, the `residual` and the `slope` at the
    previous one, whether that iterate `converged` (`converged`), whether the
    iterate is `stuck` at `lower`, and the Newton `steps` taken. The fallback: the
    step `k` of the bracket search or of the bisection, and the last point that it
    evaluated (`y_end`, with residual `r_end`). Both: the `bracket` of every point
    evaluated and the lane's `phase`.
    """

    y: Float[Array, ""]
    phase: Int[Array, ""]
    bracket: Bracket
    residual: Float[Array, ""]
    steps: Int[Array, ""] | int
    slope: Float[Array, ""]
    stuck: Bool[Array, ""]
    converged: Bool[Array, ""]
    k: Int[Array, ""]
    r_end: Float[Array, ""]
    y_end: Float[Array, ""]


def converged(previous, residual, plain, tol):
    """Whether a Newton iterate with `residual` is converged: within `tol`, or
    predicted within it after the refinement step that follows (a `plain` Newton
    step). Newton's error squares each step, r_next ~ C r^2 with C ~ r / previous^2
    from the residual before (`previous`); the prediction is trusted only where the
    two steps contract (|r| below a tenth of |previous|), and asked to be a tenth
    of `tol`. The refined root is then accurate to the tolerance, and fn's output
    there follows to the same order (`root_derivatives.aux_at_root`): a sample
    converges in one evaluation fewer."""
    last = jnp.abs(residual)
    ratio = last / jnp.abs(previous)
    contracts = (ratio <= 0.1) & jnp.isfinite(previous) & (previous != 0)
    predicted = last * ratio * ratio
    return (last <= tol) | (plain & contracts & (predicted <= 0.1 * tol))


def _newton_update(problem: RootProblem, y, r, slope, tol):
    """The next iterate from the residual `r` and the `slope` at `y`, whether the
    lane is stuck at `lower`, and whether the step was a plain Newton step."""
    slope_sign, growth = problem.slope_sign, problem.growth
    step = r / jnp.where(slope == 0, 1.0, slope)
    ok = (slope != 0) & jnp.isfinite(step)
    if slope_sign is None:
        # A flat or non-finite slope gives no step; the sample is then reported
        # unconverged instead of carrying a NaN.
        y_new = jnp.where(ok, y - step, y)
    else:
        ok = ok & (slope * slope_sign > 0)
        y_new = jnp.where(ok, y - step, 2 * y + growth)
    # An iterate that has converged takes one more Newton step as a refinement
    # (what keeps float32 times accurate over thousands of samples) only where that
    # step is small (below 1e-3 of the iterate plus 1e3 `growth`, the scale of the
    # search: a crosshead strain of 1e-3, or 1e-3 of the breaking load): where the
    # slope is nearly flat (at 0 N under hardening, a slope of 1e-18 turns a
    # residual of 1e-13 into a step of 1e5 N) the converged iterate is the answer.
    small = 1e-3 * jnp.abs(y) + (0.0 if growth is None else 1e3 * growth)
    refine = ok & (jnp.abs(step) <= small)
    y_new = jnp.where(jnp.abs(r) <= tol, jnp.where(refine, y - step, y), y_new)
    y_new = jnp.minimum(jnp.maximum(y_new, problem.lower), problem.top)
    # At `lower` and already past the root (or, without `slope_sign`, stepping
    # below `lower` again), the root is below `lower`: stop instead of repeating
    # the step.
    if slope_sign is None:
        stuck = (y <= problem.lower) & (y_new <= problem.lower)
    else:
        stuck = (y <= problem.lower) & (r * slope_sign > 0)
    # A plain Newton step: no safeguard and no bound changed it.
    plain = ok & (y_new == y - step)
    return y_new, stuck, plain


class NewtonSteps(eqx.Module):
    """Newton's method on one lane, up to `max_steps` steps to the tolerance `tol`
    (the fields of [`jaxcable.Newton`][]): where fn's slope at an iterate has the
    other sign than `slope_sign`, the iterate grows geometrically instead
    (y <- 2 y + growth), past the turning point."""

    tol: float
    max_steps: int

    def init(self, problem: RootProblem, y0: Float[Array, ""]) -> SolveState:
        """The state before the first Newton step from y0."""
        inf = jnp.full_like(y0, jnp.inf)
        no = jnp.zeros_like(y0, dtype=bool)
        zero = jnp.zeros_like(y0, dtype=jnp.int32)
        return SolveState(
            y=y0,
            residual=inf,
            slope=inf,
            bracket=Bracket.empty(y0, problem.slope_sign),
            converged=no,
            stuck=no,
            steps=0,
            phase=zero,
            k=zero,
            y_end=y0,
            r_end=inf,
        )

    def _update(self, problem, state, r, slope) -> SolveState:
        # The state after the step from `state.y`, with residual r and slope there.
        y, stuck, plain = _newton_update(problem, state.y, r, slope, self.tol)
        return eqx.tree_at(
            lambda s: (
                s.y,
                s.residual,
                s.slope,
                s.bracket,
                s.converged,
                s.stuck,
                s.steps,
            ),
            state,
            (
                y,
                r,
                slope,
                state.bracket.see(state.y, r),
                converged(state.residual, r, plain, self.tol),
                stuck,
                state.steps + 1,
            ),
        )

    def step(self, problem: RootProblem, state: SolveState) -> SolveState:
        """One Newton step from `state.y`."""
        r, slope = jax.jvp(
            lambda y: problem.fn(y, problem.args)[0],
            (state.y,),
            (jnp.ones_like(state.y),),
        )
        return self._update(problem, state, r, slope)

    def step_with_aux(self, problem: RootProblem, state: SolveState):
        """One Newton step from `state.y`, and the point it evaluated with fn's
        auxiliary output there and its derivative in y: `(state, (y, aux, aux_t))`."""
        (r, aux), (slope, aux_t) = jvp_with_aux(problem, state.y)
        return self._update(problem, state, r, slope), (state.y, aux, aux_t)

    def terminate(self, problem: RootProblem, state: SolveState) -> Bool[Array, ""]:
        """Whether the lane is done with Newton's method: converged, stuck, out of
        steps, or not live."""
        going = (state.steps < self.max_steps) & problem.live
        return ~(going & ~(state.converged | state.stuck))

    def counter(self, state: SolveState):
        """The loop counter fn's arguments are tied to."""
        return state.steps


class BracketBisection(eqx.Module):
    """The fallback of the lanes that Newton's method left unconverged: a scan of fn
    for a bracket of the wanted root where Newton's iterates found none (from
    `lower` up to 2**60 `growth`: a verdict of no root rests on this scan, not only
    on where Newton's method happened to step), then bisection on the bracket to
    the tolerance `tol`. Search and bisection share one loop, which a batch whose
    lanes all converged enters for one predicate only."""

    tol: float

    def init(
        self, problem: RootProblem, state: SolveState, failed: Bool[Array, ""]
    ) -> SolveState:
        """The state of a lane after Newton's method: searching where it `failed`,
        else done."""
        zero = jnp.zeros_like(state.y, dtype=jnp.int32)
        phase = jnp.where(failed, SEARCH, DONE) + zero
        return self._settle(problem, eqx.tree_at(lambda s: s.phase, state, phase))

    def _settle(self, problem: RootProblem, state: SolveState) -> SolveState:
        # Move each lane on to its next phase once its current one is over (possibly
        # through both at once): the search ends with a bracket or after
        # `_SEARCH_STEPS`; bisection converged, out of steps, or at once where no
        # bracket was found (no root). Without `growth` there is no search.
        phase, k, r_end = state.phase, state.k, state.r_end
        if problem.growth is None:
            leave = phase == SEARCH
        else:
            searching = (k <= _SEARCH_STEPS) & ~state.bracket.found
            leave = (phase == SEARCH) & ~searching
        phase = jnp.where(leave, BISECT, phase)
        k = jnp.where(leave, 0, k)
        r_end = jnp.where(leave, jnp.inf, r_end)
        bisecting = (
            (k < _BISECTION_STEPS) & state.bracket.found & ~(jnp.abs(r_end) <= self.tol)
        )
        phase = jnp.where((phase == BISECT) & ~bisecting, DONE, phase)
        return eqx.tree_at(lambda s: (s.phase, s.k, s.r_end), state, (phase, k, r_end))

    def step(self, problem: RootProblem, state: SolveState) -> SolveState:
        """One evaluation of fn: at the search's next point, lower + growth
        (2**k - 1), or at the bracket's midpoint."""
        y = state.bracket.midpoint()
        if problem.growth is not None:
            # 2**k in the iterate's dtype: under x64, a float32 solve would
            # otherwise get float64 iterates (2.0**k of an int is float64 there).
            power = (2.0**state.k).astype(y.dtype) - 1.0
            y_search = problem.lower + problem.growth * power
            y = jnp.where(state.phase == SEARCH, jnp.minimum(y_search, problem.top), y)
        r = problem.fn(y, problem.args)[0]
        state = eqx.tree_at(
            lambda s: (s.bracket, s.k, s.y_end, s.r_end),
            state,
            (state.bracket.see(y, r), state.k + 1, y, r),
        )
        return self._settle(problem, state)

    def terminate(self, problem: RootProblem, state: SolveState) -> Bool[Array, ""]:
        """Whether the lane is done: a root bisected, or no bracket found."""
        del problem
        return state.phase == DONE

    def counter(self, state: SolveState):
        """The loop counter fn's arguments are tied to."""
        return state.k


def iterate(solver, problem: RootProblem, state: SolveState) -> SolveState:
    """`solver`'s steps from `state` until it terminates, in a `lax.while_loop`.

    Inside the loop fn's arguments are tied to the loop's counter (`loop_tied`), so
    that what does not depend on y is computed in the iterations taken, not
    hoisted onto every call."""
    return jax.lax.while_loop(
        lambda s: ~solver.terminate(problem, s),
        lambda s: solver.step(problem.tied(solver.counter(s)), s),
        state,
    )
