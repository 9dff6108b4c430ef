"""Park's integrated model: closed-form reductions and continuity."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.optimize import brentq

import jaxcable as jc


CABLE = jc.Cable(length=0.3, speed=3e-3 / 60)


def test_constant_load_reduces_to_burgers_eq3():
    # Without hardening (beta = 0), a load held from t = 0 is Burgers (Park Eq. 3)
    # plus the instantaneous spring F / (E1c A).
    model = jc.IntegratedModel(beta=0.0)
    force = 100.0
    t = np.linspace(0.0, 3600.0, 61)
    traj = jc.simulate_force_history(model, CABLE, t, np.full_like(t, force))
    area = float(CABLE.area)
    burgers = (
        force / (model.E1c * area)
        + force / (model.E2c * area) * (1 - np.exp(-t / model.t_c))
        + force * t / (model.eta0 * area)
    )
    np.testing.assert_allclose(traj.strain, burgers, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(traj.elongation, burgers * 0.3, rtol=1e-12)


def _reference_ramp(model, cable, forces):
    """Dense NumPy reference of Park Eq. 5 = Eq. 6 on one loading ramp (brentq)."""
    area = float(cable.area)
    rate = float(cable.strain_rate)
    p = {
        k: float(getattr(model, k))
        for k in ("E1c", "beta", "gamma", "E2c", "t_c", "eta0")
    }
    t_prev, f_prev, eps_prev, impulse_prev = 0.0, 0.0, 0.0, 0.0
    times, strains = [], []
    for f in forces:
        h = 1 + p["beta"] * max(eps_prev, 0.0) ** p["gamma"]

        def strain(t):
            dt = t - t_prev
            impulse = impulse_prev + 0.5 * (f_prev + f) * dt
            creep = impulse / t * (1 - np.exp(-t / p["t_c"])) / (p["E2c"] * area)
            return (f / (p["E1c"] * area)) ** h + creep + impulse / (p["eta0"] * area)

        t = brentq(
            lambda t: strain(t) - rate * t, t_prev + 1e-12, t_prev + 1e4, xtol=1e-14
        )
        eps_prev = strain(t)
        impulse_prev += 0.5 * (f_prev + f) * (t - t_prev)
        t_prev, f_prev = t, f
        times.append(t)
        strains.append(eps_prev)
    return np.array(times), np.array(strains)


def test_single_ramp_matches_eq5_eq6_reference():
    model = jc.IntegratedModel()
    protocol = jc.Protocol.concatenate(
        jc.Protocol.start(), jc.Protocol.ramp(0, 100, 50)
    )
    traj = jc.simulate_rate_test(model, CABLE, protocol)
    times, strains = _reference_ramp(model, CABLE, np.asarray(protocol.force[1:]))
    np.testing.assert_allclose(traj.time[1:], times, rtol=1e-8)
    np.testing.assert_allclose(traj.strain[1:], strains, rtol=1e-8)
    # Eq. 6: on a ramp from rest, the strain is the crosshead strain rate times time.
    np.testing.assert_allclose(traj.strain, CABLE.strain_rate * traj.time, rtol=1e-9)


def test_rest_after_unloading_follows_eq7():
    model = jc.IntegratedModel()
    rest = 86400.0
    protocol = jc.Protocol.concatenate(
        jc.Protocol.cycles(100.0, 1, samples_per_ramp=100),
        jc.Protocol.rest(rest, samples=48),
    )
    traj = jc.simulate_rate_test(model, CABLE, protocol)
    peak = int(np.argmax(traj.force))
    t_unload = float(traj.time[peak])
    t_r2 = float(model.retardation_time_long(CABLE))
    tau = np.asarray(traj.time[peak + 1 :]) - t_unload
    force = np.asarray(traj.force[peak + 1 :])
    expected = (100.0 - force) / (model.E3r * CABLE.area) * (1 - np.exp(-tau / t_r2))
    np.testing.assert_allclose(traj.recovery_long[peak + 1 :], expected, rtol=1e-10)
    # During the rest nothing but recovery changes: the strain keeps falling.
    rest_strain = np.asarray(traj.strain[-48:])
    assert np.all(np.diff(rest_strain) < 0)
    assert np.all(np.diff(np.asarray(traj.creep[-48:])) == 0)


@pytest.mark.parametrize("first", [1, -1])
def test_strain_continuous_at_reversal(first):
    # A zero-length step that only reverses the branch must not move the strain.
    model = jc.IntegratedModel()
    state = model.init(CABLE)
    for dt, f, d in [(60.0, 80.0, 1), (30.0, 40.0, -1), (30.0, 60.0, 1)]:
        state, parts = model.advance(
            state, CABLE, jnp.asarray(dt), jnp.asarray(f), jnp.asarray(d)
        )
    if first == -1:
        state, parts = model.advance(
            state, CABLE, jnp.asarray(30.0), jnp.asarray(20.0), jnp.asarray(-1)
        )
    before = float(parts.total)
    _, after = model.advance(
        state, CABLE, jnp.asarray(0.0), state.force, jnp.asarray(-first)
    )
    assert abs(float(after.total) - before) < 1e-15


def test_strain_continuous_along_cyclic_test():
    # Refining the sampling shrinks every jump, including those at load reversals.
    model = jc.IntegratedModel()
    jumps = []
    for n in (100, 400):
        traj = jc.simulate_rate_test(model, CABLE, jc.Protocol.cycles(100.0, 3, n))
        jumps.append(float(np.max(np.abs(np.diff(traj.strain)))))
    assert jumps[1] < 0.3 * jumps[0]


def test_hardening_stiffens_cycles():
    # Park Section 4: stiffness rises over the cycles of a cyclic test.
    model = jc.IntegratedModel()
    traj = jc.simulate_rate_test(model, CABLE, jc.Protocol.cycles(100.0, 5, 200))
    f = np.asarray(traj.force)
    x = np.asarray(traj.elongation)
    starts = np.flatnonzero((f[:-1] == 0) & (f[1:] > 0))
    peaks = [s + 200 for s in starts]
    stiffness = [100.0 / (x[p] - x[s]) for s, p in zip(starts, peaks)]
    assert stiffness[-1] > stiffness[0]


def test_parameter_domain_checked_at_construction():
    with pytest.raises(ValueError, match="E1c"):
        jc.IntegratedModel(E1c=-1.0)
    with pytest.raises(ValueError, match="t_r1"):
        jc.IntegratedModel(t_r1=0.0)
    with pytest.raises(ValueError, match="beta"):
        jc.IntegratedModel(beta=-0.1)
    with pytest.raises(ValueError, match="lambda2"):
        jc.IntegratedModel(lambda2=float("nan"))


def test_retardation_time_long_rate_dependence():
    model = jc.IntegratedModel()
    short = jc.Cable(length=0.1, speed=3e-3 / 60)
    # Eq. 8: the slower strain rate of the longer cable recovers more slowly.
    assert model.retardation_time_long(CABLE) > model.retardation_time_long(short)
    expected = model.lambda1 / (3e-3 / 60 / 0.3) ** 2 - model.lambda2
    np.testing.assert_allclose(model.retardation_time_long(CABLE), expected)


def test_tree_at_parameter_update():
    model = eqx.tree_at(lambda m: m.E2r, jc.IntegratedModel(), 1e15)
    traj = jc.simulate_rate_test(model, CABLE, jc.Protocol.cycles(100.0, 1, 50))
    assert float(jnp.max(traj.recovery_short)) < 1e-6
