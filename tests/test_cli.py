import contextlib
import importlib
import io
import json
import math
import re
import subprocess
import sys

import numpy as np
import pytest

import jaxcable as jc
from jaxcable.cli import main
from jaxcable.internal import BY_CLI_NAME, cli_demo, synthetic as _synthetic

from .helpers import run_cli as _run


# One load-unload-reload history; every simulate test uses this length so that the
# force kernel compiles once.
_TIME = np.linspace(0.0, 600.0, 61)
_FORCE = np.concatenate([np.linspace(0, 100, 21), np.linspace(97.5, 0, 40)])


def _history(tmp_path, *, elongation=False, name="history.csv"):
    data = jc.TestData(
        time=_TIME,
        force=_FORCE,
        elongation=np.full_like(_TIME, 7.0) if elongation else None,
        temperature=np.full_like(_TIME, 22.0),
        extra={"gauge_V": np.arange(_TIME.size) * 0.5},
        metadata={
            "id": "cli",
            "material": "Dyneema SK78",
            "length_mm": 300.0,
            "control": "force",
        },
    )
    path = tmp_path / name
    jc.write_csv(path, data)
    return path


def test_simulate_matches_python_api(tmp_path, capsys):
    src = _history(tmp_path, elongation=True)
    out = tmp_path / "out.csv"
    assert main(["simulate", str(src), "--model", "integrated", "--out", str(out)]) == 0
    assert str(out) in capsys.readouterr().out

    data = jc.read_csv(src)
    traj = jc.simulate_force_history(
        jc.IntegratedModel(), data.cable(), data.time, data.force
    )
    result = jc.read_csv(out)
    np.testing.assert_allclose(
        result.elongation, np.asarray(traj.elongation), rtol=1e-14, atol=1e-18
    )
    assert not np.allclose(result.elongation, 7e-3)  # the old column was replaced
    # Everything else is carried through.
    np.testing.assert_array_equal(result.time, data.time)
    np.testing.assert_array_equal(result.force, data.force)
    np.testing.assert_array_equal(result.temperature, data.temperature)
    np.testing.assert_array_equal(result.extra["gauge_V"], data.extra["gauge_V"])
    assert result.metadata == {
        **data.metadata,
        "diameter_mm": 3.0,
        "rate_mm_per_min": 3.0,
        "model": "integrated",
    }


def test_simulate_params_override_defaults(tmp_path):
    src = _history(tmp_path)
    params = tmp_path / "params.json"
    params.write_text(json.dumps({"E1c": 3.0e9, "beta": 0.1}))
    out = tmp_path / "out.csv"
    assert main(["simulate", str(src), "--params", str(params), "--out", str(out)]) == 0
    data = jc.read_csv(src)
    model = jc.IntegratedModel(E1c=3.0e9, beta=0.1)
    traj = jc.simulate_force_history(model, data.cable(), data.time, data.force)
    np.testing.assert_allclose(
        jc.read_csv(out).elongation, np.asarray(traj.elongation), rtol=1e-14
    )


# (file contents, line, column) of the first problem.
_BAD_HISTORIES = {
    "missing_column": ("# length_mm: 300\ntime_s,temperature_C\n0,0\n", 2, "force_N"),
    "non_numeric": ("# length_mm: 300\ntime_s,force_N\n0,0\n1,abc\n", 4, "force_N"),
    "nan": ("# length_mm: 300\ntime_s,force_N\n0,0\n1,NaN\n", 4, "force_N"),
    "time_not_increasing": (
        "# length_mm: 300\ntime_s,force_N\n0,0\n1,1\n1,2\n",
        5,
        "time_s",
    ),
    "missing_length": ("time_s,force_N\n0,0\n1,1\n", 1, "length_mm"),
    "negative_force": ("# length_mm: 300\ntime_s,force_N\n0,0\n1,-2\n", 4, "force_N"),
}


def _one_error_line(err: str) -> str:
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("jaxcable: error: ")
    assert "Traceback" not in err
    return lines[0]


@pytest.mark.parametrize("case", list(_BAD_HISTORIES))
def test_simulate_bad_history(tmp_path, capsys, case):
    text, line, column = _BAD_HISTORIES[case]
    src = tmp_path / f"{case}.csv"
    src.write_text(text)
    out = tmp_path / "out.csv"
    assert main(["simulate", str(src), "--out", str(out)]) == 2
    message = _one_error_line(capsys.readouterr().err)
    assert str(src) in message
    assert re.search(rf"\bline {line}\b", message), message
    assert f"'{column}'" in message
    assert not out.exists()


@pytest.mark.parametrize(
    "params, expected",
    [
        ('{"E1c": 2e9,\n "nope": 1}', "parameter 'nope': not a parameter"),
        ('{"E1c": "stiff"}', "parameter 'E1c': \"stiff\" is not a number"),
        ('{"E1c": 2e9,}', "line 1, column 13: invalid JSON"),
        ("[1, 2]", "expected a JSON object"),
        ('{"E1c": -1}', "E1c"),
    ],
)
def test_simulate_bad_params(tmp_path, capsys, params, expected):
    path = tmp_path / "params.json"
    path.write_text(params)
    args = ["simulate", str(_history(tmp_path)), "--params", str(path)]
    assert main([*args, "--out", str(tmp_path / "out.csv")]) == 2
    message = _one_error_line(capsys.readouterr().err)
    assert str(path) in message and expected in message


@pytest.mark.parametrize(
    "argv",
    [
        ["simulate", "h.csv", "--model", "nonesuch", "--out", "o.csv"],
        ["simulate", "h.csv"],
        ["frobnicate"],
        [],
    ],
)
def test_usage_errors_are_one_line(capsys, argv):
    assert main(argv) == 2
    _one_error_line(capsys.readouterr().err)


@pytest.mark.parametrize("argv", [[], ["simulate"], ["fit"], ["demo"]])
def test_help(capsys, argv):
    assert main([*argv, "--help"]) == 0
    assert "usage: jaxcable" in capsys.readouterr().out


def test_module_entry_point_reports_bad_input(tmp_path):
    src = tmp_path / "bad.csv"
    src.write_text(_BAD_HISTORIES["non_numeric"][0])
    proc = subprocess.run(
        [sys.executable, "-m", "jaxcable", "simulate", str(src), "--out", "o.csv"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        timeout=120,
    )
    assert proc.returncode == 2
    message = _one_error_line(proc.stderr)
    # As `fit` reads it: the column's position and name.
    assert f"{src}, line 4, column 2 'force_N'" in message


# ----------------------------------------------------------------------------------
# simulate: rate-driven protocols


# 101 samples, as the demo's padded protocol with 5 samples per ramp (1 + 2 x 5 x 10):
# the tests share one compilation of the rate-driven kernel.
_PROTOCOL = {
    "id": "protocol-test",
    "material": "Dyneema SK78",
    "length_mm": 200,
    "rate_mm_per_min": 6,
    "segments": [
        {"cycles": 2, "force_max_N": 80, "samples_per_ramp": 15},
        {"rest_h": 2, "samples": 6},
        {"ramp_to_N": 50, "samples": 10},
        {"hold_s": 60, "force_N": 50, "samples": 4},
        {"ramp_to_N": 0, "samples": 20},
    ],
}


def _equivalent_protocol():
    """`_PROTOCOL` built with the Python API."""
    return jc.Protocol.concatenate(
        jc.Protocol.cycles(80.0, 2, 15),
        jc.Protocol.rest(7200.0, 6),
        jc.Protocol.ramp(0.0, 50.0, 10),
        jc.Protocol.hold(50.0, 60.0, 4),
        jc.Protocol.ramp(50.0, 0.0, 20),
    )


def test_simulate_protocol_matches_python_api(tmp_path, capsys):
    src = tmp_path / "protocol.json"
    src.write_text(json.dumps(_PROTOCOL))
    out = tmp_path / "out.csv"
    assert main(["simulate", str(src), "--out", str(out)]) == 0
    assert str(out) in capsys.readouterr().out

    cable = jc.Cable(length=0.2, diameter=3e-3, speed=6e-3 / 60)
    traj = jc.simulate_rate_test(jc.IntegratedModel(), cable, _equivalent_protocol())
    result = jc.read_csv(out)
    np.testing.assert_allclose(result.time, np.asarray(traj.time), rtol=1e-14)
    np.testing.assert_allclose(result.force, np.asarray(traj.force), rtol=1e-14)
    np.testing.assert_allclose(
        result.elongation, np.asarray(traj.elongation), rtol=1e-14, atol=1e-18
    )
    assert result.metadata == {
        "id": "protocol-test",
        "material": "Dyneema SK78",
        "length_mm": 200.0,
        "diameter_mm": 3.0,
        "rate_mm_per_min": 6.0,
        "protocol": "protocol.json",
        "model": "integrated",
        "control": "force",
    }


def _bad_protocol(**changes):
    doc = json.loads(json.dumps(_PROTOCOL))
    for key, value in changes.items():
        if re.fullmatch(r"segment\d+", key):
            i = int(key[len("segment") :])
            doc["segments"][i] = value
        elif value is None:
            del doc[key]
        else:
            doc[key] = value
    return json.dumps(doc)


# (file contents, what the error line must say)
_BAD_PROTOCOLS = {
    "invalid_json": ('{"length_mm": 300,\n "segments": [}', "line 2, column 15"),
    "not_an_object": ("[1, 2]", "JSON object"),
    "missing_length": (_bad_protocol(length_mm=None), "missing key 'length_mm'"),
    "missing_segments": (_bad_protocol(segments=None), "missing key 'segments'"),
    "empty_segments": (_bad_protocol(segments=[]), "segments: must be a non-empty"),
    "unknown_top_key": (_bad_protocol(lenght_mm=300), "lenght_mm: unknown key"),
    "negative_length": (_bad_protocol(length_mm=-1), "length_mm: -1 mm must be > 0"),
    "rate_not_a_number": (
        _bad_protocol(rate_mm_per_min="fast"),
        'rate_mm_per_min: "fast" is not a finite number',
    ),
    "unknown_segment_key": (
        _bad_protocol(segment0={"cycles": 2, "forcemax_N": 80}),
        "segments[0].forcemax_N: unknown key for a 'cycles' segment",
    ),
    "no_segment_kind": (
        _bad_protocol(segment1={"samples": 3}),
        "segments[1]: a segment has exactly one of",
    ),
    "two_segment_kinds": (
        _bad_protocol(segment2={"ramp_to_N": 50, "hold_s": 3}),
        "this one has ramp_to_N, hold_s",
    ),
    "missing_force_max": (
        _bad_protocol(segment0={"cycles": 2}),
        "segments[0]: missing key 'force_max_N'",
    ),
    "fractional_samples": (
        _bad_protocol(segment2={"ramp_to_N": 50, "samples": 2.5}),
        "segments[2].samples: 2.5 is not an integer >= 1",
    ),
    "above_breaking_load": (
        _bad_protocol(segment2={"ramp_to_N": 5000}),
        "segments[2].ramp_to_N: 5000 N exceeds the cable's breaking load",
    ),
    "hold_at_another_force": (
        _bad_protocol(segment3={"hold_s": 60, "force_N": 70}),
        "segments[3].force_N: 70 N differs from the force",
    ),
    "rest_under_load": (
        _bad_protocol(segment1={"ramp_to_N": 30}, segment2={"rest_h": 1}),
        "segments[2].rest_h: a rest is at 0 N",
    ),
    "ramp_to_same_force": (
        _bad_protocol(segment4={"ramp_to_N": 50}),
        "segments[4].ramp_to_N: the previous segment already ends at 50 N",
    ),
}


@pytest.mark.parametrize("case", list(_BAD_PROTOCOLS))
def test_simulate_bad_protocol(tmp_path, capsys, case):
    text, expected = _BAD_PROTOCOLS[case]
    src = tmp_path / f"{case}.json"
    src.write_text(text)
    out = tmp_path / "out.csv"
    assert main(["simulate", str(src), "--out", str(out)]) == 2
    message = _one_error_line(capsys.readouterr().err)
    assert f"{src}, " in message or f"{src}:" in message, message
    assert expected in message, message
    assert not out.exists()


def test_simulate_protocol_failure_names_the_segment(tmp_path, capsys):
    # A model outside its domain fails from the first sample on; the message names
    # the protocol file and the model (and the segment, once past the start).
    src = tmp_path / "protocol.json"
    src.write_text(json.dumps(_PROTOCOL))
    params = tmp_path / "params.json"
    # t_r2 = lambda1 (L0/v)^2 - lambda2 < 0: Park's long-term recovery is undefined.
    params.write_text(json.dumps({"lambda2": 1e9}))
    args = ["simulate", str(src), "--params", str(params)]
    assert main([*args, "--out", str(tmp_path / "out.csv")]) == 1
    message = _one_error_line(capsys.readouterr().err)
    assert str(src) in message and "model 'integrated' failed" in message


# ----------------------------------------------------------------------------------
# fit


# Burgers parameters the synthetic files are made with, and a start 0.5x-2.5x off.
_TRUE = dict(E1=2.0e9, eta0=2e11, E2=4e8, eta2=4e10)
_START = dict(E1=1.0e9, eta0=5e11, E2=1e9, eta2=1e10)
_NOISE = 1e-5  # m: 0.01 mm of elongation noise
# The synthetic files' cables creep past a real rope's breaking strain; the command
# line is tested here, so they have none (written to the files' metadata as inf).
_UNBREAKABLE = math.inf
# (id, length mm, peak force N)
_DESIGNS = (("burgers-300mm-100N", 300.0, 100.0), ("burgers-100mm-150N", 100.0, 150.0))


def _force_history(peak):
    """Load in 60 s, hold 600 s, unload in 60 s, rest 1800 s (log-spaced)."""
    ramp = np.linspace(0.0, 60.0, 21)
    hold = 60.0 + np.linspace(0.0, 600.0, 31)[1:]
    unload = 660.0 + np.linspace(0.0, 60.0, 21)[1:]
    rest = 720.0 + np.geomspace(1.0, 1800.0, 30)
    time = np.concatenate([ramp, hold, unload, rest])
    force = np.concatenate(
        [peak * ramp / 60, np.full(30, peak), peak * (1 - (unload - 660) / 60)]
    )
    return time, np.concatenate([force, np.zeros(30)])


def _synthetic_tests(model, seed=0):
    rng = np.random.default_rng(seed)
    tests = []
    for test_id, length, peak in _DESIGNS:
        time, force = _force_history(peak)
        cable = jc.Cable(length=length * 1e-3, breaking_strain=_UNBREAKABLE)
        traj = jc.simulate_force_history(model, cable, time, force)
        noise = _NOISE * rng.standard_normal(time.shape)
        tests.append(
            jc.TestData(
                time=time,
                force=force,
                elongation=np.asarray(traj.elongation) + noise,
                metadata={
                    "id": test_id,
                    "length_mm": length,
                    "control": "force",
                    "breaking_strain": _UNBREAKABLE,
                },
            )
        )
    return tests


@pytest.fixture(scope="module")
def burgers_fit(tmp_path_factory):
    """One `jaxcable fit --report` of two synthetic Burgers tests (canonical files)."""
    folder = tmp_path_factory.mktemp("fit")
    files = []
    for test in _synthetic_tests(jc.BurgersModel(**_TRUE)):
        path = folder / f"{test.metadata['id']}.csv"
        jc.write_csv(path, test)
        files.append(path)
    start = folder / "start.json"
    start.write_text(json.dumps(_START))
    params, report = folder / "PARAMS.json", folder / "report"
    # The rest's recovery at zero force is fitted: slack detection would mask it
    # (it cannot tell a fast recovery from a slack cable without an extensometer).
    argv = ["fit", *files, "--model", "burgers", "--params", start, "--starts", "2"]
    argv.append("--no-slack")
    status, stdout, stderr = _run([*argv, "--out", params, "--report", report])
    return status, stdout, stderr, files, params, report


def test_fit_recovers_known_parameters(burgers_fit):
    status, stdout, stderr, files, params, _ = burgers_fit
    assert status == 0, stderr
    assert stderr == ""  # no progress bar off a terminal, no warnings
    result = jc.FitResult.from_json(params)
    assert isinstance(result.model, jc.BurgersModel)
    assert result.converged
    assert set(result.names) == set(_TRUE)
    for name, value, err in zip(result.names, result.values, result.stderr):
        true = _TRUE[name]
        assert 0 < err < 0.1 * true, (name, err)
        assert abs(value - true) < 3 * err, (name, value, true, err)
    # The residual is the noise.
    np.testing.assert_allclose(result.rmse_mm, 1e3 * _NOISE, rtol=0.3)
    assert result.test_ids == tuple(d[0] for d in _DESIGNS)
    # The printed summary: RMSE per test (mm and %), parameters with standard errors.
    assert "RMSE mm" in stdout and "RMSE %" in stdout and "std err" in stdout
    for test_id, mm, pct in zip(result.test_ids, result.rmse_mm, result.rmse_percent):
        row = next(line for line in stdout.splitlines() if line.startswith(test_id))
        printed = [float(x) for x in row.split()[2:4]]
        np.testing.assert_allclose(printed, [mm, pct], atol=1e-2, rtol=0)
        assert int(row.split()[1]) == 101  # every sample fitted
    for name, value in zip(result.names, result.values):
        row = next(line for line in stdout.splitlines() if line.startswith(name + " "))
        np.testing.assert_allclose(float(row.split()[1]), value, rtol=1e-4)
    assert f"wrote {params}" in stdout


def test_fit_report(burgers_fit):
    status, stdout, _, files, params, report = burgers_fit
    assert status == 0
    for name in ("fit_loops.png", "fit_residuals.png"):
        assert (report / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert str(report) in stdout
    result = jc.FitResult.from_json(params)
    summary = (report / "summary.md").read_text()
    for test_id, f in zip(result.test_ids, files):
        assert f"| {test_id} | {f.name} |" in summary
    for name in result.names:
        assert f"| {name} |" in summary
    assert "± std err" in summary and "## Identifiability" in summary
    rows = (report / "rmse.csv").read_text().splitlines()
    assert rows[0] == "id,file,drive,samples,masked,rmse_mm,rmse_N,rmse_percent"
    for row, test_id, mm in zip(rows[1:], result.test_ids, result.rmse_mm):
        cells = row.split(",")
        assert cells[0] == test_id and cells[2] == "force" and cells[6] == ""
        np.testing.assert_allclose(float(cells[5]), mm, rtol=1e-5)


def test_fit_report_models_match_the_fit(burgers_fit):
    # The report's model curves are the fitted model's: their RMSE is the fit's.
    from jaxcable.internal import model_elongations

    *_, files, params, _ = burgers_fit
    result = jc.FitResult.from_json(params)
    tests = [jc.read_test(f, options=jc.ReadOptions(detect_slack=False)) for f in files]
    for test, e, rmse in zip(tests, model_elongations(result, tests), result.rmse_mm):
        np.testing.assert_allclose(
            1e3 * np.sqrt(np.mean((e - test.elongation) ** 2)), rmse, rtol=1e-8
        )


def test_simulate_with_fit_output(burgers_fit, tmp_path):
    """PARAMS.json written by `fit` drives `simulate` (round trip)."""
    *_, files, params, _ = burgers_fit
    out = tmp_path / "out.csv"
    status, stdout, stderr = _run(
        ["simulate", files[0], "--params", params, "--out", out]
    )
    assert status == 0, stderr
    assert "model 'burgers'" in stdout  # the model is taken from PARAMS.json
    fitted = jc.FitResult.from_json(params).model
    data = jc.read_csv(files[0])
    traj = jc.simulate_force_history(fitted, data.cable(), data.time, data.force)
    written = jc.read_csv(out)
    np.testing.assert_allclose(
        written.elongation, np.asarray(traj.elongation), rtol=1e-14
    )
    assert written.metadata["model"] == "burgers"
    assert json.loads(written.metadata["model_params"]) == pytest.approx(
        {n: float(getattr(fitted, n)) for n in _TRUE}
    )
    # ... and its elongation is the measured one, to the noise.
    np.testing.assert_allclose(written.elongation, data.elongation, atol=5 * _NOISE)


def test_fit_not_converged(burgers_fit, tmp_path):
    """A fit that runs out of steps: exit 1 and one line, PARAMS.json written with
    converged false for inspection."""
    *_, files, _, _ = burgers_fit
    params = tmp_path / "PARAMS.json"
    argv = ["fit", *files, "--model", "burgers", "--no-slack", "--starts", "1"]
    status, stdout, stderr = _run([*argv, "--max-steps", "2", "--out", params])
    assert status == 1
    message = _one_error_line(stderr)
    assert "the fit did not converge" in message and "--max-steps" in message
    assert "NOT converged" in stdout
    assert json.loads(params.read_text())["converged"] is False


def _per_test_params(params, tmp_path):
    """The fit's PARAMS.json turned into a fit with E1 per test."""
    doc = json.loads(params.read_text())
    doc["per_test"] = ["E1"]
    doc["parameters"]["E1"] = [1.5e9, 3.0e9]
    path = tmp_path / "per_test.json"
    path.write_text(json.dumps(doc))
    return path


def test_simulate_per_test_params_need_a_test(burgers_fit, tmp_path, capsys):
    *_, files, params, _ = burgers_fit
    per_test = _per_test_params(params, tmp_path)
    argv = ["simulate", str(files[0]), "--params", str(per_test)]
    out = tmp_path / "out.csv"
    assert main([*argv, "--out", str(out)]) == 2
    message = _one_error_line(capsys.readouterr().err)
    assert "fitted per test" in message and "--test" in message
    # The second test, by id and by index: E1 = 3e9, the rest shared.
    fitted = jc.FitResult.from_json(per_test).model
    model = jc.BurgersModel(
        **{n: (3.0e9 if n == "E1" else float(getattr(fitted, n))) for n in _TRUE}
    )
    data = jc.read_csv(files[0])
    traj = jc.simulate_force_history(model, data.cable(), data.time, data.force)
    for test in ("burgers-100mm-150N", "1"):
        assert main([*argv, "--test", test, "--out", str(out)]) == 0
        np.testing.assert_allclose(
            jc.read_csv(out).elongation, np.asarray(traj.elongation), rtol=1e-14
        )
    assert main([*argv, "--test", "nope", "--out", str(out)]) == 2
    assert "--test nope: not a test of" in _one_error_line(capsys.readouterr().err)


def _write_raw_export(path, time, elongation, force):
    """A tensile-tester export: blank first line, GBK header, units row, quoted
    numbers, CRLF, columns time, elongation, force; no metadata."""
    body = "".join(
        f'"{t:.4f}","{e:.6f}","{f:.4f}"\r\n' for t, e, f in zip(time, elongation, force)
    )
    text = "\r\n时间,位移,力\r\n(s),(mm),(N)\r\n" + body
    path.write_bytes(text.encode("gbk"))


def test_fit_raw_exports(tmp_path):
    """Raw exports with --columns and --length-mm: a Hooke cable's modulus back, and
    a slack tail (the crosshead moving on at a slightly negative force) masked."""
    true = jc.HookeModel(E=2.5e9)
    rng = np.random.default_rng(1)
    files = []
    for k, peak in enumerate((100.0, 150.0)):
        time, force = _force_history(peak)
        time, force = time[:71], force[:71]  # load, hold, unload; no rest
        traj = jc.simulate_force_history(true, jc.Cable(length=0.25), time, force)
        e_mm = 1e3 * np.asarray(traj.elongation)
        # Slack: 20 more samples over 20 s, the crosshead 2 mm further back, -0.01 N.
        time = np.concatenate([time, time[-1] + np.arange(1.0, 21.0)])
        e_mm = np.concatenate([e_mm, -0.1 * np.arange(1.0, 21.0)])
        force = np.concatenate([force, np.full(20, -0.01)])
        e_mm += 1e3 * _NOISE * rng.standard_normal(time.shape)
        path = tmp_path / f"export_{k}.csv"
        _write_raw_export(path, time, e_mm, force)
        files.append(path)
    params = tmp_path / "PARAMS.json"
    argv = ["fit", *files, "--model", "hooke"]
    argv += ["--columns", "time_s,elongation_mm,force_N"]
    status, stdout, stderr = _run([*argv, "--length-mm", "250", "--out", params])
    assert status == 0, stderr
    result = jc.FitResult.from_json(params)
    assert result.test_ids == ("export_0.csv", "export_1.csv")
    assert abs(result.values[0] - 2.5e9) < 3 * result.stderr[0]
    # The slack samples (the tail, from the unloaded sample at line 74 on) are
    # reported with their lines in the file, and not fitted.
    assert "export_0.csv: 91 samples, 21 masked (slack: lines 74-94)" in stdout
    assert result.num_samples.tolist() == [70, 70]
    np.testing.assert_allclose(result.rmse_mm, 1e3 * _NOISE, rtol=0.3)

    # Without the length the files do not describe the cable.
    status, _, stderr = _run([*argv, "--out", params])
    assert status == 2
    message = _one_error_line(stderr)
    assert str(files[0]) in message and "length_mm" in message


def _fit_argv(tmp_path, *extra):
    test = _synthetic_tests(jc.HookeModel())[0]
    path = tmp_path / "test.csv"
    jc.write_csv(path, test)
    return ["fit", str(path), "--out", str(tmp_path / "PARAMS.json"), *extra]


# (extra arguments, a file to write first (name, text), what the error line says)
_BAD_FITS = {
    "missing_file": (["nonexistent.csv"], None, "nonexistent.csv: No such file"),
    "bad_columns": (
        ["--columns", "time_s,bogus_N"],
        None,
        "column 2 'bogus_N' is not a column name",
    ),
    "columns_without_force": (["--columns", "time_s,elongation_mm,-"], None, "force"),
    "unknown_model": (["--model", "maxwell"], None, "invalid choice: 'maxwell'"),
    "unknown_fit_parameter": (
        ["--model", "burgers", "--fit", "E1,nope"],
        None,
        "--fit: 'nope' is not a parameter of model 'burgers'",
    ),
    "unknown_per_test_parameter": (
        ["--per-test", "E9"],
        None,
        "--per-test: 'E9' is not a parameter of model 'integrated'",
    ),
    "repeated_fit_parameter": (
        ["--model", "hooke", "--fit", "E,E"],
        None,
        "--fit 'E,E': a name is repeated",
    ),
    "zero_starts": (["--starts", "0"], None, "argument --starts: 0 must be at least 1"),
    "bad_length": (["--length-mm", "-5"], None, "argument --length-mm"),
    "out_folder_missing": (
        ["--out", "no/such/folder/PARAMS.json"],
        None,
        "--out no/such/folder/PARAMS.json: folder",
    ),
    "no_elongation": (
        ["no_elongation.csv"],
        ("no_elongation.csv", "# length_mm: 300\ntime_s,force_N\n0,0\n1,1\n2,2\n"),
        "no_elongation.csv: no elongation column",
    ),
    "non_numeric_cell": (
        ["bad_cell.csv"],
        (
            "bad_cell.csv",
            "# length_mm: 300\ntime_s,force_N,elongation_mm\n0,0,0\n1,x,1\n2,2,2\n",
        ),
        "line 4",
    ),
    "params_of_another_model": (
        ["--model", "hooke", "--params", "params.json"],
        ("params.json", '{"E1": 1e9}'),
        "parameter 'E1': not a parameter of model 'hooke'",
    ),
}


@pytest.mark.parametrize("case", list(_BAD_FITS))
def test_fit_bad_input(tmp_path, capsys, monkeypatch, case):
    extra, file, expected = _BAD_FITS[case]
    monkeypatch.chdir(tmp_path)
    if file is not None:
        (tmp_path / file[0]).write_text(file[1])
    argv = _fit_argv(tmp_path)
    if extra and extra[0].endswith(".csv"):
        argv[1] = extra[0]  # replace the data file
        extra = extra[1:]
    assert main([*argv, *extra]) == 2
    message = _one_error_line(capsys.readouterr().err)
    assert expected in message, message
    assert not (tmp_path / "PARAMS.json").exists()


def test_fit_params_model_mismatch(burgers_fit, tmp_path, capsys):
    *_, params, _ = burgers_fit
    argv = _fit_argv(tmp_path, "--params", str(params), "--model", "hooke")
    assert main(argv) == 2
    message = _one_error_line(capsys.readouterr().err)
    assert "holds a fit of model 'burgers', not 'hooke'" in message


def test_progress_bar():

    stream, log = io.StringIO(), io.StringIO()
    meter = jc.TextProgressMeter(log=log, stream=stream)
    with meter.bar("reading", 4) as bar:
        bar.advance(note="a.csv")
        meter.say("fitting candidate x")
        bar.advance(3)
    text = stream.getvalue()
    assert "reading [" + "#" * 6 + "." * 18 + "] 1/4" in text and "a.csv" in text
    assert "] 4/4" in text
    assert text.endswith("\r")  # the bar is erased at the end
    assert log.getvalue() == "fitting candidate x\n"
    quiet = jc.TextProgressMeter(show_bar=False, stream=io.StringIO())
    for silent in (quiet, jc.NoProgressMeter()):
        with silent.bar("fitting") as bar:
            bar.advance()
        silent.say("nothing")
    assert quiet.stream.getvalue() == ""


# ----------------------------------------------------------------------------------
# demo


# Coarser than the default 1000, to keep the test fast; the padded protocol has the
# shape of `_PROTOCOL`'s.
_SAMPLES_PER_RAMP = 5
_CASES = ("rate_3mm_per_min", "rate_50mm_per_min", "cycles10_100N", "cycles10_150N")
# The demo's fit on a small data set: two short tests made by the default model.
_DEMO_FIT = "E1c,E2c,eta0"


def _small_dataset(folder):
    from jaxcable.papers import park_protocol, synthesize

    folder.mkdir()
    for k, (length, force) in enumerate(((100.0, 100.0), (300.0, 150.0))):
        protocol = park_protocol(force, cycles=2, samples_per_ramp=15, rest_hours=2)
        cable = jc.Cable(length=length * 1e-3, speed=50e-3 / 60)
        test = synthesize(
            jc.IntegratedModel(),
            cable,
            protocol,
            seed=k,
            force_noise=0.0,  # noisy forces at rest bias the model (see README)
            metadata={"id": f"small-{k}"},
        )
        jc.write_csv(folder / f"small-{k}.csv", test)
    return folder


@pytest.fixture(scope="module")
def demo_run(tmp_path_factory):
    """One `jaxcable demo` on a small data set (slow: it compiles the rate-driven
    kernel and an IntegratedModel fit)."""
    root = tmp_path_factory.mktemp("demo")
    data = _small_dataset(root / "data")
    out = root / "demo_out"
    argv = ["demo", "--out", out, "--samples-per-ramp", _SAMPLES_PER_RAMP]
    status, stdout, stderr = _run(
        [*argv, "--data", data, "--fit", _DEMO_FIT, "--starts", "1", "--no-diagnose"]
    )
    return status, out, stdout, stderr


@pytest.mark.slow
def test_demo_writes_plots_and_histories(demo_run):
    status, out, stdout, stderr = demo_run
    for name in ("rate_effect.png", "cycles10.png"):
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert str(out) in stdout
    summary = {
        line.split()[0]: line for line in stdout.splitlines() if line[:2] == "  "
    }
    for case in _CASES:
        assert case in summary
        if "FAILED" in summary[case]:
            continue
        data = jc.read_csv(out / f"{case}.csv")
        assert data.metadata["length_mm"] == 300.0
        peak, residual = (float(x) for x in summary[case].split()[1:3])
        np.testing.assert_allclose(peak, 1e3 * np.max(data.elongation), atol=1e-3)
        # The first unloading ends 2 ramps after the start sample.
        np.testing.assert_allclose(
            residual, 1e3 * data.elongation[2 * _SAMPLES_PER_RAMP], atol=1e-3
        )
        assert 0 < residual < peak
    if status != 0:
        _one_error_line(stderr)


@pytest.mark.slow
def test_demo_all_cases_succeed(demo_run):
    status, _, stdout, stderr = demo_run
    assert "FAILED" not in stdout
    assert status == 0, stderr


@pytest.mark.slow
def test_demo_fit_report(demo_run):
    status, out, stdout, _ = demo_run
    result = jc.FitResult.from_json(out / "params.json")
    assert result.names == tuple(_DEMO_FIT.split(","))
    assert result.test_ids == ("small-0", "small-1")
    for name in ("fit_loops.png", "fit_residuals.png"):
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert (out / "summary.md").exists() and (out / "rmse.csv").exists()
    # Headline numbers: the RMSE per test and the parameters, as in params.json.
    for test_id, mm in zip(result.test_ids, result.rmse_mm):
        row = next(
            line for line in stdout.splitlines() if line.split()[:1] == [test_id]
        )
        np.testing.assert_allclose(float(row.split()[1]), mm, atol=1e-4)
    # The data were made with the default parameters, plus noise: the fit is good.
    assert result.converged
    assert np.all(result.rmse_mm < 0.05), result.rmse_mm
    # Says what was left out of the fit.
    assert "fitted 3 of 14 parameters" in stdout and "lambda2" in stdout


@pytest.mark.slow
def test_demo_history_resimulates(demo_run, tmp_path):
    # The rate-driven and the force-history drivers agree on the solved sample times.
    _, out, _, _ = demo_run
    src = out / "cycles10_100N.csv"
    resimulated = tmp_path / "re.csv"
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["simulate", str(src), "--out", str(resimulated)]) == 0
    np.testing.assert_allclose(
        jc.read_csv(resimulated).elongation,
        jc.read_csv(src).elongation,
        rtol=0,
        atol=1e-12,
    )


def test_demo_without_data(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(cli_demo, "_bundled_files", lambda: [])
    out = tmp_path / "demo_out"
    assert main(["demo", "--out", str(out)]) == 1
    message = _one_error_line(capsys.readouterr().err)
    assert "jaxcable/data/ has no *.csv files" in message
    assert not out.exists()  # failed before writing anything

    empty = tmp_path / "empty"
    empty.mkdir()
    assert main(["demo", "--out", str(out), "--data", str(empty)]) == 2
    assert "no *.csv files" in _one_error_line(capsys.readouterr().err)


@pytest.mark.slow
def test_demo_bundled_data(tmp_path):
    """`make demo` as shipped: the bundled data set, the default fit."""
    if not cli_demo._bundled_files():
        pytest.skip("jaxcable/data/ has no bundled data set yet")
    status, stdout, stderr = _run(["demo", "--out", tmp_path / "demo_out"])
    assert status == 0, stderr
    result = jc.FitResult.from_json(tmp_path / "demo_out" / "params.json")
    assert result.converged
    assert len(result.test_ids) == len(cli_demo._bundled_files())
    assert "Wrote" in stdout
    # Step 3: the diagnosis names the effect hidden in the bundled data.
    doc = json.loads(
        (tmp_path / "demo_out" / "diagnosis" / "diagnosis.json").read_text()
    )
    assert doc["named_cause"] == _synthetic.BUNDLED_EFFECT
    assert "named cause: termination_compliance" in stdout


@pytest.mark.parametrize("name", list(BY_CLI_NAME))
def test_every_registered_model_resolves(name):
    cls = BY_CLI_NAME[name].cls
    assert issubclass(cls, jc.AbstractCableModel)
    cls()  # the CLI builds every model from its defaults


@pytest.mark.slow
@pytest.mark.parametrize("name", list(BY_CLI_NAME))
def test_every_model_simulates_a_protocol(tmp_path, name):
    src = tmp_path / "protocol.json"
    src.write_text(json.dumps(_PROTOCOL))
    out = tmp_path / "out.csv"
    status, _, stderr = _run(["simulate", src, "--model", name, "--out", out])
    assert status == 0, stderr
    data = jc.read_csv(out)
    assert data.num_samples == _equivalent_protocol().num_samples
    assert np.all(np.isfinite(data.elongation)) and data.metadata["model"] == name


def test_console_entry_freezes_the_imports_and_exits_with_mains_status(monkeypatch):
    # `jaxcable` and `python -m jaxcable` run `entry`: it freezes the objects of the
    # imports (the collector then skips them), then exits with main's status.
    cli_main = importlib.import_module("jaxcable._cli.main")
    calls = []
    monkeypatch.setattr(cli_main.gc, "freeze", lambda: calls.append("freeze"))
    monkeypatch.setattr(cli_main, "main", lambda: calls.append("main") or 2)
    with pytest.raises(SystemExit) as exit_:
        cli_main.entry()
    assert exit_.value.code == 2
    assert calls == ["freeze", "main"]


def test_python_dash_m_reports_bad_input_with_status_2(tmp_path):
    missing = tmp_path / "missing.csv"
    run = subprocess.run(
        [sys.executable, "-m", "jaxcable", "fit", str(missing), "--out", "p.json"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
    )
    assert run.returncode == 2
    assert "missing.csv" in run.stderr and "Traceback" not in run.stderr
