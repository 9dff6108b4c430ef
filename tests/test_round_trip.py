"""Round trip (issue 10): data simulated with the default model and a lab's noise,
fitted with `jaxcable fit` from the true parameters, re-simulated with
`jaxcable simulate --params PARAMS.json`.

The fit must come down to the noise (each test's RMSE <= 1.3 x the elongation noise and
the force noise through the model's compliance, added in quadrature),
and the re-simulation must reproduce the fit's residuals: `simulate` drives the model
with the recorded forces exactly as `fit` does."""

import json
import math

import numpy as np
import pytest

import jaxcable as jc
from jaxcable.cli import main
from jaxcable.papers import synthesize


ELONGATION_NOISE = 1e-5  # m
FORCE_NOISE = 0.002  # of the peak force
# (length mm, peak force N): the two lengths and the two force levels.
TESTS = ((100.0, 100.0), (300.0, 150.0), (100.0, 150.0))


def _protocol(peak: float) -> jc.Protocol:
    """Three load-unload cycles, a 2 h hold at the peak force (a sample every 7.2 s),
    an unloading, a 6 h rest at 0 N (every 21.6 s) and a re-stretch cycle: 4001
    samples, 200 per ramp."""
    ramp = 200
    return jc.Protocol.concatenate(
        jc.Protocol.cycles(peak, 3, ramp),
        jc.Protocol.ramp(0.0, peak, ramp),
        jc.Protocol.hold(peak, 2 * 3600.0, 1000),
        jc.Protocol.ramp(peak, 0.0, ramp),
        jc.Protocol.rest(6 * 3600.0, 1000),
        jc.Protocol.cycles(peak, 1, ramp, start=False),
    )


def _write_tests(folder, seed: int) -> list:
    """The three tests as canonical CSV files: the true elongation (simulated from
    the true forces) plus elongation noise, and the forces as the load cell records
    them (noisy, clipped at 0, zero-suppressed below 3 sigma: `synthesize`)."""
    model = jc.IntegratedModel()
    paths = []
    for i, (length, peak) in enumerate(TESTS):
        data = synthesize(
            model,
            jc.Cable(length * 1e-3),
            _protocol(peak),
            seed=1000 * seed + i,
            elongation_noise=ELONGATION_NOISE,
            force_noise=FORCE_NOISE * peak,
            metadata={"id": f"L{length:.0f}-F{peak:.0f}"},
        )
        path = folder / f"L{length:.0f}-F{peak:.0f}.csv"
        jc.write_csv(path, data)
        paths.append(path)
    return paths


def _rmse_mm(model_m, test) -> float:
    """RMSE of a model elongation against a test's, over the samples the fit uses
    (`read_test`'s slack mask), mm."""
    r = (np.asarray(model_m) - test.elongation)[test.mask]
    return 1e3 * math.sqrt(float(np.mean(r**2)))


# Several noise draws: the target is a property of the model, not of one draw.
@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_fit_and_simulate_round_trip(tmp_path, capsys, seed):
    paths = _write_tests(tmp_path, seed)
    params = tmp_path / "PARAMS.json"
    status = main(
        [
            "fit",
            *map(str, paths),
            "--model",
            "integrated",  # starts from the defaults: the true parameters
            "--starts",
            "1",
            "--out",
            str(params),
            "--quiet",
        ]
    )
    fit_log = capsys.readouterr().out
    # Status 1 is a fit that did not converge; its best start is still written.
    assert status in (0, 1) and params.exists(), fit_log
    document = json.loads(params.read_text())
    fit_rmse = {t["id"]: t["rmse_mm"] for t in document["tests"]}

    simulate_rmse = {}
    for path in paths:
        out = tmp_path / f"simulated-{path.name}"
        argv = ["simulate", str(path), "--params", str(params), "--out", str(out)]
        assert main(argv) == 0
        test = jc.read_test(path)  # as `jaxcable fit` read it (slack mask included)
        simulated = jc.read_csv(out).elongation
        simulate_rmse[test.metadata["id"]] = _rmse_mm(simulated, test)

    report = "; ".join(
        f"{k}: fit {fit_rmse[k]:.5f} mm, simulate {simulate_rmse[k]:.5f} mm"
        for k in fit_rmse
    )
    print(f"seed {seed}: {report}")
    # One truth: `simulate --params` reproduces the fit's residuals.
    for k, rmse in fit_rmse.items():
        assert simulate_rmse[k] == pytest.approx(rmse, rel=0.01), (k, report)
    # The fit comes down to the noise: the elongation's, and the force noise that
    # drives the model, through its compliance (the delayed-elastic elements follow
    # a force within seconds, about one sample of the hold).
    model = jc.IntegratedModel()
    for (length, peak), (k, rmse) in zip(TESTS, fit_rmse.items()):
        area = float(jc.Cable(length * 1e-3).area)
        compliance = length * sum(
            1 / (float(getattr(model, e)) * area) for e in ("E1c", "E2c", "E2r", "E3r")
        )  # mm/N
        noise = math.hypot(1e3 * ELONGATION_NOISE, compliance * FORCE_NOISE * peak)
        assert rmse <= 1.3 * noise, (k, noise, report, fit_log)
    assert status == 0 and document["converged"], fit_log
