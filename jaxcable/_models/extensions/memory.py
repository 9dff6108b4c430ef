r"""Terms with state for [`jaxcable.DiscoveredTerm`][]: an internal variable that
relaxes towards a target, driven by what the data record, and a damage that grows
with the load history and scales the compliance.

A relaxing variable q (one per term) follows

    dq = k (target - q) dchi,      eps += theta q,

with `target` the stress sigma (Pa) or the covariate c, and `dchi` the driver's
increment over a step: elapsed time (s), time under load (s), the covariate's
absolute change |dc|, or equivalent load cycles dN. Over a step the target is held
at its mean, so the update is exact: q1 = m + (q0 - m) exp(-k dchi). With the driver
|dc| it is the saturating mechano-sorptive creep of wood and paper,
d(eps)/dt = m |dc/dt| (sigma / E_ms - eps) (k = m, theta = 1 / E_ms); with the
driver t and the target c a covariate strain that lags its covariate by 1/k.

A damage D = theta I, I = integral of (sigma / SIGMA_REF)^b dN (or dt), scales the
base's strain: eps += eps_base D / (1 - D), D capped at `MAX_DAMAGE` (the strain runs
away as D grows: fatigue or creep rupture approached). To first order in D the
strain is theta eps_base I, the column the discovery's regression uses.

Each term has one nonlinear parameter, k (1 / unit of the driver) or b (-), in the
`rate` field of its slot; theta is linear, as for the stateless terms.
"""

import re

import jax.numpy as jnp
from jaxtyping import Array

from ..kernels import safe_pow


# The reference stress of a damage's power law, Pa (10 MPa: a 3 mm cable at 70 N).
SIGMA_REF = 1e7
# The largest damage the strain is scaled by: D / (1 - D) <= 9.
MAX_DAMAGE = 0.9

# Each term with state: (equation of its state, unit of theta, unit of its rate,
# kind, target, driver).
MEMORY_TERMS: dict[str, tuple[str, str, str, str, str, str]] = {
    "relax_sigma_time": ("dq/dt = k (sigma - q)", "1/Pa", "1/s", "relax", "sigma", "t"),
    "relax_sigma_loaded": (
        "dq/dt_load = k (sigma - q)",
        "1/Pa",
        "1/s",
        "relax",
        "sigma",
        "t_load",
    ),
    "relax_sigma_c_abs_rate": (
        "dq/dt = k |dc/dt| (sigma - q)",
        "1/Pa",
        "1/c",
        "relax",
        "sigma",
        "|dc|",
    ),
    "relax_sigma_cycles": (
        "dq/dN = k (sigma - q)",
        "1/Pa",
        "1/cycle",
        "relax",
        "sigma",
        "N",
    ),
    "relax_c_time": ("dq/dt = k (c - q)", "1/c", "1/s", "relax", "c", "t"),
    "damage_cycles": (
        "dD/dN = theta (sigma/10 MPa)^b",
        "1/cycle",
        "-",
        "damage",
        "sigma",
        "N",
    ),
    "damage_time": (
        "dD/dt = theta (sigma/10 MPa)^b",
        "1/s",
        "-",
        "damage",
        "sigma",
        "t",
    ),
}
"""The terms with state of [`DiscoveredTerm`][]: id -> (equation, unit of theta,
unit of the rate k or exponent b, kind, target, driver)."""

# The rates the discovery's regression tries for each term (the joint fit refines
# the chosen one): relaxation rates per unit of the driver (for |dc|, per unit of
# the covariate's mean total variation over a test: see `rate_grid`), damage
# exponents.
RATE_GRID: dict[str, tuple[float, ...]] = {
    "relax_sigma_time": (1 / 300, 1 / 1800, 1 / 10800, 1 / 43200),
    "relax_sigma_loaded": (1 / 300, 1 / 1800, 1 / 10800),
    "relax_sigma_c_abs_rate": (0.3, 1.0, 3.0, 10.0),
    "relax_sigma_cycles": (0.03, 0.1, 0.3, 1.0),
    "relax_c_time": (1 / 300, 1 / 1800, 1 / 10800),
    "damage_cycles": (1.0, 2.0, 4.0),
    "damage_time": (1.0, 2.0, 4.0),
}


def covariate_in(unit: str, covariate_unit: str) -> str:
    """`unit` with its covariate's unit, the symbol `c`, written `covariate_unit`
    (`1/c` -> `1/[humidity_pct]`; `1/cycle` unchanged)."""
    return re.sub(r"\bc\b", covariate_unit, unit)


def rate_grid(term: str, covariate_variation: float = 1.0) -> tuple[float, ...]:
    """The rates of `term` the regression tries; for the |dc| driver scaled by
    1 / `covariate_variation` (the covariate's mean total variation over a test, so
    that k |dc| summed over a test is 0.3-10)."""
    grid = RATE_GRID[term]
    if MEMORY_TERMS[term][5] == "|dc|":
        return tuple(g / max(covariate_variation, 1e-300) for g in grid)
    return grid


def memory_step(
    term: str, rate, q0, sigma0, sigma1, c0, c1, dt, dt_loaded, cycles0, cycles1
) -> Array:
    """The state of a term with memory after one step, from its value `q0` and the
    step's start (0) and end (1) values: stress (Pa), covariate (its unit), step
    dt (s), time under load over it (s), cycles so far (-). Elementwise.

    **Returns:**

    q1 (a relaxing variable: Pa or the covariate's unit) or I1 (a damage's integral).
    """
    _, _, _, kind, target, driver = MEMORY_TERMS[term]
    increment = {
        "t": dt,
        "t_load": dt_loaded,
        "|dc|": jnp.abs(c1 - c0),
        "N": cycles1 - cycles0,
    }[driver]
    if kind == "relax":
        goal = 0.5 * (sigma0 + sigma1) if target == "sigma" else 0.5 * (c0 + c1)
        return goal + (q0 - goal) * jnp.exp(-rate * increment)
    load = 0.5 * (
        safe_pow(jnp.maximum(sigma0, 0.0) / SIGMA_REF, rate)
        + safe_pow(jnp.maximum(sigma1, 0.0) / SIGMA_REF, rate)
    )
    return q0 + load * increment


def memory_strain(term: str, theta, q, base_strain) -> Array:
    """The strain a term with memory adds: theta q (relaxing), or eps_base D / (1 -
    D), D = min(theta I, `MAX_DAMAGE`) (damage)."""
    if MEMORY_TERMS[term][3] == "relax":
        return theta * q
    damage = jnp.minimum(theta * q, MAX_DAMAGE)
    return base_strain * damage / (1.0 - damage)


def memory_column(term: str, q, base_strain) -> Array:
    """A term with memory's strain per unit theta, to first order: q, or eps_base I
    (the regression's column)."""
    if MEMORY_TERMS[term][3] == "relax":
        return q
    return base_strain * q


def memory_equation(term: str, theta: str, rate: str, covariate: str) -> str:
    """`term`'s contribution as an equation with its state, e.g. `eps += theta q;
    dq/dt = k (sigma - q), k = 5.6e-4 1/s`, the covariate named."""
    equation, _, _, kind, _, _ = MEMORY_TERMS[term]
    equation = equation.replace("dc", f"d{covariate}").replace(
        "(c - q)", f"({covariate} - q)"
    )
    if kind == "relax":
        return f"{theta} * q, {equation}, k = {rate}"
    return (
        f"eps_base D/(1-D), D = theta I, {equation.replace('theta', theta)}, b = {rate}"
    )
