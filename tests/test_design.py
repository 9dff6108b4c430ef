"""Test design: a designed test lowers the expected uncertainty, its protocol file
runs in `jaxcable simulate`, the command line writes it, and the budget's errors
name their field."""

import json

import numpy as np
import pytest

import jaxcable as jc
from jaxcable._uncertainty.discriminate import _lack_of_fit
from jaxcable.cli import main


TRUTH = jc.BurgersModel(E1=2.0e9, eta0=3.0e11, E2=4.0e8, eta2=2.0e10)
CABLE = jc.Cable.from_mm(length_mm=200.0, diameter_mm=3.0, rate_mm_per_min=3.0)


@pytest.fixture(scope="module")
def creep_csv(tmp_path_factory):
    time = np.concatenate([np.linspace(0.0, 10.0, 6), 10 + np.geomspace(1, 300, 18)])
    force = np.minimum(time / 10.0, 1.0) * 40.0
    e = np.asarray(jc.simulate_force_history(TRUTH, CABLE, time, force).elongation)
    e = e + 2e-6 * np.random.default_rng(0).standard_normal(e.shape)
    test = jc.TestData(
        time=time,
        force=force,
        elongation=e,
        metadata={"length_mm": 200.0, "diameter_mm": 3.0, "id": "creep"},
    )
    path = tmp_path_factory.mktemp("design") / "creep.csv"
    jc.write_csv(path, test)
    return path


BUDGET = jc.TestBudget(
    duration_s=1200.0, max_force_fraction=0.02, samples=16, blocks=1, noise_mm=0.002
)


@pytest.fixture(scope="module")
def burgers_fit(creep_csv):
    problem = jc.Problem(TRUTH, [jc.read_test(creep_csv)])
    return jc.fit(problem, jc.LeastSquares(multistart=1))


@pytest.fixture(scope="module")
def designed(burgers_fit):
    return jc.design_test(burgers_fit, jc.TestDesign(BUDGET, steps=2), cable=CABLE)


def test_designed_test_teaches(designed, tmp_path):
    assert np.all(designed.sd_after <= designed.sd_before * (1 + 1e-9))
    assert designed.criterion[1] < designed.criterion[0]
    assert designed.targets and set(designed.targets) <= set(designed.names)
    assert designed.duration_s == pytest.approx(1200.0, rel=0.05)
    levels = [s["ramp_to_N"] for s in designed.document["segments"][::2]]
    assert max(levels) <= 0.02 * float(CABLE.breaking_load) + 1e-6
    low, high = BUDGET.speed_mm_per_min
    assert low <= designed.document["rate_mm_per_min"] <= high
    assert "D_s-optimal" in designed.summary()
    path = tmp_path / "next.json"
    designed.to_json(path)
    out = tmp_path / "next.csv"
    assert main(["simulate", str(path), "--out", str(out)]) == 0
    assert jc.read_test(out).num_samples == designed.protocol.num_samples


def test_design_command(creep_csv, tmp_path, capsys):
    out = tmp_path / "NEXT.json"
    args = [
        "design", str(creep_csv), "--out", str(out), "--model", "burgers",
        "--duration-s", "1200", "--max-force-fraction", "0.02", "--samples", "16",
        "--blocks", "1", "--design-steps", "1", "--starts", "1", "--quiet",
    ]  # fmt: skip
    assert main(args) == 0
    doc = json.loads(out.read_text())
    assert doc["segments"] and doc["length_mm"] == 200.0
    assert "designed test" in capsys.readouterr().out


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(duration_s=-1.0), "duration_s"),
        (dict(duration_s=10.0, max_force_fraction=2.0), "max_force_fraction"),
        (dict(duration_s=10.0, speed_mm_per_min=(5.0, 1.0)), "speed_mm_per_min"),
        (dict(duration_s=10.0, samples=3), "samples"),
        (dict(duration_s=10.0, blocks=0), "blocks"),
        (dict(duration_s=10.0, noise_mm=0.0), "noise_mm"),
    ],
)
def test_budget_errors_name_the_field(kwargs, match):
    with pytest.raises(ValueError, match=match):
        jc.TestBudget(**kwargs)


@pytest.mark.parametrize(
    "kwargs, error, match",
    [
        (dict(budget={"duration_s": 10.0}), ValueError, "budget"),
        (dict(steps=-1), ValueError, "steps"),
        (dict(steps=2.0), TypeError, "steps"),
        (dict(learning_rate=0.0), ValueError, "learning_rate"),
        (dict(learning_rate=float("inf")), ValueError, "learning_rate"),
        (dict(learning_rate=None), TypeError, "learning_rate"),
    ],
)
def test_test_design_errors_name_the_field(kwargs, error, match):
    with pytest.raises(error, match=match):
        jc.TestDesign(**{"budget": BUDGET, **kwargs})


def test_design_rejects_other_inputs(burgers_fit):
    method = jc.TestDesign(BUDGET)
    with pytest.raises(ValueError, match="known"):
        jc.design_test("fit", method, cable=CABLE)
    # Two candidates are separated by design_discriminating_test alone.
    with pytest.raises(ValueError, match="design_discriminating_test"):
        jc.design_test((burgers_fit, burgers_fit), method, cable=CABLE)
    with pytest.raises(ValueError, match="candidates"):
        jc.design_discriminating_test((burgers_fit,), method, cable=CABLE)
    with pytest.raises(ValueError, match="method"):
        jc.design_test(burgers_fit, BUDGET, cable=CABLE)
    with pytest.raises(ValueError, match="cable"):
        jc.design_discriminating_test((burgers_fit, burgers_fit), method, cable=None)
    with pytest.raises(ValueError, match="targets"):
        jc.design_test(burgers_fit, method, cable=CABLE, targets=["nope"])


def test_lack_of_fit_is_the_refitted_residual():
    # What a linear candidate keeps of a difference after moving its parameters,
    # held by a prior precision: the minimum of the penalised least squares.
    rng = np.random.default_rng(3)
    jac, diff = rng.standard_normal((30, 3)), rng.standard_normal(30)
    precision, sigma = np.diag([0.5, 2.0, 1.0]), 0.7
    a = jac.T @ jac / sigma**2 + precision
    step = np.linalg.solve(a, jac.T @ diff / sigma**2)
    direct = np.sum((diff - jac @ step) ** 2) / sigma**2 + step @ precision @ step
    value = float(_lack_of_fit(diff, jac, precision, sigma))
    assert value == pytest.approx(direct, rel=1e-10)
    assert 0 < value < diff @ diff / sigma**2
    # A difference the candidate can follow freely leaves nothing.
    free = float(_lack_of_fit(jac @ [1.0, -2.0, 0.5], jac, 0 * precision, sigma))
    assert abs(free) < 1e-8


@pytest.fixture(scope="module")
def separating(burgers_fit, creep_csv):
    # A rival that cannot creep: the test that separates it from Burgers holds the
    # load.
    problem = jc.Problem(jc.HookeModel(), [jc.read_test(creep_csv)])
    hooke = jc.fit(problem, jc.LeastSquares(multistart=1))
    method = jc.TestDesign(BUDGET, steps=2)
    return jc.design_discriminating_test((burgers_fit, hooke), method, cable=CABLE)


def test_discriminating_test_separates(separating, tmp_path):
    assert separating.candidates == ("BurgersModel", "HookeModel")
    t_ab, t_ba = separating.separation
    assert np.isfinite(t_ab) and np.isfinite(t_ba) and min(t_ab, t_ba) > 0
    # BIC(Hooke) - BIC(Burgers) now, plus T, plus the penalty of Burgers' three
    # more parameters growing with the new samples.
    now, n, grow = separating.bic_now, separating.samples_before, separating.samples
    assert now > 10 and n == 24
    penalty = 3 * np.log((n + grow) / n)
    assert separating.expected_delta_bic() == pytest.approx(
        (now + t_ab - penalty, -now + t_ba + penalty)
    )
    assert separating.duration_s == pytest.approx(1200.0, rel=0.05)
    text = separating.summary()
    assert "T-optimal" in text and "HookeModel is true" in text
    path = tmp_path / "separate.json"
    separating.to_json(path)
    out = tmp_path / "separate.csv"
    assert main(["simulate", str(path), "--out", str(out)]) == 0
    assert jc.read_test(out).num_samples == separating.protocol.num_samples


@pytest.mark.parametrize(
    "separate, extra, match",
    [
        ("sensor_drift", [], "two different extension ids"),
        ("sensor_drift,sensor-drift", [], "two different extension ids"),
        ("sensor_drift,no_such_cause", [], "two different extension ids"),
        ("sensor_drift,bedding_in", ["--targets", "E1"], "--targets"),
    ],
)
def test_design_command_separate_errors(
    creep_csv, tmp_path, capsys, separate, extra, match
):
    args = [
        "design", str(creep_csv), "--out", str(tmp_path / "NEXT.json"),
        "--model", "burgers", "--duration-s", "600", "--separate", separate, *extra,
    ]  # fmt: skip
    assert main(args) != 0
    assert match in capsys.readouterr().err
    assert not (tmp_path / "NEXT.json").exists()


def test_a_diagnosis_gives_its_two_leading_candidates(burgers_fit):
    from jaxcable._uncertainty.discriminate import _leading_pair

    def candidate(id, delta_bic, fit=burgers_fit, **kw):
        nan = float("nan")
        return jc.Candidate(
            id, nan, nan, nan, delta_bic, nan, nan, "", "", False, fit=fit, **kw
        )

    diagnosis = object.__new__(jc.Diagnosis)
    object.__setattr__(
        diagnosis,
        "candidates",
        [
            candidate("a", -5.0),
            candidate("b", -40.0, diverging="departs"),
            candidate("c", -20.0),
            candidate("d", -30.0, fit=None),
            candidate("e", -12.0),
        ],
    )
    name_a, _, name_b, _, now = _leading_pair(diagnosis)
    assert (name_a, name_b, now) == ("c", "e", 8.0)
    object.__setattr__(diagnosis, "candidates", [candidate("a", -5.0)])
    with pytest.raises(ValueError, match="fewer than two"):
        jc.design_discriminating_test(diagnosis, jc.TestDesign(BUDGET), cable=CABLE)
