"""Diagnoses of displacement-controlled tests and of tests mixing both drives
(issue 11): the drives are resolved once, the held-out scores, the noise level and
the residual structure are in the scored channel (N), or in noise units when the
drives mix; and `jaxcable diagnose --drive`."""

import dataclasses
import json
import math

import numpy as np
import pytest

import jaxcable as jc
from jaxcable.cli import main
from jaxcable.internal import heldout_rmse


TRUTH = jc.BurgersModel(E1=2.0e9, eta0=3.0e11, E2=4.0e8, eta2=2.0e10)
START = jc.BurgersModel(E1=1.5e9, eta0=1.0e11, E2=6.0e8, eta2=1.0e10)
LENGTH_MM = 200.0
# The synthetic cable creeps past a real rope's breaking strain (10 % at 1000 N);
# the diagnosis is tested here, so it has none (nor do its tests' metadata).
CABLE = jc.Cable.from_mm(length_mm=LENGTH_MM, diameter_mm=3.0, breaking_strain=math.inf)
NOISE = 0.005  # of the peak of the scored channel
SAMPLES = 120
# Two candidates that wrap any base: enough to exercise the scoring, and fast.
CANDIDATES = ["termination_compliance", "sensor_drift"]


def _names(drives) -> tuple[str, ...]:
    """The names of drives (a drive value prints as its name)."""
    return tuple(str(d) for d in drives)


def _times(ramp: float, hold: float) -> np.ndarray:
    # Evenly spaced in the hold: the time split's training part (its first 70 %)
    # then reaches well into the hold, where the long-term creep is determined (a
    # log-spaced hold leaves it to the held-out part, and the fits extrapolate).
    ramp_n = SAMPLES // 4
    hold_n = SAMPLES - ramp_n
    return np.concatenate(
        [
            np.linspace(0.0, ramp, ramp_n),
            ramp + np.linspace(hold / hold_n, hold, hold_n),
        ]
    )


def _metadata(name: str, control: str | None) -> dict:
    metadata = {
        "length_mm": LENGTH_MM,
        "diameter_mm": 3.0,
        "id": name,
        "breaking_strain": math.inf,
    }
    if control:
        metadata["control"] = control
    return metadata


def relaxation(strain: float, seed: int, control: str | None = "elongation"):
    """A ramp to `strain` in 20 s, held 600 s; force noise NOISE of the peak."""
    t = _times(20.0, 600.0)
    e = np.minimum(t / 20.0, 1.0) * strain * LENGTH_MM * 1e-3
    f = np.asarray(jc.simulate_elongation_history(TRUTH, CABLE, t, e).force)
    f = f + NOISE * f.max() * np.random.default_rng(seed).standard_normal(f.size)
    return jc.TestData(
        t, np.clip(f, 0.0, None), e, metadata=_metadata(f"relax-{strain}", control)
    )


def constant_rate(strain: float, seed: int):
    """Up and down at a constant crosshead rate; force noise NOISE of the peak."""
    t = np.linspace(0.0, 200.0, SAMPLES)
    e = strain * LENGTH_MM * 1e-3 * (1.0 - np.abs(t / 100.0 - 1.0))
    f = np.asarray(jc.simulate_elongation_history(TRUTH, CABLE, t, e).force)
    f = f + NOISE * f.max() * np.random.default_rng(seed).standard_normal(f.size)
    return jc.TestData(
        t,
        np.clip(f, 0.0, None),
        e,
        metadata=_metadata(f"rate-{strain}", "elongation"),
    )


def creep(force: float, seed: int):
    """A force ramp in 10 s, held 900 s; elongation noise NOISE of the peak."""
    t = _times(10.0, 900.0)
    f = np.minimum(t / 10.0, 1.0) * force
    e = np.asarray(jc.simulate_force_history(TRUTH, CABLE, t, f).elongation)
    e = e + NOISE * e.max() * np.random.default_rng(seed).standard_normal(e.size)
    return jc.TestData(t, f, e, metadata=_metadata(f"creep-{force:g}", "force"))


@pytest.fixture(scope="module")
def displacement_tests():
    return [relaxation(0.01, 1), relaxation(0.02, 2), constant_rate(0.015, 3)]


def test_displacement_controlled_diagnosis_names_nothing_in_newtons(
    displacement_tests,
):
    """The Burgers truth, diagnosed with a Burgers base by the elongation drive: the
    base predicts the held-out force to within the noise, no cause is named, and
    every score is in N."""
    tests = displacement_tests
    d = jc.diagnose(jc.Problem(START, tests), jc.CandidateSearch(candidates=CANDIDATES))
    assert _names(d.drives) == ("elongation",) * 3
    assert _names(d.base_fit.drives) == ("elongation",) * 3
    assert d.unit == "N"
    assert d.named_cause == "none", d.summary()
    # The force noise is 0.5 % of each test's peak force (about 0.4-1 N here).
    peaks = [float(np.max(t.force)) for t in tests]
    assert NOISE * min(peaks) < d.noise < 1.2 * NOISE * max(peaks)
    floor = heldout_rmse(TRUTH, tests)
    assert 0.5 * d.noise < floor < 2 * d.noise
    assert d.base_heldout_rmse <= 1.2 * floor, (floor, d.summary())
    for c in d.candidates:
        assert c.unit == "N" and math.isfinite(c.heldout_rmse)
        assert math.isnan(c.heldout_rmse_mm)
    # The mm fields keep meaning mm: not given for a diagnosis in N.
    assert math.isnan(d.base_heldout_rmse_mm) and math.isnan(d.noise_mm)
    doc = json.loads(d.to_json())
    assert doc["unit"] == "N" and doc["base_heldout_rmse_mm"] is None
    assert doc["base_heldout_rmse"] == pytest.approx(d.base_heldout_rmse)
    assert doc["drives"] == ["elongation"] * 3
    assert doc["structure"]["unit"] == "N"
    assert doc["structure"]["mean_mm"]["hold"] is None
    assert doc["structure"]["mean"]["hold"] is not None
    assert " N held out" in d.summary()
    # The structure is the force residuals': white noise, nothing relates to it.
    assert abs(d.structure["autocorrelation"]) < 4 * d.structure["white_noise_band"]


def test_drives_are_fixed_once_for_every_fold(displacement_tests):
    """Untagged files, an explicit drive: every fold of leave-one-test-out fits
    with it (a fold never re-detects)."""
    untagged = [
        dataclasses.replace(
            t, metadata={k: v for k, v in t.metadata.items() if k != "control"}
        )
        for t in displacement_tests
    ]
    d = jc.diagnose(
        jc.Problem(START, untagged, drive="elongation"),
        jc.CandidateSearch(
            candidates=["termination_compliance"], heldout=jc.HeldOut(split="tests")
        ),
    )
    assert d.unit == "N" and _names(d.drives) == ("elongation",) * 3
    assert _names(d.base_fit.drives) == ("elongation",) * 2
    fit = d.candidate("termination_compliance").fit
    assert _names(fit.drives) == ("elongation",) * 2
    with pytest.raises(ValueError, match="drive"):
        jc.diagnose(jc.Problem(START, untagged, drive=["force", "elongation"]))


def test_mixed_drives_are_scored_in_noise_units():
    """Two force-controlled creep tests and two relaxation tests of one cable: the
    diagnosis runs, its scores are in noise units (about 1 for the right model), and
    it names nothing."""
    tests = [creep(500.0, 10), creep(1000.0, 11), relaxation(0.01, 12)]
    tests.append(relaxation(0.02, 13))
    d = jc.diagnose(jc.Problem(START, tests), jc.CandidateSearch(candidates=CANDIDATES))
    assert _names(d.drives) == ("force", "force", "elongation", "elongation")
    assert d.unit == "noise"
    assert d.named_cause == "none", d.summary()
    # Each residual is divided by its own channel's noise: both are about 1.
    assert 0.7 < d.noise < 1.3
    floor = heldout_rmse(TRUTH, tests)
    assert 0.7 < floor < 1.5
    assert d.base_heldout_rmse <= 1.2 * floor, (floor, d.summary())
    assert d.base_heldout_rmse == pytest.approx(heldout_rmse(d.base_fit, tests))
    assert len(d.scales) == 4 and all(s > 0 for s in d.scales)
    assert math.isnan(d.base_heldout_rmse_mm)
    doc = d.to_dict()
    assert doc["unit"] == "noise" and doc["noise_mm"] is None
    assert all(c["unit"] == "noise" for c in doc["candidates"])
    assert "noise units" in d.summary() and "held-out noise" in d.summary()
    assert d.structure["strongest"] is not None


@pytest.mark.slow
def test_cli_diagnose_drive_elongation(displacement_tests, tmp_path, capsys):
    files = []
    for i, t in enumerate(displacement_tests[:2]):
        # No control line: the command line decides.
        untagged = dataclasses.replace(
            t, metadata={k: v for k, v in t.metadata.items() if k != "control"}
        )
        path = tmp_path / f"relax{i}.csv"
        jc.write_csv(path, untagged)
        files.append(str(path))
    start = tmp_path / "start.json"
    start.write_text(
        json.dumps({k: float(getattr(START, k)) for k in ("E1", "eta0", "E2", "eta2")})
    )
    report = tmp_path / "report"
    status = main(
        [
            "diagnose",
            *files,
            "--model",
            "burgers",
            "--params",
            str(start),
            "--drive",
            "elongation",
            "--candidates",
            "termination_compliance",
            "--json",
            "--report",
            str(report),
        ]
    )
    captured = capsys.readouterr()
    assert status == 0, captured.err
    doc = json.loads(captured.out)
    assert doc["unit"] == "N" and doc["drives"] == ["elongation"] * 2
    assert doc["named_cause"] == "none"
    assert doc["base_heldout_rmse_mm"] is None and doc["base_heldout_rmse"] > 0
    # Each file's drive and why, as `jaxcable fit` prints it.
    assert captured.err.count("drive: elongation (given)") == 2, captured.err
    summary = (report / "summary.md").read_text()
    assert "held-out RMSE N" in summary and " N held out" in summary
    assert (report / "residuals.png").stat().st_size > 0
