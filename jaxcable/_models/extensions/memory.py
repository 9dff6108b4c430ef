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

A damage grows with the load history, I = integral of (sigma / SIGMA_REF)^b dN (or
dt), and scales the base's strain (`damage_*`) or the stress (`compliance_*`: an
elastic compliance that grows, and leaves with the load):

    eps += theta x I / (1 - D),      D = a I capped at `MAX_DAMAGE`,

with x = eps_base or sigma, so that the strain runs away as the damage D approaches 1 (fatigue or creep
rupture approached). The amplitude theta and the acceleration a are apart: a
damage confined to a small part of the cable (a splice, the sections at the
terminations) softens the whole by little and still runs away. a = 0 is a damage
linear in I; a = theta is D / (1 - D) of the whole cable (D = theta I).

Each term has one nonlinear parameter, k (1 / unit of the driver) or b (-), in the
`rate` field of its slot, and a damage a second one, a (1/cycle or 1/s: 1 / the
unit of I), in its `accel` field; theta is linear, as for the stateless terms, and
the regression's column is the strain per unit theta at a fixed rate and
acceleration.
"""

import re

import jax.numpy as jnp
from jaxtyping import Array

from ..kernels import safe_pow


# The reference stress of a damage's power law, Pa (10 MPa: a 3 mm cable at 70 N).
SIGMA_REF = 1e7
# The largest damage the strain is scaled by: 1 / (1 - D) <= 10.
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
        "dI/dN = (sigma/10 MPa)^b",
        "1/cycle",
        "-",
        "damage",
        "strain",
        "N",
    ),
    "damage_time": (
        "dI/dt = (sigma/10 MPa)^b",
        "1/s",
        "-",
        "damage",
        "strain",
        "t",
    ),
    "compliance_cycles": (
        "dI/dN = (sigma/10 MPa)^b",
        "1/(Pa cycle)",
        "-",
        "damage",
        "sigma",
        "N",
    ),
    "compliance_time": (
        "dI/dt = (sigma/10 MPa)^b",
        "1/(Pa s)",
        "-",
        "damage",
        "sigma",
        "t",
    ),
}
"""The terms with state of [`DiscoveredTerm`][]: id -> (equation, unit of theta,
unit of the rate k or exponent b, kind, target, driver). A relaxing term's target
is what q relaxes towards; a damage's is what it scales: the base's strain (creep
included, and what stays after unloading) or the stress (an elastic compliance
that grows: it leaves with the load)."""

# The exponents b of a damage the regression tries (the joint fit holds the chosen
# one, and the acceleration: see `DiscoveredTerm.used_fields`).
DAMAGE_EXPONENTS = (1.0, 2.0, 3.0, 4.0, 6.0)
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
    "damage_cycles": DAMAGE_EXPONENTS,
    "damage_time": DAMAGE_EXPONENTS,
    "compliance_cycles": DAMAGE_EXPONENTS,
    "compliance_time": DAMAGE_EXPONENTS,
}
# The accelerations of a damage the regression tries, as the damage D = a I they
# reach at the largest I of the tests (`accel_grid`): nearly linear, then running
# away more and more by the end.
ACCEL_GRID = (0.02, 0.2, 0.35, 0.5, 0.6, 0.7, 0.8, 0.85)


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


def accel_unit(term: str) -> str:
    """The unit of a damage's acceleration a: 1 / the unit of its integral I."""
    return "1/cycle" if MEMORY_TERMS[term][5] == "N" else "1/s"


def accel_grid(term: str, largest: float) -> tuple[float, ...]:
    """The accelerations a of `term` the regression tries: `ACCEL_GRID` / `largest`
    (the largest damage integral I of the tests), or (0,) for a relaxing term."""
    if MEMORY_TERMS[term][3] != "damage":
        return (0.0,)
    return tuple(f / max(largest, 1e-300) for f in ACCEL_GRID)


def driver_increment(driver: str, dt, dt_loaded, c0, c1, cycles0, cycles1):
    """The increment of a term's driver over a step (see [`memory_step`][] for the
    arguments): elapsed time, time under load, |dc| or load cycles. Elementwise, on
    traced arrays and on NumPy ones alike (NumPy stays NumPy: the regression's
    columns keep float64)."""
    return {
        "t": dt,
        "t_load": dt_loaded,
        "|dc|": abs(c1 - c0),
        "N": cycles1 - cycles0,
    }[driver]


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
    increment = driver_increment(driver, dt, dt_loaded, c0, c1, cycles0, cycles1)
    if kind == "relax":
        goal = 0.5 * (sigma0 + sigma1) if target == "sigma" else 0.5 * (c0 + c1)
        return goal + (q0 - goal) * jnp.exp(-rate * increment)
    load = 0.5 * (
        safe_pow(jnp.maximum(sigma0, 0.0) / SIGMA_REF, rate)
        + safe_pow(jnp.maximum(sigma1, 0.0) / SIGMA_REF, rate)
    )
    return q0 + load * increment


def memory_strain(term: str, theta, q, base_strain, sigma, accel=0.0) -> Array:
    """The strain a term with memory adds: theta q (relaxing), or theta x I / (1 -
    D), D = min(a I, `MAX_DAMAGE`) (damage; `accel` a >= 0), x the base's strain
    `base_strain` or the stress `sigma` (Pa), as the term's target says."""
    return theta * memory_column(term, q, base_strain, sigma, accel)


def memory_column(term: str, q, base_strain, sigma, accel=0.0) -> Array:
    """A term with memory's strain per unit theta: q, or x I / (1 - D) (the
    regression's column at a fixed rate and acceleration; x as in
    [`memory_strain`][])."""
    _, _, _, kind, target, _ = MEMORY_TERMS[term]
    if kind == "relax":
        return q
    scaled = base_strain if target == "strain" else sigma
    # min(a I, MAX_DAMAGE) by arithmetic, so that NumPy columns (the regression's)
    # stay NumPy float64 whatever JAX's default precision.
    damage = accel * q
    damage = damage + (MAX_DAMAGE - damage) * (damage > MAX_DAMAGE)
    return scaled * q / (1.0 - damage)


def memory_equation(
    term: str, theta: str, rate: str, covariate: str, accel: str = "0"
) -> str:
    """`term`'s contribution as an equation with its state, e.g. `eps += theta q;
    dq/dt = k (sigma - q), k = 5.6e-4 1/s`, the covariate named (`accel`: a
    damage's acceleration a, as text)."""
    equation, _, _, kind, _, _ = MEMORY_TERMS[term]
    equation = equation.replace("dc", f"d{covariate}").replace(
        "(c - q)", f"({covariate} - q)"
    )
    if kind == "relax":
        return f"{theta} * q, {equation}, k = {rate}"
    scaled = "eps_base" if MEMORY_TERMS[term][4] == "strain" else "sigma"
    return f"{theta} * {scaled} I/(1 - a I), {equation}, b = {rate}, a = {accel}"
