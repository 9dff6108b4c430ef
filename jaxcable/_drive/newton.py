"""The scalar root finder of the drives: [`jaxcable.Newton`][] and `root_scalar`, which
solves one sample's unknown (a loading time, a force) with Newton's method or any
optimistix root finder, past turning points, differentiated implicitly."""

from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx
from jaxtyping import Array, Bool, Float


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


def root_scalar(
    fn: Callable[[Float[Array, ""], Any], Float[Array, ""]],
    solver: Newton | optx.AbstractRootFinder,
    guess: Float[Array, ""],
    args: Any,
    lower: Float[Array, ""],
    slope_sign: Float[Array, ""] | None = None,
    growth: Float[Array, ""] | None = None,
) -> tuple[Float[Array, ""], Bool[Array, ""]]:
    """Solve fn(y, args) = 0 for a scalar y >= lower; returns (y, converged).

    `slope_sign` (+1 or -1), where known, is the sign of fn's slope at the wanted
    root. Where the slope at an iterate has the other sign (or is zero), the root
    lies beyond a turning point of fn, and a Newton step would run away from it: the
    iterate is then grown geometrically instead, y <- 2 y + `growth`. This is what
    makes the loading-time solve robust when a fast recovery briefly outruns the
    crosshead (a residual that first falls, then rises through zero). An optimistix
    solver gets the same treatment of its initial guess only: it starts from the
    first y (of guess, 2 guess + growth, ...) where the slope has `slope_sign`.
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
        return sol.value, sol.result == optx.RESULTS.successful
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
        return jnp.maximum(y_new, lower), r

    def converged(y, y_prev, r):
        del y_prev
        return jnp.abs(r) <= solver.tol

    def solve(f, y0):
        y_prev, y, r = y0, y0, jnp.full_like(y0, jnp.inf)
        for _ in range(solver.unrolled):
            y_prev = y
            y, r = newton_step(f, y)

        def cond(c):
            y, y_prev, r, k = c
            return (k < solver.max_steps) & ~converged(y, y_prev, r)

        def body(c):
            y, _, _, k = c
            y_new, r = newton_step(f, y)
            return y_new, y, r, k + 1

        init = (y, y_prev, r, jnp.array(solver.unrolled))
        y, y_prev, r, _ = jax.lax.while_loop(cond, body, init)
        # A float flag: custom_root gives aux a tangent, which a bool cannot have.
        ok = converged(y, y_prev, r) & jnp.isfinite(y)
        return y, ok.astype(y.dtype)

    def tangent_solve(g, y):
        # A zero slope only occurs where the caller discards the root (e.g. a slack
        # cable); keep its tangent finite so that `jnp.where` does not leak NaNs.
        slope = g(jnp.ones_like(y))
        bad = (slope == 0) | ~jnp.isfinite(slope)
        return y / jnp.where(bad, 1.0, slope)

    y, ok = jax.lax.custom_root(
        lambda y: fn(y, args), guess, solve, tangent_solve, has_aux=True
    )
    return y, jax.lax.stop_gradient(ok) > 0.5
