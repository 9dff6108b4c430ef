import contextlib
import io
import json
import re
import subprocess
import sys

import numpy as np
import pytest

import jaxcable as jc
from jaxcable import _cli
from jaxcable._cli import main


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
        metadata={"id": "cli", "material": "Dyneema SK78", "length_mm": 300.0},
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
    "missing_column": ("# length_mm: 300\ntime_s,elongation_mm\n0,0\n", 2, "force_N"),
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


def test_simulate_model_not_available(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(_cli._MODELS, "maxwell", "MaxwellModel")
    args = ["simulate", str(_history(tmp_path)), "--model", "maxwell"]
    assert main([*args, "--out", str(tmp_path / "out.csv")]) == 2
    message = _one_error_line(capsys.readouterr().err)
    assert "jaxcable.MaxwellModel" in message


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


@pytest.mark.parametrize("argv", [[], ["simulate"], ["demo"]])
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
    assert f"{src}, line 4, column 'force_N'" in message


# ----------------------------------------------------------------------------------
# demo


_SAMPLES_PER_RAMP = 100  # coarser than the default 1000, to keep the test fast
_CASES = ("rate_3mm_per_min", "rate_50mm_per_min", "cycles10_100N", "cycles10_150N")


@pytest.fixture(scope="module")
def demo_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("demo") / "demo_out"
    stdout, stderr = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
        status = main(
            ["demo", "--out", str(out), "--samples-per-ramp", str(_SAMPLES_PER_RAMP)]
        )
    return status, out, stdout.getvalue(), stderr.getvalue()


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


def test_demo_all_cases_succeed(demo_run):
    status, _, stdout, _ = demo_run
    assert "FAILED" not in stdout
    assert status == 0


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


@pytest.mark.parametrize("name", list(_cli._MODELS))
def test_every_registered_model_resolves(name):
    cls = _cli._model_class(name)
    assert issubclass(cls, jc.AbstractCableModel)
    cls()  # the CLI builds every model from its defaults
