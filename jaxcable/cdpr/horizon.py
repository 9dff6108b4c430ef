r"""The online estimator's re-linearisation: a Gauss-Newton solve over a moving horizon
of the robot's recorded samples, run every `every` samples inside
[`jaxcable.cdpr.OnlineEstimator`][]`.step`.

**Why.** The extended Kalman filter linearises each fix once, at the estimate of the
moment, and moves the model's states by their sensitivities times the parameters'
step. From a start 30 % away from the cables' values those early linearisations are
wrong by more than the data's noise, and what they leave in the estimate and its
covariance never goes away. On a robot whose cables differ from the model only in
the estimated parameters (four draws of an hour, exact load cells), its 95 % intervals
held the truth in about 40 % of cases, and the maximum a-posteriori estimate of the
same data, linearised at its own solution, in about 90 %; with the robot of
`benchmarks/online.py` (every parameter drawn, noisy and drifting load cells) the
filter's held 23 % and the solve's 60 % (`benchmarks/results/online.json`). The horizon solve is that estimate, bounded in memory: the samples of
the last `window` control steps (times, load-cell forces, encoder lengths and the
fixes the filter accepted) in a ring, the model's states at the window's start with
their sensitivities (the anchor), and what the samples before the window said about
the parameters, as one Gaussian (the arrival cost: its information matrix and
shift, the prior's included).

**A solve.** Each pass re-simulates the window from the anchor at the linearisation
point, in the order of the filter's step (the fix against the last sample's strain,
then the step to the sample's forces), and accumulates the normal equations of the
fixes' residuals (`A`, `b`); the Gauss-Newton step with the arrival cost is

$$(\Lambda_a + A)\,\theta^{+} = \eta_a + A\,\theta_l + b,$$

whose inverse matrix is the parameters' covariance. `iterations` passes, each at the
last one's solution. The states after the window are those of the last pass, moved by
their sensitivities to the final solution (a step that is small by then). Once the
ring is full, the oldest samples are folded into the anchor: their states (from the
last pass) become the window's start and their normal equations join the arrival
cost, linearised where the last pass was.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int

from .._drive import ControllerState, controller_step
from .robot import Robot
from .signals import Fix, fix_prediction


class Window(eqx.Module):
    """The samples of a moving horizon, in a ring of `W` slots (n cables, SI).

    **Fields:** `time` (s, `(W,)`), `forces` (N, `(W, n)`), `lengths` (m, `(W, n)`:
    the free lengths the model was stepped at), `fix_position` (m, `(W, 3)`),
    `fix_lengths` (m, `(W, n)`), `fix_used` (`(W,)`: a fix the filter accepted),
    `start` (the oldest sample's slot), `count` (samples held), `since` (samples
    since the last solve).
    """

    time: Float[Array, " W"]
    forces: Float[Array, "W n"]
    lengths: Float[Array, "W n"]
    fix_position: Float[Array, "W 3"]
    fix_lengths: Float[Array, "W n"]
    fix_used: Bool[Array, " W"]
    start: Int[Array, ""]
    count: Int[Array, ""]
    since: Int[Array, ""]

    @property
    def size(self) -> int:
        return self.time.shape[0]

    def sample(self, k):
        """The k-th oldest sample: `(time, forces, lengths, fix)`."""
        i = (self.start + k) % self.size
        fix = Fix(self.fix_position[i], self.fix_lengths[i], self.fix_used[i])
        return self.time[i], self.forces[i], self.lengths[i], fix


def window_init(size: int, n: int, dtype) -> Window:
    """An empty ring of `size` samples of n cables."""
    zero = jnp.zeros((), jnp.int32)
    return Window(
        time=jnp.zeros(size, dtype),
        forces=jnp.zeros((size, n), dtype),
        lengths=jnp.ones((size, n), dtype),
        fix_position=jnp.zeros((size, 3), dtype),
        fix_lengths=jnp.ones((size, n), dtype),
        fix_used=jnp.zeros(size, bool),
        start=zero,
        count=zero,
        since=zero,
    )


def window_push(window: Window, time, forces, lengths, fix: Fix) -> Window:
    """The ring with one more sample (the caller keeps `count` below the size by
    solving, which folds the oldest samples, before it is full)."""
    i = (window.start + window.count) % window.size
    return eqx.tree_at(
        lambda w: (
            w.time,
            w.forces,
            w.lengths,
            w.fix_position,
            w.fix_lengths,
            w.fix_used,
            w.count,
            w.since,
        ),
        window,
        (
            window.time.at[i].set(time),
            window.forces.at[i].set(forces),
            window.lengths.at[i].set(lengths),
            window.fix_position.at[i].set(fix.position),
            window.fix_lengths.at[i].set(fix.lengths),
            window.fix_used.at[i].set(fix.valid),
            jnp.minimum(window.count + 1, window.size),
            window.since + 1,
        ),
    )


class Track(eqx.Module):
    """The model along a history with its sensitivities to the log-parameters (n
    cables, p parameters): the states, d states / d theta (one tangent per
    parameter), the last sample's strains `(n,)` and their derivatives `(p, n)`."""

    model: ControllerState
    sensitivity: tuple[Float[Array, "p n _k"], ...]
    strain: Float[Array, " n"]
    strain_sensitivity: Float[Array, "p n"]

    def moved(self, step: Float[Array, "n p"]) -> "Track":
        """The states to first order at the log-parameters plus `step`."""
        packed = tuple(
            x + jnp.einsum("pnk,np->nk", s, step)
            for x, s in zip(self.model.packed, self.sensitivity)
        )
        model = eqx.tree_at(lambda m: m.packed, self.model, packed)
        strain = self.strain + jnp.einsum("pn,np->n", self.strain_sensitivity, step)
        return Track(model, self.sensitivity, strain, self.strain_sensitivity)


class Anchor(eqx.Module):
    """The window's start: the track there, linearised at `theta` `(n, p)`, and the
    arrival cost, a Gaussian on the log-parameters given by its information
    `(n p, n p)` and shift (information times mean, `(n p,)`)."""

    track: Track
    theta: Float[Array, "n p"]
    information: Float[Array, "np np"]
    shift: Float[Array, " np"]


def fix_residual(robot: Robot, strain, strain_sensitivity, fix: Fix):
    """A fix's residual against the position the predicted strains imply, and its
    Jacobian in the log-parameters, `(3,)` and `(3, n p)` (cable-major)."""
    lengths = fix.lengths
    x_pred, dx_de = fix_prediction(robot, lengths, strain * lengths, fix.position)
    de = (strain_sensitivity * lengths).T
    H = (dx_de[:, :, None] * de[None, :, :]).reshape(3, -1)
    return fix.position - x_pred, H


def unit_directions(n: int, p: int, dtype) -> Float[Array, "p n p"]:
    """The tangents of the log-parameters, one per parameter: tangent j moves
    parameter j of every cable at once (the cables are independent, so cable i's
    tangent is its derivative in its own parameter j)."""
    return jnp.broadcast_to(jnp.eye(p, dtype=dtype)[:, None, :], (p, n, p))


def tangent_step(estimator, theta, track: Track, time, forces, lengths, origin):
    """One step of the cables' model at the log-parameters `theta` with the
    sensitivities carried forward (`jax.linearize`, one tangent per parameter).

    **Returns:** `(new_state, track, elongation)`: the model's new
    `ControllerState` (its result included), the new `Track` and the elongations,
    m, `(n,)`.
    """
    n, p = theta.shape
    cables = estimator.robot.cables(lengths)
    template = track.model

    def run(theta, packed):
        state = eqx.tree_at(lambda m: m.packed, template, packed)
        model, load = (
            estimator.models(theta),
            estimator.forces(theta, time, origin, forces),
        )
        new, elongation = controller_step(model, cables, state, time, load, throw=False)
        return (new.packed, elongation), new

    (_, elongation), linear, new = jax.linearize(
        run, theta, template.packed, has_aux=True
    )
    directions = unit_directions(n, p, elongation.dtype)
    sensitivity, d_elongation = jax.vmap(linear)(directions, track.sensitivity)
    track = Track(new, sensitivity, elongation / lengths, d_elongation / lengths)
    return new, track, elongation


def _pass(estimator, window: Window, anchor: Anchor, theta, fold, active, origin):
    """Re-simulate the window at `theta` from the anchor: the normal equations of
    its fixes, the track after it, and the track and normal equations after its
    first `fold` samples."""
    n, p = theta.shape
    m = n * p
    dtype = theta.dtype
    track = anchor.track.moved(theta - anchor.theta)
    zeros = (jnp.zeros((m, m), dtype), jnp.zeros(m, dtype))
    inverse_variance = 1.0 / estimator.fix_noise**2

    def body(k, carry):
        track, A, b, chi2, kept = carry
        # The fold's anchor is the track before sample `fold`.
        kept = jax.tree.map(
            lambda new, old: jnp.where(k == fold, new, old), (track, A, b), kept
        )
        time, forces, lengths, fix = window.sample(k)
        r, H = fix_residual(
            estimator.robot, track.strain, track.strain_sensitivity, fix
        )
        w = jnp.where(fix.valid, inverse_variance, 0.0)
        A = A + w * (H.T @ H)
        b = b + w * (H.T @ r)
        chi2 = chi2 + jnp.stack([w * (r @ r), jnp.where(fix.valid, 3.0, 0.0)])
        _, track, _ = tangent_step(
            estimator, theta, track, time, forces, lengths, origin
        )
        return track, A, b, chi2, kept

    kept = (track, *zeros)
    chi2 = jnp.zeros(2, dtype)
    # Under `vmap` a `lax.cond` runs both branches: an inactive pass is empty.
    count = jnp.where(active, window.count, 0)
    track, A, b, chi2, kept = jax.lax.fori_loop(
        0, count, body, (track, *zeros, chi2, kept)
    )
    return track, A, b, chi2, kept


class _Point(eqx.Module):
    """A linearisation point of the horizon's least squares and its pass."""

    theta: Float[Array, "n p"]
    track: Track
    A: Float[Array, "np np"]
    b: Float[Array, " np"]
    chi2: Float[Array, " 2"]
    kept: tuple
    objective: Float[Array, ""]


def _point(estimator, window, anchor, theta, fold, active, origin) -> _Point:
    track, A, b, chi2, kept = _pass(
        estimator, window, anchor, theta, fold, active, origin
    )
    x = theta.reshape(-1)
    # The negative log-posterior, up to a constant: the fixes' chi-square and the
    # arrival cost's quadratic form.
    objective = 0.5 * chi2[0] + 0.5 * x @ (anchor.information @ x) - anchor.shift @ x
    objective = jnp.where(jnp.isfinite(objective), objective, jnp.inf)
    return _Point(theta, track, A, b, chi2, kept, objective)


def solve(
    estimator,
    window: Window,
    anchor: Anchor,
    theta,
    other=None,
    active=True,
    origin: float | Array = 0.0,
):
    """The horizon's maximum a-posteriori solve from `theta` `(n, p)` (or from
    `other` where its posterior is higher): a Levenberg-Marquardt iteration on the
    window's Gauss-Newton normal equations (its passes empty where `active` is
    False).

    A pass at the start, then `estimator.iterations` trial steps, each a pass at the
    trial point, taken when it lowers the negative log-posterior (the damping then
    shrinks) and refused otherwise (it grows): the switch between the loading and
    the unloading moduli (Park Eq. 9) makes the posterior kinked, and plain
    Gauss-Newton steps can cycle across it.

    **Returns:** `(theta, covariance, reduced_chi2, track, window, anchor)`: the
    solution, its covariance (the inverse Gauss-Newton Hessian there), the fixes'
    reduced chi-square, the track after the window at the solution, and the window
    and anchor after folding the samples that the next `every` samples will push
    out. `origin` is the estimator's start (s), where a load cell's drift is zero.
    """
    n, p = theta.shape
    fold = jnp.maximum(window.count + estimator.every - window.size, 0)
    start = _point(estimator, window, anchor, theta, fold, active, origin)
    if other is not None:
        alternative = _point(estimator, window, anchor, other, fold, active, origin)
        better = alternative.objective < start.objective
        start = jax.tree.map(lambda a, b: jnp.where(better, a, b), alternative, start)

    def trial(carry, _):
        best, damping = carry
        information = anchor.information + best.A
        rhs = anchor.shift + best.b - anchor.information @ best.theta.reshape(-1)
        scale = jnp.diag(jnp.diagonal(information))
        step = jnp.linalg.solve(information + damping * scale, rhs).reshape(n, p)
        new = _point(estimator, window, anchor, best.theta + step, fold, active, origin)
        better = new.objective < best.objective
        best = jax.tree.map(lambda a, b: jnp.where(better, a, b), new, best)
        damping = jnp.where(better, damping / 3.0, damping * 4.0)
        return (best, damping), None

    damping = jnp.asarray(1e-2, theta.dtype)
    (best, _), _ = jax.lax.scan(
        trial, (start, damping), None, length=estimator.iterations
    )
    covariance = jnp.linalg.inv(anchor.information + best.A)
    covariance = 0.5 * (covariance + covariance.T)
    # The reduced chi-square of the fixes: about 1 when the model and the fixes'
    # noise are right.
    reduced_chi2 = best.chi2[0] / jnp.maximum(best.chi2[1] - n * p, 1.0)
    kept_track, A_fold, b_fold = best.kept
    lin = best.theta
    new_anchor = Anchor(
        track=kept_track,
        theta=lin,
        information=anchor.information + A_fold,
        shift=anchor.shift + A_fold @ lin.reshape(-1) + b_fold,
    )
    folded = fold > 0
    anchor = jax.tree.map(lambda a, o: jnp.where(folded, a, o), new_anchor, anchor)
    window = eqx.tree_at(
        lambda w: (w.start, w.count, w.since),
        window,
        (
            (window.start + fold) % window.size,
            window.count - fold,
            jnp.zeros_like(window.since),
        ),
    )
    return lin, covariance, reduced_chi2, best.track, window, anchor
