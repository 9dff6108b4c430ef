"""`newton.root_scalar` with an optimistix root finder: `optx.root_find` from the
guess moved past a turning point, with the verdict of no root from the two ends it
saw."""

import jax
import jax.numpy as jnp
import optimistix as optx

from .bracket import Bracket


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


def optimistix_root(fn, solver, guess, args, lower, slope_sign, growth):
    """Solve fn(y, args) = 0 with an optimistix root finder (see
    `newton.root_scalar`): the root, whether it converged, and whether no root was
    bracketed by the points seen."""
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
    seen = Bracket.empty(y, slope_sign)
    seen = seen.see(guess, fn(guess, args)).see(y, fn(y, args))
    return y, converged, ~converged & ~seen.found
