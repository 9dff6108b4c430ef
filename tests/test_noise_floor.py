"""The noise a diagnosis weighs its residuals against exists: on a smooth record
(a noise-free simulation resampled linearly onto a finer grid, as processed or
digitised records are; the same with noise, low-pass filtered) the second
differences collapse, the record is flagged smooth and the noise is floored at what
the base's residual scatters at short range, said in its source; on the same record
with white noise the estimate is the noise's, from the second differences."""

import numpy as np
import pytest

import jaxcable as jc
from jaxcable.internal import channel_noise, grid_step, white_part
from jaxcable.papers import hidden_effect_model

from .helpers import creep_recovery_protocol


TRUTH = hidden_effect_model(None, seed=5)
SIGMA = 5e-6
# Samples per interval of the simulation on the resampled grid.
FINER = 4


def _records(sigma: float, smoothing: float = 0.0):
    """Three tests of `TRUTH` simulated, resampled linearly onto a grid `FINER`
    times finer (force and elongation), plus white noise `sigma` (m), then
    Gaussian-filtered over `smoothing` samples (0: not). Also the RMS of the
    record's error against the model on its own grid (m): the noise it has."""
    rng = np.random.default_rng(11)
    tests, errors = [], []
    for length, force in ((100.0, 120.0), (200.0, 160.0), (300.0, 80.0)):
        cable = jc.Cable(length=length * 1e-3, speed=3e-3 / 60)
        traj = jc.simulate_rate_test(TRUTH, cable, creep_recovery_protocol(force))
        t0, f0, e0 = (
            np.asarray(a, float) for a in (traj.time, traj.force, traj.elongation)
        )
        steps = [
            np.linspace(a, b, FINER, endpoint=False) for a, b in zip(t0[:-1], t0[1:])
        ]
        time = np.concatenate([*steps, t0[-1:]])
        f = np.interp(time, t0, f0)
        e = np.interp(time, t0, e0) + sigma * rng.standard_normal(time.size)
        if smoothing:
            kernel = np.exp(-0.5 * (np.arange(-12, 13) / smoothing) ** 2)
            padded = np.pad(e, 12, mode="edge")
            e = np.convolve(padded, kernel / kernel.sum(), mode="valid")
        exact = jc.simulate_force_history(TRUTH, cable, time, f).elongation
        errors.append(e - np.asarray(exact, float))
        tests.append(
            jc.TestData(
                time=time,
                force=f,
                elongation=e,
                metadata={
                    "length_mm": length,
                    "rate_mm_per_min": 3.0,
                    "control": "force",
                    "id": f"L{length:.0f}-F{force:.0f}",
                },
            )
        )
    return tests, float(np.sqrt(np.mean(np.concatenate(errors) ** 2)))


def _diagnosis(tests):
    """The base alone (no candidate): its noise estimate."""
    problem = jc.Problem(jc.IntegratedModel(), tests).with_scaled_start()
    search = jc.CandidateSearch(candidates=[], max_rounds=1, discover=False)
    return jc.diagnose(problem, search)


@pytest.fixture(scope="module")
def smooth():
    tests, error = _records(0.0)
    return tests, error, _diagnosis(tests)


def test_smooth_record_is_flagged_and_floored(smooth):
    tests, error, d = smooth
    # The second differences see nothing: linear between the simulated samples.
    assert max(channel_noise(t, "force") for t in tests) < 1e-3 * error
    assert "smooth" in d.noise_source
    assert "white part of the base residual" in d.noise_source
    assert d.to_dict()["noise_source"] == d.noise_source
    assert "smooth" in d.summary()
    # Floored at the size of the record's own error (the resampling's, largest
    # where the creep turns): neither collapsed nor above the base's misfit.
    noise = d.noise * 1e-3
    assert 0.3 * error <= noise <= 3.0 * error
    assert d.noise <= 2.0 * d.base_heldout_rmse


def test_noisy_record_keeps_the_second_differences():
    tests, _ = _records(SIGMA)
    d = _diagnosis(tests)
    assert d.noise_source == "second differences"
    assert d.noise * 1e-3 == pytest.approx(SIGMA, rel=0.2)


def test_filtered_record_is_floored_at_its_scatter():
    tests, error = _records(SIGMA, smoothing=3.0)
    d = _diagnosis(tests)
    assert "smooth" in d.noise_source
    # A Gaussian filter of 3 samples keeps 5 / sqrt(2 sqrt(pi) 3) = 1.5 um of the
    # noise; the second differences see a fifth of that.
    filtered = SIGMA / np.sqrt(2.0 * np.sqrt(np.pi) * 3.0)
    assert max(channel_noise(t, "force") for t in tests) < 0.5 * filtered
    assert filtered <= d.noise * 1e-3 <= 3.0 * error


def test_quantised_record_floors_at_its_step():
    rng = np.random.default_rng(3)
    time = np.linspace(0.0, 1000.0, 400)
    force = np.full(time.size, 50.0)
    # 0.1 um of noise on a 10 um grid: most second differences are zero.
    step = 1e-5
    e = (
        np.round((1e-3 + 1e-7 * time + 1e-7 * rng.standard_normal(time.size)) / step)
        * step
    )
    test = jc.TestData(
        time=time, force=force, elongation=e, metadata={"length_mm": 100.0}
    )
    assert grid_step(e) == pytest.approx(step, rel=1e-6)
    assert channel_noise(test, "force") == pytest.approx(step / np.sqrt(12.0))


def test_white_part_of_white_noise():
    rng = np.random.default_rng(5)
    r = 2.0 * rng.standard_normal(5000) + np.linspace(0.0, 50.0, 5000) ** 1.5 / 100
    assert white_part(r) == pytest.approx(2.0, rel=0.05)
