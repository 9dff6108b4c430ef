from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np
import optimistix as optx
from jax.ad_checkpoint import checkpoint_name
from jaxtyping import Array, ArrayLike, Bool, Float, Int, PyTree

from .. import _checks
from .._cable import Cable, check_scalar_cable
from .._models import AbstractCableModel, StrainParts
from .._results import RESULTS
from .newton import Newton, root_scalar
from .protocol import Protocol


# Incremented each time a kernel is traced; tests use it to show that a repeated call
# with the same shapes does not retrace.
TRACE_COUNTS: dict[str, int] = {"rate": 0, "force": 0, "elongation": 0}

_MAX_NEWTON_STEPS = 32


class Trajectory(eqx.Module):
    """A simulated strain history (one cable; a leading batch axis when vmapped).

    **Fields:**

    - `time`: time of each sample, s.
    - `force`: cable force, N.
    - `strain`: total strain (elongation / L0), dimensionless.
    - `elongation`: elongation, m.
    - `parts`: the strain split into instantaneous, creep and short- and long-term
        recovery ([`jaxcable.StrainParts`][]).
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

    A [`jaxcable.CableState`][].
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


def _select(pred, new, old):
    return jtu.tree_map(lambda a, b: jnp.where(pred, a, b), new, old)


def _first_failure(old: RESULTS, new: RESULTS) -> RESULTS:
    return RESULTS.where(old == RESULTS.successful, new, old)


def _commit(
    carry: CableState,
    model_state,
    parts: StrainParts,
    time,
    force,
    step_result: RESULTS,
    mask,
) -> tuple[CableState, Any]:
    strain = parts.total
    # A non-finite strain is reported only when the step had no cause of its own (a
    # time going backwards, a negative force), which is the more useful message.
    step_result = RESULTS.where(
        jnp.isfinite(strain) | (step_result != RESULTS.successful),
        step_result,
        RESULTS.nonphysical_strain,
    )
    new = CableState(
        model_state=model_state,
        time=time,
        force=force,
        strain=strain,
        last_step=time - carry.time,
        result=_first_failure(carry.result, step_result),
    )
    new = _select(mask, new, carry)
    return new, new


# Residuals are relative strain errors, with this floor on the strain scale so that a
# nearly unloaded cable is solved to an absolute strain accuracy of floor * tol.
_STRAIN_FLOOR = 1e-4


def _default_solver(dtype) -> Newton:
    # float32 resolves a strain to ~1e-7 relative; ask for a little above that.
    tol = 1e-12 if jnp.dtype(dtype) == jnp.float64 else 2e-6
    return Newton(tol=tol, max_steps=_MAX_NEWTON_STEPS)


def step(
    model: AbstractCableModel,
    cable: Cable,
    state: CableState,
    time: Float[ArrayLike, ""],
    force: Float[ArrayLike, ""],
) -> tuple[CableState, StrainParts]:
    """Advance one cable by one time-stamped force sample (no solve).

    A pure function for a user's own `lax.scan`, a controller, `jit`, `vmap` or
    `grad`. The force is linear between samples; the model is told the sign of the
    force change (`direction`). Every entry point that takes a force history
    ([`jaxcable.simulate_force_history`][], [`jaxcable.fit`][],
    [`jaxcable.controller_step`][], [`jaxcable.monte_carlo`][]) is this step in a
    scan, so all of them give the same elongations for the same history.

    **Arguments:**

    - `model`: any [`jaxcable.AbstractCableModel`][].
    - `cable`: the [`jaxcable.Cable`][].
    - `state`: the [`jaxcable.CableState`][] after the previous sample.
    - `time`: time of this sample, s (>= `state.time`).
    - `force`: force of this sample, N.

    **Returns:**

    `(new_state, parts)`: the new [`jaxcable.CableState`][] and the
    [`jaxcable.StrainParts`][] of this sample (strain = `parts.total`).
    """
    time = jnp.asarray(time, state.time.dtype)
    force = jnp.asarray(force, state.force.dtype)
    new, parts = _force_step(model, cable, state, time, force, jnp.array(True))
    return new, parts


def _direction(delta) -> Int[Array, ""]:
    # No threshold: a threshold is a discontinuity in the force history (issue 10).
    return jnp.where(delta > 0, 1, jnp.where(delta < 0, -1, 0)).astype(jnp.int32)


def _force_step(model, cable, carry: CableState, time, force, mask):
    dt = time - carry.time
    direction = _direction(force - carry.force)
    model_state, parts = model.advance(carry.model_state, cable, dt, force, direction)
    ok = (dt >= 0) & jnp.isfinite(dt)
    step_result = RESULTS.where(ok, RESULTS.successful, RESULTS.nonphysical_time)
    step_result = RESULTS.where(
        (force >= 0) & jnp.isfinite(force), step_result, RESULTS.nonphysical_force
    )
    new, _ = _commit(carry, model_state, parts, time, force, step_result, mask)
    parts = _select(mask, parts, _parts_of(carry, parts))
    return new, parts


def _parts_of(carry: CableState, like: StrainParts) -> StrainParts:
    # Padding samples repeat the last strain; its split is not needed bit-exact.
    z = jnp.zeros_like(like.instantaneous)
    return StrainParts(carry.strain, z, z, z)


# The name under which the drivers mark the solved unknown of each sample (the
# loading time of a rate-driven test, the force of an elongation history), and the
# rematerialisation policy that keeps it, so that the backward pass does not redo the
# Newton solve.
_SOLUTION = "jaxcable_solution"
_SAVE_SOLUTION = jax.checkpoint_policies.save_only_these_names(_SOLUTION)


def _scan(body, carry, xs, mask_index: int, checkpoint: int | None):
    """`lax.scan` over samples; with `checkpoint`, a scan over blocks of that many
    samples whose body is rematerialised (`jax.checkpoint`) in the backward pass.

    Reverse-mode memory then grows as (samples / checkpoint) carries plus one block of
    intermediates, instead of every intermediate of every sample: choose
    `checkpoint` near sqrt(samples) for 10^5-10^6-sample histories. The history is
    padded to whole blocks with masked samples, which leave the carry unchanged.
    """
    # Reverse mode stores, per sample, only the carry and the solved unknown, and
    # recomputes the rest of the step in the backward pass (no effect on a forward
    # pass). Storing every intermediate of every sample instead (one array of the
    # history's length each, ~100 of them) makes the gradient of a batch memory-bound:
    # measured 2.3x slower at 1024 cables x 2000 samples (benchmarks/kernel.py).
    body = jax.checkpoint(body, policy=_SAVE_SOLUTION)
    if checkpoint is None:
        return jax.lax.scan(body, carry, xs)
    if not isinstance(checkpoint, int) or checkpoint < 1:
        raise ValueError(f"`checkpoint` must be a positive int, got {checkpoint!r}.")
    n = jnp.shape(xs[0])[0]
    blocks = -(-n // checkpoint)
    pad = blocks * checkpoint - n

    def padded(i, x):
        fill = jnp.zeros_like(x[-1:]) if i == mask_index else x[-1:]
        x = jnp.concatenate([x, jnp.repeat(fill, pad, axis=0)]) if pad else x
        return x.reshape(blocks, checkpoint, *x.shape[1:])

    xs = tuple(padded(i, x) for i, x in enumerate(xs))

    @jax.checkpoint
    def block(carry, xs_block):
        return jax.lax.scan(body, carry, xs_block)

    final, ys = jax.lax.scan(block, carry, xs)
    ys = jtu.tree_map(lambda y: y.reshape(blocks * checkpoint, *y.shape[2:])[:n], ys)
    return final, ys


def _trajectory(cable, outs, parts, result, throw) -> Trajectory:
    states, mask = outs
    traj = Trajectory(
        time=states.time,
        force=states.force,
        strain=states.strain,
        elongation=states.strain * cable.length,
        parts=parts,
        mask=mask,
        result=result,
    )
    if throw:
        traj = result.error_if(traj, result != RESULTS.successful)
    return traj


# ----------------------------------------------------------------------------------
# Time-stamped force history (a robot's log): no solve.


@eqx.filter_jit
def _force_kernel(model, cable, time, force, mask, throw, checkpoint):
    TRACE_COUNTS["force"] += 1
    carry = init_state(model, cable, time[0])

    def body(carry, x):
        t, f, m = x
        new, parts = _force_step(model, cable, carry, t, f, m)
        return new, (new, m, parts)

    final, (states, masks, parts) = _scan(
        body, carry, (time, force, mask), 2, checkpoint
    )
    return _trajectory(cable, (states, masks), parts, final.result, throw)


def simulate_force_history(
    model: AbstractCableModel,
    cable: Cable,
    time: Float[ArrayLike, " samples"],
    force: Float[ArrayLike, " samples"],
    *,
    mask: Bool[ArrayLike, " samples"] | None = None,
    throw: bool = True,
    checkpoint: int | None = None,
) -> Trajectory:
    """Simulate a time-stamped force history, as a robot logs it.

    The force is linear between samples; the model is told the sign of each force
    change, with no threshold. The forces are used as given, with no deadband or
    smoothing, here as in every other entry point ([`jaxcable.step`][]): the same
    history gives the same elongations everywhere. The first sample is the initial
    condition reached from the unloaded cable at `time[0]` (a nonzero `force[0]` is
    applied instantly).

    **Arguments:**

    - `model`: any [`jaxcable.AbstractCableModel`][].
    - `cable`: the [`jaxcable.Cable`][] (one cable; `jax.vmap` for a batch).
    - `time`: sample times, s, strictly increasing.
    - `force`: cable force at each sample, N, 0 <= force <= `cable.breaking_load`.
    - `mask`: optional, False marks padding samples (histories of different lengths
        in one vmapped batch); they leave the state unchanged.
    - `throw`: raise on failure (default). With `throw=False` the failure is returned
        in `Trajectory.result` (per cable under vmap).
    - `checkpoint`: optional block length (samples) of a checkpointed scan, for the
        gradients of long histories in bounded memory (about sqrt(samples)).

    **Returns:**

    A [`jaxcable.Trajectory`][].
    """
    time, force, mask = check_history(cable, time, force, mask, "force")
    return _force_kernel(model, cable, time, force, mask, throw, checkpoint)


def check_history(cable, time, x, mask, xname):
    if _checks.is_concrete(cable):
        check_scalar_cable(cable)
    if _checks.is_concrete(time, x, mask):
        time = _checks.require_samples("time", time)
        x = _checks.require_samples(xname, x)
        if mask is not None:
            mask = _checks.require_samples("mask", mask)
        _checks.require_same_shape(time=time, **{xname: x}, mask=mask)
        m = None if mask is None else np.asarray(mask, bool)
        _checks.require_finite("time", time if m is None else np.asarray(time)[m])
        _checks.require_finite(xname, x if m is None else np.asarray(x)[m])
        _checks.require_increasing("time", time, m)
        if xname == "force":
            _checks.require_positive("force", x, allow_zero=True)
            if _checks.is_concrete(cable.breaking_load):
                _checks.require_below("force", x, cable.breaking_load, "breaking load")
    dtype = jnp.result_type(float, cable.length)
    time = jnp.asarray(time, dtype)
    x = jnp.asarray(x, dtype)
    mask = jnp.ones(time.shape, bool) if mask is None else jnp.asarray(mask, bool)
    return time, x, mask


# ----------------------------------------------------------------------------------
# Rate-driven test: the time of each force sample is solved by Newton.


class _TimeProblem(eqx.Module):
    model: AbstractCableModel
    cable: Cable
    carry: CableState
    force: Float[Array, ""]
    direction: Int[Array, ""]
    duration: Float[Array, ""]
    # Strain scale of the relative residual, independent of dt (see _time_residual).
    scale: Float[Array, ""]


def _time_residual(dt, problem: _TimeProblem):
    """Park Eq. 5 = Eq. 6 along one ramp: (model strain - crosshead strain), relative.

    The relative scale is fixed per sample (`_TimeProblem.scale`), not a function of
    `dt`: a `dt`-dependent scale such as |eps_kin(dt)| adds a term
    -(residual) d scale / d dt to the slope, which on an unloading ramp with a strong
    short-term recovery flips the slope's sign far from the root, and the solver then
    takes the iterate for one beyond a turning point.

    On a hold the residual is (dt - duration) / (duration + 1 s): solved in one step.
    """
    c = problem.carry
    rate = problem.cable.strain_rate
    _, parts = problem.model.advance(
        c.model_state, problem.cable, dt, problem.force, problem.direction
    )
    ramp = problem.direction != 0
    sign = jnp.where(ramp, problem.direction, 1)
    kinematic = c.strain + sign * rate * dt
    hold = (dt - problem.duration) / (problem.duration + 1.0)
    return jnp.where(ramp, (parts.total - kinematic) / problem.scale, hold)


def _rate_step(model, cable, carry: CableState, x, solver):
    force, direction, duration, mask, continues = x

    # Initial guess. Inside a ramp, the previous step's duration (samples are close
    # and creep is smooth, so two Newton steps suffice). At the start of a ramp, the
    # time the instantaneous strain step alone takes at speed v. On a hold, its
    # duration. `continues` comes from the protocol, so when one protocol is shared
    # by a vmapped batch the cond stays a branch and the first-sample guess costs
    # nothing on the other samples.
    def first_guess():
        zero = jnp.zeros_like(duration)
        _, parts0 = model.advance(carry.model_state, cable, zero, force, direction)
        jump = jnp.abs(parts0.total - carry.strain) / cable.strain_rate
        return jnp.where(direction != 0, jump, duration)

    guess = jax.lax.cond(continues, lambda: carry.last_step, first_guess)
    # Along a loading ramp the crosshead overtakes the model strain (slope < 0 at the
    # root); along an unloading ramp the other way round; a hold is linear in dt.
    slope_sign = jnp.where(direction != 0, -direction, 1).astype(guess.dtype)
    # The residual's scale: the strains at the start of the step and at the guessed
    # end (the crosshead's, where the guess puts it), which bracket the strain of the
    # solution to first order; fixed for the solve so that it cannot bend the slope.
    sign = jnp.where(direction != 0, direction, 1).astype(guess.dtype)
    target = carry.strain + sign * cable.strain_rate * guess
    scale = jnp.abs(carry.strain) + jnp.abs(target) + _STRAIN_FLOOR
    problem = _TimeProblem(model, cable, carry, force, direction, duration, scale)
    growth = 1e-6 / cable.strain_rate
    dt, converged = root_scalar(
        _time_residual,
        solver,
        guess,
        problem,
        jnp.zeros_like(guess),
        slope_sign=slope_sign,
        growth=growth,
    )
    dt = checkpoint_name(dt, _SOLUTION)
    step_result = RESULTS.where(converged, RESULTS.successful, RESULTS.newton_failed)
    step_result = RESULTS.where(
        (dt >= 0) & jnp.isfinite(dt), step_result, RESULTS.nonphysical_time
    )
    model_state, parts = model.advance(carry.model_state, cable, dt, force, direction)
    new, _ = _commit(
        carry, model_state, parts, carry.time + dt, force, step_result, mask
    )
    parts = _select(mask, parts, _parts_of(carry, parts))
    return new, parts


@eqx.filter_jit
def _rate_kernel(model, cable, protocol: Protocol, solver, throw, checkpoint):
    TRACE_COUNTS["rate"] += 1
    carry = init_state(model, cable)
    dtype = carry.strain.dtype
    if solver is None:
        solver = _default_solver(dtype)
    direction = jnp.asarray(protocol.direction, jnp.int32)
    previous = jnp.concatenate([jnp.zeros_like(direction[:1]), direction[:-1]])
    xs = (
        jnp.asarray(protocol.force, dtype),
        direction,
        jnp.asarray(protocol.duration, dtype),
        jnp.asarray(protocol.mask, bool),
        (direction != 0) & (direction == previous),
    )

    def body(carry, x):
        new, parts = _rate_step(model, cable, carry, x, solver)
        return new, (new, x[3], parts)

    final, (states, masks, parts) = _scan(body, carry, xs, 3, checkpoint)
    return _trajectory(cable, (states, masks), parts, final.result, throw)


def simulate_rate_test(
    model: AbstractCableModel,
    cable: Cable,
    protocol: Protocol,
    *,
    solver: Newton | optx.AbstractRootFinder | None = None,
    throw: bool = True,
    checkpoint: int | None = None,
) -> Trajectory:
    """Simulate a rate-driven test, as a tensile tester runs it (Park Section 4).

    The crosshead moves at `cable.speed`, so along each ramp the strain follows
    eps_kin(t) = eps_start +/- (v / L0) (t - t_start) (Park Eq. 6). The time t_i at
    which each force sample is reached is the root of model strain minus eps_kin
    (Park Eq. 5 = Eq. 6), found per sample by Newton's method (optimistix) inside the
    scan, vectorised under `vmap` and differentiated by the implicit function theorem.

    **Arguments:**

    - `model`: any [`jaxcable.AbstractCableModel`][].
    - `cable`: the [`jaxcable.Cable`][] (one cable; `jax.vmap` for a batch).
    - `protocol`: the [`jaxcable.Protocol`][] (ramps, holds, rests).
    - `solver`: optional [`jaxcable.Newton`][] or any optimistix root finder (default
        `jaxcable.Newton` with tolerances in seconds set by the dtype).
    - `throw`: raise on failure (default); `throw=False` returns the status in
        `Trajectory.result`.
    - `checkpoint`: optional block length (samples) of a checkpointed scan, for the
        gradients of long histories in bounded memory (about sqrt(samples)).

    **Returns:**

    A [`jaxcable.Trajectory`][] whose `time` holds the solved sample times, s.
    """
    if not isinstance(protocol, Protocol):
        raise ValueError(
            f"`protocol` must be a jaxcable.Protocol, got {type(protocol).__name__}."
        )
    if _checks.is_concrete(cable):
        check_scalar_cable(cable)
        if _checks.is_concrete(protocol.force):
            if jnp.ndim(protocol.force) != 1:
                raise ValueError(
                    f"`protocol.force` must be 1-dimensional, got shape "
                    f"{jnp.shape(protocol.force)}; vmap over a batch of protocols."
                )
            _checks.require_below(
                "protocol.force", protocol.force, cable.breaking_load, "breaking load"
            )
    return _rate_kernel(model, cable, protocol, solver, throw, checkpoint)


# ----------------------------------------------------------------------------------
# Time-stamped elongation history (displacement control): the force is solved.


class _ForceProblem(eqx.Module):
    model: AbstractCableModel
    cable: Cable
    carry: CableState
    dt: Float[Array, ""]
    target: Float[Array, ""]
    direction: Int[Array, ""]


def _force_residual(force, problem: _ForceProblem):
    c = problem.carry
    _, parts = problem.model.advance(
        c.model_state, problem.cable, problem.dt, force, problem.direction
    )
    return (parts.total - problem.target) / (jnp.abs(problem.target) + _STRAIN_FLOOR)


def _elongation_step(model, cable, carry: CableState, x, solver):
    time, elongation, mask = x
    target = elongation / cable.length
    dt = time - carry.time
    direction = _direction(target - carry.strain)
    problem = _ForceProblem(model, cable, carry, dt, target, direction)
    # Slack: an imposed length below the zero-force length leaves the cable unloaded.
    zero = jnp.zeros_like(target)
    slack = _force_residual(zero, problem) >= 0
    # Initial guess from the local compliance at the previous force (Newton's first
    # step taken by hand with a floor, since the hardening law has zero slope at 0 N).
    f_prev = jnp.maximum(carry.force, 1e-3 * cable.breaking_load)
    r_prev, compliance = jax.jvp(
        lambda f: _force_residual(f, problem), (f_prev,), (jnp.ones_like(f_prev),)
    )
    guess = jnp.clip(
        f_prev - r_prev / compliance, 1e-6 * cable.breaking_load, cable.breaking_load
    )
    # Strain rises with force; a flat slope (0 N under hardening) grows the force.
    solved, converged = root_scalar(
        _force_residual,
        solver,
        guess,
        problem,
        zero,
        slope_sign=jnp.ones_like(guess),
        growth=1e-6 * cable.breaking_load,
    )
    force = checkpoint_name(jnp.where(slack, zero, solved), _SOLUTION)
    converged = slack | converged
    step_result = RESULTS.where(converged, RESULTS.successful, RESULTS.newton_failed)
    step_result = RESULTS.where(
        (force >= 0) & jnp.isfinite(force), step_result, RESULTS.nonphysical_force
    )
    model_state, parts = model.advance(carry.model_state, cable, dt, force, direction)
    new, _ = _commit(carry, model_state, parts, time, force, step_result, mask)
    parts = _select(mask, parts, _parts_of(carry, parts))
    return new, parts


@eqx.filter_jit
def _elongation_kernel(model, cable, time, elongation, mask, solver, throw, checkpoint):
    TRACE_COUNTS["elongation"] += 1
    carry = init_state(model, cable, time[0])
    if solver is None:
        solver = _default_solver(carry.strain.dtype)

    def body(carry, x):
        new, parts = _elongation_step(model, cable, carry, x, solver)
        return new, (new, x[2], parts)

    final, (states, masks, parts) = _scan(
        body, carry, (time, elongation, mask), 2, checkpoint
    )
    return _trajectory(cable, (states, masks), parts, final.result, throw)


def simulate_elongation_history(
    model: AbstractCableModel,
    cable: Cable,
    time: Float[ArrayLike, " samples"],
    elongation: Float[ArrayLike, " samples"],
    *,
    mask: Bool[ArrayLike, " samples"] | None = None,
    solver: Newton | optx.AbstractRootFinder | None = None,
    throw: bool = True,
    checkpoint: int | None = None,
) -> Trajectory:
    """Simulate a time-stamped elongation history (displacement control, e.g. a
    relaxation test): the force of each sample is solved by Newton's method.

    The branch follows the sign of the imposed elongation change; a hold keeps it.
    Where the imposed length is below the cable's zero-force length the cable is
    slack: the force is 0 and the strain is the model's free strain.

    **Arguments:**

    - `model`: any [`jaxcable.AbstractCableModel`][].
    - `cable`: the [`jaxcable.Cable`][].
    - `time`: sample times, s, strictly increasing.
    - `elongation`: imposed elongation, m.
    - `mask`, `solver`, `throw`, `checkpoint`: as in
        [`jaxcable.simulate_rate_test`][] and [`jaxcable.simulate_force_history`][].

    **Returns:**

    A [`jaxcable.Trajectory`][] whose `force` holds the solved forces, N.
    """
    time, elongation, mask = check_history(cable, time, elongation, mask, "elongation")
    return _elongation_kernel(
        model, cable, time, elongation, mask, solver, throw, checkpoint
    )
