"""The scalar root finder of the drives: [`jaxcable.Newton`][] and `root_scalar`, which
solves one sample's unknown (a loading time, a force) with Newton's method or any
optimistix root finder, past turning points, differentiated implicitly."""

from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx
from jaxtyping import Array, Bool, Float, Int


class Newton(eqx.Module):
    """Newton–Raphson for the scalar root of each sample, built for the scan.

    The per-sample problems of jaxcable (the loading time of a force sample, Park
    Eq. 6; the force of an imposed elongation) are scalar and smooth, and a good
    initial guess is known (along a ramp, the previous sample's duration), so Newton
    converges in one or two steps. This solver takes `unrolled` steps without a loop,
    then continues in a `lax.while_loop` only while some sample is unconverged, up to
    `max_steps`. One unrolled step is the fastest on a CPU (measured in
    `benchmarks/kernel.py`): each unrolled step is a copy of the model's code in the
    scan body, and a larger body costs more per sample than the loop's predicate,
    also under `vmap`, where the loop runs until every lane has converged.
    Derivatives are taken by the implicit function theorem (`jax.lax.custom_root`),
    never through the iterations.

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
        `RESULTS.newton_failed`.
    - `unrolled`: Newton steps taken before the convergence loop.
    """

    tol: float
    max_steps: int = 32
    unrolled: int = 1


def _past_turning_point(fn, y, args, slope_sign, growth, max_steps: int = 32):
    """Grow y <- 2 y + growth until fn's slope at y has the sign `slope_sign`."""

    def wrong_side(y):
        _, slope = jax.jvp(lambda y: fn(y, args), (y,), (jnp.ones_like(y),))
        return ~(slope * slope_sign > 0)

    def cond(c):
        y, k = c
        return (k < max_steps) & wrong_side(y)

    def body(c):
        y, k = c
        return 2 * y + growth, k + 1

    y, _ = jax.lax.while_loop(cond, body, (y, jnp.array(0)))
    # Only the start of the solve: its derivatives come from the implicit function
    # theorem at the root, not from here.
    return jax.lax.stop_gradient(y)


# Bisection halves the bracket each step: 100 steps take a bracket of 1e7 s (or N)
# to below float64 resolution.
_BISECTION_STEPS = 100
# The bracket search of a failed solve spans lower + growth * (2**k - 1) up to this
# k: 2**60 growths is 1e12 crosshead strains (a loading time) or 1e12 breaking
# loads (a force).
_SEARCH_STEPS = 60


class RootResult(eqx.Module):
    """What `root_scalar` found: the root `value`, whether the solve `converged`, and
    `no_root`: where it did not converge, whether no residual it evaluated had the
    other sign (so no root was bracketed; a physical verdict on the problem, such as
    a force out of reach, rather than a numerical failure)."""

    value: Float[Array, ""]
    converged: Bool[Array, ""]
    no_root: Bool[Array, ""]


class _Bracket(eqx.Module):
    """A bracket of the wanted root, from the points a solve has evaluated.

    With s = `slope_sign`, the wanted root has fn * s < 0 to its left (not yet
    reached) and fn * s > 0 to its right (past it). `left` is the largest y seen on
    the left side, `right` the smallest y seen past the root and above `left`; while
    `left < right` the interval holds a crossing of fn in the wanted direction
    (fn continuous). A crossing in the other direction (a root where fn has the other
    slope, e.g. where creep overtakes the crosshead after the force was passed) is
    never bracketed. Without `slope_sign`, any sign change is a bracket.
    """

    left: Float[Array, ""]
    right: Float[Array, ""]
    has_left: Bool[Array, ""]
    has_right: Bool[Array, ""]
    slope_sign: Float[Array, ""] | None

    @staticmethod
    def empty(y, slope_sign):
        no = jnp.zeros_like(y, dtype=bool)
        return _Bracket(y, y, no, no, slope_sign)

    def see(self, y, r):
        if self.slope_sign is None:
            is_left, is_right = r < 0, r > 0
            left = jnp.where(is_left, y, self.left)
            right = jnp.where(is_right, y, self.right)
            return _Bracket(
                left, right, self.has_left | is_left, self.has_right | is_right, None
            )
        q = r * self.slope_sign
        is_left = (q < 0) & (~self.has_left | (y > self.left))
        left = jnp.where(is_left, y, self.left)
        has_left = self.has_left | is_left
        # A `right` at or below the new `left` no longer brackets anything.
        has_right = self.has_right & (~has_left | (self.right > left))
        is_right = (q > 0) & (~has_left | (y > left)) & (~has_right | (y < self.right))
        right = jnp.where(is_right, y, self.right)
        return _Bracket(left, right, has_left, has_right | is_right, self.slope_sign)

    @property
    def found(self):
        return self.has_left & self.has_right

    def midpoint(self):
        return 0.5 * (self.left + self.right)


class _NewtonState(eqx.Module):
    """The carry of `root_scalar`'s Newton loop: the next iterate `y`, the residual
    at the previous one (|residual| <= tol: converged), the bracket of all points
    evaluated, whether the iterate is `stuck` at `lower`, and the steps taken."""

    y: Float[Array, ""]
    residual: Float[Array, ""]
    bracket: _Bracket
    stuck: Bool[Array, ""]
    steps: Int[Array, ""] | int


class _SearchState(eqx.Module):
    """The carry of `_search` and `_bisect`: the bracket, the last point evaluated
    and its residual, and the steps taken."""

    bracket: _Bracket
    y: Float[Array, ""]
    residual: Float[Array, ""]
    steps: Int[Array, ""] | int


def _search(f, bracket: _Bracket, lower, growth, searching):
    """Look for a bracket where Newton's iterates found none: fn at lower +
    growth (2**k - 1), k = 0, 1, ..., up to 2**_SEARCH_STEPS growths, in the lanes
    `searching`. Only a solve that failed gets here, so a verdict of no root rests
    on this scan and not only on where Newton's method happened to step."""

    def cond(c: _SearchState):
        return (c.steps <= _SEARCH_STEPS) & searching & ~c.bracket.found

    def body(c: _SearchState):
        y = lower + growth * (2.0**c.steps - 1.0)
        r = f(y)
        return _SearchState(c.bracket.see(y, r), y, r, c.steps + 1)

    inf = jnp.full_like(bracket.left, jnp.inf)
    init = _SearchState(bracket, inf, inf, jnp.array(0))
    return jax.lax.while_loop(cond, body, init).bracket


def _bisect(f, bracket: _Bracket, tol: float, bisecting):
    """Bisection on a bracket in the lanes `bisecting`: it converges wherever a
    crossing was bracketed, whatever the shape of fn."""

    def cond(c: _SearchState):
        converged = jnp.abs(c.residual) <= tol
        return (c.steps < _BISECTION_STEPS) & bisecting & c.bracket.found & ~converged

    def body(c: _SearchState):
        y = c.bracket.midpoint()
        r = f(y)
        return _SearchState(c.bracket.see(y, r), y, r, c.steps + 1)

    y0 = bracket.midpoint()
    init = _SearchState(bracket, y0, jnp.full_like(y0, jnp.inf), jnp.array(0))
    end = jax.lax.while_loop(cond, body, init)
    return end.y, jnp.abs(end.residual) <= tol


def root_scalar(
    fn: Callable[[Float[Array, ""], Any], Float[Array, ""]],
    solver: Newton | optx.AbstractRootFinder,
    guess: Float[Array, ""],
    args: Any,
    lower: Float[Array, ""],
    slope_sign: Float[Array, ""] | None = None,
    growth: Float[Array, ""] | None = None,
    active: Bool[Array, ""] | None = None,
) -> RootResult:
    """Solve fn(y, args) = 0 for a scalar y >= lower.

    `slope_sign` (+1 or -1), where known, is the sign of fn's slope at the wanted
    root. Where the slope at an iterate has the other sign (or is zero), the root
    lies beyond a turning point of fn, and a Newton step would run away from it: the
    iterate is then grown geometrically instead, y <- 2 y + `growth`. This is what
    makes the loading-time solve robust when a fast recovery briefly outruns the
    crosshead (a residual that first falls, then rises through zero). An optimistix
    solver gets the same treatment of its initial guess only: it starts from the
    first y (of guess, 2 guess + growth, ...) where the slope has `slope_sign`.

    Every residual evaluated updates a bracket of the wanted root (`_Bracket`: a
    crossing in the direction of `slope_sign`). Where Newton's method has not
    converged in `max_steps`, fn is scanned for a bracket if its iterates found
    none (`_search`: from `lower` up to 2**60 `growth`), and the solve is finished
    by bisection on the bracket. Where the scan finds none either,
    `RootResult.no_root` is set: a problem without a root (e.g. a force that creep
    keeps out of reach), not a solver failure. `scripts/sweep_draws.py` checks the
    verdict on 10^5 random cables against a denser scan of the residual. None of
    this costs anything on a solve that converges.

    `active` (default: all) marks the lanes to solve: a lane that is not active
    (a cable that has already failed, under `vmap`) takes the unrolled steps only,
    so it never keeps the batch's loops running.
    """
    if isinstance(solver, optx.AbstractRootFinder):
        if slope_sign is not None:
            guess = _past_turning_point(fn, guess, args, slope_sign, growth)
        sol = optx.root_find(
            fn,
            solver,
            guess,
            args=args,
            options=dict(lower=lower),
            max_steps=256,
            throw=False,
        )
        converged = sol.result == optx.RESULTS.successful
        # optimistix keeps no bracket: only the two ends of the search are seen.
        y = sol.value
        seen = _Bracket.empty(y, slope_sign)
        seen = seen.see(guess, fn(guess, args)).see(y, fn(y, args))
        return RootResult(y, converged, ~converged & ~seen.found)
    if not isinstance(solver, Newton):
        raise ValueError(
            "`solver` must be a jaxcable.Newton or an optimistix root finder, got "
            f"{type(solver).__name__}."
        )

    def newton_step(f, y):
        r, slope = jax.jvp(f, (y,), (jnp.ones_like(y),))
        step = r / jnp.where(slope == 0, 1.0, slope)
        ok = (slope != 0) & jnp.isfinite(step)
        if slope_sign is None:
            # A flat or non-finite slope gives no step; the sample is then reported
            # unconverged instead of carrying a NaN.
            y_new = jnp.where(ok, y - step, y)
        else:
            ok = ok & (slope * slope_sign > 0)
            y_new = jnp.where(ok, y - step, 2 * y + growth)
        # An iterate that has converged is the answer: a further step is no
        # refinement where the slope is nearly flat (at 0 N under hardening, a slope
        # of 1e-18 turns a residual of 1e-13 into a step of 1e5 N).
        y_new = jnp.where(jnp.abs(r) <= solver.tol, y, y_new)
        return jnp.maximum(y_new, lower), r

    def advance(state: _NewtonState, f) -> _NewtonState:
        y, r = newton_step(f, state.y)
        # At `lower` and already past the root (or, without `slope_sign`, stepping
        # below `lower` again), the root is below `lower`: stop instead of
        # repeating the step.
        if slope_sign is None:
            stuck = (state.y <= lower) & (y <= lower)
        else:
            stuck = (state.y <= lower) & (r * slope_sign > 0)
        return _NewtonState(
            y=y,
            residual=r,
            bracket=state.bracket.see(state.y, r),
            stuck=stuck,
            steps=state.steps + 1,
        )

    live = jnp.ones_like(guess, dtype=bool) if active is None else active

    def solve(f, y0):
        inf = jnp.full_like(y0, jnp.inf)
        no = jnp.zeros_like(y0, dtype=bool)
        state = _NewtonState(y0, inf, _Bracket.empty(y0, slope_sign), no, 0)
        for _ in range(solver.unrolled):
            state = advance(state, f)

        def cond(state):
            done = (jnp.abs(state.residual) <= solver.tol) | state.stuck
            return (state.steps < solver.max_steps) & live & ~done

        state = jax.lax.while_loop(cond, lambda s: advance(s, f), state)
        y, bracket = state.y, state.bracket
        ok = (jnp.abs(state.residual) <= solver.tol) & jnp.isfinite(y)
        # Only the lanes Newton's method left unconverged search and bisect.
        failed = live & ~ok
        if growth is not None:
            bracket = _search(f, bracket, lower, growth, failed)
        y_bisect, ok_bisect = _bisect(f, bracket, solver.tol, failed)
        no_root = failed & ~bracket.found
        y = jnp.where(failed & bracket.found, y_bisect, y)
        ok = ok | (failed & ok_bisect)
        # Float flags: custom_root gives aux a tangent, which a bool cannot have.
        return y, (ok.astype(y.dtype), no_root.astype(y.dtype))

    def tangent_solve(g, y):
        # A zero slope only occurs where the caller discards the root (e.g. a slack
        # cable); keep its tangent finite so that `jnp.where` does not leak NaNs.
        slope = g(jnp.ones_like(y))
        bad = (slope == 0) | ~jnp.isfinite(slope)
        return y / jnp.where(bad, 1.0, slope)

    y, (ok, no_root) = jax.lax.custom_root(
        lambda y: fn(y, args), guess, solve, tangent_solve, has_aux=True
    )
    ok, no_root = jax.lax.stop_gradient((ok, no_root))
    return RootResult(y, ok > 0.5, no_root > 0.5)
