"""Physical invariants as property tests (hypothesis)."""

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from hypothesis import given, settings, strategies as st

import jaxcable as jc


N = 24
# No breaking strain: the invariants are the model's at any strain, and the drawn
# loads (up to 1500 N) and parameters pass any real rope's.
CABLE = jc.Cable(length=0.3, speed=3e-3 / 60, breaking_strain=math.inf)
SETTINGS = settings(max_examples=25, deadline=None, derandomize=True)
_SCALED = ("E1c", "E1r", "E2c", "t_c", "eta0", "E2r", "t_r1", "E3r")


def _perturbed(log_scales):
    """The default integrated model with its moduli and times scaled by 10**s."""
    model = jc.IntegratedModel()
    values = tuple(getattr(model, n) * 10.0**s for n, s in zip(_SCALED, log_scales))
    return eqx.tree_at(lambda m: tuple(getattr(m, n) for n in _SCALED), model, values)


log_scales = st.lists(
    st.floats(-0.3, 0.3), min_size=len(_SCALED), max_size=len(_SCALED)
)
steps = st.lists(st.floats(0.1, 500.0), min_size=N - 1, max_size=N - 1)


@jax.jit
def _force_strain(model, time, force):
    return jc.simulate_force_history(
        model, CABLE, time, force, method=jc.Simulation(throw=False)
    )


def _times(dts):
    return np.concatenate([[0.0], np.cumsum(dts)])


@SETTINGS
@given(log_scales, steps)
def test_zero_load_history_gives_zero_strain(scales, dts):
    for model in (
        _perturbed(scales),
        jc.FiveElementModel(),
        jc.BurgersModel(),
        jc.HookeModel(),
        jc.BoucWenModel(),
    ):
        traj = _force_strain(model, _times(dts), np.zeros(N))
        assert traj.result == jc.RESULTS.successful
        np.testing.assert_array_equal(traj.strain, 0.0)


@SETTINGS
@given(log_scales, steps, st.floats(1.0, 1500.0))
def test_creep_never_decreases_under_constant_load(scales, dts, force):
    model = _perturbed(scales)
    traj = _force_strain(model, _times(dts), np.full(N, force))
    assert traj.result == jc.RESULTS.successful
    assert np.all(np.diff(np.asarray(traj.creep)) >= 0)
    # The total strain is not asserted: Park's hardening recursion (Eq. 1-2) lowers
    # the instantaneous strain as epsilon_{i-1} grows, even at constant force.


def _cycle_works(traj):
    f = np.asarray(traj.force)
    x = np.asarray(traj.elongation)
    work = 0.5 * (f[1:] + f[:-1]) * np.diff(x)
    zeros = np.flatnonzero(f == 0)
    # Work done on the cable over each closed force cycle 0 -> F -> 0, J.
    return [work[a:b].sum() for a, b in zip(zeros[:-1], zeros[1:]) if b > a + 1]


@SETTINGS
@given(log_scales, st.floats(0.0, 0.3), st.floats(10.0, 150.0), st.floats(1.0, 120.0))
def test_loop_energy_per_cycle_is_non_negative(scales, stiffer, force, period):
    # Three triangular cycles 0 -> F -> 0 of `period` seconds per ramp. Passivity
    # holds where the instantaneous unloading is not softer than the loading
    # (E1r >= E1c, as every calibrated set): a softer unloading would return more
    # elastic energy than the loading stored.
    model = _perturbed(scales)
    model = eqx.tree_at(lambda m: m.E1r, model, model.E1c * 10.0**stiffer)
    k = 8
    up = np.linspace(0, force, k + 1)[1:]
    one = np.concatenate([up, up[::-1][1:], [0.0]])
    f = np.concatenate([[0.0], one, one, one])
    t = np.arange(len(f)) * (period / k)
    traj = _force_strain(model, t, f)
    assert traj.result == jc.RESULTS.successful
    works = _cycle_works(traj)
    assert len(works) == 3
    assert min(works) >= -1e-12


@SETTINGS
@given(st.floats(0.05, 10.0), st.floats(10.0, 1000.0))
def test_strain_scales_with_nothing_but_force_for_hooke(length, force):
    cable = jc.Cable(length=length)
    traj = jc.simulate_force_history(
        jc.HookeModel(), cable, jnp.arange(3.0), jnp.array([0.0, force, 0.0])
    )
    np.testing.assert_allclose(
        traj.elongation[1],
        force * length / (jc.HookeModel().E * cable.area),
        rtol=1e-12,
    )


# Random histories with rests: blocks of (duration, force) with the force linear within a
# block and blocks at 0 N (rests) of up to 3 days, on the scaled parameter sets above.
blocks = st.lists(
    st.tuples(
        st.floats(1.0, 3 * 86400.0),
        st.one_of(st.just(0.0), st.floats(0.0, 200.0)),
    ),
    min_size=N - 1,
    max_size=N - 1,
)


@SETTINGS
@given(log_scales, blocks)
def test_never_shorter_than_new_nor_than_the_set(scales, history):
    # Issue 10: the recoveries are bounded by the creep that produced them, as a
    # property of the model (any parameters near the defaults, any history): the
    # strain never falls below the instantaneous set, itself >= 0.
    model = _perturbed(scales)
    dts, forces = zip(*history)
    time = _times(dts)
    force = np.concatenate([[0.0], forces])
    traj = _force_strain(model, time, force)
    assert traj.result == jc.RESULTS.successful
    strain = np.asarray(traj.strain)
    rounding = 1e-12 * np.asarray(traj.creep)  # creep - its recovered share, rounded
    assert np.all(strain >= -rounding)
    assert np.all(strain >= np.asarray(traj.instantaneous) - rounding)
