"""`jaxcable.fit_each`: many specimens, one parameter set each, solved by one vmapped
kernel, each equal to its own `jaxcable.fit`; a failing specimen leaves the others;
arguments checked at the boundary; `jaxcable fit --each`."""

import csv
import math

import equinox as eqx
import numpy as np
import pytest

import jaxcable as jc

from .helpers import run_cli as _run


NAMES = ("E1", "eta0", "E2", "eta2")
TRUTH = jc.BurgersModel(E1=2.0e9, eta0=2e11, E2=4e8, eta2=4e10)
START = jc.BurgersModel(E1=1.2e9, eta0=4e11, E2=8e8, eta2=2e10)
# (length m, peak force N, rest samples): two tests of different lengths, so that
# each specimen pads and masks.
DESIGNS = ((0.3, 100.0, 30), (0.1, 150.0, 20))


def _history(peak, rest_samples):
    """Load in 60 s, hold 600 s, unload in 60 s, rest 30 min (log-spaced)."""
    time = np.concatenate(
        [
            np.linspace(0.0, 60.0, 21),
            60.0 + np.linspace(0.0, 600.0, 31)[1:],
            660.0 + np.linspace(0.0, 60.0, 21)[1:],
            720.0 + np.geomspace(1.0, 1800.0, rest_samples),
        ]
    )
    force = np.interp(time, [0.0, 60.0, 660.0, 720.0], [0.0, peak, peak, 0.0])
    return time, force


def _specimen(factors, seed, designs=DESIGNS, breaking_strain=math.inf):
    """Synthetic tests of one specimen: TRUTH scaled by `factors` (one per NAME),
    with 10 um of elongation noise."""
    truth = eqx.tree_at(
        lambda m: [getattr(m, n) for n in NAMES],
        TRUTH,
        [getattr(TRUTH, n) * f for n, f in zip(NAMES, factors)],
    )
    rng = np.random.default_rng(seed)
    tests = []
    for length, peak, rest in designs:
        time, force = _history(peak, rest)
        cable = jc.Cable(length=length, breaking_strain=math.inf)
        elongation = np.asarray(
            jc.simulate_force_history(truth, cable, time, force).elongation
        )
        metadata = {
            "length_mm": 1e3 * length,
            "id": f"{seed}-{1e3 * length:.0f}mm",
            "control": "force",
            "breaking_strain": breaking_strain,
        }
        noisy = elongation + 1e-5 * rng.standard_normal(time.shape)
        tests.append(jc.TestData(time, force, noisy, metadata=metadata))
    return tests


SPECIMENS = [
    _specimen((1.0, 1.0, 1.0, 1.0), 0),
    _specimen((1.3, 0.8, 1.1, 1.0), 1),
    _specimen((0.8, 1.2, 0.9, 1.3), 2),
]
METHOD = jc.LeastSquares(multistart=2)


def _problems(specimens, **fields):
    """One problem per specimen: START and its tests, NAMES fitted."""
    return [jc.Problem(START, tests, **{"fit": NAMES, **fields}) for tests in specimens]


@pytest.fixture(scope="module")
def each():
    return jc.fit_each(_problems(SPECIMENS), METHOD)


def test_each_specimen_equals_its_own_fit(each):
    assert len(each) == len(SPECIMENS)
    for problem, result in zip(_problems(SPECIMENS), each):
        alone = jc.fit(problem, METHOD)
        assert result.result == jc.RESULTS.successful
        assert result.names == alone.names
        np.testing.assert_allclose(result.values, alone.values, rtol=1e-6)
        np.testing.assert_allclose(result.stderr, alone.stderr, rtol=1e-6)
        np.testing.assert_allclose(result.loss, alone.loss, rtol=1e-6)
        assert result.num_steps == alone.num_steps
        assert result.test_ids == alone.test_ids
        np.testing.assert_array_equal(result.num_samples, alone.num_samples)
    # Each specimen has its own parameters (the specimens' truths differ by 30 %).
    assert abs(each[1].values[0] / each[0].values[0] - 1.3) < 0.05


def test_solves_waiting_for_a_lane_are_their_own(each):
    # 14 copies of each specimen, 2 starts each: more solves (84) than the lanes
    # that run them, so most solves wait, and each starts when a lane frees. Every
    # copy ends where its specimen's own fit ends, whichever lane ran it and when.
    results = jc.fit_each(_problems(SPECIMENS * 14), METHOD)
    for k, result in enumerate(results):
        alone = each[k % len(SPECIMENS)]
        assert result.result == jc.RESULTS.successful
        np.testing.assert_allclose(result.values, alone.values, rtol=1e-6)
        assert result.num_steps == alone.num_steps


def test_a_failing_specimen_returns_the_others(each):
    # Specimen 1's cables break under the start's creep: `jaxcable.fit` refuses
    # that start; here the specimen fails alone, with the simulation's result.
    broken = _specimen((1.3, 0.8, 1.1, 1.0), 1, breaking_strain=1e-4)
    with pytest.raises(ValueError, match="start parameters fail"):
        jc.fit(jc.Problem(START, broken, fit=NAMES), METHOD)
    results = jc.fit_each(_problems([SPECIMENS[0], broken, SPECIMENS[2]]), METHOD)
    assert results[1].result == jc.RESULTS.strain_beyond_break
    assert not results[1].converged and np.all(np.isnan(results[1].values))
    assert results[1].names == each[1].names
    for k in (0, 2):
        assert results[k].result == jc.RESULTS.successful
        np.testing.assert_allclose(results[k].values, each[k].values, rtol=1e-12)


def test_a_solve_that_does_not_converge_is_reported():
    method = jc.LeastSquares(multistart=1, max_steps=2)
    results = jc.fit_each(_problems(SPECIMENS[:1]), method)
    assert results[0].result == jc.RESULTS.nonlinear_max_steps_reached
    assert np.all(np.isfinite(results[0].values))


def test_specimens_of_other_shapes_and_per_test_parameters():
    # One specimen of one test beside one of two: two kernels, each specimen
    # still its own fit, E1 fitted per test.
    specimens = [SPECIMENS[0], SPECIMENS[1][:1]]
    problems = _problems(specimens, fit=NAMES[1:], per_test=["E1"])
    method = jc.LeastSquares(multistart=1)
    results = jc.fit_each(problems, method)
    for problem, result in zip(problems, results):
        alone = jc.fit(problem, method)
        assert result.names == alone.names
        np.testing.assert_allclose(result.values, alone.values, rtol=1e-6)
    assert results[0].names[:2] == ("E1[0]", "E1[1]")


_ONE = jc.Problem(START, SPECIMENS[0], fit=NAMES)


@pytest.mark.parametrize(
    "kwargs, error, match",
    [
        (dict(problems=_ONE), ValueError, "`problems`"),
        (dict(problems=[]), ValueError, "`problems` is empty"),
        (dict(problems=[_ONE, "a.csv"]), ValueError, r"`problems\[1\]`"),
        (
            dict(problems=[_ONE, jc.Problem(START, SPECIMENS[1])]),
            ValueError,
            r"`problems\[1\]\.fit`",
        ),
        (
            dict(problems=[_ONE, jc.Problem(TRUTH, SPECIMENS[1], fit=NAMES)]),
            ValueError,
            r"`problems\[1\]\.model`",
        ),
        (dict(fit=("E1", "nope")), ValueError, "`fit`"),
        (dict(drive=["force"]), ValueError, "`drive`"),
        (dict(method="lm"), TypeError, "`method`"),
        (dict(method=jc.LeastSquares(key=7)), TypeError, "`key`"),
        (dict(progress_meter="bar"), ValueError, "`progress_meter`"),
    ],
)
def test_bad_arguments_are_named(kwargs, error, match):
    kwargs = dict(kwargs)
    fields = {k: kwargs.pop(k) for k in ("fit", "drive") if k in kwargs}
    arguments = dict(problems=_problems(SPECIMENS[:2], **fields), method=METHOD)
    arguments.update(kwargs)
    with pytest.raises(error, match=match):
        jc.fit_each(**arguments)


def test_a_malformed_specimen_is_named():
    short = [
        jc.TestData(
            np.array([0.0, 1.0]),
            np.zeros(2),
            np.zeros(2),
            metadata={"length_mm": 300.0},
        )
    ]
    with pytest.raises(ValueError, match=r"`problems\[1\]`.*fitted samples"):
        jc.fit_each(_problems([SPECIMENS[0], short]))


def test_cli_fit_each(tmp_path):
    files = []
    for k, specimen in enumerate(SPECIMENS):
        path = tmp_path / f"specimen{k}.csv"
        jc.write_csv(path, specimen[0])
        files.append(path)
    out = tmp_path / "out"
    options = ["--model", "burgers", "--fit", ",".join(NAMES), "--starts", "1"]
    status, stdout, stderr = _run(["fit", "--each", *files, *options, "--out", out])
    assert status == 0, stderr
    with open(out / "summary.csv", encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    assert [r["file"] for r in rows] == [p.name for p in files]
    assert all(r["result"] == "successful" for r in rows)
    for k, (row, path) in enumerate(zip(rows, files)):
        params = jc.FitResult.from_json(out / f"{path.stem}.PARAMS.json")
        assert params.converged and params.names == NAMES
        np.testing.assert_allclose(params.values, [float(row[n]) for n in NAMES])
        assert row["file"] in stdout
    # Specimen 1 is 30 % stiffer than specimen 0.
    assert float(rows[1]["E1"]) > 1.2 * float(rows[0]["E1"])
    # One folder per run, no report, distinct file names.
    argv = ["fit", "--each", *files, *options, "--out", out]
    assert _run([*argv, "--report", tmp_path / "r"])[0] == 2
    (tmp_path / "again").mkdir()
    twin = tmp_path / "again" / files[0].name
    jc.write_csv(twin, SPECIMENS[1][0])
    status, _, stderr = _run(["fit", "--each", *files, twin, *options, "--out", out])
    assert status == 2 and "distinct" in stderr
