"""Failure is never silent: Python-boundary ValueErrors and traced RESULTS."""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxcable as jc


CABLE = jc.Cable(length=0.3, speed=3e-3 / 60)
# The same cable without a breaking strain, for the verdicts that a break (a strain
# beyond `Cable.breaking_strain`, met earlier in these histories) would precede.
UNBREAKABLE = jc.Cable(length=0.3, speed=3e-3 / 60, breaking_strain=math.inf)
MODEL = jc.IntegratedModel()
T = np.linspace(0.0, 100.0, 11)
F = np.linspace(0.0, 100.0, 11)


@pytest.mark.parametrize(
    "time, force, match",
    [
        (T, np.where(np.arange(11) == 3, np.nan, F), r"`force`.*element 3 is nan"),
        (np.where(np.arange(11) == 5, np.inf, T), F, r"`time`.*finite"),
        (
            np.array([0.0, 1.0, 1.0, 2.0]),
            np.ones(4),
            r"`time` must be strictly increasing; sample 2",
        ),
        (np.array([0.0, 2.0, 1.0]), np.ones(3), r"`time` must be strictly increasing"),
        (T, F[:-1], r"Mismatched shapes: `time` \(11,\), `force` \(10,\)"),
        (np.array([]), np.array([]), r"`time` is empty"),
        (
            T,
            np.full(11, 2500.0),
            r"`force` exceeds the cable's breaking load \(2000 N\)",
        ),
        (T, -F, r"`force` must be non-negative"),
        (np.stack([T, T]), np.stack([F, F]), r"`time` must be 1-dimensional"),
    ],
)
def test_force_history_bad_inputs(time, force, match):
    with pytest.raises(ValueError, match=match):
        jc.simulate_force_history(MODEL, CABLE, time, force)


def test_elongation_history_bad_inputs():
    with pytest.raises(ValueError, match=r"`elongation`.*element 2 is nan"):
        jc.simulate_elongation_history(
            MODEL, CABLE, T, np.where(np.arange(11) == 2, np.nan, F)
        )
    with pytest.raises(ValueError, match="`time` must be strictly increasing"):
        jc.simulate_elongation_history(MODEL, CABLE, T[::-1], F * 1e-5)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(length=0.0), "`length` must be positive"),
        (dict(length=-0.3), "`length` must be positive"),
        (dict(length=0.3, diameter=0.0), "`diameter` must be positive"),
        (dict(length=0.3, speed=-1.0), "`speed` must be positive"),
        (dict(length=np.nan), "`length` must be finite"),
        (dict(length=0.3, breaking_load=0.0), "`breaking_load` must be positive"),
    ],
)
def test_cable_bad_inputs(kwargs, match):
    with pytest.raises(ValueError, match=match):
        jc.Cable(**kwargs)


def test_batched_cable_needs_vmap():
    cables = jc.Cable(length=jnp.array([0.1, 0.3]))
    with pytest.raises(ValueError, match="`cable.length` has shape \\(2,\\)"):
        jc.simulate_force_history(MODEL, cables, T, F)


def test_protocol_bad_inputs():
    with pytest.raises(ValueError, match="samples"):
        jc.Protocol.ramp(0.0, 100.0, 0)
    with pytest.raises(ValueError, match="force_to != force_from"):
        jc.Protocol.ramp(10.0, 10.0, 5)
    with pytest.raises(ValueError, match="`duration` must be non-negative"):
        jc.Protocol.hold(10.0, -1.0)
    with pytest.raises(ValueError, match="`Protocol.force` must be non-negative"):
        jc.Protocol.ramp(0.0, -10.0, 5)
    with pytest.raises(ValueError, match="breaking load"):
        jc.simulate_rate_test(MODEL, CABLE, jc.Protocol.cycles(2500.0, 1, 10))
    with pytest.raises(ValueError, match="`protocol` must be a jaxcable.Protocol"):
        jc.simulate_rate_test(MODEL, CABLE, F)


def _bad_tr2_model():
    # t_r2 = lambda1 / rate^2 - lambda2 <= 0 for this cable (Park Eq. 8).
    rate = float(CABLE.strain_rate)
    return eqx.tree_at(lambda m: m.lambda2, MODEL, float(MODEL.lambda1) / rate**2 * 2)


def test_parameter_out_of_domain_raises_and_reports():
    model = _bad_tr2_model()
    with pytest.raises(Exception, match="t_r2"):
        jc.simulate_force_history(model, CABLE, T, F)
    traj = jc.simulate_force_history(
        model, CABLE, T, F, method=jc.Simulation(throw=False)
    )
    assert traj.result == jc.RESULTS.parameter_out_of_domain


def test_per_sample_status_in_a_batch():
    # throw=False in a Monte-Carlo batch: the good parameter sets are kept and each
    # set carries its own status.
    good, bad = MODEL, _bad_tr2_model()
    stacked = jax.tree_util.tree_map(lambda *xs: jnp.stack(xs), good, bad, good)
    trajs = jax.vmap(
        lambda m: jc.simulate_force_history(
            m, CABLE, T, F, method=jc.Simulation(throw=False)
        )
    )(stacked)
    ok = trajs.result == jc.RESULTS.successful
    np.testing.assert_array_equal(ok, [True, False, True])
    assert np.all(np.isfinite(trajs.strain[0]))
    # And with throw=True, the batch raises.
    with pytest.raises(Exception, match="outside its domain"):
        jax.vmap(lambda m: jc.simulate_force_history(m, CABLE, T, F))(stacked)


@pytest.mark.parametrize("ratio", [0.5, 2.0, 3.0])
def test_force_out_of_reach_is_physics_not_a_solver_failure(ratio):
    # Park's dashpot creeps at F / (eta0 A) under F; when that is at least the
    # crosshead strain rate v / L0 the crosshead never catches up with the cable
    # (Park Eq. 5-6 has no root): `unreachable_force`, not `newton_failed`.
    peak = 300.0
    eta0 = peak / (CABLE.area * CABLE.strain_rate * ratio)
    model = eqx.tree_at(lambda m: m.eta0, MODEL, jnp.asarray(eta0))
    # Coarse samples (every 60 N), so that none lies just below the force
    # peak / ratio where the crosshead takes hours to catch up.
    protocol = jc.Protocol.cycles(peak, 1, 5)
    traj = jc.simulate_rate_test(
        model, UNBREAKABLE, protocol, method=jc.Simulation(throw=False)
    )
    if ratio < 1:
        assert traj.result == jc.RESULTS.successful
        return
    assert traj.result == jc.RESULTS.unreachable_force
    with pytest.raises(Exception, match="cannot be reached at this crosshead speed"):
        jc.simulate_rate_test(model, UNBREAKABLE, protocol)


def test_solve_beyond_twice_the_length_is_flagged():
    # A flow with a low activation stress (sigma_a = 15 MPa: 8.3e-4 / s at 1500 N)
    # creeps the cable past a strain of 1 within the hour's hold. A rate test (a
    # solved time per sample) is flagged there; the force history, which solves
    # nothing, is the model's formula at any strain. At 50 mm/min (2.8e-3 / s on
    # 300 mm) the crosshead outruns that creep, so 1500 N is reached; at 3 mm/min
    # (1.7e-4 / s) the creep outruns the crosshead from about 1330 N on: out of
    # reach, not a strain beyond 1.
    model = jc.IntegratedModel(strain_a=1.5e7 / 2.591e9)
    protocol = jc.Protocol.concatenate(
        jc.Protocol.cycles(1500.0, 1, 10), jc.Protocol.hold(1500.0, 3600.0, 6)
    )
    fast = jc.Cable(length=0.3, speed=50e-3 / 60, breaking_strain=math.inf)
    traj = jc.simulate_rate_test(
        model, fast, protocol, method=jc.Simulation(throw=False)
    )
    assert traj.result == jc.RESULTS.nonphysical_strain
    assert np.max(traj.strain) > 1.0
    with pytest.raises(Exception, match="above 1"):
        jc.simulate_rate_test(model, fast, protocol)
    # With a breaking strain, its crossing (on the first ramp) comes first.
    brittle = jc.Cable(length=0.3, speed=50e-3 / 60, breaking_strain=0.05)
    broken = jc.simulate_rate_test(
        model, brittle, protocol, method=jc.Simulation(throw=False)
    )
    assert broken.result == jc.RESULTS.strain_beyond_break
    slow = jc.simulate_rate_test(
        model, UNBREAKABLE, protocol, method=jc.Simulation(throw=False)
    )
    assert slow.result == jc.RESULTS.unreachable_force
    # Up to 1200 N (reached) the strain stays below 1.
    assert 0.0 < float(slow.strain[8]) < 1.0
    t = np.linspace(0.0, 3600.0, 13)
    history = jc.simulate_force_history(model, UNBREAKABLE, t, np.full(13, 1500.0))
    assert np.max(history.strain) > 1.0


def test_traced_nonfinite_force_is_flagged_not_silent():
    # Inside a user's jit the Python checks cannot see values; the kernel flags them.
    f = jnp.asarray(F).at[4].set(jnp.nan)
    run = jax.jit(
        lambda f: (
            jc.simulate_force_history(
                MODEL, CABLE, T, f, method=jc.Simulation(throw=False)
            ).result
        )
    )
    assert run(f) != jc.RESULTS.successful
    with pytest.raises(Exception, match="force|strain"):
        jax.jit(lambda f: jc.simulate_force_history(MODEL, CABLE, T, f).strain)(f)


def test_traced_decreasing_time_is_flagged():
    t = jnp.asarray(T).at[5].set(-1.0)
    res = jax.jit(
        lambda t: (
            jc.simulate_force_history(
                MODEL, CABLE, t, F, method=jc.Simulation(throw=False)
            ).result
        )
    )(t)
    assert res == jc.RESULTS.nonphysical_time


def test_bad_solver_type():
    with pytest.raises(ValueError, match="solver"):
        jc.simulate_rate_test(
            MODEL,
            CABLE,
            jc.Protocol.cycles(100.0, 1, 10),
            method=jc.Simulation(solver="newton"),
        )


def test_optimistix_solver_agrees_with_builtin_newton():
    import optimistix as optx

    protocol = jc.Protocol.cycles(100.0, 1, 20)
    a = jc.simulate_rate_test(MODEL, CABLE, protocol)
    b = jc.simulate_rate_test(
        MODEL,
        CABLE,
        protocol,
        method=jc.Simulation(solver=optx.Newton(rtol=1e-12, atol=1e-12)),
    )
    np.testing.assert_allclose(a.time, b.time, rtol=1e-9)
