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
    """Dense NumPy reference of Park Eq. 5 = Eq. 6 on one loading ramp (brentq), with
    time under tension counted as the model documents (`jaxcable._models.kernels`)."""
    area = float(cable.area)
    f_on = 1e-4 * float(cable.breaking_load)

    def tension_share(f0, f1):  # mean of min(F / F_on, 1) over a linear step
        def g(x):
            return x * x / (2 * f_on) if x < f_on else x - f_on / 2

        return (g(f1) - g(f0)) / (f1 - f0)

    rate = float(cable.strain_rate)
    p = {
        k: float(getattr(model, k))
        for k in ("E1c", "beta", "gamma", "E2c", "t_c", "eta0")
    }
    t_prev, f_prev, eps_prev, impulse_prev, tension_prev = 0.0, 0.0, 0.0, 0.0, 0.0
    times, strains = [], []
    for f in forces:
        h = 1 + p["beta"] * max(eps_prev, 0.0) ** p["gamma"]

        def strain(t):
            dt = t - t_prev
            impulse = impulse_prev + 0.5 * (f_prev + f) * dt
            tension = tension_prev + tension_share(f_prev, f) * dt
            creep = (
                impulse
                / tension
                * (1 - np.exp(-tension / p["t_c"]))
                / (p["E2c"] * area)
            )
            return (f / (p["E1c"] * area)) ** h + creep + impulse / (p["eta0"] * area)

        t = brentq(
            lambda t: strain(t) - rate * t, t_prev + 1e-12, t_prev + 1e4, xtol=1e-14
        )
        eps_prev = strain(t)
        impulse_prev += 0.5 * (f_prev + f) * (t - t_prev)
        tension_prev += tension_share(f_prev, f) * (t - t_prev)
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
    # From the end of a full unloading (F = 0 N) both recoveries relax towards Park's
    # amplitudes exactly as Eq. 4 and Eq. 7 do; Park starts them at the reversal,
    # this reading ramps them in with the force drop, so the two differ by at most
    # the lag built up over the unloading, which decays as exp(-tau / t_r).
    model = jc.IntegratedModel()
    rest = 86400.0
    protocol = jc.Protocol.concatenate(
        jc.Protocol.cycles(100.0, 1, samples_per_ramp=100),
        jc.Protocol.rest(rest, samples=48),
    )
    traj = jc.simulate_rate_test(model, CABLE, protocol)
    peak = int(np.argmax(traj.force))
    end = int(np.flatnonzero(np.asarray(traj.force) == 0)[-49])  # end of unloading
    area = float(CABLE.area)
    t_r2 = float(model.retardation_time_long(CABLE))
    amplitude = 100.0 / (float(model.E3r) * area)  # Eq. 7 at F = 0 N, F_f = 100 N
    tau_end = np.asarray(traj.time[end:]) - float(traj.time[end])
    q0 = float(traj.recovery_long[end])
    expected = amplitude + (q0 - amplitude) * np.exp(-tau_end / t_r2)
    np.testing.assert_allclose(traj.recovery_long[end:], expected, rtol=1e-10)
    # Against Eq. 7 as printed (clock from the reversal): within the ramp's lag.
    t_unload = float(traj.time[end] - traj.time[peak])
    tau = np.asarray(traj.time[end:]) - float(traj.time[peak])
    printed = amplitude * (1 - np.exp(-tau / t_r2))
    lag = amplitude * t_unload / t_r2
    assert np.all(np.abs(np.asarray(traj.recovery_long[end:]) - printed) <= lag)
    # Eq. 4 the same way, with the equivalent force frozen at rest.
    t_r1 = float(model.t_r1)
    s0 = float(traj.recovery_short[end])
    short = np.asarray(traj.recovery_short[end:])
    target = short[-1]  # 24 h >> t_r1: the amplitude itself
    np.testing.assert_allclose(
        short, target + (s0 - target) * np.exp(-tau_end / t_r1), rtol=1e-9, atol=1e-15
    )
    # During the rest nothing but recovery changes: the strain keeps falling.
    rest_strain = np.asarray(traj.strain[-48:])
    assert np.all(np.diff(rest_strain) < 0)
    assert np.all(np.diff(np.asarray(traj.creep[-48:])) == 0)


def _noisy_300mm_history(noise, seed=0):
    # Issue 10: 0 -> 100 N in 300 s, hold 2 h, unload to 2 N in 300 s, rest 2 h.
    t = np.arange(0.0, 15001.0, 1.0)
    f = np.interp(t, [0, 300, 7500, 7800, 15000], [0, 100, 100, 2, 2])
    rng = np.random.default_rng(seed)
    return t, f, np.maximum(f + noise * rng.standard_normal(f.shape), 0.0)


def test_micro_newton_noise_does_not_move_the_elongation():
    # Regression: with a loading/unloading branch flag, 1e-6 N of force noise moved
    # this 300 mm cable by 0.95 mm (every downward blip started the full short-term
    # recovery). Now the change is of the order of the noise times the compliances.
    cable = jc.Cable(length=0.3)
    model = jc.IntegratedModel()
    t, f, noisy = _noisy_300mm_history(1e-6)
    clean = jc.simulate_force_history(model, cable, t, f).elongation
    perturbed = jc.simulate_force_history(model, cable, t, noisy).elongation
    assert float(np.max(np.abs(perturbed - clean))) < 1e-7  # m, i.e. 1e-4 mm


def test_direction_argument_is_ignored():
    # No state depends on the sign of a force change: the same step with any
    # `direction` gives the same state and strain.
    model = jc.IntegratedModel()
    state = model.init(CABLE)
    for dt, f in [(60.0, 80.0), (30.0, 40.0), (30.0, 60.0)]:
        state, _ = model.advance(state, CABLE, jnp.asarray(dt), jnp.asarray(f), 1)
    outs = [
        model.advance(state, CABLE, jnp.asarray(5.0), jnp.asarray(59.0), d)
        for d in (-1, 0, 1)
    ]
    for out in outs[1:]:
        assert eqx.tree_equal(out, outs[0])


@pytest.mark.parametrize(
    "length, speed_mm_min, cycles, rest_h",
    [(0.1, 50.0, 1, 24.0), (0.1, 3.0, 10, 72.0), (0.3, 3.0, 10, 72.0)],
)
def test_never_shorter_than_new(length, speed_mm_min, cycles, rest_h):
    # Regression (issue 10): the previous reading ended these rests shorter than new
    # (-1.68 mm, -0.47 mm, ...): its long-term recovery F_f / (E3r A) did not depend
    # on how much creep there was to recover. Now the recoveries remove at most the
    # creep, so the cable keeps at least its instantaneous set, itself >= 0.
    cable = jc.Cable(length=length, speed=speed_mm_min * 1e-3 / 60)
    protocol = jc.Protocol.concatenate(
        jc.Protocol.cycles(100.0, cycles, samples_per_ramp=50),
        jc.Protocol.rest(rest_h * 3600.0, samples=50),
    )
    traj = jc.simulate_rate_test(jc.IntegratedModel(), cable, protocol)
    assert float(np.min(traj.strain)) >= 0.0
    assert np.all(np.asarray(traj.strain) >= np.asarray(traj.instantaneous) - 1e-15)
    assert np.all(np.asarray(traj.instantaneous) >= 0.0)


def test_recoveries_bounded_by_creep_whatever_the_parameters():
    # A calibration-independent bound: even with a long-term recovery modulus 100x
    # too soft, the rest ends at the instantaneous set, never below.
    model = eqx.tree_at(lambda m: m.E3r, jc.IntegratedModel(), 7.989e6)
    cable = jc.Cable(length=0.1, speed=50e-3 / 60)
    protocol = jc.Protocol.concatenate(
        jc.Protocol.cycles(100.0, 1, samples_per_ramp=50),
        jc.Protocol.rest(24 * 3600.0, samples=20),
    )
    traj = jc.simulate_rate_test(model, cable, protocol)
    np.testing.assert_allclose(traj.strain[-1], traj.instantaneous[-1], rtol=1e-9)
    removed = traj.recovery_short + traj.recovery_long
    assert np.all(np.asarray(removed) <= np.asarray(traj.creep) * (1 + 1e-12))


def test_reload_follows_unloading_line_below_the_largest_force():
    # Below the largest force the instantaneous strain is Park Eq. 9's unloading line
    # from that force, on unloading and on reloading alike (no hysteresis of its own).
    model = jc.IntegratedModel(beta=0.0)
    area = float(CABLE.area)
    t = np.array([0.0, 100.0, 150.0, 200.0])
    f = np.array([0.0, 100.0, 40.0, 70.0])
    traj = jc.simulate_force_history(model, CABLE, t, f)
    peak = 100.0 / (float(model.E1c) * area)
    line = peak - (100.0 - f[2:]) / (float(model.E1r) * area)
    np.testing.assert_allclose(traj.instantaneous[2:], line, rtol=1e-12)


@pytest.mark.parametrize("first", [1, -1])
def test_strain_continuous_at_reversal(first):
    # Regression: a step that reverses the force by a nano-newton must move the strain
    # by no more than the instantaneous compliance times the change (the previous
    # reading started the full short-term recovery on any reversal).
    model = jc.IntegratedModel()
    state = model.init(CABLE)
    for dt, f in [(60.0, 80.0), (30.0, 40.0), (30.0, 60.0)]:
        state, parts = model.advance(state, CABLE, jnp.asarray(dt), jnp.asarray(f), 1)
    if first == -1:
        state, parts = model.advance(
            state, CABLE, jnp.asarray(30.0), jnp.asarray(20.0), -1
        )
    d = 1e-9
    up = model.advance(state, CABLE, jnp.asarray(1.0), state.force + d, 1)[1]
    down = model.advance(state, CABLE, jnp.asarray(1.0), state.force - d, -1)[1]
    area = float(CABLE.area)
    bound = 2 * d * (1 / model.E1c + 1 / model.E1r + 1 / model.E2r + 1 / model.E3r)
    assert abs(float(up.total) - float(down.total)) <= float(bound) / area


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
