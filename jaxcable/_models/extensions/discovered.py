r"""A strain found by sparse regression on the residual of a base model
([`DiscoveredTerm`][]): d(eps_d)/dt = sum_k theta_k phi_k over a fixed library of
terms (the stress, its rate, time under load, rest time, cycles, a recorded
covariate, its rate, and products), each computable from the model's own inputs.

The library is one function (`term_increments`) of a step's end values, used
both inside `advance` (scalars, traced) and host-side by the discovery on whole
histories (arrays), so that the regression and the model integrate the same terms.
"""

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float, Int, PyTree

from ..._cable import Cable
from ..base import (
    AbstractExtension,
    StrainParts,
    add_parts,
    covariate_of,
    state_zero,
)
from ..fields import parameter, signed_effect
from ..kernels import running_max, tension_time_step
from .memory import MEMORY_TERMS, covariate_in, memory_step, memory_strain


# Each term of the library: its symbol in an equation and its unit ("c" stands for
# the covariate's unit). The term's coefficient theta has unit 1/s per unit of phi.
TERMS: dict[str, tuple[str, str]] = {
    "sigma": ("sigma", "Pa"),
    "sigma_rate": ("d(sigma)/dt", "Pa/s"),
    "sigma_abs_rate": ("|d(sigma)/dt|", "Pa/s"),
    "time_loaded": ("t_load", "s"),
    "time_rest": ("t_rest", "s"),
    "cycles": ("N_cyc", "-"),
    "sigma_sq": ("sigma^2", "Pa^2"),
    "sigma_cycles_rate": ("d(sigma N_cyc)/dt", "Pa/s"),
    "c": ("c", "c"),
    "c_rate": ("dc/dt", "c/s"),
    "c_abs_rate": ("|dc/dt|", "c/s"),
    "sigma_c": ("sigma * c", "Pa c"),
    "sigma_c_abs_rate": ("sigma * |dc/dt|", "Pa c/s"),
}
"""The library of [`DiscoveredTerm`][]: term id -> (symbol, unit of phi)."""

# The most terms one DiscoveredTerm carries (its fields theta0..theta3).
MAX_TERMS = 4
THETA_FIELDS = tuple(f"theta{k}" for k in range(MAX_TERMS))
RATE_FIELDS = tuple(f"rate{k}" for k in range(MAX_TERMS))
ACCEL_FIELDS = tuple(f"accel{k}" for k in range(MAX_TERMS))


def theta_unit(term: str, covariate_unit: str = "c") -> str:
    """The unit of the coefficient of `term`: 1/s per unit of phi (the covariate's
    unit written `covariate_unit`); for a term with memory its own
    (`MEMORY_TERMS`)."""
    if term in MEMORY_TERMS:
        return covariate_in(MEMORY_TERMS[term][1], covariate_unit)
    unit = TERMS[term][1]
    per_second = unit.endswith("/s")
    unit = unit.removesuffix("/s")
    unit = " ".join(covariate_unit if u == "c" else u for u in unit.split())
    if unit == "-":
        return "1/s"
    if per_second:
        return f"1/({unit})" if " " in unit else f"1/{unit}"
    return f"1/({unit} s)"


def term_increments(
    sigma0, sigma1, c0, c1, dt, loaded0, loaded1, rest0, rest1, cycles0, cycles1
) -> dict[str, Array]:
    """The integral of each library term over a step (the rates exactly, the others
    by the trapezoid rule), from the values at the step's start (0) and end (1):
    stress sigma (Pa), covariate c (its unit), step dt (s), time under load and rest
    time so far (s), cycles so far (-). Elementwise: scalars or whole histories.

    A rate term's integral is its increment (no division by dt, so a step of dt = 0,
    the first sample, is exact); an absolute rate's is the absolute increment.

    **Returns:**

    `{term: integral of phi over the step}`, in the unit of phi times s.
    """
    mean = lambda a, b: 0.5 * (a + b) * dt  # noqa: E731
    abs_dc = jnp.abs(c1 - c0)
    return {
        "sigma": mean(sigma0, sigma1),
        "sigma_rate": sigma1 - sigma0,
        "sigma_abs_rate": jnp.abs(sigma1 - sigma0),
        "time_loaded": mean(loaded0, loaded1),
        "time_rest": mean(rest0, rest1),
        "cycles": mean(cycles0, cycles1),
        "sigma_sq": mean(sigma0**2, sigma1**2),
        "sigma_cycles_rate": sigma1 * cycles1 - sigma0 * cycles0,
        "c": mean(c0, c1),
        "c_rate": c1 - c0,
        "c_abs_rate": abs_dc,
        "sigma_c": mean(sigma0 * c0, sigma1 * c1),
        "sigma_c_abs_rate": 0.5 * (sigma0 + sigma1) * abs_dc,
    }


def cycle_count(variation, force_max):
    """Equivalent full load cycles: the total variation of the force (N) over twice
    its largest value so far (N); 0 before any load. Continuous in the force
    history (no count of sign changes)."""
    positive = force_max > 0
    return jnp.where(positive, variation / (2.0 * jnp.where(positive, force_max, 1)), 0)


def _theta():
    """A coefficient of [`DiscoveredTerm`][]: 1/s per unit of its term (either
    sign; 0 by default: the term is off)."""
    return signed_effect("1/s per unit of phi")


class DiscoveredTermState(eqx.Module):
    """Scan carry of [`jaxcable.DiscoveredTerm`][] (SI; the covariate in its unit).

    **Fields:**

    - `base`: the wrapped model's state.
    - `started`: False until the first step (whose covariate has no predecessor).
    - `force`: force of the previous sample, N.
    - `covariate`: covariate of the previous sample, its unit.
    - `force_max`: the largest force so far, N.
    - `variation`: total variation of the force so far, N.
    - `loaded`: time under load so far, s (the base's continuous tension clock).
    - `rest`: time not under load so far, s.
    - `strain`: the discovered strain eps_d of the stateless terms.
    - `c_start`: the covariate at the first sample (a lagging covariate strain is
        measured from it), its unit.
    - `memory`: the state of each term with memory (a relaxing variable q, or a
        damage's integral I), one slot per term.
    """

    base: PyTree
    started: Array
    force: Float[Array, ""]
    covariate: Float[Array, ""]
    force_max: Float[Array, ""]
    variation: Float[Array, ""]
    loaded: Float[Array, ""]
    rest: Float[Array, ""]
    strain: Float[Array, ""]
    c_start: Float[Array, ""]
    memory: Float[Array, " 4"]


def _rate():
    """The nonlinear parameter of a term with memory: its relaxation rate k per unit
    of its driver, or its damage exponent b (positive; unused by stateless terms)."""
    return parameter(
        1.0, unit="1/unit of the driver (k), or - (b)", note="a rate or exponent"
    )


def _accel():
    """A damage's acceleration a (>= 0; 1/cycle or 1/s, 1 / the unit of its I): the
    damage D = a I that runs the strain away (unused by the other terms)."""
    return parameter(
        0.0,
        unit="1/unit of the damage integral I",
        domain="nonnegative",
        note="a damage's acceleration",
    )


class DiscoveredTerm(AbstractExtension[DiscoveredTermState]):
    r"""A strain integrated from a sparse sum of library terms:

        d(eps_d)/dt = sum_k theta_k phi_k,   eps = eps_base + eps_d (creep part),

    each phi_k one of `TERMS` (at most four, static strings in `terms`):

    | term | phi | unit of phi | unit of theta |
    | --- | --- | --- | --- |
    | `sigma` | sigma = F / A | Pa | 1/(Pa s) |
    | `sigma_rate` | d(sigma)/dt | Pa/s | 1/Pa |
    | `sigma_abs_rate` | abs(d(sigma)/dt) | Pa/s | 1/Pa |
    | `time_loaded` | time under load so far | s | 1/s^2 |
    | `time_rest` | time not under load so far | s | 1/s^2 |
    | `cycles` | equivalent load cycles, total variation of F / (2 max F) | - | 1/s |
    | `sigma_sq` | sigma^2 (creep faster than linear in stress) | Pa^2 | 1/(Pa^2 s) |
    | `sigma_cycles_rate` | d(sigma N_cyc)/dt (a compliance growing with cycles) | Pa/s | 1/Pa |
    | `c` | the covariate c (`Cable.covariate`) | c | 1/(c s) |
    | `c_rate`, `c_abs_rate` | dc/dt, abs(dc/dt) | c/s | 1/c |
    | `sigma_c` | sigma c | Pa c | 1/(Pa c s) |
    | `sigma_c_abs_rate` | sigma abs(dc/dt) (mechano-sorptive creep) | Pa c/s | 1/(Pa c) |

    `sigma_cycles_rate` integrates to theta sigma N_cyc: a strain that grows with
    the load cycles, as the compliance of a braid abraded cycle after cycle.
    Where c is in the unit of the recorded covariate column (the fit sets
    `Cable.covariate` per sample from `jaxcable.fit(..., covariate=NAME)`). Over a
    step the terms are integrated as `term_increments` says (rates exactly,
    others by the trapezoid rule); time under load is the base's continuous tension
    clock (`jaxcable._models.kernels.tension_time_step`). Theta `k` belongs to
    `terms[k]`; the thetas beyond `len(terms)` are unused, stay 0 and are not
    fitted (fit only `used_fields()`). All thetas 0 is the base exactly.

    **Continuity.** The increment is linear in the thetas and Lipschitz in the force
    and covariate samples, except that the absolute-rate terms (`sigma_abs_rate`,
    `c_abs_rate`, `sigma_c_abs_rate`), `cycles` and `sigma_cycles_rate` accumulate the total variation of
    their signal: noise on it adds theta x its total variation. The discovery keeps
    such a term only when it predicts held-out data.

    **Fields:**

    - `base`: the wrapped model.
    - `theta0` .. `theta3`: the coefficients, 1/s per unit of phi (either sign).
    - `rate0` .. `rate3`: a term with memory's rate k or damage exponent b
        (`jaxcable._models.extensions.memory`).
    - `accel0` .. `accel3`: a damage's acceleration a, the unit of its theta
        (0: linear in its integral I).
    - `terms`: the term ids, at most four, static.

    `wrap(base)` gives all thetas 0 and no terms (the base); the discovery builds
    the instance to fit (`jaxcable.discover`).
    """

    CLI_NAME = "discovered"

    theta0: Float[Array, ""] = _theta()
    theta1: Float[Array, ""] = _theta()
    theta2: Float[Array, ""] = _theta()
    theta3: Float[Array, ""] = _theta()
    rate0: Float[Array, ""] = _rate()
    rate1: Float[Array, ""] = _rate()
    rate2: Float[Array, ""] = _rate()
    rate3: Float[Array, ""] = _rate()
    accel0: Float[Array, ""] = _accel()
    accel1: Float[Array, ""] = _accel()
    accel2: Float[Array, ""] = _accel()
    accel3: Float[Array, ""] = _accel()
    terms: tuple[str, ...] = eqx.field(static=True, default=())

    def check_more(self):
        terms = self.terms
        if not isinstance(terms, tuple) or len(terms) > MAX_TERMS:
            raise ValueError(
                f"DiscoveredTerm `terms` must be a tuple of at most {MAX_TERMS} term "
                f"ids, got {terms!r}."
            )
        unknown = [t for t in terms if t not in TERMS and t not in MEMORY_TERMS]
        if unknown or len(set(terms)) != len(terms):
            raise ValueError(
                f"DiscoveredTerm `terms` {terms!r}: each must be one of "
                f"{[*TERMS, *MEMORY_TERMS]}, without repeats."
            )

    def used_fields(self) -> tuple[str, ...]:
        """The fields of the terms in use (the ones to fit): `theta0`, ... and the
        rate k of each relaxing term. A damage's shape, its exponent b and its
        acceleration a, is held where the discovery's held-out choice put it: over
        tests at a few stress levels b trades with theta (theta (sigma / 10 MPa)^b
        at one level), and the training samples see too little of the run-away to
        fix a (fitted, both drift to a shape that fits the training samples and
        extrapolates worse)."""
        rates = [
            RATE_FIELDS[k]
            for k, t in enumerate(self.terms)
            if t in MEMORY_TERMS and MEMORY_TERMS[t][3] == "relax"
        ]
        return THETA_FIELDS[: len(self.terms)] + tuple(rates)

    def init(self, cable: Cable) -> DiscoveredTermState:
        zero = state_zero(cable, *(getattr(self, n) for n in THETA_FIELDS))
        return DiscoveredTermState(
            self.base.init(cable),
            jnp.array(False),
            zero,
            zero,
            zero,
            zero,
            zero,
            zero,
            zero,
            zero,
            jnp.zeros(MAX_TERMS, zero.dtype),
        )

    def advance(
        self,
        state: DiscoveredTermState,
        cable: Cable,
        dt: Float[Array, ""],
        force: Float[Array, ""],
        direction: Int[Array, ""],
    ) -> tuple[DiscoveredTermState, StrainParts]:
        base_state, parts = self.base.advance(state.base, cable, dt, force, direction)
        area = cable.area
        covariate = covariate_of(cable, state.covariate)
        # The first step has no previous covariate: no change of it then.
        c0 = jnp.where(state.started, state.covariate, covariate)
        force_max = running_max(state.force_max, force)
        dt_loaded = tension_time_step(state.force, force, dt, cable, force_max)
        loaded = state.loaded + dt_loaded
        rest = state.rest + (dt - dt_loaded)
        variation = state.variation + jnp.abs(force - state.force)
        increments = term_increments(
            state.force / area,
            force / area,
            c0,
            covariate,
            dt,
            state.loaded,
            loaded,
            state.rest,
            rest,
            cycle_count(state.variation, state.force_max),
            cycle_count(variation, force_max),
        )
        stateless = [(k, t) for k, t in enumerate(self.terms) if t in TERMS]
        strain = state.strain + sum(
            (getattr(self, THETA_FIELDS[k]) * increments[t] for k, t in stateless),
            start=jnp.zeros_like(state.strain),
        )
        c_start = jnp.where(state.started, state.c_start, covariate)
        memory, added = state.memory, strain
        # The cable's strain: a damage never scales what the instrument adds.
        base_strain = parts.total - parts.apparatus
        for k, t in enumerate(self.terms):
            if t not in MEMORY_TERMS:
                continue
            rate = getattr(self, RATE_FIELDS[k])
            # A relaxing covariate starts at the first sample's covariate.
            q0 = jnp.where(state.started, memory[k], c_start)
            q0 = q0 if t == "relax_c_time" else memory[k]
            q1 = memory_step(
                t,
                rate,
                q0,
                state.force / area,
                force / area,
                c0,
                covariate,
                dt,
                dt_loaded,
                cycle_count(state.variation, state.force_max),
                cycle_count(variation, force_max),
            )
            memory = memory.at[k].set(q1)
            q = q1 - c_start if t == "relax_c_time" else q1
            added = added + memory_strain(
                t,
                getattr(self, THETA_FIELDS[k]),
                q,
                base_strain,
                force / area,
                getattr(self, ACCEL_FIELDS[k]),
            )
        new = DiscoveredTermState(
            base_state,
            jnp.array(True),
            force,
            covariate,
            force_max,
            variation,
            loaded,
            rest,
            strain,
            c_start,
            memory,
        )
        return new, add_parts(parts, creep=added)
