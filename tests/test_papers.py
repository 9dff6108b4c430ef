"""The default IntegratedModel against Park et al.'s printed numbers (the set was
fitted to them by `jaxcable.papers.calibrate_sk78`, see notebooks/01_papers.ipynb)."""

import json
import os
import subprocess
import sys

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxcable as jc
from jaxcable import papers
from jaxcable.internal import calibration, park


# Errors (%) of the default set, as measured when it was fitted (samples_per_ramp=200).
MEASURED_ERRORS = {
    "creep_ratio_300mm": -1.67,
    "residual_300mm": -3.89,
    "residual_100mm": 4.06,
    "second_test_100mm_24h": 1.69,
    "second_test_100mm_48h": 1.81,
    "second_test_100mm_72h": 0.52,
    "second_test_300mm_24h": -2.80,
    "second_test_300mm_48h": 3.75,
    "second_test_300mm_72h": -3.80,
    "peak_300mm_50mm_min": -1.44,
    "peak_300mm_3mm_min": -3.03,
}
# Targets the model cannot reach within 5 % (none reached at present).
MISSED = set()


@pytest.fixture(scope="module")
def report():
    return {row.name: row for row in papers.sk78_targets_report()}


def test_targets_are_sourced():
    names = [t.name for t in papers.SK78_TARGETS]
    assert len(set(names)) == len(names) == 11
    for target in papers.SK78_TARGETS:
        assert "Park" in target.source
        assert "mm/min" in target.quantity  # the simulated test it is read from
        assert target.derived == target.name.startswith("peak_")


def test_reached_targets_within_5_percent(report):
    assert set(report) == set(MEASURED_ERRORS)
    for name, row in report.items():
        if name not in MISSED:
            assert abs(row.error) < 5.0, (name, row.error)


def test_errors_as_recorded(report):
    for name, row in report.items():
        assert row.error == pytest.approx(MEASURED_ERRORS[name], abs=0.3), name
        assert row.error == pytest.approx(100 * (row.model / row.paper - 1))


def test_cyclic_behaviour():
    # Park Figs. 4-7 and Tables 4-5: stiffness rises then converges, the dissipated
    # energy per cycle falls, the cable ends each cycle longer.
    checks = papers.sk78_qualitative_checks()
    for force, c in checks.items():
        assert c["stiffness_rises"], (force, c["stiffness"])
        assert c["stiffness_converges"], (force, c["stiffness"])
        assert c["energy_falls"], (force, c["energy"])
        assert c["elongation_grows"], (force, c["valley"])


def test_default_set_is_physical():
    # The constraints of the fit (`jaxcable.internal.calibration`): no hardening (not
    # identified; beta > 0 would break the monotonicity in load); the unloading line
    # at least as stiff as the loading curve; the short-term element creeps faster
    # than it recovers; the flow fixed at its literature anchor.
    model = jc.IntegratedModel()
    assert float(model.beta) == 0.0
    assert float(model.E1r) >= float(model.E1c)
    assert float(model.t_e) <= float(model.t_r1)
    for name, value in calibration.SK78_FLOW.items():
        assert float(getattr(model, name)) == value


def test_rest_dependence_of_the_second_test(report):
    # Park Table 3, 300 mm: the longer the rest, the more the cable stretches back
    # (5.05 < 5.99 < 7.12 mm); 100 mm: recovered within a day (2.33, 2.33, 2.36).
    long_ = [report[f"second_test_300mm_{h}h"].model for h in (24, 48, 72)]
    short = [report[f"second_test_100mm_{h}h"].model for h in (24, 48, 72)]
    assert long_[0] < long_[1] < long_[2]
    assert max(short) - min(short) < 0.05 * min(short)


def test_rests_end_no_shorter_than_new():
    # After 10 cycles to 100 N at 3 mm/min, the 100 and 300 mm cables end the 24,
    # 48 and 72 h rests longer than new. At the report's 200 samples per ramp: the
    # simulations the `report` fixture compiled.
    _, ok, rest_ends, _ = park.simulate_targets(
        jc.IntegratedModel(), 200, None, throw=False
    )
    assert bool(np.all(ok))
    assert np.all(np.asarray(rest_ends) > 0), rest_ends


@pytest.mark.parametrize("length", [0.1, 0.3])
@pytest.mark.parametrize("rate_mm_per_min", [3.0, 50.0])
@pytest.mark.parametrize("force", [100.0, 150.0])
def test_park_protocol_simulates(length, rate_mm_per_min, force):
    # Park's protocol (10 cycles, a rest, the re-stretch) at his lengths, rates and
    # forces: the re-stretch passes through the strain at which h = 1 + beta
    # eps**gamma starts, and must still have a loading time for every force sample.
    from jaxcable.papers import park_protocol

    cable = jc.Cable(length=length, speed=rate_mm_per_min * 1e-3 / 60)
    for rest_hours in (24.0, 48.0, 72.0):
        protocol = park_protocol(force, rest_hours=rest_hours, samples_per_ramp=50)
        traj = jc.simulate_rate_test(
            jc.IntegratedModel(), cable, protocol, method=jc.Simulation(throw=False)
        )
        assert traj.result == jc.RESULTS.successful, (rest_hours, traj.result)


def test_rate_effect():
    # Park Fig. 3: slower stretching, more creep, a longer cable at 100 N.
    ramp = jc.Protocol.cycles(100.0, cycles=1, samples_per_ramp=50)
    peaks = [
        float(
            jc.simulate_rate_test(
                jc.IntegratedModel(), jc.Cable(length=0.3, speed=v), ramp
            ).elongation[50]
        )
        for v in (3e-3 / 60, 50e-3 / 60)
    ]
    assert peaks[0] > peaks[1]


def test_failed_simulation_reported_as_nan():
    # t_r2 < 0 at 50 mm/min (Park Eq. 8): only that target is lost.
    # The report's default sampling and lambda2 an array of the fields' dtype (not a
    # weak one): the program the `report` fixture compiled.
    model = eqx.tree_at(
        lambda m: m.lambda2, jc.IntegratedModel(), jnp.asarray(1e3, jnp.float64)
    )
    rows = {r.name: r for r in papers.sk78_targets_report(model)}
    assert np.isnan(rows["peak_300mm_50mm_min"].model)
    assert all(
        np.isfinite(r.model)
        for n, r in rows.items()
        if not n.startswith("peak_300mm_50")
    )


def test_parametrisation_round_trip():
    model = jc.IntegratedModel()
    back = calibration._model_from_log(jnp.asarray(calibration._log_from_model(model)))
    for name in calibration._FIELDS:
        assert float(getattr(back, name)) == pytest.approx(
            float(getattr(model, name)), rel=1e-9, abs=1e-9
        ), name
    # Both retardation times of the fit are positive at every rate Park used.
    for length in (0.1, 0.3):
        for speed in (3e-3 / 60, 50e-3 / 60):
            cable = jc.Cable(length=length, speed=speed)
            assert float(model.retardation_time_long(cable)) > 0


def test_target_gradient_matches_finite_differences():
    # The fit differentiates the targets in forward mode through the kernel.
    n = 10

    def second_test_300mm_72h(log_e3r):
        model = eqx.tree_at(lambda m: m.E3r, jc.IntegratedModel(), jnp.exp(log_e3r))
        values, _ = park.target_values(model, n, None, throw=False)
        return values[8]

    # One compiled function gives the derivative and the finite differences.
    value_and_slope = jax.jit(lambda x: jax.jvp(second_test_300mm_72h, (x,), (1.0,)))
    x = jnp.log(jc.IntegratedModel().E3r)
    h = 1e-5
    _, slope = value_and_slope(x)
    fd = (value_and_slope(x + h)[0] - value_and_slope(x - h)[0]) / (2 * h)
    assert float(slope) == pytest.approx(float(fd), rel=1e-5)
    assert slope < 0  # a stiffer long-term element recovers, and re-extends, less


_CALIBRATE = """
import json, jax
jax.config.update("jax_enable_x64", True)
import numpy as np, jaxcable as jc
from jaxcable import papers
cal = papers.calibrate_sk78(jc.IntegratedModel(), starts=1, max_steps=3, samples_per_ramp=20)
print(json.dumps(dict(
    model=isinstance(cal.model, jc.IntegratedModel), rows=len(cal.rows),
    targets=len(papers.SK78_TARGETS), costs=[float(c) for c in cal.costs],
    steps=[int(k) for k in cal.steps])))
"""


@pytest.mark.slow
def test_calibrate_runs_and_does_not_worsen(jax_cache_env):
    # In a fresh interpreter: compiled late in the full suite, in a process that has
    # compiled hundreds of kernels before, XLA's CPU compiler crashed (SIGSEGV) on this
    # large forward-mode program, twice in a row on a fresh clone, while the same test
    # alone passes; isolated, the crash cannot take the suite down with it. With the
    # run's compilation cache (tests/conftest.py): the report the calibration ends with
    # is the program of this module's `report` fixture, which then loads it.
    out = subprocess.run(
        [sys.executable, "-c", _CALIBRATE],
        capture_output=True,
        text=True,
        timeout=900,
        env={**os.environ, **jax_cache_env},
    )
    assert out.returncode == 0, out.stderr[-2000:]
    cal = json.loads(out.stdout.strip().splitlines()[-1])
    assert cal["model"] and cal["rows"] == cal["targets"]
    assert np.all(np.isfinite(cal["costs"])) and cal["steps"][0] <= 3
