"""Park's integrated model: closed-form reductions and continuity."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.optimize import brentq

import jaxcable as jc


CABLE = jc.Cable(length=0.3, speed=3e-3 / 60)


def _held_strain(model, cable, force, t, flow_rate=None):
    """Closed form of a force held from t = 0: the instantaneous spring, three
    Kelvin-Voigt elements creeping from 0 and the flow at a constant rate (by default
    the Eyring rate)."""
    area = float(cable.area)
    p = {k: float(getattr(model, k)) for k in model.__dataclass_fields__}
    p["sigma_a"] = float(model.sigma_a)
    elements = sum(
        force / (p[modulus] * area) * (1 - np.exp(-t / p[time]))
        for modulus, time in (("E2c", "t_c"), ("E2r", "t_e"), ("E3r", "t_e"))
    )
    if flow_rate is None:
        stress = force / area
        flow_rate = p["sigma_a"] / p["eta0"] * np.sinh(stress / p["sigma_a"])
    return force / (p["E1c"] * area) + elements + flow_rate * t


def test_constant_load_reduces_to_burgers_eq3():
    # Without hardening (beta = 0), a load held from t = 0 is Burgers (Park Eq. 3)
    # with three Kelvin-Voigt elements and the flow; at a stress well below sigma_a
    # the flow is Park's dashpot F t / (eta0 A).
    model = jc.IntegratedModel(beta=0.0)
    force = 100.0
    t = np.linspace(0.0, 3600.0, 61)
    traj = jc.simulate_force_history(model, CABLE, t, np.full_like(t, force))
    expected = _held_strain(model, CABLE, force, t)
    np.testing.assert_allclose(traj.strain, expected, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(traj.elongation, expected * 0.3, rtol=1e-12)
    low = jc.IntegratedModel(beta=0.0, strain_a=1e12 / 2.591e9)
    traj = jc.simulate_force_history(low, CABLE, t, np.full_like(t, force))
    dashpot = force / (float(low.eta0) * float(CABLE.area))
    burgers = _held_strain(low, CABLE, force, t, flow_rate=dashpot)
    np.testing.assert_allclose(traj.strain, burgers, rtol=1e-10, atol=1e-15)


def _reference_ramp(model, cable, forces):
    """Dense NumPy reference of Eq. 6 on one loading ramp from a new cable (brentq):
    the time of each force sample is the root of strain(F, t) = rate * t, with the
    Kelvin-Voigt elements integrated exactly for a force linear between samples."""
    area = float(cable.area)
    rate = float(cable.strain_rate)
    p = {k: float(getattr(model, k)) for k in model.__dataclass_fields__}
    p["sigma_a"] = float(model.sigma_a)
    elements = (("E2c", "t_c"), ("E2r", "t_e"), ("E3r", "t_e"))

    def kv(q0, f0, f1, dt, modulus, tau):
        # q' = (F(t) / (E A) - q) / tau, F linear from f0 to f1 over dt.
        tau = p[tau]
        a = np.exp(-dt / tau)
        k = (f1 - f0) / dt
        return q0 * a + (f0 * (1 - a) + k * (dt - tau * (1 - a))) / (p[modulus] * area)

    def flow_rate(f):
        return p["sigma_a"] / p["eta0"] * np.sinh(f / area / p["sigma_a"])

    t_prev, f_prev, qs, flow = 0.0, 0.0, [0.0, 0.0, 0.0], 0.0
    times, strains = [], []
    for f in forces:

        def state(t):
            dt = t - t_prev
            q = [kv(q0, f_prev, f, dt, *e) for q0, e in zip(qs, elements)]
            fl = flow + 0.5 * (flow_rate(f_prev) + flow_rate(f)) * dt
            return q, fl, f / (p["E1c"] * area) + sum(q) + fl

        t = brentq(
            lambda t: state(t)[2] - rate * t, t_prev + 1e-12, t_prev + 1e4, xtol=1e-14
        )
        qs, flow, eps = state(t)
        t_prev, f_prev = t, f
        times.append(t)
        strains.append(eps)
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


def test_rest_after_unloading_follows_eq4_and_eq7():
    # At rest (0 N) the short- and long-term elements recover exactly as Eq. 4 and
    # Eq. 7, q0 exp(-tau / t_r) from where the unloading left them; the permanent
    # element and the flow stay where they are.
    model = jc.IntegratedModel()
    rest = 86400.0
    protocol = jc.Protocol.concatenate(
        jc.Protocol.cycles(100.0, 1, samples_per_ramp=100),
        jc.Protocol.rest(rest, samples=48),
    )
    traj = jc.simulate_rate_test(model, CABLE, protocol)
    end = int(np.flatnonzero(np.asarray(traj.force) == 0)[-49])  # end of unloading
    tau = np.asarray(traj.time[end:]) - float(traj.time[end])
    for part, t_r in (
        ("recovery_long", float(model.retardation_time_long(CABLE))),
        ("recovery_short", float(model.t_r1)),
    ):
        recovered = np.asarray(getattr(traj, part)[end:])
        # recovered(tau) - recovered(0) = q(0) (1 - exp(-tau / t_r)): the same q(0)
        # from every sample of the rest.
        q0 = (recovered[1:] - recovered[0]) / -np.expm1(-tau[1:] / t_r)
        assert q0[0] > 1e-4
        np.testing.assert_allclose(q0, q0[0], rtol=1e-9)
    # Nothing creeps at 0 N; the strain keeps falling through the rest.
    assert np.all(np.diff(np.asarray(traj.creep[end:])) == 0)
    assert np.all(np.diff(np.asarray(traj.strain[-48:])) < 0)


def test_second_tensile_test_stretches_back():
    # Park Table 3 is the elongation of a second tensile test after the rest: the
    # rested cable must stretch back on reloading, more after a longer rest where
    # the recovery is not complete (300 mm) and the same where it is (100 mm).
    from jaxcable import papers
    from jaxcable.internal import second_test_indices

    n = 40
    rest_end, peak2 = second_test_indices(n)
    out = {}
    for length in (0.1, 0.3):
        cable = jc.Cable(length=length, speed=3e-3 / 60)
        for h in (24.0, 72.0):
            protocol = papers.park_protocol(
                100.0, samples_per_ramp=n, rest_hours=h, rest_samples=1
            )
            traj = jc.simulate_rate_test(jc.IntegratedModel(), cable, protocol)
            x = np.asarray(traj.elongation)
            out[length, h] = x[peak2] - x[rest_end]
            # More than the instantaneous elongation: the recovered creep returns.
            elastic = 100.0 / (float(jc.IntegratedModel().E1r) * float(cable.area))
            assert out[length, h] > 2 * elastic * length
    assert out[0.3, 72.0] > 1.1 * out[0.3, 24.0]
    np.testing.assert_allclose(out[0.1, 72.0], out[0.1, 24.0], rtol=0.03)


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
    # A calibration-independent bound: even with a long-term element 10x too
    # soft, the rest ends at or above the instantaneous set, never below: an element
    # recovers only what it crept.
    model = eqx.tree_at(lambda m: m.E3r, jc.IntegratedModel(), 8.045e7)
    # So soft an element stretches the cable past any rope's breaking strain.
    cable = jc.Cable(length=0.1, speed=50e-3 / 60, breaking_strain=float("inf"))
    protocol = jc.Protocol.concatenate(
        jc.Protocol.cycles(100.0, 1, samples_per_ramp=50),
        jc.Protocol.rest(24 * 3600.0, samples=20),
    )
    traj = jc.simulate_rate_test(model, cable, protocol)
    assert np.all(np.asarray(traj.strain) >= np.asarray(traj.instantaneous))
    assert float(traj.recovery_long[-1]) > 0.5 * float(traj.creep[-1])
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
