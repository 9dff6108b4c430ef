import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxcable as jc


def _trajectory(force, elongation, mask=None, length=0.3):
    force = jnp.asarray(force, float)
    elongation = jnp.asarray(elongation, float)
    strain = elongation / length
    zero = jnp.zeros_like(strain)
    mask = jnp.ones(force.shape, bool) if mask is None else jnp.asarray(mask)
    return jc.Trajectory(
        time=jnp.arange(force.shape[-1], dtype=float),
        force=force,
        strain=strain,
        elongation=elongation,
        parts=jc.StrainParts(strain, zero, zero, zero, zero),
        mask=mask,
        result=jc.RESULTS.successful,
    )


def _ellipse(force_amp, x_amp, lag, samples=4001, force_mid=None, x_mid=0.01):
    """A loop F = Fc - Fa cos t, x = xc - xa cos(t - lag): the elongation lags the
    force, so the loop runs clockwise and encloses pi Fa xa sin(lag)."""
    theta = np.linspace(0.0, 2 * np.pi, samples)
    force_mid = force_amp if force_mid is None else force_mid
    force = force_mid - force_amp * np.cos(theta)
    x = x_mid - x_amp * np.cos(theta - lag)
    return force, x


def test_ellipse_loop_energy():
    force, x = _ellipse(50.0, 1e-3, 0.3)
    traj = _trajectory(force, x)
    assert jc.split_cycles(traj) == [(0, len(force))]
    expected = math.pi * 50.0 * 1e-3 * math.sin(0.3)
    (energy,) = np.asarray(jc.loop_energies(traj))
    assert energy == pytest.approx(expected, rel=1e-5)


def test_triangle_loop_energy_and_stiffness_exact():
    # Load along a line to (x1, F1), unload along another to (x2, 0): the open loop's
    # net work is F1 x2 / 2, exact under the trapezoid rule (piecewise linear).
    f1, x1, x2 = 100.0, 8e-3, 6e-3
    up = np.linspace(0.0, 1.0, 51)
    down = np.linspace(1.0, 0.0, 51)[1:]
    force = np.concatenate([f1 * up, f1 * down])
    x = np.concatenate([x1 * up, x2 + (x1 - x2) * down])
    traj = _trajectory(force, x)
    np.testing.assert_allclose(jc.loop_energies(traj), [f1 * x2 / 2], rtol=1e-12)
    np.testing.assert_allclose(jc.secant_stiffness(traj), [f1 / x1], rtol=1e-12)


def test_split_cycles_of_a_protocol_with_holds_and_rests():
    n = 5
    protocol = jc.Protocol.concatenate(
        jc.Protocol.rest(10.0, samples=2),
        jc.Protocol.cycles(100.0, cycles=3, samples_per_ramp=n, hold=30.0),
        jc.Protocol.rest(100.0, samples=3),
        jc.Protocol.ramp(0.0, 50.0, n),  # a loading without its unloading
    )
    force = np.asarray(protocol.force)
    traj = _trajectory(force, 1e-4 * force)
    cycles = jc.split_cycles(traj)
    assert len(cycles) == 3
    for start, stop in cycles:
        f = force[start:stop]
        assert f[0] == 0.0 and f[-1] == 0.0 and f.max() == 100.0
        # Load, hold at the peak, unload: one rise and one fall.
        steps = np.sign(np.diff(f))
        steps = steps[steps != 0]
        assert np.all(steps[:n] == 1) and np.all(steps[n:] == -1)
    # Consecutive cycles share the valley sample.
    assert all(a[1] - 1 == b[0] for a, b in zip(cycles, cycles[1:]))


def test_split_cycles_ignores_padding_and_small_changes():
    force = np.array([0.0, 50, 100, 50, 0, 0.1, 0.0, 50, 100, 50, 0, 0, 0])
    mask = np.array([True] * 11 + [False] * 2)
    traj = _trajectory(force, 1e-5 * force, mask)
    assert jc.split_cycles(traj) == [(0, 5), (4, 7), (6, 11)]
    assert jc.split_cycles(traj, tolerance=0.5) == [(0, 5), (6, 11)]


def test_linear_elastic_cable_has_no_loop_and_its_stiffness():
    k = 4.5e4  # N/m
    force = np.concatenate([np.linspace(0, 100, 11), np.linspace(100, 0, 11)[1:]])
    traj = _trajectory(force, force / k)
    np.testing.assert_allclose(jc.loop_energies(traj), [0.0], atol=1e-15)
    np.testing.assert_allclose(jc.secant_stiffness(traj), [k], rtol=1e-12)


def test_differentiable_with_static_cycles():
    force, x = _ellipse(50.0, 1e-3, 0.3, samples=201)
    cycles = jc.split_cycles(_trajectory(force, x))

    @jax.jit
    def energy(scale):
        traj = _trajectory(force, scale * jnp.asarray(x))
        return jc.loop_energies(traj, cycles)[0] + jc.secant_stiffness(traj, cycles)[0]

    e0 = energy(1.0)
    # Loop energy scales with x, secant stiffness with 1 / x.
    traj = _trajectory(force, x)
    expected = jc.loop_energies(traj)[0] - jc.secant_stiffness(traj)[0]
    np.testing.assert_allclose(jax.grad(energy)(1.0), expected, rtol=1e-10)
    assert np.isfinite(e0)


def test_simulated_cyclic_test():
    n = 50
    cable = jc.Cable(length=0.3)
    protocol = jc.Protocol.cycles(100.0, cycles=4, samples_per_ramp=n)
    traj = jc.simulate_rate_test(jc.IntegratedModel(), cable, protocol)
    cycles = jc.split_cycles(traj)
    assert cycles == [(2 * k * n, 2 * (k + 1) * n + 1) for k in range(4)]
    energy = np.asarray(jc.loop_energies(traj))
    stiffness = np.asarray(jc.secant_stiffness(traj))
    assert np.all(energy > 0) and np.all(np.diff(energy) < 0)
    assert np.all(np.diff(stiffness) > 0)
    # Stiffness by hand: 100 N over the elongation of the k-th loading ramp.
    x = np.asarray(traj.elongation)
    hand = [100.0 / (x[(2 * k + 1) * n] - x[2 * k * n]) for k in range(4)]
    np.testing.assert_allclose(stiffness, hand, rtol=1e-12)


def test_empty_and_batched():
    traj = _trajectory(np.linspace(0, 100, 5), np.linspace(0, 1e-3, 5))
    assert jc.split_cycles(traj) == []
    assert jc.loop_energies(traj).shape == (0,)
    assert jc.secant_stiffness(traj).shape == (0,)
    batched = jax.tree_util.tree_map(
        lambda a: jnp.stack([a, a]) if eqx.is_array(a) and a.ndim == 1 else a, traj
    )
    with pytest.raises(ValueError, match="one cable"):
        jc.split_cycles(batched)
