"""The state of one simulated cable and what every drive does with it at each sample:
[`jaxcable.states.CableState`][], [`jaxcable.init_state`][], the commit of a sample (the
first failure kept, padding samples skipped) and the [`jaxcable.Trajectory`][] that a
simulation returns."""

import math

import equinox as eqx
import jax.numpy as jnp
import jax.tree_util as jtu
from jaxtyping import Array, ArrayLike, Bool, Float, Int, PyTree

from .._cable import Cable
from .._models import AbstractCableModel, StrainParts
from .._results import RESULTS


class Trajectory(eqx.Module):
    """A simulated strain history (one cable; a leading batch axis when vmapped).

    **Fields:**

    - `time`: time of each sample, s.
    - `force`: cable force, N.
    - `strain`: total strain (elongation / L0), dimensionless.
    - `elongation`: elongation, m.
    - `parts`: the strain split into instantaneous, creep, short- and long-term
        recovery and the apparatus's part ([`jaxcable.StrainParts`][]).
    - `mask`: False at padding samples (their values repeat the last valid sample).
    - `result`: a [`jaxcable.RESULTS`][]: `successful`, or the first failure.
    """

    time: Float[Array, "*batch samples"]
    force: Float[Array, "*batch samples"]
    strain: Float[Array, "*batch samples"]
    elongation: Float[Array, "*batch samples"]
    parts: StrainParts
    mask: Bool[Array, "*batch samples"]
    result: RESULTS

    @property
    def instantaneous(self):
        return self.parts.instantaneous

    @property
    def creep(self):
        return self.parts.creep

    @property
    def recovery_short(self):
        return self.parts.recovery_short

    @property
    def recovery_long(self):
        return self.parts.recovery_long

    @property
    def apparatus(self):
        return self.parts.apparatus


class CableState(eqx.Module):
    """The driver-level state of one simulated cable: a model's state plus the last
    sample's time (s), force (N) and strain, the duration of the last step (s) and
    the first failure so far.

    This is the carry of every simulation's `lax.scan`, and what [`jaxcable.step`][]
    takes and returns inside a user's own scan or controller.
    """

    model_state: PyTree
    time: Float[Array, ""]
    force: Float[Array, ""]
    strain: Float[Array, ""]
    last_step: Float[Array, ""]
    result: RESULTS


def init_state(
    model: AbstractCableModel, cable: Cable, time: ArrayLike = 0.0
) -> CableState:
    """The state of a new, unloaded cable at `time` (s).

    **Arguments:**

    - `model`: any [`jaxcable.AbstractCableModel`][].
    - `cable`: the [`jaxcable.Cable`][].
    - `time`: the time of the initial state, s.

    **Returns:**

    A [`jaxcable.states.CableState`][].
    """
    model_state = model.init(cable)
    dtype = jnp.result_type(float, cable.length)
    zero = jnp.zeros((), dtype)
    return CableState(
        model_state=model_state,
        time=jnp.asarray(time, dtype),
        force=zero,
        strain=zero,
        last_step=zero,
        result=model.check(cable),
    )


def direction(delta: Float[Array, ""]) -> Int[Array, ""]:
    """The branch a change `delta` of the force (or strain) asks of the model: +1, -1,
    or 0 for no change."""
    # No threshold: a threshold is a discontinuity in the force history.
    return jnp.where(delta > 0, 1, jnp.where(delta < 0, -1, 0)).astype(jnp.int32)


def sample_result(
    *,
    converged: Bool[Array, ""] | None = None,
    unreachable: Bool[Array, ""] | None = None,
    dt: Float[Array, ""] | None = None,
    force: Float[Array, ""] | None = None,
) -> RESULTS:
    """The result of one sample: `newton_failed` unless its solve `converged` (or
    `unreachable_force` where the failed solve showed the sample `unreachable`), then
    `nonphysical_time` unless `dt` is finite and >= 0, then `nonphysical_force` unless
    `force` is finite and >= 0 (the later check's failure wins); each check only
    where its argument is given."""
    result = RESULTS.successful
    if converged is not None:
        result = RESULTS.where(converged, RESULTS.successful, RESULTS.newton_failed)
        if unreachable is not None:
            result = RESULTS.where(
                ~converged & unreachable, RESULTS.unreachable_force, result
            )
    if dt is not None:
        ok = (dt >= 0) & jnp.isfinite(dt)
        result = RESULTS.where(ok, result, RESULTS.nonphysical_time)
    if force is not None:
        ok = (force >= 0) & jnp.isfinite(force)
        result = RESULTS.where(ok, result, RESULTS.nonphysical_force)
    return result


def strain_limit(model: AbstractCableModel) -> float:
    """The largest strain at which a drive solves a sample's time or force for
    `model` (an extension: for its base): the class variable `SOLVED_STRAIN_LIMIT`,
    else no limit.

    The integrated model sets 1, a cable twice its length: no polymer cable comes
    near it (UHMWPE breaks at about 0.035, polyester at 0.15, nylon at 0.4), and
    beyond it the hardening law (Park Eq. 2, h = 1 + beta eps**gamma, eps**gamma
    unbounded in gamma) makes the strain almost independent of the force, so that a
    solved force or time would be one of many. The linear and hysteretic baselines
    (an elastomer stretched to 6 times its length in a relaxation test) have no such
    limit. A force history, which is not inverted, is simulated at any strain. The
    cable's own breaking strain (`Cable.breaking_strain`) is a separate check, made
    for every drive (`commit`).
    """
    base = getattr(model, "base", None)
    while isinstance(base, AbstractCableModel):
        model, base = base, getattr(base, "base", None)
    return float(getattr(type(model), "SOLVED_STRAIN_LIMIT", math.inf))


def solved_result(
    result: RESULTS, strain: Float[Array, ""], limit: float = math.inf
) -> RESULTS:
    """`result` of a solved sample, or `nonphysical_strain` where it was successful
    but its strain is beyond `limit` (see `strain_limit`)."""
    ok = (jnp.abs(strain) <= limit) | ~jnp.isfinite(strain)
    return RESULTS.where(
        ok | (result != RESULTS.successful), result, RESULTS.nonphysical_strain
    )


def select(pred, new, old):
    """`new` where `pred`, else `old`, leaf by leaf (two pytrees of one structure)."""
    return jtu.tree_map(lambda a, b: jnp.where(pred, a, b), new, old)


def broken_result(
    result: RESULTS, strain: Float[Array, ""], breaking_strain: Float[Array, ""]
) -> RESULTS:
    """`result` of a sample, or `strain_beyond_break` where it was successful but its
    strain is above the cable's `breaking_strain` (`Cable.breaking_strain`)."""
    # The sample's own cause comes first: a strain that is not finite, or beyond the
    # model's limit, has a message of its own (and a NaN compares False, so it would
    # otherwise read as a break). The limit in the strain's dtype, so that a float32
    # simulation of a cable built with float64 fields compares in float32.
    limit = jnp.asarray(breaking_strain, strain.dtype)
    ok = (strain <= limit) | (result != RESULTS.successful)
    return RESULTS.where(ok, result, RESULTS.strain_beyond_break)


def commit(
    state: CableState,
    cable: Cable,
    model_state: PyTree,
    parts: StrainParts,
    time: Float[Array, ""],
    force: Float[Array, ""],
    result: RESULTS,
    mask: Bool[Array, ""],
) -> tuple[CableState, StrainParts]:
    """The state after one sample, from the model's new state and strain.

    **Arguments:**

    - `state`: the [`jaxcable.states.CableState`][] before the sample.
    - `cable`: the [`jaxcable.Cable`][], whose `breaking_strain` the strain is
        checked against.
    - `model_state`, `parts`: the model's state and strain after the sample.
    - `time`, `force`: the sample's time (s) and force (N).
    - `result`: the sample's own result (`sample_result`).
    - `mask`: False for a padding sample, which leaves the state unchanged.

    **Returns:**

    `(new_state, parts)`. The state keeps the first failure so far; a padding
    sample returns the old state and the old strain.
    """
    strain = parts.total
    # A non-finite strain is reported only when the step had no cause of its own (a
    # time going backwards, a negative force), which is the more useful message.
    result = RESULTS.where(
        jnp.isfinite(strain) | (result != RESULTS.successful),
        result,
        RESULTS.nonphysical_strain,
    )
    # Every drive passes here, so a strain beyond the break is flagged for all of
    # them; a comparison on the result only, so the trajectory is unchanged.
    result = broken_result(result, strain, cable.breaking_strain)
    new = CableState(
        model_state=model_state,
        time=time,
        force=force,
        strain=strain,
        last_step=time - state.time,
        result=RESULTS.where(state.result == RESULTS.successful, result, state.result),
    )
    # Padding samples repeat the last strain; its split is not needed bit-exact.
    z = jnp.zeros_like(parts.instantaneous)
    old_parts = StrainParts(state.strain, z, z, z, z)
    return select(mask, new, state), select(mask, parts, old_parts)
