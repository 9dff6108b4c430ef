"""The online estimator's moving-horizon re-linearisation (jaxcable.cdpr.horizon): its
solve is the maximum a-posteriori estimate of the window's fixes, recomputed here
from scratch with the public model API; folding the oldest samples into the anchor
changes nothing at a fixed linearisation point; the solve runs inside the step."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxcable as jc
from jaxcable import cdpr
from jaxcable.cdpr import horizon
from jaxcable.cdpr.scenario import real_sensors


ROBOT = cdpr.Robot()
ESTIMATOR = cdpr.OnlineEstimator(ROBOT, window=400, every=100, iterations=6)


@pytest.fixture(scope="module")
def loop():
    # Four minutes of pick-and-place, cables 10 % off, fixes every 10 s with 0.5 mm
    # of noise, exact load cells: the estimator's model is the real cables'. The
    # ropes are bedded in (E1r 1.5 E1c): away from the kink of Park's Eq. 9, where
    # the posterior is smooth and its optimum stationary.
    scenario = cdpr.pick_and_place(hours=4 / 60)
    real = cdpr.real_cables(
        jax.random.key(2), relative_std=0.1, compliance=0.0, bedded_in=range(8)
    )
    real = real.base  # no termination compliance: correctly specified
    sensors = real_sensors(
        jax.random.key(3), scenario, ROBOT.num_cables, force_noise=0.0, force_drift=0.0
    )
    run = cdpr.simulate_online(ESTIMATOR, scenario, real, sensors)
    return scenario, run


def _objective(estimator, window, theta0, theta):
    """The negative log-posterior of the window's fixes (from the start, no fold),
    re-simulated with `controller_init` / `controller_step` and `fix_prediction`."""
    robot = estimator.robot
    n = robot.num_cables
    model = estimator.models(theta)
    t0 = window.time[0]
    state = jc.controller_init(
        model, robot.cables(window.lengths[0]), t0, per_cable=True
    )
    state = eqx.tree_at(lambda s: s.packed, state, state.packed)

    def body(carry, k):
        state, strain = carry
        t, forces, lengths, fix = window.sample(k)
        x, _ = cdpr.fix_prediction(
            robot, fix.lengths, strain * fix.lengths, fix.position
        )
        r = jnp.where(fix.valid, fix.position - x, 0.0) / estimator.fix_noise
        state, elongation = jc.controller_step(
            model, robot.cables(lengths), state, t, forces, throw=False
        )
        return (state, elongation / lengths), r

    strain0 = jnp.zeros(n, theta.dtype)
    _, r = jax.lax.scan(body, (state, strain0), jnp.arange(window.count))
    prior = (theta - theta0).reshape(-1) / jnp.sqrt(
        jnp.tile(estimator.prior_variance, n)
    )
    return jnp.concatenate([r.reshape(-1), prior])


def test_the_solve_is_the_maximum_a_posteriori_estimate(loop):
    _, run = loop
    state = run.state
    window = state.window
    assert int(window.start) == 0 and int(window.count) == 241
    theta0 = (
        cdpr.OnlineEstimator(ROBOT)
        .init(window.lengths[0], cdpr.HOME, 0.0)
        .log_parameters
    )
    theta, covariance, chi2, *_ = horizon.solve(
        ESTIMATOR, window, state.anchor, state.solution, state.log_parameters
    )
    residuals = jax.jit(lambda th: _objective(ESTIMATOR, window, theta0, th))
    jacobian = jax.jit(jax.jacfwd(residuals))
    J = jacobian(theta).reshape(-1, theta.size)
    gradient = J.T @ residuals(theta)
    gradient_at_start = jacobian(theta0).reshape(-1, theta.size).T @ residuals(theta0)
    # Stationary: the gradient 1e-3 of its size at the prior's centre.
    assert float(jnp.linalg.norm(gradient)) < 1e-3 * float(
        jnp.linalg.norm(gradient_at_start)
    )
    # The covariance is the inverse Gauss-Newton Hessian of the posterior.
    expected = jnp.linalg.inv(J.T @ J)
    np.testing.assert_allclose(
        jnp.sqrt(jnp.diagonal(covariance)), jnp.sqrt(jnp.diagonal(expected)), rtol=1e-3
    )
    # Exact load cells, a correct model: the fixes' noise is all that is left.
    assert 0.6 < float(chi2) < 1.4


def test_folding_into_the_anchor_is_exact_at_a_fixed_point(loop):
    _, run = loop
    state = run.state
    theta = state.solution
    # No trial step: each solve linearises at `theta`. every=250: 241 + 250 > 400,
    # the oldest 91 samples are folded; every=100: none.
    once = cdpr.OnlineEstimator(ROBOT, window=400, every=100, iterations=0)
    folding = cdpr.OnlineEstimator(ROBOT, window=400, every=250, iterations=0)
    results = []
    for estimator in (folding, once):
        _, _, _, _, window, anchor = horizon.solve(
            estimator, state.window, state.anchor, theta
        )
        results.append((int(window.count), horizon.solve(once, window, anchor, theta)))
    (count_a, a), (count_b, b) = results
    assert (count_a, count_b) == (150, 241)
    np.testing.assert_allclose(a[0], b[0], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(a[1], b[1], rtol=1e-7, atol=1e-14)
    np.testing.assert_allclose(a[3].strain, b[3].strain, rtol=1e-10)


def test_the_step_solves_every_every_samples(loop):
    scenario, run = loop
    t = np.asarray(scenario.time)
    # The solves at samples 100 and 200 move the estimate; the filter's updates
    # between them move it only at the fixes (every 10 s).
    moved = np.any(np.diff(np.asarray(run.log_parameters), axis=0) != 0, axis=(1, 2))
    steps = t[1:][moved]
    assert {100.0, 200.0} <= set(steps.tolist())
    assert set(steps.tolist()) - {100.0, 200.0} <= {10.0 * k + 1 for k in range(25)}
    assert bool(jnp.all(run.result == jc.RESULTS.successful))
    assert run.state.solution.shape == (ROBOT.num_cables, 4)


def test_bad_horizon_options_are_refused():
    for options in (
        dict(every=-1),
        dict(window=100, every=100),
        dict(every=10, iterations=-1),
        dict(window=1.5),
        dict(prior_std=(0.3, 0.3)),
        dict(prior_std=(0.3, 0.3, 0.3, -1.0)),
    ):
        with pytest.raises(ValueError):
            cdpr.OnlineEstimator(ROBOT, **options)
    # every=0: the plain filter, no window needed.
    cdpr.OnlineEstimator(ROBOT, every=0, window=0)


def test_a_load_cells_drift_is_learnt_with_the_cables():
    # Exact fixes every 10 s told 0.1 mm; load cells drifting at 36 N/h each (drawn),
    # no noise; the estimator learns each cell's rate with E1c, E1r, E3r and t_e.
    scenario = cdpr.pick_and_place(hours=20 / 60)
    real = cdpr.real_cables(
        jax.random.key(4), relative_std=0.05, compliance=0.0, bedded_in=range(8)
    ).base
    sensors = real_sensors(
        jax.random.key(5), scenario, ROBOT.num_cables, force_noise=0.0, force_drift=36.0
    )
    sensors = eqx.tree_at(lambda s: s.fix_error, sensors, 0.0 * sensors.fix_error)
    t = np.asarray(scenario.time)
    rate = np.polyfit(t, np.asarray(sensors.force_error), 1)[0] * 3600.0  # N/h
    names = cdpr.DEFAULT_PARAMETERS + ("load_cell_drift",)
    options = dict(window=1300, every=400, fix_noise=1e-4)
    learning = cdpr.OnlineEstimator(
        ROBOT, parameters=names, prior_std=(0.3,) * 4 + (50.0,), **options
    )
    ignoring = cdpr.OnlineEstimator(ROBOT, **options)
    state = cdpr.simulate_online(learning, scenario, real, sensors).state
    assert state.additive == (False,) * 4 + (True,)
    drift = np.asarray(state.parameters[:, 4])
    low, high = (np.asarray(a[:, 4]) for a in state.interval())
    # Twenty minutes identify the rates only in part (a drift and a softer cable
    # look alike at first): each interval holds the true rate and is narrower than
    # the prior's (N/h, not exp'd).
    assert np.all((low <= rate) & (rate <= high)), (drift, rate)
    assert np.all(np.asarray(state.std[:, 4]) < 0.7 * 50.0)
    # Unlearnt, the drift leaves misfit: a reduced chi-square several times larger.
    other = cdpr.simulate_online(ignoring, scenario, real, sensors).state
    assert float(other.reduced_chi2) > 3.0 * float(state.reduced_chi2)
    with pytest.raises(ValueError):
        cdpr.OnlineEstimator(ROBOT, parameters=("E1c", "load_cells"))
