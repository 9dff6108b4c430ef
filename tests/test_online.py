"""The online estimator of the robot's cables (jaxcable.cdpr.OnlineEstimator): its
recovery of known parameters, its carried sensitivities against finite differences,
jit and vmap, and its failures (divergence with a fallback, a lost signal)."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxcable as jc
from jaxcable import cdpr


ROBOT = cdpr.Robot()
NO = jnp.asarray(False)


def _rich_scenario(minutes: float, seed: int = 0, segment: float = 10.0):
    """Random waypoints over the workspace and random payloads: the fixes see the
    cables from many poses and loads."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(minutes * 60), dtype=float)
    count = t.size // int(segment) + 2
    way = np.column_stack(
        [
            rng.uniform(-1.0, 1.0, count),
            rng.uniform(-1.0, 1.0, count),
            rng.uniform(0.9, 2.2, count),
        ]
    )
    way[0] = cdpr.HOME
    mass = rng.uniform(0.0, 60.0, count)
    i = (t // segment).astype(int)
    s = np.clip((t % segment) / (0.6 * segment), 0.0, 1.0)
    s = s**3 * (10 - 15 * s + 6 * s**2)
    position = way[i] + s[:, None] * (way[i + 1] - way[i])
    return cdpr.Scenario(t, position, mass[i])


@eqx.filter_jit
def _closed_loop(estimator, scenario, real, fixes, reversed_forces, stuck=None):
    """The robot of `cdpr.simulate_robot` compensated by the estimator's prediction;
    a fix (exact) of the previous sample where `fixes`; the load cells' variations
    reversed (max + min - F) where `reversed_forces`; the first load cell's reading
    frozen where `stuck`."""
    stuck = jnp.zeros_like(fixes) if stuck is None else stuck
    robot = estimator.robot
    x0 = scenario.position[0]
    lengths0 = robot.free_lengths(x0)
    t0 = scenario.time[0]
    real_state = jc.controller_init(real, robot.cables(lengths0), t0, per_cable=True)
    nominal = jc.controller_init(estimator.model, robot.cables(lengths0), t0)
    state0 = estimator.init(lengths0, x0, t0)
    carry = (state0, real_state, nominal, x0, lengths0, jnp.zeros_like(lengths0))

    def body(carry, sample):
        state, real_state, nominal, x, command, last = carry
        t, x_d, payload, fix_here, stuck_here = sample
        forces = cdpr.tension_distribution(robot, x, robot.platform_mass + payload)
        fed = jnp.where(
            reversed_forces, jnp.max(forces) + jnp.min(forces) - forces, forces
        )
        fed = fed.at[0].set(jnp.where(stuck_here, last[0], fed[0]))
        lengths = robot.free_lengths(x_d)
        state, predicted = estimator.step(
            state, t, fed, lengths, cdpr.Fix(x, command, fix_here)
        )
        # The nominal model on the same signals: the fallback's reference.
        nominal, reference = jc.controller_step(
            estimator.model, robot.cables(lengths), nominal, t, fed, throw=False
        )
        command = lengths - predicted
        real_state, elongation = jc.controller_step(
            real, robot.cables(command), real_state, t, forces
        )
        x = cdpr.forward_kinematics(robot, command + elongation - robot.routing, x)
        record = (predicted, reference, state.result == jc.RESULTS.successful)
        record += (state.result == jc.RESULTS.estimator_diverged,)
        record += (state.result == jc.RESULTS.signal_lost,)
        return (state, real_state, nominal, x, command, fed), record

    xs = (scenario.time, scenario.position, scenario.payload, fixes, stuck)
    (state, *_), records = jax.lax.scan(body, carry, xs)
    return state, records


def _truth(estimator, offsets):
    n = ROBOT.num_cables
    start = jnp.stack(
        [jnp.log(getattr(estimator.model, p)) for p in estimator.parameters]
    )
    return start + jnp.asarray(offsets).reshape(n, -1)


def test_recovers_known_parameters_from_a_noiseless_loop():
    # Exact fixes at every sample, the filter told they are 10 µm; bedded-in cables
    # (E1c 3 % below its nominal value, so below E1r) drawn 1 % around that.
    estimator = cdpr.OnlineEstimator(ROBOT, fix_noise=1e-5)
    p = len(estimator.parameters)
    scenario = _rich_scenario(20.0)
    offsets = 0.01 * jax.random.normal(jax.random.key(1), (ROBOT.num_cables, p))
    truth = _truth(estimator, offsets).at[:, 0].add(-0.03)
    real = estimator.models(truth)
    fixes = jnp.arange(scenario.time.shape[0]) > 0
    state, (_, _, ok, *_) = _closed_loop(estimator, scenario, real, fixes, NO)
    assert bool(jnp.all(ok))
    start = _truth(estimator, jnp.zeros_like(offsets))
    start_error = float(jnp.max(jnp.abs(truth - start)))
    error = float(jnp.max(jnp.abs(state.log_parameters - truth)))
    assert start_error > 0.03
    assert error < 1e-3, (start_error, error)
    # Its uncertainty has shrunk from the prior's 30 % and the truth is inside.
    assert float(jnp.max(state.std)) < 0.01
    assert bool(jnp.all(cdpr.interval_covers(state, jnp.exp(truth), 5.0)))


@pytest.fixture(scope="module")
def forces_history():
    # A load, a hold, an unloading below the peak and a reload, on 8 cables.
    k = np.arange(40.0)
    shape = np.interp(k, [0, 10, 20, 28, 40], [20.0, 200.0, 200.0, 60.0, 150.0])
    scale = np.linspace(0.8, 1.2, ROBOT.num_cables)
    return jnp.asarray(shape[:, None] * scale[None, :])


def _run_without_fixes(estimator, forces):
    lengths = ROBOT.free_lengths(jnp.asarray(cdpr.HOME))
    state = estimator.init(lengths, jnp.asarray(cdpr.HOME), 0.0)

    def body(state, sample):
        t, f = sample
        state, _ = estimator.step(state, t, f, lengths, cdpr.Fix.missing(lengths))
        return state, None

    times = 1.0 + jnp.arange(forces.shape[0], dtype=forces.dtype)
    state, _ = jax.lax.scan(body, state, (times, forces))
    return state


_run_without_fixes_jit = eqx.filter_jit(_run_without_fixes)


def test_carried_sensitivities_match_finite_differences(forces_history):
    estimator = cdpr.OnlineEstimator(ROBOT)
    state = _run_without_fixes_jit(estimator, forces_history)
    assert state.track.strain.dtype == jnp.float64
    h = 1e-6
    for j, name in enumerate(estimator.parameters):

        def shifted(sign, name=name):
            value = getattr(estimator.model, name) * np.exp(sign * h)
            model = eqx.tree_at(lambda m: getattr(m, name), estimator.model, value)
            return _run_without_fixes_jit(
                eqx.tree_at(lambda e: e.model, estimator, model), forces_history
            )

        plus, minus = shifted(1.0), shifted(-1.0)
        fd = (plus.track.strain - minus.track.strain) / (2 * h)
        carried = state.track.strain_sensitivity[j]
        scale = float(jnp.max(jnp.abs(carried)))
        assert scale > 0, name
        np.testing.assert_allclose(carried, fd, rtol=1e-5, atol=1e-6 * scale)
        # The model state's sensitivity, every packed column.
        pairs = zip(plus.track.model.packed, minus.track.model.packed)
        for s, (a, b) in zip(state.track.sensitivity, pairs):
            np.testing.assert_allclose(s[j], (a - b) / (2 * h), rtol=1e-4, atol=1e-9)


def test_fix_prediction_jacobian_matches_finite_differences():
    x0 = jnp.asarray(cdpr.PICK)
    lengths = ROBOT.free_lengths(x0)
    elongation = jnp.linspace(0.02, 0.06, ROBOT.num_cables)
    x, jacobian = cdpr.fix_prediction(ROBOT, lengths, elongation, x0)
    h = 1e-7
    for i in range(ROBOT.num_cables):
        e = jnp.zeros(ROBOT.num_cables).at[i].set(h)
        a, _ = cdpr.fix_prediction(ROBOT, lengths, elongation + e, x0)
        b, _ = cdpr.fix_prediction(ROBOT, lengths, elongation - e, x0)
        np.testing.assert_allclose(jacobian[:, i], (a - b) / (2 * h), atol=1e-7)
    assert float(jnp.max(jnp.abs(jacobian))) > 0.1


@pytest.fixture(scope="module")
def short_loop():
    # Five minutes of pick-and-place, fixes every 10 s.
    scenario = cdpr.pick_and_place(hours=5 / 60)
    fixes = (jnp.arange(scenario.time.shape[0]) % 10 == 0) & (scenario.time > 0)
    real = cdpr.real_cables(jax.random.key(3), relative_std=0.1, compliance=0.0)
    return scenario, fixes, real


def test_jit_and_vmap_over_robots_agree(short_loop):
    scenario, fixes, _ = short_loop
    # Horizon solves at samples 100, 200 and 300 (the last folding 100 samples).
    estimator = cdpr.OnlineEstimator(ROBOT, window=300, every=100)
    keys = jax.random.split(jax.random.key(5), 2)
    offsets = jax.vmap(lambda k: 0.05 * jax.random.normal(k, (ROBOT.num_cables, 4)))(
        keys
    )
    truths = jax.vmap(lambda o: _truth(estimator, o))(offsets)
    reals = jax.vmap(estimator.models)(truths)
    batched = eqx.filter_vmap(
        _closed_loop, in_axes=(None, None, eqx.if_array(0), None, None)
    )
    states, records = eqx.filter_jit(batched)(estimator, scenario, reals, fixes, NO)
    for b in range(2):
        real = jax.tree.map(lambda x: x[b], reals)
        state, record = _closed_loop(estimator, scenario, real, fixes, NO)
        np.testing.assert_allclose(
            states.log_parameters[b], state.log_parameters, rtol=1e-9, atol=1e-12
        )
        np.testing.assert_allclose(
            states.covariance[b], state.covariance, rtol=1e-8, atol=1e-14
        )
        np.testing.assert_allclose(records[0][b], record[0], rtol=1e-9, atol=1e-12)
    # The two robots learnt different cables.
    assert (
        float(jnp.max(jnp.abs(states.log_parameters[0] - states.log_parameters[1])))
        > 1e-3
    )


def test_reversed_forces_diverge_and_fall_back_to_nominal(short_loop):
    scenario, fixes, real = short_loop
    estimator = cdpr.OnlineEstimator(ROBOT)
    state, (predicted, nominal, ok, diverged, _) = _closed_loop(
        estimator, scenario, real, fixes, jnp.asarray(True), jnp.zeros_like(fixes)
    )
    assert state.result == jc.RESULTS.estimator_diverged
    assert bool(state.diverged)
    first = int(jnp.argmax(diverged))
    assert first > 0 and bool(jnp.all(diverged[first:]))
    # Before: the estimate's own prediction; after: the nominal model's, finite.
    assert float(jnp.max(jnp.abs(predicted[:first] - nominal[:first]))) > 1e-5
    np.testing.assert_array_equal(predicted[first:], nominal[first:])
    assert bool(jnp.all(jnp.isfinite(predicted)))
    # The estimates froze at the divergence.
    assert bool(jnp.all(jnp.isfinite(state.log_parameters)))


def test_no_fix_for_too_long_is_a_lost_signal_until_fixes_return(short_loop):
    scenario, fixes, real = short_loop
    estimator = cdpr.OnlineEstimator(ROBOT)
    # No fix between 60 s and 180 s (max_fix_gap 60 s).
    gap = (scenario.time > 60) & (scenario.time < 180)
    state, (_, _, ok, diverged, lost) = _closed_loop(
        estimator, scenario, real, fixes & ~gap, NO, jnp.zeros_like(fixes)
    )
    t = scenario.time
    assert not bool(jnp.any(diverged))
    assert bool(jnp.all(lost[(t > 125) & (t < 180)]))
    assert not bool(jnp.any(lost[t < 110]))
    assert bool(jnp.all(ok[t > 185]))
    assert state.result == jc.RESULTS.successful


def test_a_stuck_load_cell_is_a_lost_signal_while_it_lasts(short_loop):
    scenario, fixes, real = short_loop
    estimator = cdpr.OnlineEstimator(ROBOT)
    t = scenario.time
    stuck = (t >= 100) & (t < 160)
    state, (_, _, ok, diverged, lost) = _closed_loop(
        estimator, scenario, real, fixes, NO, stuck
    )
    # Lost once the reading has not changed for stuck_time (30 s), back after.
    assert not bool(jnp.any(diverged))
    assert bool(jnp.all(lost[(t > 131) & (t < 160)]))
    assert not bool(jnp.any(lost[t < 129]))
    assert bool(jnp.all(ok[t >= 160]))
    assert bool(jnp.all(jnp.isfinite(state.log_parameters)))


def test_simulate_online_compensates_better_than_the_nominal_model(short_loop):
    scenario, _, real = short_loop
    estimator = cdpr.OnlineEstimator(ROBOT)
    sensors = cdpr.Sensors.exact(scenario, ROBOT.num_cables, every=10)
    online = cdpr.simulate_online(estimator, scenario, real, sensors)
    nominal = cdpr.simulate_robot(ROBOT, scenario, real, cdpr.NOMINAL)
    last = scenario.time > 180

    def rms(run):
        return float(jnp.sqrt(jnp.mean(jnp.sum(run.error[last] ** 2, axis=-1))))

    assert bool(jnp.all(online.result == jc.RESULTS.successful))
    assert online.log_parameters.shape == (scenario.time.shape[0], 8, 4)
    # Cables drawn 10 % around the nominal model: 5 mm of error left by the
    # nominal compensation, about 1 mm by the estimator's after three minutes.
    assert rms(online.run) < 0.4 * rms(nominal)


def test_real_sensors_and_bedded_in_cables():
    from jaxcable.cdpr.scenario import real_sensors

    scenario = cdpr.pick_and_place(hours=0.5)
    t = np.asarray(scenario.time)
    sensors = real_sensors(
        jax.random.key(0),
        scenario,
        ROBOT.num_cables,
        force_drift=36.0,
        dropouts=[(600.0, 300.0)],
        stuck=[(2, 100.0, 60.0)],
    )
    fix = np.asarray(sensors.fix)
    # A fix every 10 s, none in the dropout.
    assert (
        not fix[0] and fix[10] and not fix[11] and not fix[(t >= 600) & (t < 900)].any()
    )
    assert fix.sum() == np.sum((t % 10 == 0) & (t > 0)) - 30
    stuck = np.asarray(sensors.stuck)
    assert stuck[:, 2].sum() == 60 and stuck.sum() == 60
    # 0.5 mm and 0.5 N of noise; the drift (36 N/h per cell) grows with time.
    assert 0.4e-3 < float(jnp.std(sensors.fix_error)) < 0.6e-3
    error = np.asarray(sensors.force_error)
    assert 0.4 < np.std(np.diff(error, axis=0)) / np.sqrt(2) < 0.6
    assert np.mean(np.abs(error[-100:])) > 5 * np.mean(np.abs(error[:100]))
    real = cdpr.real_cables(jax.random.key(1), relative_std=0.3, bedded_in=(1, 4))
    ratio = np.asarray(real.base.E1r / real.base.E1c)
    np.testing.assert_allclose(ratio[[1, 4]], 1.5)
    assert not np.allclose(ratio[[0, 2, 3]], 1.5)
