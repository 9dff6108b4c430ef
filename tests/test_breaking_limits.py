"""A material's limits come from its data: a file's `# breaking_strain:` (or
`--breaking-strain`, `inf` for a material that does not break) limits every
simulation; with only `# breaking_load_N:`, the limit is the model's strain at that
load; with neither, there is none (the Dyneema default must not stop another
material); a cable read without a breaking load does not inherit the 3 mm rope's
2000 N."""

import json
import math

import numpy as np
import pytest

import jaxcable as jc

from .helpers import run_cli as _run


# Burgers parameters pinned here (not the library defaults). Held at 100 N on the
# 3 mm cable, it strains 0.0064 at once and creeps past 0.1 within the hold.
PARAMS = dict(E1=2.2e9, eta0=1.6e11, E2=3.7e8, eta2=3.7e10)
PEAK_N = 100.0
AREA = math.pi * 3e-3**2 / 4
# One history shape for every simulation here, so that it compiles once.
TIME = np.concatenate([np.linspace(0.0, 10.0, 6), 10.0 + np.geomspace(1.0, 2000.0, 15)])
FORCE = np.minimum(TIME / 10.0, 1.0) * PEAK_N


def _history(path, force=FORCE, **metadata):
    """A force-controlled creep history (canonical file) with `metadata`."""
    data = jc.TestData(
        time=TIME,
        force=force,
        elongation=1e-3 * np.linspace(0.0, 3.0, TIME.size),
        metadata={"length_mm": 300.0, "control": "force", **metadata},
    )
    jc.write_csv(path, data)
    return path


@pytest.fixture(scope="module")
def params(tmp_path_factory):
    path = tmp_path_factory.mktemp("limits") / "params.json"
    path.write_text(json.dumps(PARAMS))
    return path


def _simulate(src, params, tmp_path, *options):
    out = tmp_path / "out.csv"
    argv = ["simulate", src, "--model", "burgers", "--params", params, *options]
    return (*_run([*argv, "--out", out]), out)


# ----------------------------------------------------------------------------------
# the cable a file describes


def test_a_file_without_limits_has_none_of_the_3mm_rope(tmp_path):
    thin = jc.read_test(
        _history(tmp_path / "a.csv", force=FORCE / 100, diameter_mm=0.34)
    )
    cable = thin.cable()
    assert float(cable.breaking_strain) == math.inf
    # The rope's 2000 N scaled with the cross-section, not 2000 N.
    assert float(cable.breaking_load) == pytest.approx(2000.0 * (0.34 / 3.0) ** 2)
    assert float(cable.breaking_load) == pytest.approx(jc.default_breaking_load(0.34))
    # A test that carried more than that did not break there: its peak is the floor.
    strong = jc.read_test(_history(tmp_path / "b.csv", diameter_mm=0.34))
    assert float(strong.cable().breaking_load) == pytest.approx(PEAK_N)
    # At Park's 3 mm, the rated 2000 N.
    assert float(jc.Cable.from_mm(length_mm=300.0).breaking_load) == 2000.0


def test_a_file_gives_its_limits(tmp_path):
    both = _history(tmp_path / "a.csv", breaking_strain=0.02, breaking_load_N=150.0)
    cable = jc.read_test(both).cable()
    assert float(cable.breaking_strain) == 0.02
    assert float(cable.breaking_load) == 150.0
    # Only a breaking load: no strain limit before a fit.
    load = jc.read_test(_history(tmp_path / "b.csv", breaking_load_N=150.0)).cable()
    assert (
        float(load.breaking_strain) == math.inf and float(load.breaking_load) == 150.0
    )
    # The option replaces the file's value, inf included.
    with pytest.warns(jc.MetadataConflictWarning, match="breaking_strain=inf given"):
        given = jc.read_test(both, metadata={"breaking_strain": math.inf}).cable()
    assert float(given.breaking_strain) == math.inf


# ----------------------------------------------------------------------------------
# simulate: the limit, the RESULTS member, the option


def test_a_history_beyond_the_files_breaking_strain_fails(params, tmp_path):
    src = _history(tmp_path / "brittle.csv", breaking_strain=0.02)
    status, _, stderr, out = _simulate(src, params, tmp_path)
    assert status == 1
    assert str(src) in stderr
    assert jc.RESULTS[jc.RESULTS.strain_beyond_break] in stderr
    assert not out.exists()
    # --breaking-strain inf: a material that does not break; said to replace the file's.
    status, _, stderr, out = _simulate(
        src, params, tmp_path, "--breaking-strain", "inf"
    )
    assert status == 0, stderr
    assert "breaking_strain=inf given, the file says 0.02" in stderr
    assert float(np.max(jc.read_csv(out).elongation)) / 0.3 > 0.02  # it did go beyond


def test_no_limit_without_one_in_the_file(params, tmp_path):
    # The same history without limits: the 0.07 of a Dyneema rope does not apply.
    status, _, stderr, out = _simulate(
        _history(tmp_path / "free.csv"), params, tmp_path
    )
    assert status == 0, stderr
    assert float(np.max(jc.read_csv(out).elongation)) / 0.3 > jc.DEFAULT_BREAKING_STRAIN


def test_a_breaking_load_gives_the_models_strain_there(params, tmp_path):
    load = 1.1 * PEAK_N
    src = _history(tmp_path / "rated.csv", breaking_load_N=load)
    status, stdout, stderr, _ = _simulate(src, params, tmp_path)
    # The hold creeps past the strain a ramp to the breaking load reaches.
    assert status == 1
    assert jc.RESULTS[jc.RESULTS.strain_beyond_break] in stderr
    said = float(stdout.split("breaking strain ")[1].split(",")[0])
    assert f"the model's strain at the breaking load {load:g} N" in stdout
    # That strain, independently: a ramp at the file's 3 mm/min, finely sampled.
    cable = jc.Cable.from_mm(length_mm=300.0, breaking_strain=math.inf)
    ramp = jc.Protocol.concatenate(
        jc.Protocol.start(), jc.Protocol.ramp(0.0, load, 200)
    )
    traj = jc.simulate_rate_test(jc.BurgersModel(**PARAMS), cable, ramp)
    assert said == pytest.approx(float(traj.strain[-1]), rel=0.02)
    assert said > load / (PARAMS["E1"] * AREA)  # more than the spring alone


@pytest.mark.parametrize("value", ["-1", "0", "nan", "brittle"])
@pytest.mark.parametrize("command", ["simulate", "fit", "diagnose", "design"])
def test_breaking_strain_option_is_checked_on_every_command(tmp_path, command, value):
    src = _history(tmp_path / "h.csv")
    argv = [command, src, "--out", tmp_path / "o.json", "--breaking-strain", value]
    status, _, stderr = _run(argv)
    assert status == 2
    assert "--breaking-strain" in stderr and value in stderr


@pytest.mark.parametrize("command", ["fit", "diagnose", "design"])
def test_every_command_that_fits_reads_the_option(tmp_path, command):
    # Read before any fit: the option replaces the file's value (said), and the
    # file is then refused for a force far below zero, so nothing compiles.
    force = FORCE.copy()
    force[10] = -5.0
    src = _history(tmp_path / "h.csv", force=force, breaking_strain=0.02)
    argv = [command, src, "--model", "burgers", "--out", tmp_path / "o.json"]
    status, _, stderr = _run([*argv, "--breaking-strain", "inf"])
    assert status == 2
    assert "breaking_strain=inf given, the file says 0.02" in stderr
    assert "line 15, column 'force_N'" in stderr
