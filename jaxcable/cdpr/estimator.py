r"""A robot that calibrates its own cables: an online estimator of each cable's model
parameters, run as a step function beside [`jaxcable.controller_step`][] (one call
per control sample, inside the closed loop's `lax.scan`).

**Method: an extended Kalman filter over the cables' log-parameters, re-linearised
every `every` samples by a Gauss-Newton solve over a moving horizon of the recorded
samples.** The unknowns are a few parameters of each cable (by default E1c, E1r,
E3r and t_e of the integrated model, as logs: the moduli and times are positive and
their uncertainty is relative). The model's internal states are not estimated
separately: given the force history they are a function of the parameters,
propagated by `controller_step` with one parameter set per cable (`per_cable=True`),
with their sensitivity dstate/dtheta carried along (a forward-mode tangent per
parameter, `jax.linearize` of the step), so that the Jacobian of a predicted
elongation is that of the whole history, not of one step.

Between two solves, each fix updates the estimates at once (the extended Kalman
filter over the joint state-parameter vector with no process noise on the states:
an update moves the states by the sensitivity times the parameters' step, the
recursive prediction-error method of Ljung): the compensation improves within
seconds of the first fixes. That filter linearises each fix once, where the
estimate happened to be, and from a start 30 % away from the cables those
linearisations stay in its estimate and covariance: its 95 % intervals are too narrow
(the numbers: [`jaxcable.cdpr.horizon`][]). Every `every` samples the
horizon solve ([`jaxcable.cdpr.horizon`][]) replaces estimate, covariance and states
by the maximum a-posteriori estimate of the samples of the last `window` steps,
linearised at its own solution (Levenberg-Marquardt passes, each a re-simulation of
the window with the sensitivities, the normal equations accumulated as it goes). Its
memory is the window's samples (27 numbers per sample for 8 cables), its cost
`iterations + 2` model steps with tangents per sample of the window, once per
`every` samples.

**Why these parameters.** Over a quarter-hour of pick-and-place the Jacobian of a
cable's elongations in E1c, E1r, E3r and t_e is well conditioned (largest
correlation 0.94; 0.1 mm of noise at 1 Hz leaves standard deviations below 0.1 %).
E2r creeps with the same t_e as E3r and is told apart only by its faster recovery:
through the fixes' three coordinates it converges several times slower than the
others, so it is not estimated by default. E2c (with t_c = 0.9 s it acts as one
compliance with the spring) and the flow's viscosity (1e-9/s, invisible in hours)
are not identified by a robot's signals. The parameters not estimated stay at the
nominal model's values. E1r is identified only where it exceeds E1c (a rope with a
constructional elongation, Park Eq. 9): otherwise the loading curve is the strain
and E1r does not enter it, and its interval stays the prior's (reported as not
identified, not as tight). The default set's E1c and E1r differ by 0.1 %, on the
kink of that maximum: a cable drawn across it is learnt more slowly. Any scalar field
of the model can be chosen (`parameters`, dotted for a wrapped model: `"base.E2r"`,
the terminations' `"compliance"`; `benchmarks/online.py` learns seven and the
compliance), and `"load_cell_drift"` adds each load cell's drift rate.

**Measurements.** A position fix ([`jaxcable.cdpr.Fix`][]) is compared with the
position that the encoders' lengths plus the predicted elongations imply
([`jaxcable.cdpr.fix_prediction`][]). The fix refers to the end of the previous
sample (where the last command put the end-effector): the step first updates with it
against the strains and sensitivities it stored then, and then propagates the model
to the new sample's forces. The redundancy of eight cables on three coordinates is
not used as a measurement of its own: the simulated robot
([`jaxcable.cdpr.simulate_robot`][]) places its end-effector at the least-squares
compromise of stretched lengths that do not close (millimetres apart), so a
closure residual has no known true value there.

**Why not dynamax.** dynamax's extended Kalman filter (`dynamax.nonlinear_gaussian_ssm`)
filters a whole recorded sequence in one call, over a flat state vector whose
dynamics and emission functions it differentiates itself; its one-step predict and
update are private. Here the filter must be one step of the robot's own scan, the
model's state is a structured pytree with integer bookkeeping (the branch, the
result) that a Jacobian over a flat vector would differentiate needlessly, and the
sensitivities come from the cable model's own step. dynamax (with TensorFlow
Probability) is also not a dependency of jaxcable.

**Failures.** The filter's `result` ([`jaxcable.RESULTS`][]) is
`RESULTS.signal_lost` while no fix has come for `max_fix_gap` seconds or a load cell
has read the same value for `stuck_time` seconds (no update meanwhile), and
`RESULTS.estimator_diverged` once a prediction is not finite, the model fails on
the forces, or `patience` fixes in a row fall beyond the chi-square gate: the
estimates are then frozen and the predicted elongation is the nominal model's
(propagated beside it at every sample), never a silent NaN.
"""

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
from jaxtyping import Array, ArrayLike, Float

from .._drive import controller_init, controller_step
from .._models import AbstractCableModel
from .._results import RESULTS
from .horizon import (
    Anchor,
    Track,
    fix_residual,
    solve,
    tangent_step,
    unit_directions,
    window_init,
    window_push,
)
from .robot import NOMINAL, Robot, _solve3
from .signals import Fix
from .state import EstimatorState


DEFAULT_PARAMETERS = ("E1c", "E1r", "E3r", "t_e")
# Not a field of the model: each load cell's drift rate, N/h, from zero at the
# estimator's start (its readings less rate * elapsed time reach the model).
LOAD_CELL_DRIFT = "load_cell_drift"


def _getter(name: str):
    return lambda model: functools.reduce(getattr, name.split("."), model)


class OnlineEstimator(eqx.Module):
    """An online estimator of each cable's model parameters: an extended Kalman
    filter over their logs, with the model's states and their sensitivities carried
    along (the method and its reasons: this module's documentation).

    **Fields (SI):**

    - `robot`: the [`jaxcable.cdpr.Robot`][] (geometry of the fixes' measurement).
    - `model`: the nominal model shared by the cables (default
        [`jaxcable.cdpr.NOMINAL`][]): the start of the estimates, the values of
        the parameters not estimated and the fallback.
    - `parameters`: the names of the estimated scalar fields (default E1c, E1r,
        E3r, t_e), dotted for a wrapped model (`"base.E2r"`), and
        `"load_cell_drift"`: each load cell's drift rate, N/h, from zero at the start
        (estimated as it is, not as a log; its `prior_std` in N/h).
    - `prior_std`: the standard deviation of the start's logs (0.3: 30 %), one
        for all parameters or one per parameter (a tuple).
    - `drift`: the random walk of the logs, 1/sqrt(s) (0: constant cables).
    - `fix_noise`: standard deviation of a fix's coordinates, m.
    - `gate`: the normalised innovation squared above which a fix is rejected
        (chi-square, 3 degrees of freedom: 25 is a 1.6e-5 false alarm).
    - `patience`: rejected fixes in a row that mean divergence.
    - `max_fix_gap`: s without a fix before `RESULTS.signal_lost`.
    - `stuck_time`: s of one unchanged load-cell reading before
        `RESULTS.signal_lost` (a noisy load cell never repeats a value).
    - `window`: samples in the moving horizon of the re-linearisation (3600: an
        hour at 1 Hz; memory grows with it, cost with `window / every`).
    - `every`: samples between two re-linearisations (0: never, the plain
        extended Kalman filter).
    - `iterations`: Levenberg-Marquardt trial steps per re-linearisation (each a
        pass over the window, after the pass at the start).
    """

    robot: Robot = eqx.field(default_factory=Robot)
    model: AbstractCableModel = NOMINAL
    parameters: tuple[str, ...] = eqx.field(default=DEFAULT_PARAMETERS, static=True)
    prior_std: float | tuple[float, ...] = eqx.field(default=0.3, static=True)
    drift: float = eqx.field(default=0.0, static=True)
    fix_noise: float = eqx.field(default=0.5e-3, static=True)
    gate: float = eqx.field(default=25.0, static=True)
    patience: int = eqx.field(default=3, static=True)
    max_fix_gap: float = eqx.field(default=60.0, static=True)
    stuck_time: float = eqx.field(default=30.0, static=True)
    window: int = eqx.field(default=7200, static=True)
    every: int = eqx.field(default=600, static=True)
    iterations: int = eqx.field(default=4, static=True)

    def __check_init__(self):
        if not isinstance(self.model, AbstractCableModel):
            raise TypeError(
                f"`model` must be a jaxcable model, got {type(self.model).__name__}."
            )
        if len(self.parameters) == 0:
            raise ValueError("`parameters` must name at least one field.")
        for name in self.parameters:
            if name == LOAD_CELL_DRIFT:
                continue
            try:
                leaf = _getter(name)(self.model)
            except AttributeError:
                raise ValueError(
                    f"`parameters`: {type(self.model).__name__} has no field {name!r}."
                ) from None
            if not (eqx.is_array(leaf) and jnp.ndim(leaf) == 0):
                raise ValueError(
                    f"`parameters`: {name!r} is not a scalar array field of the model."
                )
            if not float(leaf) > 0:
                raise ValueError(
                    f"`parameters`: {name!r} = {float(leaf)} must be positive (its "
                    "log is estimated)."
                )
        prior = self.prior_std
        prior = prior if isinstance(prior, tuple) else (prior,) * len(self.parameters)
        if len(prior) != len(self.parameters) or not all(v > 0 for v in prior):
            raise ValueError(
                f"`prior_std` must be positive, one value or one per parameter "
                f"({len(self.parameters)}), got {self.prior_std!r}."
            )
        for name in ("fix_noise", "gate", "max_fix_gap", "stuck_time"):
            if not getattr(self, name) > 0:
                raise ValueError(f"`{name}` must be positive.")
        if not self.drift >= 0 or not (isinstance(self.patience, int)):
            raise ValueError("`drift` must be >= 0 and `patience` an integer.")
        for name in ("window", "every", "iterations"):
            value = getattr(self, name)
            if not (isinstance(value, int) and value >= 0):
                raise ValueError(f"`{name}` must be an integer >= 0, got {value!r}.")
        if self.every > 0 and not self.window > self.every:
            raise ValueError(
                f"`window` ({self.window}) must exceed `every` ({self.every}) to "
                "re-linearise."
            )

    @property
    def prior_variance(self) -> Float[Array, " p"]:
        """The variance of each parameter's log at the start, `(p,)`."""
        prior = jnp.asarray(self.prior_std, float)
        return jnp.broadcast_to(prior**2, (len(self.parameters),))

    def models(self, log_parameters: Float[ArrayLike, "n p"]) -> AbstractCableModel:
        """The cables' model with these log-parameters: every array with a leading
        axis n (use with `per_cable=True`), the other parameters the nominal ones.

        **Arguments:**

        - `log_parameters`: shape `(n, p)`.

        **Returns:**

        The model (the type of `model`).
        """
        theta = jnp.asarray(log_parameters)
        n = theta.shape[0]
        model = jtu.tree_map(
            lambda x: jnp.broadcast_to(x, (n, *jnp.shape(x))) if eqx.is_array(x) else x,
            self.model,
        )
        fields = [
            (j, _getter(name))
            for j, name in enumerate(self.parameters)
            if name != LOAD_CELL_DRIFT
        ]
        values = tuple(jnp.exp(theta[:, j]) for j, _ in fields)
        return eqx.tree_at(lambda m: tuple(g(m) for _, g in fields), model, values)

    @property
    def additive(self) -> tuple[bool, ...]:
        """Which estimated quantities are not logs (the load cells' drift)."""
        return tuple(name == LOAD_CELL_DRIFT for name in self.parameters)

    def forces(self, theta, time, origin, forces):
        """The load cells' readings less their estimated drift, N, `(n,)`."""
        if LOAD_CELL_DRIFT not in self.parameters:
            return forces
        rate = theta[:, self.parameters.index(LOAD_CELL_DRIFT)]
        return forces - rate * (time - origin) / 3600.0

    def _nominal_log(self, n: int, dtype) -> Float[Array, "n p"]:
        logs = jnp.stack(
            [
                jnp.zeros(())
                if name == LOAD_CELL_DRIFT
                else jnp.log(_getter(name)(self.model))
                for name in self.parameters
            ]
        )
        return jnp.broadcast_to(logs.astype(dtype), (n, len(self.parameters)))

    def init(
        self,
        lengths: Float[ArrayLike, " n"],
        position: Float[ArrayLike, " 3"],
        time: Float[ArrayLike, ""] = 0.0,
    ) -> EstimatorState:
        """The estimator's state for new, unloaded cables: the nominal model's
        parameters with `prior_std`.

        **Arguments:**

        - `lengths`: the cables' free lengths, m, shape `(n,)`.
        - `position`: the end-effector's known start position, m.
        - `time`: s.

        **Returns:**

        An [`jaxcable.cdpr.EstimatorState`][].
        """
        lengths = jnp.asarray(lengths, jnp.result_type(float, lengths))
        dtype, (n,) = lengths.dtype, lengths.shape
        p = len(self.parameters)
        time = jnp.asarray(time, dtype)
        theta = self._nominal_log(n, dtype)
        cables = self.robot.cables(lengths)

        def packed(theta):
            init = controller_init(self.models(theta), cables, time, per_cable=True)
            return init.packed

        model_state = controller_init(self.models(theta), cables, time, per_cable=True)
        _, tangent = jax.linearize(packed, theta)
        sensitivity = jax.vmap(tangent)(unit_directions(n, p, dtype))
        track = Track(
            model_state, sensitivity, jnp.zeros(n, dtype), jnp.zeros((p, n), dtype)
        )
        variance = jnp.tile(self.prior_variance.astype(dtype), n)
        information = jnp.diag(1.0 / variance)
        zero = jnp.zeros((), dtype)
        return EstimatorState(
            log_parameters=theta,
            covariance=jnp.diag(variance),
            track=track,
            window=window_init(max(self.window, 1), n, dtype),
            anchor=Anchor(track, theta, information, information @ theta.reshape(-1)),
            solution=theta,
            reduced_chi2=zero,
            nominal=controller_init(self.model, cables, time),
            position=jnp.asarray(position, dtype),
            time=time,
            fix_time=time,
            forces=jnp.full(n, jnp.nan, dtype),
            force_time=jnp.full(n, time),
            nis=zero,
            rejected=zero,
            result=RESULTS.successful,
            origin=time,
            additive=self.additive,
        )

    def step(
        self,
        state: EstimatorState,
        time: Float[ArrayLike, ""],
        forces: Float[ArrayLike, " n"],
        lengths: Float[ArrayLike, " n"],
        fix: Fix,
    ) -> tuple[EstimatorState, Float[Array, " n"]]:
        """One control sample: update with the previous sample's fix, then predict
        this sample's elongations from the measured forces.

        A pure function (jit, vmap over robots, `lax.scan` over samples).

        **Arguments:**

        - `state`: the [`jaxcable.cdpr.EstimatorState`][] after the previous sample.
        - `time`: this sample's time, s.
        - `forces`: the load cells' forces, N, shape `(n,)`.
        - `lengths`: the free lengths at which to predict, m, shape `(n,)` (the
            encoders', or the desired position's as
            [`jaxcable.cdpr.simulate_robot`][] commands them; the strain is what is
            stored for the next fix).
        - `fix`: a [`jaxcable.cdpr.Fix`][] of the end of the previous sample (its
            `valid` False when there is none).

        **Returns:**

        `(state, elongation)`: the new state and the predicted elongations, m,
        shape `(n,)` (the nominal model's once the estimator has diverged).
        """
        dtype = state.log_parameters.dtype
        time = jnp.asarray(time, dtype)
        forces = jnp.asarray(forces, dtype)
        lengths = jnp.asarray(lengths, dtype)
        # Signals: the fix's age and the load cells' last change.
        changed = forces != state.forces
        force_time = jnp.where(changed, time, state.force_time)
        stuck = jnp.any(time - force_time > self.stuck_time)
        fix_time = jnp.where(fix.valid, state.time, state.fix_time)
        lost = stuck | (time - fix_time > self.max_fix_gap)
        state = eqx.tree_at(
            lambda s: (s.forces, s.force_time, s.fix_time),
            state,
            (forces, force_time, fix_time),
        )
        if self.every > 0:
            due = (state.window.since >= self.every) & ~state.diverged
            state = jax.lax.cond(
                due, lambda s: self._relinearise(s, due), lambda s: s, state
            )
        state, used = self._update(state, fix, ~stuck)
        if self.every > 0:
            sample = Fix(fix.position, fix.lengths, used)
            window = window_push(state.window, time, forces, lengths, sample)
            state = eqx.tree_at(lambda s: s.window, state, window)
        dt = jnp.maximum(time - state.time, 0.0)
        covariance = state.covariance + (self.drift**2 * dt) * jnp.eye(
            state.covariance.shape[0], dtype=dtype
        )
        state = eqx.tree_at(lambda s: s.covariance, state, covariance)
        return self._propagate(state, time, forces, lengths, lost)

    def _update(self, state: EstimatorState, fix: Fix, usable):
        """The Kalman update with a fix (a no-op without one); also whether the fix
        was used."""
        n, p = state.log_parameters.shape
        P = state.covariance
        track = state.track
        innovation, H = fix_residual(
            self.robot, track.strain, track.strain_sensitivity, fix
        )
        PHt = P @ H.T
        S = H @ PHt + self.fix_noise**2 * jnp.eye(3, dtype=P.dtype)
        Sinv = jax.vmap(lambda b: _solve3(S, b), out_axes=1)(jnp.eye(3, dtype=P.dtype))
        nis = innovation @ Sinv @ innovation
        K = PHt @ Sinv
        step = K @ innovation
        # Joseph form: the covariance stays symmetric and positive.
        IKH = jnp.eye(n * p, dtype=P.dtype) - K @ H
        P_new = IKH @ P @ IKH.T + self.fix_noise**2 * (K @ K.T)
        P_new = 0.5 * (P_new + P_new.T)
        finite = jnp.isfinite(nis) & jnp.all(jnp.isfinite(P_new))
        accepted = fix.valid & usable & finite & (nis <= self.gate) & ~state.diverged
        rejected = jnp.where(
            fix.valid & usable,
            jnp.where(accepted, 0.0, state.rejected + 1.0),
            state.rejected,
        )
        diverged = state.diverged | (rejected >= self.patience)
        diverged = diverged | (fix.valid & ~finite)
        step = jnp.where(accepted, step, 0.0).reshape(n, p)
        # The model's states move with their sensitivities (the joint EKF's update
        # of states that carry no noise of their own).
        state = eqx.tree_at(
            lambda s: (
                s.log_parameters,
                s.covariance,
                s.track,
                s.position,
                s.nis,
                s.rejected,
                s.result,
            ),
            state,
            (
                state.log_parameters + step,
                jnp.where(accepted, P_new, P),
                track.moved(step),
                jnp.where(fix.valid, fix.position, state.position),
                jnp.where(fix.valid, nis, state.nis),
                rejected,
                RESULTS.where(diverged, RESULTS.estimator_diverged, state.result),
            ),
        )
        return state, accepted

    def _relinearise(self, state: EstimatorState, due) -> EstimatorState:
        """The moving horizon's Gauss-Newton solve (`jaxcable.cdpr.horizon`) in
        place of the filter's estimate, covariance and track; a solve that is not
        finite is not taken and means divergence."""
        # From the last solution or the filter's estimate, whichever the window's
        # fixes prefer: the filter wanders between solves, and the anchor's states
        # are first order in the parameters; but early on it may be ahead.
        theta, covariance, chi2, track, window, anchor = solve(
            self,
            state.window,
            state.anchor,
            state.solution,
            state.log_parameters,
            due,
            state.origin,
        )
        finite = jnp.all(jnp.isfinite(theta)) & jnp.all(jnp.isfinite(covariance))
        finite = finite & jnp.all(jnp.isfinite(track.strain))
        solved = eqx.tree_at(
            lambda s: (
                s.log_parameters,
                s.covariance,
                s.track,
                s.window,
                s.anchor,
                s.solution,
                s.reduced_chi2,
            ),
            state,
            (theta, covariance, track, window, anchor, theta, chi2),
        )
        state = jax.tree.map(lambda a, b: jnp.where(finite, a, b), solved, state)
        result = RESULTS.where(finite, state.result, RESULTS.estimator_diverged)
        return eqx.tree_at(lambda s: s.result, state, result)

    def _propagate(self, state, time, forces, lengths, lost):
        """The model's step at the estimates, with the sensitivities' tangents, and
        the nominal model's step (the fallback)."""
        new, track, elongation = tangent_step(
            self, state.log_parameters, state.track, time, forces, lengths, state.origin
        )
        cables = self.robot.cables(lengths)
        nominal, fallback = controller_step(
            self.model, cables, state.nominal, time, forces, throw=False
        )
        failed = jnp.any(new.result != RESULTS.successful)
        failed = failed | ~jnp.all(jnp.isfinite(elongation))
        diverged = state.diverged | failed
        result = RESULTS.where(
            diverged,
            RESULTS.estimator_diverged,
            RESULTS.where(lost, RESULTS.signal_lost, RESULTS.successful),
        )
        predicted = jnp.where(diverged, fallback, elongation)
        new_state = eqx.tree_at(
            lambda s: (s.track, s.nominal, s.time, s.result),
            state,
            (track, nominal, time, result),
        )
        return new_state, predicted
