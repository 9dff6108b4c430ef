"""Fits of displacement-controlled tests: the elongation drive, the control detection,
and fits that mix force- and displacement-controlled tests."""

import dataclasses
import json
import math

import numpy as np
import pytest

import jaxcable as jc
from jaxcable.papers import synthesize_history


TRUTH = jc.BurgersModel(E1=2.0e9, eta0=3.0e11, E2=4.0e8, eta2=2.0e10)
TRUE = {"E1": 2.0e9, "eta0": 3.0e11, "E2": 4.0e8, "eta2": 2.0e10}
START = jc.BurgersModel(E1=1.5e9, eta0=1.0e11, E2=6.0e8, eta2=1.0e10)
LENGTH_MM = 200.0
# The synthetic cable creeps past any real rope's breaking strain (10 % at 1000 N);
# these tests are about the drives, so it has none (nor do its tests' metadata).
CABLE = jc.Cable.from_mm(length_mm=LENGTH_MM, diameter_mm=3.0, breaking_strain=math.inf)
UNBREAKABLE = {"breaking_strain": math.inf}
NOISE = 0.005  # of the peak of the scored channel
SAMPLES = 120


def _names(drives) -> tuple[str, ...]:
    """The names of drive values, as PARAMS.json and the command line write them."""
    return tuple(d.name for d in drives)


def _times(ramp: float, hold: float, n: int = SAMPLES) -> np.ndarray:
    ramp_n = n // 4
    return np.concatenate(
        [np.linspace(0.0, ramp, ramp_n), ramp + np.geomspace(0.5, hold, n - ramp_n)]
    )


def relaxation(strain: float, seed: int, control: str | None = "elongation"):
    """A ramp to `strain` in 20 s, held 600 s; force noise NOISE of the peak."""
    t = _times(20.0, 600.0)
    e = np.minimum(t / 20.0, 1.0) * strain * LENGTH_MM * 1e-3
    data, sigma = synthesize_history(
        TRUTH,
        CABLE,
        t,
        e,
        drive="elongation",
        seed=seed,
        metadata={"id": f"relax-{strain}", **UNBREAKABLE},
    )
    if control != "elongation":
        data.metadata.pop("control")
    return data, sigma


def constant_rate(strain: float, seed: int):
    """A ramp up and down at a constant crosshead rate; force noise NOISE of the peak."""
    t = np.linspace(0.0, 200.0, SAMPLES)
    e = strain * LENGTH_MM * 1e-3 * (1.0 - np.abs(t / 100.0 - 1.0))
    return synthesize_history(
        TRUTH,
        CABLE,
        t,
        e,
        drive="elongation",
        seed=seed,
        metadata={"id": f"rate-{strain}", **UNBREAKABLE},
    )


def creep(force: float, seed: int, control: str | None = "force"):
    """A force ramp in 10 s, held 900 s; elongation noise NOISE of the peak."""
    t = _times(10.0, 900.0)
    f = np.minimum(t / 10.0, 1.0) * force
    data, sigma = synthesize_history(
        TRUTH,
        CABLE,
        t,
        f,
        drive="force",
        seed=seed,
        metadata={"id": f"creep-{force:g}", **UNBREAKABLE},
    )
    if control != "force":
        data.metadata.pop("control")
    return data, sigma


@pytest.fixture(scope="module")
def displacement_tests():
    return [relaxation(0.01, 1), relaxation(0.02, 2), constant_rate(0.015, 3)]


@pytest.fixture(scope="module")
def displacement_fit(displacement_tests):
    problem = jc.Problem(START, [t for t, _ in displacement_tests])
    return jc.fit(problem, jc.LeastSquares(multistart=1))


def test_metadata_names_the_control():
    data = jc.TestData(
        np.arange(3.0), np.ones(3), np.ones(3), metadata={"length_mm": 1.0}
    )
    assert data.control is None
    for text, control in [
        ("force", "force"),
        ("Load", "force"),
        ("displacement", "elongation"),
        ("Extension control", "elongation"),
        ("position", "elongation"),
    ]:
        assert jc.ControlDetection is not None
        from jaxcable.internal import control_name

        assert control_name(text, "x") == control


def test_control_line_is_read_and_a_bad_one_refused(tmp_path):
    good = tmp_path / "good.csv"
    good.write_text(
        "# length_mm: 100\n# control: Displacement\ntime_s,force_N,elongation_mm\n"
        "0,0,0\n1,1,0.1\n2,2,0.2\n"
    )
    assert jc.read_csv(good).control == "elongation"
    bad = tmp_path / "bad.csv"
    bad.write_text(
        "# length_mm: 100\n# control: sideways\ntime_s,force_N,elongation_mm\n"
        "0,0,0\n1,1,0.1\n"
    )
    with pytest.raises(ValueError, match=r"bad.csv, line 2, metadata 'control'"):
        jc.read_csv(bad)


def test_control_is_detected_from_the_data():
    for make, arg, expected in [
        (relaxation, 0.02, "elongation"),
        (creep, 800.0, "force"),
    ]:
        data, _ = make(arg, 0, control=None)
        found = jc.detect_control(data.time, data.force, data.elongation)
        assert found.control == expected, found
        assert found.detected and expected in found.reason


def test_drive_precedence_argument_then_metadata_then_data():
    data, _ = relaxation(0.02, 0, control=None)
    tagged = dataclasses.replace(data, metadata={**data.metadata, "control": "force"})
    assert _names(jc.pad_tests([data]).drive) == ("elongation",)  # detected
    assert _names(jc.pad_tests([tagged]).drive) == ("force",)  # the file's line
    by_name = jc.pad_tests([tagged], drive="elongation")
    assert _names(by_name.drive) == ("elongation",)
    # A drive value is accepted where its name is, and compares by value.
    by_value = jc.pad_tests([tagged], drive=by_name.drive[0])
    assert by_value.drive == by_name.drive
    mixed = jc.pad_tests([tagged, data], drive=["force", "elongation"])
    assert _names(mixed.drive) == ("force", "elongation")
    assert [d.scores_force for d in mixed.drive] == [False, True]
    assert [d.unit for d in mixed.drive] == ["m", "N"]


def test_bad_drives_are_refused():
    data, _ = relaxation(0.02, 0)
    with pytest.raises(ValueError, match="`drive`"):
        jc.pad_tests([data], drive="sideways")
    with pytest.raises(ValueError, match="`drive` names 2 drives for 1 tests"):
        jc.pad_tests([data], drive=["force", "force"])
    hole = data.elongation.copy()
    hole[5] = np.nan
    mask = np.ones(data.num_samples, bool)
    mask[5] = False
    broken = dataclasses.replace(data, elongation=hole, mask=mask)
    # A masked sample is not scored, but an elongation-driven test is driven by it.
    with pytest.raises(ValueError, match=r"tests\[0\].*elongation"):
        jc.pad_tests([broken], drive="elongation")
    jc.pad_tests([broken], drive="force")


def test_round_trip_of_displacement_controlled_tests(
    displacement_tests, displacement_fit
):
    """Synthetic relaxation and constant-rate tests: the fitted force RMSE is within
    1.3 x the noise on every test, and the parameters within 3 standard errors."""
    result = displacement_fit
    assert result.converged
    assert _names(result.drives) == ("elongation",) * 3
    assert result.loss_unit == "N^2"
    assert np.all(np.isnan(result.rmse_mm))
    for i, (_, sigma) in enumerate(displacement_tests):
        assert result.rmse_N[i] <= 1.3 * sigma, (i, result.rmse_N[i], sigma)
    z = [
        (v - TRUE[n]) / s for n, v, s in zip(result.names, result.values, result.stderr)
    ]
    assert np.all(np.abs(z) < 3), z
    assert "relax-0.01" in result.summary() and " N " in result.summary()


def test_simulated_force_reproduces_the_fit_residuals(
    displacement_tests, displacement_fit
):
    data = displacement_tests[0][0]
    traj = jc.simulate_elongation_history(
        displacement_fit.models[0], data.cable(), data.time, data.elongation
    )
    rmse = np.sqrt(np.mean((np.asarray(traj.force) - data.force) ** 2))
    np.testing.assert_allclose(rmse, displacement_fit.rmse_N[0], rtol=1e-6)


def test_fit_result_json_keeps_the_drives(displacement_fit, tmp_path):
    path = tmp_path / "params.json"
    displacement_fit.to_json(path)
    document = json.loads(path.read_text())
    assert document["loss_unit"] == "N^2"
    assert [t["drive"] for t in document["tests"]] == ["elongation"] * 3
    back = jc.FitResult.from_json(path)
    assert back.drives == displacement_fit.drives
    np.testing.assert_allclose(back.rmse_N, displacement_fit.rmse_N)


@pytest.mark.parametrize("seed", [0])
def test_mixed_fit_recovers_the_parameters(seed):
    """Two creep tests (force control) and two relaxation tests (displacement
    control) of one cable in one fit: every parameter within 3 standard errors
    (scripts/drive_targets.py runs 6 seeds)."""
    tests = [
        creep(500.0, 10 * seed)[0],
        creep(1000.0, 10 * seed + 1)[0],
        relaxation(0.01, 10 * seed + 2)[0],
        relaxation(0.02, 10 * seed + 3)[0],
    ]
    result = jc.fit(jc.Problem(START, tests), jc.LeastSquares(multistart=1))
    assert result.converged
    assert _names(result.drives) == ("force", "force", "elongation", "elongation")
    assert result.loss_unit == "1"
    # Residuals in noise units: the SSR is about the number of samples.
    n = int(np.sum(result.num_samples))
    assert 0.7 * n < result.loss < 1.3 * n
    z = [
        (v - TRUE[k]) / s for k, v, s in zip(result.names, result.values, result.stderr)
    ]
    assert np.all(np.abs(z) < 3), z
    assert np.all(np.isfinite(result.rmse_mm[:2])) and np.all(
        np.isnan(result.rmse_mm[2:])
    )
    assert np.all(np.isfinite(result.rmse_N[2:]))


def test_cli_fit_and_simulate_with_the_elongation_drive(
    displacement_tests, displacement_fit, tmp_path, capsys
):
    """`jaxcable fit` reads each file's drive and fits it; `jaxcable simulate --params
    --drive elongation` fills in force_N, whose residual is the fit's."""
    from jaxcable.cli import main

    files = []
    for i, (data, _) in enumerate(displacement_tests):
        path = tmp_path / f"t{i}.csv"
        jc.write_csv(path, data)
        files.append(str(path))
    params = tmp_path / "p.json"
    start = tmp_path / "start.json"
    start.write_text(json.dumps({k: float(getattr(START, k)) for k in TRUE}))
    argv = ["fit", *files, "--model", "burgers", "--out", str(params), "--quiet"]
    argv += ["--params", str(start)]
    assert main(argv + ["--starts", "1"]) == 0
    out = capsys.readouterr().out
    assert "drive: elongation (the file's 'control' line)" in out
    fitted = jc.FitResult.from_json(params)
    # The command line masks the slack samples (the clipped zero forces at the end
    # of the constant-rate test) that the API fit above kept.
    np.testing.assert_allclose(fitted.rmse_N, displacement_fit.rmse_N, rtol=0.2)
    read = jc.read_test(files[0])
    # The measured history without its forces: simulate fills them in.
    bare = tmp_path / "bare.csv"
    bare.write_text(
        "# length_mm: 200\n# diameter_mm: 3\ntime_s,elongation_mm\n"
        + "".join(
            f"{float(t)!r},{1e3 * float(e)!r}\n"
            for t, e in zip(
                displacement_tests[0][0].time, displacement_tests[0][0].elongation
            )
        )
    )
    for source in (files[0], str(bare)):
        out_csv = tmp_path / "sim.csv"
        argv = ["simulate", source, "--params", str(params), "--out", str(out_csv)]
        assert main(argv + ["--drive", "elongation"]) == 0
        simulated = jc.read_csv(out_csv)
        assert simulated.control == "elongation"
        miss = (simulated.force - read.force)[read.mask]
        np.testing.assert_allclose(
            np.sqrt(np.mean(miss**2)), fitted.rmse_N[0], rtol=1e-6
        )


def test_a_start_that_fails_says_why():
    """The integrated model solves no force beyond a strain of 1 (its hardening law);
    a displacement-controlled test stretched past it is refused with that reason (on
    a cable with no breaking strain, whose crossing would come first)."""
    t = np.linspace(0.0, 10.0, 12)
    e = np.minimum(t / 5.0, 1.0) * 1.5 * 0.1  # to a strain of 1.5 on 100 mm
    meta = {"length_mm": 100.0, "id": "far", **UNBREAKABLE}
    data = jc.TestData(t, np.linspace(0.0, 100.0, 12), e, metadata=meta)
    with pytest.raises(
        ValueError, match=r"tests\[0\] \(far, elongation-driven\).*above 1"
    ):
        jc.fit(
            jc.Problem(jc.IntegratedModel(), [data], fit=["E1c"], drive="elongation")
        )


def test_report_of_a_displacement_controlled_fit(
    displacement_tests, displacement_fit, tmp_path
):
    """The report plots the model's force at the measured elongation and tabulates
    the force RMSE, for each elongation-driven test."""
    from jaxcable.internal import write_report

    tests = [t for t, _ in displacement_tests]
    written = write_report(tmp_path, displacement_fit, tests)
    assert [p.name for p in written][:2] == ["fit_loops.png", "fit_residuals.png"]
    rows = (tmp_path / "rmse.csv").read_text().splitlines()
    assert rows[0] == "id,file,drive,samples,masked,rmse_mm,rmse_N,rmse_percent"
    for row, rmse in zip(rows[1:], displacement_fit.rmse_N):
        cells = row.split(",")
        assert cells[2] == "elongation" and cells[5] == ""
        np.testing.assert_allclose(float(cells[6]), rmse, rtol=1e-5)
    summary = (tmp_path / "summary.md").read_text()
    assert "N^2" in summary and "| elongation |" in summary
    responses = jc.model_responses(displacement_fit, jc.Problem(START, tests))
    for test, force, rmse in zip(tests, responses, displacement_fit.rmse_N):
        np.testing.assert_allclose(
            np.sqrt(np.mean((force - test.force) ** 2)), rmse, rtol=1e-8
        )
