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
from .._models import AbstractCableModel, discovered, memory


MAX_TERMS = discovered.MAX_TERMS
TERMS = discovered.TERMS
THETA_FIELDS = discovered.THETA_FIELDS
RATE_FIELDS = discovered.RATE_FIELDS
ACCEL_FIELDS = discovered.ACCEL_FIELDS
MEMORY_TERMS = memory.MEMORY_TERMS
SIGMA_REF = memory.SIGMA_REF
memory_column = memory.memory_column
memory_equation = memory.memory_equation
covariate_in = memory.covariate_in
rate_grid = memory.rate_grid
accel_grid = memory.accel_grid
accel_unit = memory.accel_unit
DiscoveredTerm = discovered.DiscoveredTerm
cycle_count = discovered.cycle_count
term_increments = discovered.term_increments
theta_unit = discovered.theta_unit
tension_time_step = discovered.tension_time_step

# The terms that read the covariate (left out of the library without one).
COVARIATE_TERMS = (
    "c",
    "c_rate",
    "c_abs_rate",
    "sigma_c",
    "sigma_c_abs_rate",
    "relax_sigma_c_abs_rate",
    "relax_c_time",
)


def step_inputs(test, covariate: str | None) -> dict[str, np.ndarray]:
    """The start (0) and end (1) values of every step of a force-driven test, as
    `DiscoveredTerm.advance` sees them: stress (Pa), covariate (its unit; 0 without
    one), dt (s), time under load and rest time so far (s), cycles so far (-), and
    the step's time under load (s). The first sample is applied from the unloaded
    cable at time[0] (dt = 0)."""
    time = np.asarray(test.time, float)
    force = np.asarray(test.force, float)
    c = np.zeros_like(time)
    if covariate is not None:
        c = np.asarray(test.extra[covariate], float)
    cable = test.cable()
    area = float(cable.area)
    force0 = np.r_[0.0, force[:-1]]
    c0 = np.r_[c[0], c[:-1]]
    dt = np.r_[0.0, np.diff(time)]
    force_max = np.maximum.accumulate(np.maximum(force, 0.0))
    dt_loaded = np.asarray(
        jax.vmap(tension_time_step, in_axes=(0, 0, 0, None, 0))(
            jnp.asarray(force0),
            jnp.asarray(force),
            jnp.asarray(dt),
            cable,
            jnp.asarray(force_max),
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

    return {
        "sigma0": force0 / area,
        "sigma1": force / area,
        "c0": c0,
        "c1": c,
        "dt": dt,
        "loaded0": before(loaded),
        "loaded1": loaded,
        "rest0": before(rest),
        "rest1": rest,
        "cycles0": before(cycles),
        "cycles1": cycles,
        "dt_loaded": dt_loaded,
    }


def library(test, covariate: str | None, names=tuple(TERMS)) -> dict[str, np.ndarray]:
    """Each library term's contribution to the discovered strain per unit theta,
    eps_k(t) (the cumulative sum of `term_increments` along the test, as
    `DiscoveredTerm.advance` integrates it), host-side.

    **Arguments:**

    - `test`: a force-driven test (time s, force N, `cable()`).
    - `covariate`: the extra column read as c, or None (c = 0).
    - `names`: the terms wanted.

    **Returns:**

    `{term: eps_k per sample}` (1/theta_k units: s x unit of phi).
    """
    x = step_inputs(test, covariate)
    increments = term_increments(
        *(x[k] for k in ("sigma0", "sigma1", "c0", "c1", "dt", "loaded0")),
        *(x[k] for k in ("loaded1", "rest0", "rest1", "cycles0", "cycles1")),
    )
    return {k: np.cumsum(np.asarray(increments[k], float)) for k in names}


def _driver_steps(x: dict[str, np.ndarray], driver: str) -> np.ndarray:
    """The increments of a term's driver over every step of `step_inputs`' `x`."""
    keys = ("dt", "dt_loaded", "c0", "c1", "cycles0", "cycles1")
    return memory.driver_increment(driver, *(x[k] for k in keys))


def damage_integral(x: dict[str, np.ndarray], term: str, rate: float) -> np.ndarray:
    """A damage's integral I = integral of (sigma / `SIGMA_REF`)^b dN (or dt) at
    every sample of a test (b = `rate`), host-side: the recurrence of `memory_step`
    on the test's [`step_inputs`][] `x`."""
    load = 0.5 * (
        (np.maximum(x["sigma0"], 0.0) / SIGMA_REF) ** rate
        + (np.maximum(x["sigma1"], 0.0) / SIGMA_REF) ** rate
    )
    return np.cumsum(load * _driver_steps(x, MEMORY_TERMS[term][5]))


def memory_library(
    test, covariate: str | None, base_strain: np.ndarray, keys
) -> dict[tuple, np.ndarray]:
    """Each term with memory's strain per unit theta along a test, at a fixed rate
    (and for a damage a fixed acceleration; the base's strain held: `memory_column`),
    host-side: the recurrences of `memory_step` in NumPy.

    **Arguments:**

    - `test`, `covariate`: as in `library`.
    - `base_strain`: the base model's strain at every sample (a `damage_*` scales
        it; a `compliance_*` scales the stress).
    - `keys`: `(term, rate, accel)` triples ([`MEMORY_TERMS`][] ids; `accel` is
        read by the damages only).

    **Returns:**

    `{(term, rate, accel): column per sample}`.
    """
    x = step_inputs(test, covariate)
    out = {}
    for term, rate, accel in keys:
        _, _, _, kind, target, driver = MEMORY_TERMS[term]
        if kind == "damage":
            q = damage_integral(x, term, rate)
        else:
            start = x["c1"][0] if target == "c" else 0.0
            goal = 0.5 * (
                x["sigma0"] + x["sigma1"] if target == "sigma" else x["c0"] + x["c1"]
            )
            decay = np.exp(-rate * _driver_steps(x, driver))
            q = np.empty_like(goal)
            value = start
            for i in range(goal.size):
                value = goal[i] + (value - goal[i]) * decay[i]
                q[i] = value
            q = q - start
        column = memory_column(term, q, base_strain, x["sigma1"], accel)
        out[(term, rate, accel)] = np.asarray(column, float)
    return out


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


def sensitivities(
    base, base_fit: FitResult, tests, covariate: str | None = None
) -> list[np.ndarray]:
    """d(model elongation)/du of the base's fitted parameters at its fit (u: the
    fit's unconstrained parameters, log for the positive ones), m, one
    `(samples, p)` array per test, every sample; the base driven by the column
    `covariate` (or none)."""
    names = list(dict.fromkeys(n.split("[")[0] for n in base_fit.names))
    full = [
        dataclasses.replace(
            t, mask=None, elongation=np.nan_to_num(np.asarray(t.elongation, float))
        )
        for t in tests
    ]
    problem, u = make_problem(
        base, full, names, None, None, FORCE_DRIVEN.name, covariate
    )
    _, jacobian = residuals_and_jacobian(problem, u, "fwd")
    jacobian = np.asarray(jacobian).reshape(len(full), -1, u.shape[0])
    return [jacobian[i, : len(t.time)] for i, t in enumerate(full)]
