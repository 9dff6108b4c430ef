"""`jaxcable.Problem` and `jaxcable.LeastSquares`: the values every fit takes. Each
refuses a bad field by its name when it is made; `fit`, `fit_each`, `make_loss` and
`model_responses` of one problem agree; `Problem.with_scaled_start`."""

import math

import equinox as eqx
import numpy as np
import pytest

import jaxcable as jc


NOISE = 1e-5  # m


def _test(length, peak, seed, model=jc.HookeModel(E=2.5e9)):
    """A short load-hold-unload test of `model` plus elongation noise."""
    time = np.linspace(0.0, 120.0, 41)
    force = np.interp(time, [0.0, 30.0, 90.0, 120.0], [0.0, peak, peak, 0.0])
    cable = jc.Cable(length=length, breaking_strain=math.inf)
    elongation = np.asarray(
        jc.simulate_force_history(model, cable, time, force).elongation
    )
    noisy = elongation + NOISE * np.random.default_rng(seed).standard_normal(41)
    metadata = {
        "length_mm": 1e3 * length,
        "id": f"{1e3 * length:.0f}mm",
        "control": "force",
        "breaking_strain": math.inf,
    }
    return jc.TestData(time, force, noisy, metadata=metadata)


TESTS = [_test(0.3, 100.0, 0), _test(0.1, 150.0, 1)]
START = jc.HookeModel(E=1e9)


@pytest.mark.parametrize(
    "fields, error, match",
    [
        (dict(model=jc.HookeModel), TypeError, "`model`"),
        (dict(model=jc.Cable(length=0.3)), TypeError, "`model`"),
        (dict(tests=None), ValueError, "`tests`"),
        (dict(tests="data.csv"), ValueError, "`tests`"),
        (dict(tests=[]), ValueError, "`tests` is empty"),
        (dict(tests=[TESTS[0], "b.csv"]), TypeError, r"`tests\[1\]`"),
        (dict(fit="E"), TypeError, "`fit`"),
        (dict(per_test=[1]), TypeError, "`per_test`"),
        (dict(transforms={"E": "sqrt"}), ValueError, "`transforms`"),
        (dict(covariate=3), TypeError, "`covariate`"),
    ],
)
def test_a_bad_problem_names_its_field(fields, error, match):
    arguments = {"model": START, "tests": TESTS, **fields}
    with pytest.raises(error, match=match):
        jc.Problem(**arguments)


@pytest.mark.parametrize(
    "fields, error, match",
    [
        (dict(multistart=0), ValueError, "`multistart`"),
        (dict(multistart=1.5), TypeError, "`multistart`"),
        (dict(multistart=True), TypeError, "`multistart`"),
        (dict(max_steps=0), ValueError, "`max_steps`"),
        (dict(spread=-1.0), ValueError, "`spread`"),
        (dict(spread=math.nan), ValueError, "`spread`"),
        (dict(spread="wide"), TypeError, "`spread`"),
        (dict(solver="lm"), TypeError, "`solver`"),
    ],
)
def test_a_bad_method_names_its_field(fields, error, match):
    with pytest.raises(error, match=match):
        jc.LeastSquares(**fields)


def test_the_functions_name_an_argument_of_another_type():
    problem = jc.Problem(START, TESTS)
    with pytest.raises(TypeError, match="`problem`"):
        jc.fit(START)
    with pytest.raises(TypeError, match="`method`"):
        jc.fit(problem, "lm")
    with pytest.raises(TypeError, match="`problem`"):
        jc.make_loss(TESTS)
    with pytest.raises(TypeError, match="`problem`"):
        jc.model_responses(START, TESTS)
    with pytest.raises(TypeError, match="`method`"):
        jc.fit_each([problem], jc.LeastSquares)


@pytest.fixture(scope="module")
def fitted():
    problem = jc.Problem(START, TESTS, per_test=["E"])
    method = jc.LeastSquares(multistart=2)
    return problem, method, jc.fit(problem, method)


def test_fit_equals_fit_each_of_one_problem(fitted):
    problem, method, result = fitted
    (each,) = jc.fit_each([problem], method)
    assert result.converged and each.converged
    assert each.names == result.names == ("E[0]", "E[1]")
    np.testing.assert_allclose(each.values, result.values, rtol=1e-6)
    np.testing.assert_allclose(each.stderr, result.stderr, rtol=1e-6)
    assert each.num_steps == result.num_steps
    np.testing.assert_allclose(result.values, 2.5e9, rtol=1e-2)


def test_loss_and_responses_of_the_problem(fitted):
    problem, _, result = fitted
    loss, params, to_model = jc.make_loss(problem)
    np.testing.assert_allclose(params["E"], np.log([1e9, 1e9]))
    at_fit = {"E": np.log(np.asarray(result.values))}
    np.testing.assert_allclose(float(loss(at_fit)), result.loss, rtol=1e-8)
    assert to_model(at_fit).E.shape == (2,)
    responses = jc.model_responses(result, problem)
    for test, elongation, rmse_mm in zip(TESTS, responses, result.rmse_mm):
        rmse = np.sqrt(np.mean((elongation - test.elongation) ** 2))
        np.testing.assert_allclose(1e3 * rmse, rmse_mm, rtol=1e-8)


def test_with_scaled_start():
    problem = jc.Problem(jc.BurgersModel(), TESTS, fit=["E1"], drive="force")
    scaled = problem.with_scaled_start()
    expected = jc.scaled_start(jc.BurgersModel(), TESTS, drive="force")
    assert eqx.tree_equal(scaled.model, expected)
    # Everything else is the problem's, and the problem itself is unchanged.
    assert (scaled.fit, scaled.drive, scaled.tests) == (
        problem.fit,
        problem.drive,
        problem.tests,
    )
    assert eqx.tree_equal(problem.model, jc.BurgersModel())
    assert float(scaled.model.E1) != float(problem.model.E1)
