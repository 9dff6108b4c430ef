"""Every command reads a data file as `jaxcable fit` does: an Instron Bluehill export
whose load cell reads a little below zero at rest is accepted by `fit`, `simulate`,
`diagnose` and `design` alike, its force within the noise read as 0 N; a force far
below zero is refused by each, naming file, line and column, where the force drives
the model."""

import json
import math
import re

import numpy as np
import pytest

import jaxcable as jc

from .helpers import run_cli as _run


# A 0.34 mm fibre, 13 mm long, stretched to 0.15 mm and held (relaxation), with
# Burgers parameters pinned here (not the library's defaults, which may change).
TRUE = dict(E1=2.2e9, eta0=1.6e11, E2=3.7e8, eta2=3.7e10)
LENGTH_MM, DIAMETER_MM = 13.0, 0.34
NOISE_N = 0.004
DIP_N = -0.01  # the load cell's reading at rest, on line DIP_LINE
HEADER_LINES = 7  # 4 metadata lines, a blank, the header, the units row
DIP_SAMPLE = 2
DIP_LINE = HEADER_LINES + 1 + DIP_SAMPLE
# The options every command here runs with: one parameter, one start, few steps.
FAST = ["--model", "burgers", "--fit", "E1", "--starts", "1", "--max-steps", "20"]


def _relaxation():
    """(time s, extension mm, load N) of the export: a rest, a ramp, a hold."""
    t = np.concatenate(
        [
            np.linspace(0.0, 4.0, 5),
            4.0 + np.linspace(0.0, 6.0, 13)[1:],
            10.0 + np.geomspace(1.0, 110.0, 30),
        ]
    )
    e = np.where(t < 4.0, 0.0, np.minimum((t - 4.0) / 6.0, 1.0) * 0.15)
    cable = jc.Cable.from_mm(
        length_mm=LENGTH_MM, diameter_mm=DIAMETER_MM, breaking_strain=math.inf
    )
    traj = jc.simulate_elongation_history(jc.BurgersModel(**TRUE), cable, t, 1e-3 * e)
    f = np.asarray(traj.force) + NOISE_N * np.random.default_rng(0).normal(size=t.size)
    f[:5] = np.clip(f[:5], -0.002, 0.002)
    f[DIP_SAMPLE] = DIP_N
    return t, e, f


def _bluehill(path, t, e, f, extra=()):
    lines = [
        'Specimen properties : Specimen label,"fibre-1"',
        f'Specimen properties : Length,"{LENGTH_MM:.5f}",mm',
        f'Specimen properties : Diameter,"{DIAMETER_MM:.5f}",mm',
        'Test : Rate 1,"1.50000",mm/min',
        *extra,
        "",
        "Time,Extension,Load",
        "(s),(mm),(N)",
    ]
    lines += [f'"{a:.5f}","{b:.5f}","{c:.5f}"' for a, b, c in zip(t, e, f)]
    path.write_bytes(("\r\n".join(lines) + "\r\n").encode())
    return path


@pytest.fixture(scope="module")
def export(tmp_path_factory):
    folder = tmp_path_factory.mktemp("agree")
    path = _bluehill(folder / "Specimen_RawData_1.csv", *_relaxation())
    start = folder / "start.json"
    start.write_text(json.dumps({**TRUE, "E1": 2.0e9}))
    return folder, path, start


@pytest.fixture(scope="module")
def fitted(export):
    folder, path, start = export
    params = folder / "PARAMS.json"
    argv = ["fit", path, *FAST, "--params", start, "--drive", "elongation"]
    status, out, err = _run([*argv, "--quiet", "--out", params])
    assert status == 0, err
    return params, out


def test_the_dip_is_within_the_noise_and_read_as_zero(export):
    _, path, _ = export
    data = jc.read_test(path)
    report = data.slack_report
    assert -report.threshold < DIP_N < 0  # the case the tests below are about
    assert data.force[DIP_SAMPLE] == 0.0 and data.force_raw[DIP_SAMPLE] == DIP_N
    assert data.mask[DIP_SAMPLE]  # within the noise: a reading of 0 N, fitted


def test_fit_accepts_the_export(fitted):
    params, out = fitted
    assert "drive: elongation (given)" in out
    result = jc.FitResult.from_json(params)
    assert result.converged
    assert float(result.model.E1) == pytest.approx(TRUE["E1"], rel=0.02)


@pytest.mark.parametrize("drive", ["elongation", "force"])
def test_simulate_accepts_what_fit_accepts(export, fitted, tmp_path, drive):
    # Force-driven, the dipping Load column is the input: read as 0 N there.
    _, path, _ = export
    params, _ = fitted
    out = tmp_path / "sim.csv"
    argv = ["simulate", path, "--params", params, "--drive", drive, "--out", out]
    status, stdout, stderr = _run(argv)
    assert status == 0, stderr
    written = jc.read_csv(out)
    assert written.metadata["length_mm"] == LENGTH_MM
    assert written.metadata["diameter_mm"] == DIAMETER_MM
    if drive == "force":
        assert written.force[DIP_SAMPLE] == 0.0
        assert np.all(written.force >= 0.0)
    else:
        assert np.all(np.isfinite(written.force)) and np.ptp(written.force) > 1.0


def test_diagnose_accepts_the_export(export):
    _, path, start = export
    argv = ["diagnose", path, *FAST, "--params", start, "--drive", "elongation"]
    argv += ["--max-rounds", "1", "--candidates", "sensor_drift", "--quiet", "--json"]
    status, stdout, stderr = _run([*argv, "--family", "never"])
    assert status == 0, stderr
    out = json.loads(stdout)
    assert out["verdict"]
    # --family never reaches the diagnosis: no other family fitted, and it says so.
    assert out["family"]["chosen"] == "burgers" and not out["family"]["switched"]
    assert "switched off" in out["family"]["reason"]


def test_design_accepts_the_export_with_a_default_duration(export, tmp_path):
    _, path, start = export
    out = tmp_path / "next.json"
    argv = ["design", path, *FAST, "--params", start, "--drive", "elongation"]
    argv += ["--design-steps", "1", "--samples", "16", "--blocks", "1", "--quiet"]
    status, stdout, stderr = _run([*argv, "--out", out])
    assert status == 0, stderr
    # No --duration-s: the longest measured test's, said and used.
    t, _, _ = _relaxation()
    duration = t[-1] - t[0]
    assert f"--duration-s: {duration:.6g} s" in stdout
    assert "--noise-mm:" in stdout  # elongation-driven: from the force residual
    protocol = json.loads(out.read_text())
    segments = protocol["segments"]
    total = sum(s.get("hold_s", 0) + s.get("rest_s", 0) for s in segments)
    assert total == pytest.approx(duration, rel=0.2)
    assert protocol["diameter_mm"] == DIAMETER_MM


# ----------------------------------------------------------------------------------
# a force far below zero


def _creep_with_a_push(tmp_path, push_at=20):
    """A force-controlled creep test to 100 N (canonical names in a Bluehill layout)
    whose Load reads -5 N at sample `push_at`: a real error, not noise."""
    t = np.linspace(0.0, 60.0, 41)
    f = np.minimum(t / 10.0, 1.0) * 100.0
    f = f + 0.05 * np.random.default_rng(1).normal(size=t.size)
    f[0] = 0.0
    f[push_at] = -5.0
    e = 1e-3 * np.minimum(t / 10.0, 1.0) * 3.0 + 1e-4 * t
    path = _bluehill(tmp_path / "push.csv", t, e * 1e3, f, ["Control mode,Load"])
    return path, HEADER_LINES + 2 + push_at  # the control line adds one


@pytest.mark.parametrize("command", ["fit", "simulate", "diagnose", "design"])
def test_a_real_negative_force_is_refused_where_it_drives(tmp_path, command):
    path, line = _creep_with_a_push(tmp_path)
    out = tmp_path / ("out.csv" if command == "simulate" else "out.json")
    argv = [command, path, "--model", "burgers", "--out", out]
    status, _, stderr = _run(argv)
    assert status == 2, stderr
    message = stderr.strip()
    assert re.search(rf"{re.escape(str(path))}, line {line}, column 'Load'", message)
    assert "force -5 N is negative" in message and "cannot push" in message
    assert not out.exists()
