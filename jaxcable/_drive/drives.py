"""The three drives of the scan kernel, each a sample type and the step of one sample:

- `ForceDrive`: a time-stamped force history (a robot's log): no solve;
- `RateDrive`: a rate-driven test (a tensile tester): the time at which each force
    sample is reached is solved by Newton's method (Park Eq. 6);
- `ElongationDrive`: a time-stamped elongation history (displacement control):
    the force of each sample is solved by Newton's method.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx
from jax.ad_checkpoint import checkpoint_name
from jaxtyping import Array, Bool, Float, Int

from .._cable import Cable
from .._models import AbstractCableModel, StrainParts
from .._results import RESULTS
from .newton import FAST, REPLAY, Newton, branches_are_cheap, root_scalar
from .protocol import Protocol
from .scan import SOLUTION, AbstractDrive, AbstractSample, Solve
from .state import (
    CableState,
    commit,
    direction,
    init_state,
    sample_result,
    select,
    solved_result,
    strain_limit,
)


# Residuals are relative strain errors, with this floor on the strain scale so that a
# nearly unloaded cable is solved to an absolute strain accuracy of floor * tol.
_STRAIN_FLOOR = 1e-4


def _verified(miss: Float[Array, ""]) -> Bool[Array, ""]:
    """Whether a solved sample's relative strain error `miss`, recomputed from the
    strain the model gives at the solution, is small: a check of the solve's answer
    against gross errors (a far spurious root), looser than the solver's tolerance
    so that it never rejects what the tolerance accepted."""
    loose = 1e-6 if miss.dtype == jnp.float64 else 1e-3
    return jnp.abs(miss) <= loose


def _active(state: CableState, sample: AbstractSample) -> Bool[Array, ""]:
    """Whether a sample's solve matters: not padding, and no failure before it (the
    first failure is what a simulation reports)."""
    return sample.mask & (state.result == RESULTS.successful)


def default_solver(dtype) -> Newton:
    """The solver of the drives that solve per sample, unless one is given."""
    # float32 resolves a strain to ~1e-7 relative; ask for a little above that.
    tol = 1e-12 if jnp.dtype(dtype) == jnp.float64 else 2e-6
    return Newton(tol=tol, max_steps=32)


# ----------------------------------------------------------------------------------
# Time-stamped force history: no solve.


class ForceSample(AbstractSample):
    """A force sample: `time` (s), `force` (N), `mask` (False: padding)."""

    time: Float[Array, "*samples"]
    force: Float[Array, "*samples"]
    mask: Bool[Array, "*samples"]


def force_step(
    model: AbstractCableModel, cable: Cable, state: CableState, sample: ForceSample
) -> tuple[CableState, StrainParts]:
    """Advance one cable by one force sample, the force linear since the last one
    (the step of [`jaxcable.step`][] and of `ForceDrive`)."""
    dt = sample.time - state.time
    branch = direction(sample.force - state.force)
    model_state, parts = model.advance(
        state.model_state, cable, dt, sample.force, branch
    )
    result = sample_result(dt=dt, force=sample.force)
    return commit(
        state,
        cable,
        model_state,
        parts,
        sample.time,
        sample.force,
        result,
        sample.mask,
    )


class ForceDrive(AbstractDrive[ForceSample]):
    """A time-stamped force history, from the unloaded cable at its first time."""

    samples: ForceSample

    def init(self, model, cable):
        return init_state(model, cable, self.samples.time[0]), self.samples

    def step(self, model, cable, state, sample, solve):
        new, parts = force_step(model, cable, state, sample)
        return new, parts, jnp.zeros_like(new.force)


# ----------------------------------------------------------------------------------
# Rate-driven test: the time of each force sample is solved.


class RateSample(AbstractSample):
    """A sample of a [`jaxcable.Protocol`][], with `continues`: whether the sample
    goes on the ramp of the previous one (from the protocol, not from the state)."""

    force: Float[Array, "*samples"]
    direction: Int[Array, "*samples"]
    duration: Float[Array, "*samples"]
    mask: Bool[Array, "*samples"]
    continues: Bool[Array, "*samples"]


class _SampleProblem(eqx.Module):
    """What the residual of one sample's solve needs: the model, the cable and the
    state before the sample."""

    model: AbstractCableModel
    cable: Cable
    state: CableState


class _TimeProblem(_SampleProblem):
    force: Float[Array, ""]
    direction: Int[Array, ""]
    duration: Float[Array, ""]
    # Strain scale of the relative residual, independent of dt (see _time_residual).
    scale: Float[Array, ""]


def _time_residual(dt, problem: _TimeProblem):
    """Park Eq. 6 along one ramp: (model strain - crosshead strain), relative; with
    the model's state and strain after the step (the solve's auxiliary output).

    The relative scale is fixed per sample (`_TimeProblem.scale`), not a function of
    `dt`: a `dt`-dependent scale such as |eps_kin(dt)| adds a term
    -(residual) d scale / d dt to the slope, which on an unloading ramp with a strong
    short-term recovery flips the slope's sign far from the root, and the solver then
    takes the iterate for one beyond a turning point.

    On a hold the residual is (dt - duration) / (duration + 1 s): solved in one step.
    """
    s = problem.state
    rate = problem.cable.strain_rate
    model_state, parts = problem.model.advance(
        s.model_state, problem.cable, dt, problem.force, problem.direction
    )
    ramp = problem.direction != 0
    sign = jnp.where(ramp, problem.direction, 1)
    kinematic = s.strain + sign * rate * dt
    hold = (dt - problem.duration) / (problem.duration + 1.0)
    residual = jnp.where(ramp, (parts.total - kinematic) / problem.scale, hold)
    return residual, (model_state, parts)


def _first_guess(model, cable, state: CableState, sample: RateSample):
    """The guess of a sample's time that starts a ramp: the time the instantaneous
    strain step alone takes at speed v; on a hold, its duration."""
    force, branch, duration = sample.force, sample.direction, sample.duration
    zero = jnp.zeros_like(duration)
    _, parts0 = model.advance(state.model_state, cable, zero, force, branch)
    jump = jnp.abs(parts0.total - state.strain) / cable.strain_rate
    # In the dtype of the carry (a float32 cable with float64 parameters computes
    # the jump in float64).
    return jnp.where(branch != 0, jump, duration).astype(state.last_step.dtype)


def _rate_guess(
    model, cable, state: CableState, sample: RateSample, solve: Solve
) -> Float[Array, ""]:
    """The initial guess of a sample's time, s. Inside a ramp, the previous step's
    duration (samples are close and creep is smooth, so two Newton steps suffice);
    at the start of a ramp or on a hold, `_first_guess`; to replay, the known root.
    `continues` comes from the protocol, so when one protocol is shared by a
    vmapped batch the cond stays a branch and the first-sample guess costs nothing
    on the other samples."""
    if solve.how == REPLAY:
        return solve.known_root
    if solve.how == FAST and not branches_are_cheap():
        first = _first_guess(model, cable, state, sample)
        return jnp.where(sample.continues, state.last_step, first)
    return jax.lax.cond(
        sample.continues,
        lambda: state.last_step,
        lambda: _first_guess(model, cable, state, sample),
    )


class RateDrive(AbstractDrive[RateSample]):
    """A rate-driven test: the crosshead moves at `cable.speed` along each ramp, so
    the strain follows eps_kin(t) = eps_start +/- (v / L0) (t - t_start) (Park Eq. 6),
    and the time of each force sample is the root of model strain minus eps_kin
    (Park Eq. 6). Starts from the unloaded cable at t = 0."""

    protocol: Protocol
    solver: Newton | optx.AbstractRootFinder

    def init(self, model, cable):
        state = init_state(model, cable)
        dtype = state.strain.dtype
        protocol = self.protocol
        branch = jnp.asarray(protocol.direction, jnp.int32)
        previous = jnp.concatenate([jnp.zeros_like(branch[:1]), branch[:-1]])
        samples = RateSample(
            force=jnp.asarray(protocol.force, dtype),
            direction=branch,
            duration=jnp.asarray(protocol.duration, dtype),
            mask=jnp.asarray(protocol.mask, bool),
            continues=(branch != 0) & (branch == previous),
        )
        return state, samples

    def step(self, model, cable, state, sample: RateSample, solve: Solve):
        force, branch, duration = sample.force, sample.direction, sample.duration
        guess = _rate_guess(model, cable, state, sample, solve)
        limit = strain_limit(model)
        # Along a loading ramp the crosshead overtakes the model strain (slope < 0 at
        # the root); along an unloading ramp the other way round; a hold is linear in
        # dt.
        slope_sign = jnp.where(branch != 0, -branch, 1).astype(guess.dtype)
        # The residual's scale: the strains at the start of the step and at the
        # guessed end (the crosshead's, where the guess puts it), which bracket the
        # strain of the solution to first order; fixed for the solve so that it
        # cannot bend the slope. Not differentiated: at the root the residual's
        # numerator is zero, so the root does not depend on the scale, and its
        # derivative would carry the guess's (a whole step of the model at the
        # start of a ramp) into every differentiated program.
        sign = jnp.where(branch != 0, branch, 1).astype(guess.dtype)
        target = state.strain + sign * cable.strain_rate * guess
        scale = jax.lax.stop_gradient(
            jnp.abs(state.strain) + jnp.abs(target) + _STRAIN_FLOOR
        )
        problem = _TimeProblem(model, cable, state, force, branch, duration, scale)
        root = root_scalar(
            _time_residual,
            self.solver,
            guess,
            problem,
            jnp.zeros_like(guess),
            slope_sign=slope_sign,
            growth=1e-6 / cable.strain_rate,
            active=_active(state, sample),
            name=SOLUTION,
            # On a ramp, beyond a crosshead travel of twice the model's strain
            # limit no root is physical (a root below it but past the limit is
            # flagged `nonphysical_strain` below); a hold's time is its duration.
            # Infinite without a limit.
            upper=jnp.where(
                branch != 0,
                (2 * limit + jnp.abs(state.strain)) / cable.strain_rate,
                jnp.inf,
            ),
            has_aux=True,
            how=solve.how,
            known=solve.root,
        )
        dt = checkpoint_name(root.value, SOLUTION)
        model_state, parts = root.aux
        kinematic = state.strain + sign * cable.strain_rate * dt
        miss = jnp.where(branch != 0, (parts.total - kinematic) / scale, 0.0)
        result = sample_result(
            converged=root.converged & _verified(miss),
            unreachable=root.no_root,
            dt=dt,
        )
        result = solved_result(result, parts.total, limit)
        new, parts = commit(
            state,
            cable,
            model_state,
            parts,
            state.time + dt,
            force,
            result,
            sample.mask,
        )
        return new, parts, dt


# ----------------------------------------------------------------------------------
# Time-stamped elongation history: the force is solved.


class ElongationSample(AbstractSample):
    """An elongation sample: `time` (s), `elongation` (m), `mask` (False: padding)."""

    time: Float[Array, "*samples"]
    elongation: Float[Array, "*samples"]
    mask: Bool[Array, "*samples"]


class _ForceProblem(_SampleProblem):
    dt: Float[Array, ""]
    target: Float[Array, ""]
    direction: Int[Array, ""]


def _force_residual(force, problem: _ForceProblem):
    """The relative strain error at `force`, with the model's state and strain
    after the step (the solve's auxiliary output)."""
    s = problem.state
    model_state, parts = problem.model.advance(
        s.model_state, problem.cable, problem.dt, force, problem.direction
    )
    scale = jnp.abs(problem.target) + _STRAIN_FLOOR
    return (parts.total - problem.target) / scale, (model_state, parts)


def _force_guess(state: CableState, cable: Cable, problem: _ForceProblem):
    """The initial guess of an elongation sample's force, N: from the local
    compliance at the previous force (Newton's first step taken by hand with a
    floor, since the hardening law has zero slope at 0 N)."""
    f_prev = jnp.maximum(state.force, 1e-3 * cable.breaking_load)
    r_prev, compliance = jax.jvp(
        lambda f: _force_residual(f, problem)[0],
        (f_prev,),
        (jnp.ones_like(f_prev),),
    )
    return jnp.clip(
        f_prev - r_prev / compliance,
        1e-6 * cable.breaking_load,
        cable.breaking_load,
    )


class ElongationDrive(AbstractDrive[ElongationSample]):
    """A time-stamped elongation history, from the unloaded cable at its first time.

    The branch follows the sign of the imposed elongation change; below the cable's
    zero-force length the cable is slack (0 N)."""

    samples: ElongationSample
    solver: Newton | optx.AbstractRootFinder

    def init(self, model, cable):
        return init_state(model, cable, self.samples.time[0]), self.samples

    def step(self, model, cable, state, sample: ElongationSample, solve: Solve):
        target = sample.elongation / cable.length
        dt = sample.time - state.time
        branch = direction(target - state.strain)
        problem = _ForceProblem(model, cable, state, dt, target, branch)
        # Slack: an imposed length below the zero-force length leaves the cable
        # unloaded. Where the strain is not monotone in the force (a creep or
        # recovery term that moves with it), a length can be both below the
        # zero-force length and reached at a force > 0: the root that continues the
        # history (Newton's, from the previous force) wins over slack.
        zero = jnp.zeros_like(target)
        r_zero, at_zero = _force_residual(zero, problem)
        slack = r_zero >= 0
        if solve.how == REPLAY:
            guess = solve.known_root
        else:
            guess = _force_guess(state, cable, problem)
        # Strain rises with force; a flat slope (0 N under hardening) grows the force.
        root = root_scalar(
            _force_residual,
            self.solver,
            guess,
            problem,
            zero,
            slope_sign=jnp.ones_like(guess),
            growth=1e-6 * cable.breaking_load,
            active=_active(state, sample),
            name=SOLUTION,
            has_aux=True,
            how=solve.how,
            known=solve.root,
        )
        unloaded = slack & ~root.converged
        force = checkpoint_name(jnp.where(unloaded, zero, root.value), SOLUTION)
        model_state, parts = select(unloaded, at_zero, root.aux)
        miss = (parts.total - target) / (jnp.abs(target) + _STRAIN_FLOOR)
        result = sample_result(
            converged=unloaded | (root.converged & _verified(miss)), force=force
        )
        result = solved_result(result, parts.total, strain_limit(model))
        new, parts = commit(
            state, cable, model_state, parts, sample.time, force, result, sample.mask
        )
        return new, parts, force
