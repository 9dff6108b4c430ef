"""The five-element model with distinct loading (L) and unloading (UL) sets: where it
is Piao's Eq. 2-3 and where it differs, its recovery bound (never shorter than new),
and that the bound leaves equal sets unchanged and monotone in the load
(docs/model_notes.md point 10).

Every simulated history has `N` samples, so each jitted function compiles once.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import jaxcable
from jaxcable import StrainParts
from jaxcable.internal import piao


N = 40
CABLE = jaxcable.Cable(length=7.4, diameter=6e-3, breaking_load=20000.0)
AREA = float(CABLE.area)
LOADING = ("E_L1", "E_L2", "E_L3", "eta_L2", "eta_L3")
# 50 kg on Piao's 6 mm cable, 7.4 m: E_L1 = E_UL1 from Table 3 (the preset's reading).
F0 = 50 * 9.81
E1 = float(jaxcable.PIAO_TABLE3(50.0, 7.4))
# The distinct UL set of benchmarks/continuity.py (less compliant than the L set in
# total) and a softer one (Table 1's unloading moduli halved).
STIFFER_UL = dict(E_UL2=2 * 9.5e9, eta_UL2=3e10, E_UL3=2.5e10, eta_UL3=2e13)
SOFTER_UL = dict(E_UL2=9.5e9 / 2, E_UL3=5.0e10 / 2)


def _piao(**unloading):
    """Piao Table 1 (loading), E_L1 = E_UL1 = Table 3 at 50 kg and 7.4 m."""
    return jaxcable.FiveElementModel(**{"E_L1": E1, "E_UL1": E1, **unloading})


def _equal(model):
    """`model` with its UL set replaced by its L set."""
    names = tuple(n.replace("_L", "_UL") for n in LOADING)
    values = tuple(getattr(model, n) for n in LOADING)
    return eqx.tree_at(lambda m: tuple(getattr(m, n) for n in names), model, values)


@eqx.filter_jit
def _simulate(model, time, force):
    return jaxcable.simulate_force_history(model, CABLE, time, force)


def _scan(model, time, force):
    """`model.advance` over a history (dt = 0 first: an instant load): the strain
    parts of every sample. No jitted function inside, so that `_unbounded` cannot
    leave a patched trace in a cache."""

    def body(state, x):
        dt, f = x
        return model.advance(state, CABLE, dt, f, jnp.array(0))

    dts = jnp.diff(time, prepend=time[0])
    return jax.lax.scan(body, model.init(CABLE), (dts, force))[1]


_parts = eqx.filter_jit(_scan)
# Traced only under `_unbounded`: a separate cache from `_parts`.
_unbounded_parts = eqx.filter_jit(lambda model, time, force: _scan(model, time, force))


def _J(model, family, t):
    """Creep compliance J(t) of Piao Eq. 1 with the `family` set ("L" or "UL"), 1/Pa."""

    def E(k):
        return float(getattr(model, f"E_{family}{k}"))

    def eta(k):
        return float(getattr(model, f"eta_{family}{k}"))

    return 1.0 / E(1) - sum(np.expm1(-E(k) * t / eta(k)) / E(k) for k in (2, 3))


# A step load at t = 0 held to t_r = 600 s, an instant unloading (two samples at
# t_r: `_scan` takes dt = 0), a rest to 10 h.
T_R = 600.0
AFTER = np.concatenate(
    [[0.0, 1.0, 10.0, 100.0, 600.0, 3600.0], np.geomspace(4e3, 3.6e4, N - 9)]
)
STEP_TIME = np.concatenate([[0.0, 0.0, T_R], T_R + AFTER])
STEP_FORCE = np.concatenate([[0.0, F0, F0], np.zeros(len(AFTER))])


def _eq3(model, t):
    """Piao Eq. 3 as printed (eta_UL3 in the third exponent), strain."""
    sigma0 = F0 / AREA
    out = 0.0
    for k in ("2", "3"):
        E, eta = float(getattr(model, "E_UL" + k)), float(getattr(model, "eta_UL" + k))
        out = out + sigma0 / E * np.expm1(E * T_R / eta) * np.exp(-E * t / eta)
    return out


@pytest.mark.parametrize(
    "unloading, documented",
    [
        # docs/model_notes.md point 10: elongation (mm) of the model and of Eq. 3 at 1 s
        # and 3600 s after the unloading.
        ({}, ((7.654, 7.654), (0.000, 0.000))),
        (STIFFER_UL, ((12.777, 6.293), (4.246, 0.030))),
        (SOFTER_UL, ((5.722, 20.786), (0.000, 0.000))),
    ],
)
def test_step_unloading_against_piao_eq3(unloading, documented):
    """Equal sets: Eq. 3 exactly. Distinct sets: max(Eq. 3 + D(t), 0) with
    D(t) = sigma_0 (J_L(t) - J_UL(t)), t from the load step."""
    model = _piao(**unloading)
    parts = _parts(model, STEP_TIME, STEP_FORCE)
    strain = np.asarray(parts.total)[3:]
    t = T_R + AFTER
    eq3 = _eq3(model, t)
    shift = F0 / AREA * (_J(model, "L", t) - _J(model, "UL", t))
    np.testing.assert_allclose(
        strain, np.maximum(eq3 + shift, 0.0), rtol=1e-9, atol=1e-15
    )
    if not unloading:
        np.testing.assert_allclose(strain, eq3, rtol=1e-9, atol=1e-15)
    mm = 1e3 * CABLE.length
    for k, (model_mm, eq3_mm) in zip((1, 5), documented):
        assert round(float(strain[k] * mm), 3) == model_mm
        assert round(float(eq3[k] * mm), 3) == eq3_mm


def _cycles(hold, rest):
    """Two load-hold-unload-rest cycles of `N` samples (the second to a lower
    force): ramps of 2 s, holds of `hold` s, rests of `rest` s (geometric grid)."""
    half = N // 2

    def cycle(start, force):
        on = np.linspace(0.0, 2.0, 3)
        held = 2.0 + np.geomspace(1.0, hold, 5)
        off = held[-1] + np.linspace(0.0, 2.0, 4)[1:]
        rested = off[-1] + np.geomspace(0.5, rest, half - 11)
        time = start + np.concatenate([on, held, off, rested])
        levels = np.concatenate([on / 2.0, np.ones(5), 1 - np.linspace(0, 1, 4)[1:]])
        return time, force * np.concatenate([levels, np.zeros(half - 11)])

    t1, f1 = cycle(0.0, F0)
    t2, f2 = cycle(t1[-1] + 1.0, 0.6 * F0)
    return np.concatenate([t1, t2]), np.concatenate([f1, f2])


@pytest.mark.parametrize(
    "unloading",
    [
        SOFTER_UL,
        dict(E_UL1=2.0e9),  # an unloading spring softer than the whole L family
        dict(E_UL2=3e9, eta_UL2=3e11, E_UL3=1e10, eta_UL3=1e11),
    ],
)
@pytest.mark.parametrize("hold, rest", [(600.0, 36000.0), (5.0, 200.0)])
def test_softer_unloading_set_never_ends_shorter_than_new(
    monkeypatch, unloading, hold, rest
):
    """Regression: sigma_0 sum(1/E_L - 1/E_UL) < 0 left the cable shorter than new
    (-16.1 mm for SOFTER_UL at 50 kg on 7.4 m). Now strain >= 0 at every sample."""
    model = _piao(**unloading)
    time, force = _cycles(hold, rest)
    # Before the bound it ended more than 7 mm short of new (the permanent set).
    assert np.min(_unbounded(monkeypatch, model, time, force).total) < -1e-3
    permanent_set = F0 / AREA * (_J(model, "L", np.inf) - _J(model, "UL", np.inf))
    assert permanent_set < -1e-3
    traj = _simulate(model, time, force)
    assert traj.result == jaxcable.RESULTS.successful
    strain = np.asarray(traj.strain)
    assert np.min(strain) >= -1e-12
    # The bound is what holds it: the strain is 0 where the recoveries are not.
    recovered = np.asarray(traj.recovery_short + traj.recovery_long)
    assert np.any((np.abs(strain) < 1e-12) & (recovered > 1e-4))


def _unbounded_sum(loading, unloading):
    """Piao Eq. 2-3's sum of the two families without the recovery bound: the code
    of `superposed_strain` before the bound."""
    spring_L, q_L2, q_L3 = loading
    spring_UL, q_UL2, q_UL3 = unloading
    return StrainParts(
        instantaneous=spring_L + spring_UL,
        creep=q_L2 + q_L3,
        recovery_short=-q_UL2,
        recovery_long=-q_UL3,
        apparatus=jnp.zeros_like(q_L2),
    )


def _unbounded(monkeypatch, model, time, force):
    """The strain parts of the model before the recovery bound."""
    with monkeypatch.context() as patch:
        patch.setattr(piao, "superposed_strain", _unbounded_sum)
        return _unbounded_parts(model, time, force)


def test_equal_sets_are_unchanged(monkeypatch):
    """With equal L and UL sets and a non-negative force the bound never acts: the
    model selects the unscaled terms, the same operations on the same states as
    before the bound. Compared with the pre-bound code to a few ulp, not bit for
    bit: XLA may fuse (and round) the two programs' outputs differently
    (docs/model_notes.md point 10: public outputs bit-identical on 36,000 samples
    with XLA's default CPU compilation, 1-2 ulp at 24 of 216,000 values with the
    CPU loop kernels that the suite enables)."""
    rng = np.random.default_rng(3)
    base = _piao()
    for trial in range(6):
        scales = 10.0 ** rng.uniform(-1.0, 1.0, len(LOADING))
        scales[0] = 10.0 ** rng.uniform(-4.0, 0.0)  # E_L1: rigid to compliant
        model = eqx.tree_at(
            lambda m: tuple(getattr(m, n) for n in LOADING),
            base,
            tuple(getattr(base, n) * s for n, s in zip(LOADING, scales)),
        )
        model = _equal(model)
        time = np.cumsum(10.0 ** rng.uniform(-2.0, 4.0, N))
        force = rng.uniform(0.0, 2 * F0, N) * (rng.uniform(size=N) < 0.6)
        if trial % 2:  # a load, a hold, an unloading to 0 N, a long rest
            force = np.where(np.arange(N) < N // 4, F0, 0.0)
        new = _parts(model, time, force)
        old = _unbounded(monkeypatch, model, time, force)
        for name in ("instantaneous", "creep", "recovery_short", "recovery_long"):
            np.testing.assert_allclose(
                getattr(new, name), getattr(old, name), rtol=1e-15, atol=1e-19
            )
        np.testing.assert_allclose(new.total, old.total, rtol=1e-14, atol=1e-17)
        # The histories unload: the comparison covers recovering samples.
        assert np.any(np.asarray(old.recovery_short) > 1e-5)


# ----------------------------------------------------------------------------------
# Monotone in the load (equal sets): a non-negative pulse added to any non-negative
# force history never leaves the cable shorter at any later sample.


@eqx.filter_jit
def _elongations(model, time, forces):
    def run(force):
        return jaxcable.simulate_force_history(model, CABLE, time, force).elongation

    return jax.vmap(run)(forces)


@settings(max_examples=25, deadline=None, derandomize=True)
@given(
    scales=st.lists(st.floats(-1.0, 1.0), min_size=5, max_size=5),
    dts=st.lists(st.floats(0.01, 3000.0), min_size=N - 1, max_size=N - 1),
    levels=st.lists(st.floats(0.0, 1000.0), min_size=N, max_size=N),
    loaded=st.lists(st.booleans(), min_size=N, max_size=N),
    start=st.integers(0, N - 1),
    width=st.integers(1, 6),
    amplitude=st.floats(0.0, 1000.0),
)
def test_adding_a_pulse_never_shortens_the_cable(
    scales, dts, levels, loaded, start, width, amplitude
):
    # E_L1 from 1.25e10 to 1.25e14 Pa (compliant to Piao's rigid spring).
    scales = np.asarray(scales)
    scales[0] = 2.0 * scales[0] - 2.0
    base = _piao()
    model = _equal(
        eqx.tree_at(
            lambda m: tuple(getattr(m, n) for n in LOADING),
            base,
            tuple(getattr(base, n) * 10.0**s for n, s in zip(LOADING, scales)),
        )
    )
    time = np.concatenate([[0.0], np.cumsum(dts)])
    force = np.asarray(levels) * np.asarray(loaded)
    pulse = np.zeros(N)
    pulse[start : start + width] = amplitude
    without, with_pulse = np.asarray(
        _elongations(model, time, np.stack([force, force + pulse]))
    )
    np.testing.assert_array_equal(with_pulse[:start], without[:start])
    assert np.all(with_pulse[start:] >= without[start:] - 1e-9)
