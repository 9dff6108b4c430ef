import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np


def tree_allclose(x, y, *, rtol=1e-10, atol=1e-12) -> bool:
    same = jax.tree_util.tree_structure(x) == jax.tree_util.tree_structure(y)
    leaves = zip(jax.tree_util.tree_leaves(x), jax.tree_util.tree_leaves(y))
    return same and all(
        np.allclose(np.asarray(a), np.asarray(b), rtol=rtol, atol=atol)
        for a, b in leaves
    )


def finite_difference_grad(loss, model, rel_step=1e-6):
    """Central finite differences of `loss(model)` w.r.t. every array leaf (float64)."""
    assert jax.config.jax_enable_x64, "finite differences need float64"
    params, static = eqx.partition(model, eqx.is_inexact_array)
    leaves, treedef = jax.tree_util.tree_flatten(params)
    grads = []
    for i, leaf in enumerate(leaves):
        h = rel_step * max(abs(float(leaf)), 1e-12)

        def shifted(delta, i=i):
            new = list(leaves)
            new[i] = leaf + delta
            return float(
                loss(eqx.combine(jax.tree_util.tree_unflatten(treedef, new), static))
            )

        grads.append((shifted(h) - shifted(-h)) / (2 * h))
    return jax.tree_util.tree_unflatten(treedef, [jnp.asarray(g) for g in grads])


def leaf_names(model):
    params, _ = eqx.partition(model, eqx.is_inexact_array)
    paths = jax.tree_util.tree_flatten_with_path(params)[0]
    return [jax.tree_util.keystr(p) for p, _ in paths]
