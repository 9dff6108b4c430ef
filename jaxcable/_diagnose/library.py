"""What the discovery and the covariates' candidates read: each library term's
integrated strain along a force-driven test per unit of its coefficient
([`jaxcable.DiscoveredTerm`][]), the fitted base as a start and its sensitivities at
its fit, and the recorded covariate columns."""

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._drive import FORCE_DRIVEN
from .._fit import FitResult, make_problem, residuals_and_jacobian
from .._models import AbstractCableModel, discovered


MAX_TERMS = discovered.MAX_TERMS
TERMS = discovered.TERMS
THETA_FIELDS = discovered.THETA_FIELDS
DiscoveredTerm = discovered.DiscoveredTerm
cycle_count = discovered.cycle_count
term_increments = discovered.term_increments
theta_unit = discovered.theta_unit
tension_time_step = discovered.tension_time_step

# The terms that read the covariate (left out of the library without one).
COVARIATE_TERMS = ("c", "c_rate", "c_abs_rate", "sigma_c", "sigma_c_abs_rate")


def library(test, covariate: str | None, names=tuple(TERMS)) -> dict[str, np.ndarray]:
    """Each library term's contribution to the discovered strain per unit theta,
    eps_k(t) (the cumulative sum of [`term_increments`][] along the test, as
    `DiscoveredTerm.advance` integrates it), host-side.

    **Arguments:**

    - `test`: a force-driven test (time s, force N, `cable()`).
    - `covariate`: the extra column read as c, or None (c = 0).
    - `names`: the terms wanted.

    **Returns:**

    `{term: eps_k per sample}` (1/theta_k units: s x unit of phi).
    """
    time = np.asarray(test.time, float)
    force = np.asarray(test.force, float)
    c = np.zeros_like(time)
    if covariate is not None:
        c = np.asarray(test.extra[covariate], float)
    cable = test.cable()
    area = float(cable.area)
    # The first sample is applied from the unloaded cable at time[0] (dt = 0).
    force0 = np.r_[0.0, force[:-1]]
    c0 = np.r_[c[0], c[:-1]]
    dt = np.r_[0.0, np.diff(time)]
    force_max = np.maximum.accumulate(np.maximum(force, 0.0))
    dt_loaded = np.asarray(
        jax.vmap(tension_time_step, in_axes=(0, 0, 0, None, 0))(
            jnp.asarray(force0), jnp.asarray(force), jnp.asarray(dt), cable, force_max
        ),
        float,
    )
    loaded = np.cumsum(dt_loaded)
    rest = np.cumsum(dt - dt_loaded)
    cycles = np.asarray(
        cycle_count(np.cumsum(np.abs(force - force0)), force_max), float
    )

    def before(x):
        return np.r_[0.0, x[:-1]]

    increments = term_increments(
        force0 / area,
        force / area,
        c0,
        c,
        dt,
        before(loaded),
        loaded,
        before(rest),
        rest,
        before(cycles),
        cycles,
    )
    return {k: np.cumsum(np.asarray(increments[k], float)) for k in names}


def base_start(base_fit: FitResult) -> AbstractCableModel:
    """The fitted base as a start model (per-test values averaged to scalars)."""
    return jax.tree_util.tree_map(
        lambda x: jnp.mean(x) if eqx.is_inexact_array(x) and x.ndim else x,
        base_fit.model,
    )


def base_fit_names(base_fit: FitResult) -> tuple[list[str], list[str]]:
    """`(shared, per_test)`: the base's fitted parameters as paths of a model
    wrapping it (`base.NAME`), the per-test ones apart."""
    per = ["base." + n for n in getattr(base_fit, "per_test", ())]
    names = dict.fromkeys("base." + n.split("[")[0] for n in base_fit.names)
    return [n for n in names if n not in per], per


def sensitivities(base, base_fit: FitResult, tests) -> list[np.ndarray]:
    """d(model elongation)/du of the base's fitted parameters at its fit (u: the
    fit's unconstrained parameters, log for the positive ones), m, one
    `(samples, p)` array per test, every sample."""
    names = list(dict.fromkeys(n.split("[")[0] for n in base_fit.names))
    full = [
        dataclasses.replace(
            t, mask=None, elongation=np.nan_to_num(np.asarray(t.elongation, float))
        )
        for t in tests
    ]
    problem, u = make_problem(base, full, names, None, None, FORCE_DRIVEN.name)
    _, jacobian = residuals_and_jacobian(problem, u, "fwd")
    jacobian = np.asarray(jacobian).reshape(len(full), -1, u.shape[0])
    return [jacobian[i, : len(t.time)] for i, t in enumerate(full)]
