"""What a cable does over the hours and days it is used: more load never makes it
shorter (hypothesis), long holds stay bounded, and Park's second tensile test."""

import jax
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import jaxcable as jc


N = 40
SETTINGS = settings(max_examples=25, deadline=None, derandomize=True)
CABLE = jc.Cable(length=0.1)
DAY = 86400.0


@jax.jit
def _elongation(model, time, force):
    # throw=False: the linear baselines pass the breaking strain over a day at
    # 300 N; monotonicity holds beyond it all the same.
    return jc.simulate_force_history(
        model, CABLE, time, force, method=jc.Simulation(throw=False)
    ).elongation


def _history(dts, levels):
    time = np.concatenate([[0.0], np.cumsum(dts)])
    return time, np.asarray(levels)


# A history: N samples with steps from a tenth of a second to a day, forces in
# 0-300 N (15 % of the breaking load); a pulse: a non-negative force added over a
# random window of samples.
steps = st.lists(
    st.sampled_from([0.1, 1.0, 10.0, 60.0, 600.0, 3600.0, DAY]),
    min_size=N - 1,
    max_size=N - 1,
)
levels = st.lists(st.floats(0.0, 300.0), min_size=N, max_size=N)
pulses = st.tuples(st.integers(0, N - 1), st.integers(1, N), st.floats(0.0, 200.0))


def _pulsed(force, pulse):
    start, width, size = pulse
    extra = np.zeros_like(force)
    extra[start : start + width] = size
    return force + extra


MONOTONE_MODELS = {
    "integrated": jc.IntegratedModel(),
    "burgers": jc.BurgersModel(),
    "five-element": jc.FiveElementModel(),
}


@pytest.mark.parametrize("name", sorted(MONOTONE_MODELS))
@SETTINGS
@given(dts=steps, force=levels, pulse=pulses)
def test_more_load_never_makes_the_cable_shorter(name, dts, force, pulse):
    # Adding a non-negative force to any history never leaves the cable shorter at
    # any later sample (the five-element model with its equal L / UL sets). Bouc-Wen
    # is not monotone: its loop's branch depends on the sign of the last change.
    model = MONOTONE_MODELS[name]
    time, force = _history(dts, force)
    base = np.asarray(_elongation(model, time, force))
    more = np.asarray(_elongation(model, time, _pulsed(force, pulse)))
    assert np.all(more >= base - 1e-9)


def test_pulse_that_used_to_shorten_the_cable():
    # 100 mm, 0 -> 50 N in 10 s held 2 h, against the same plus a 100 N triangular
    # pulse between 10 and 15 s: a reading whose recovery targets followed the
    # all-time largest force ended the pulsed cable 0.95 mm shorter.
    time = np.concatenate([np.linspace(0, 15, 31), np.linspace(20, 7210, 60)])
    force = np.minimum(5.0 * time, 50.0)
    pulse = np.interp(time, [10, 12.5, 15], [0, 100, 0])
    model = jc.IntegratedModel()
    plain = np.asarray(_elongation(model, time, force))
    pulsed = np.asarray(_elongation(model, time, force + pulse))
    assert np.all(pulsed >= plain - 1e-12)
    assert pulsed[-1] > plain[-1]


def _hold(force, days=30.0, samples=200):
    """0 -> force in 60 s, then held; log-spaced samples out to `days`."""
    time = np.concatenate([[0.0], np.geomspace(1.0, days * DAY, samples)])
    return time, np.minimum(force * time / 60.0, force)


@pytest.mark.parametrize("force", [100.0, 150.0])
def test_thirty_day_hold_stays_bounded(force):
    # 100 and 150 N are 5 and 7.5 % of this rope's breaking load: from 1 h to 30
    # days of a hold the strain grows by <= 1 %, it ends <= 6 %, and nothing is
    # flagged (throw=True raises on any failure, the breaking strain included).
    time, f = _hold(force)
    traj = jc.simulate_force_history(
        jc.IntegratedModel(), jc.Cable(length=0.3), time, f
    )
    strain = np.asarray(traj.strain)
    hour = np.searchsorted(time, 3600.0)
    assert strain[-1] - strain[hour] <= 0.01
    assert strain[-1] <= 0.06
    # Bounded primary creep: after a day the strain grows only by the slow flow.
    day = np.searchsorted(time, DAY)
    rate = (strain[-1] - strain[day]) / (time[-1] - time[day])
    assert 0 < rate < 1e-8  # 1/s


def test_hold_near_the_breaking_load_is_flagged():
    # 95 % of the breaking load: the rope passes its breaking strain in the hold.
    time, f = _hold(
        0.95 * float(jc.Cable(length=0.3).breaking_load), days=1.0, samples=40
    )
    traj = jc.simulate_force_history(
        jc.IntegratedModel(),
        jc.Cable(length=0.3),
        time,
        f,
        method=jc.Simulation(throw=False),
    )
    assert traj.result == jc.RESULTS.strain_beyond_break
    with pytest.raises(Exception, match="breaking strain"):
        jc.simulate_force_history(jc.IntegratedModel(), jc.Cable(length=0.3), time, f)


_SCALED = ("E1c", "E2c", "t_c", "E2r", "t_r1", "E3r", "t_e", "eta0", "strain_a")


@SETTINGS
@given(
    dts=steps,
    force=levels,
    pulse=pulses,
    scales=st.lists(st.floats(-1.0, 1.0), min_size=len(_SCALED), max_size=len(_SCALED)),
    stiffer=st.floats(0.0, 1.0),
)
def test_monotone_whatever_the_parameters(dts, force, pulse, scales, stiffer):
    # The order-keeping is built into the model, not into a calibration: any
    # parameters with beta = 0 and an unloading line at least as stiff as the
    # loading curve (E1r >= E1c), moduli and times scaled by up to 10x either way.
    base = jc.IntegratedModel()
    fields = {n: float(getattr(base, n)) * 10.0**s for n, s in zip(_SCALED, scales)}
    model = jc.IntegratedModel(**fields, E1r=fields["E1c"] * (1.0 + stiffer))
    time, force = _history(dts, force)
    plain = np.asarray(_elongation(model, time, force))
    more = np.asarray(_elongation(model, time, _pulsed(force, pulse)))
    assert np.all(more >= plain - 1e-9)
