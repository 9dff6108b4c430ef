import contextlib
import io

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import jaxcable as jc
from jaxcable.cli import main


# Park's 3 mm cable, 300 mm long, and the default (SK78) integrated model.
PARK_CABLE = jc.Cable(length=0.3)
PARK_MODEL = jc.IntegratedModel()


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


def asymmetric_five_element():
    """A five-element model with distinct loading and unloading sets, compliant and
    with seconds-scale retardation times, so that every term of Piao Eq. 1-3 is
    visible in the strain."""
    return jc.FiveElementModel(
        E_L1=2.0e10,
        E_L2=9.5e9,
        E_L3=5.0e10,
        eta_L2=1.0e10,
        eta_L3=1.0e12,
        E_UL1=1.5e10,
        E_UL2=6.0e9,
        E_UL3=3.0e10,
        eta_UL2=2.0e10,
        eta_UL3=5.0e11,
    )


def floats(model):
    """The model with Python-float array leaves, for NumPy reference formulas."""
    return jax.tree.map(lambda x: float(x) if eqx.is_array(x) else x, model)


def humidity_history(seed: int, samples: int = 150):
    """A cycling force (N, loaded throughout) and a humidity (%RH) with steps, flats
    and ramps at another period: `(time s, force, humidity)`. A mechano-sorptive
    creep runs only while the humidity changes, unlike any function of the load or
    of the humidity itself."""
    rng = np.random.default_rng(seed)
    time = np.linspace(0.0, 3000.0, samples)
    force = 100.0 * (1 + 0.3 * seed) * (0.6 - 0.4 * np.cos(2 * np.pi * time / 500.0))
    force = np.clip(force + 0.2 * rng.normal(size=samples), 0.0, None)
    knots = np.array([0, 600, 900, 1500, 1800, 2300, 2600, 3000]) + 50 * seed
    humidity = np.interp(time, knots, [50, 50, 80, 80, 50, 50, 85, 85])
    return time, force, humidity


def run_cli(argv):
    """`jaxcable` with `argv`, in this process, stdout and stderr captured:
    `(status, stdout, stderr)`."""
    stdout, stderr = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
        status = main([str(a) for a in argv])
    return status, stdout.getvalue(), stderr.getvalue()


def creep_recovery_protocol(force):
    """A short force-controlled history: one cycle to `force` (N), then twice a
    creep hold (1 h in two parts) and a recovery (2 h at 0 N); a blocked time split
    holds out the repeat."""
    block = jc.Protocol.concatenate(
        jc.Protocol.ramp(0.0, force, 10),
        jc.Protocol.hold(force, 600.0, 5),
        jc.Protocol.hold(force, 3000.0, 6),
        jc.Protocol.ramp(force, 0.0, 10),
        jc.Protocol.rest(600.0, 5),
        jc.Protocol.rest(6600.0, 6),
    )
    return jc.Protocol.concatenate(jc.Protocol.cycles(force, 1, 10), block, block)
