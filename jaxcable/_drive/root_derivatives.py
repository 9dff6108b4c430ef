"""How a root solved by `newton.root_scalar` is differentiated: the root by the
implicit function theorem ([`implicit_root`][]), the solve's auxiliary output at the
root as fn's output there ([`aux_at_root`][]); never through the iterations."""

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp


def split_tangents(t_args, args) -> tuple[Any, Any]:
    """`args` split into its differentiated leaves (those with a tangent in `t_args`)
    and the rest, so that only the differentiated ones get tangents (the others
    stay symbolic zeros)."""
    is_none = lambda x: x is None
    diff = jax.tree_util.tree_map(
        lambda t, a: None if t is None else a, t_args, args, is_leaf=is_none
    )
    rest = jax.tree_util.tree_map(
        lambda t, a: a if t is None else None, t_args, args, is_leaf=is_none
    )
    return diff, rest


@eqx.filter_custom_jvp
def implicit_root(y, slope, args, *, fn, slope_known=False):
    """The root `y` of fn(., args), differentiated in `args` by the implicit function
    theorem: dy = -(d fn / d args . dargs) / slope.

    `slope` (d fn / dy) is the one the solve evaluated at its last Newton iterate
    (within the tolerance of the root), so that a derivative costs one
    differentiated evaluation of fn, not two (`jax.lax.custom_root` linearises fn in
    y again at the root). Where it is NaN (a root found by bisection, which evaluates
    no slopes) it is evaluated at the root here, in a loop that a batch without such
    roots enters for one predicate only; with `slope_known`, `slope` is never NaN
    (a solve that evaluated it at its root) and that loop is left out."""
    del slope, args, fn, slope_known
    return y


@implicit_root.def_jvp
def _implicit_root_jvp(primals, tangents, *, fn, slope_known=False):
    y, slope, args = primals
    _, _, t_args = tangents
    if t_args is None:
        return y, None
    diff, rest = split_tangents(t_args, args)
    _, rhs = jax.jvp(lambda d: fn(y, eqx.combine(d, rest)), (diff,), (t_args,))

    def root_slope(y, args):
        return jax.jvp(lambda y: fn(y, args), (y,), (jnp.ones_like(y),))[1]

    if not slope_known:
        slope = evaluate_where(jnp.isnan(slope), root_slope, y, args, slope)
    # A zero slope only occurs where the caller discards the root (e.g. a slack
    # cable); keep its tangent finite so that `jnp.where` does not leak NaNs.
    bad = (slope == 0) | ~jnp.isfinite(slope)
    return y, -rhs / jnp.where(bad, 1.0, slope)


def evaluate_where(need, f, y, args, otherwise):
    """`f(y, args)` where `need`, `otherwise` elsewhere: f runs in a loop that a
    batch (under `vmap`) enters only when some lane needs it, and then once.

    y and args enter the loop tied to its counter ([`loop_tied`][]): XLA would
    otherwise hoist f out of the loop onto every call."""

    def body(c):
        passes, _ = c
        return passes + 1, f(*loop_tied((y, args), passes))

    _, out = jax.lax.while_loop(
        lambda c: need & (c[0] == 0), body, (jnp.zeros_like(y), otherwise)
    )
    return out


def loop_tied(tree, counter):
    """`tree`, its floating leaves made to depend on a loop's `counter` without
    changing a bit (x * (1 + 0 k), which keeps the sign of a zero).

    Inside a `lax.while_loop`, code that depends on loop-invariant values only (in a
    rate-driven sample: the hardening powers of Park's step, which depend on the
    state and the force but not on the solved time) is hoisted by XLA out of the
    loop, so it runs on every call of the enclosing scan step even when the loop
    runs no iteration; once per loop, in a step with three loops (seen in the
    optimised HLO). Tied to the counter, it runs only in the iterations that are
    taken. `0 k` is computed in floating point, which XLA does not fold to 0."""
    counter = jnp.asarray(counter)

    def tie(x):
        if not (eqx.is_array(x) and inexact(x)):
            return x
        return x * (1 + 0 * counter.astype(x.dtype))

    return jax.tree_util.tree_map(tie, tree)


def inexact(x) -> bool:
    """Whether `x` has a floating (or complex) dtype, so that it has derivatives."""
    return jnp.issubdtype(jnp.result_type(x), jnp.inexact)


@eqx.filter_custom_jvp
def aux_at_root(y, y_eval, aux, aux_t, args, *, fn):
    """fn's auxiliary output at the root `y`, from the solve's last evaluation at
    `y_eval`: aux + aux_t (y - y_eval), to first order.

    `y - y_eval` is the refinement step of a converged solve (a residual within the
    tolerance: the second-order term is ~tol^2 relative, below rounding) or 0 (a
    bisected root, a failed solve), so this is fn's auxiliary output at the root
    without evaluating fn again. Differentiated as fn's auxiliary output at y itself
    (in y and `args`): a derivative costs the evaluation that the primal saved."""
    del args, fn
    return _extrapolate(y, y_eval, aux, aux_t)


def _extrapolate(y, y_eval, aux, aux_t):
    step = y - y_eval
    return jax.tree_util.tree_map(
        lambda a, t: a + t * step if inexact(a) else a, aux, aux_t
    )


@aux_at_root.def_jvp
def _aux_at_root_jvp(primals, tangents, *, fn):
    y, y_eval, aux, aux_t, args = primals
    t_y, _, _, _, t_args = tangents
    primal = _extrapolate(y, y_eval, aux, aux_t)
    t_y = jnp.zeros_like(y) if t_y is None else t_y
    diff, rest = (None, args) if t_args is None else split_tangents(t_args, args)
    _, tangent = jax.jvp(
        lambda y, d: fn(y, eqx.combine(d, rest))[1], (y, diff), (t_y, t_args)
    )
    return primal, tangent
