"""One compiled fit kernel for every candidate of a diagnosis (issue 14): a fit of a
subset of a model's parameters (`jaxcable.internal.fit_subset`) equals `jaxcable.fit` of
the same parameters, the extension stack reproduces each candidate alone, and a
diagnosis traces the fit kernel at most once."""

import numpy as np
import pytest

import jaxcable as jc
from jaxcable.internal import (
    fit_solver as _solver,
    fit_subset,
    shared_layout,
    stack_of,
    synthetic as _synthetic,
)


BURGERS = jc.BurgersModel(E1=2.0e9, eta0=2.0e12, E2=5.0e8, eta2=5.0e9)
ALL = ("E1", "eta0", "E2", "eta2")


@pytest.fixture(scope="module")
def tests():
    truth = jc.BurgersModel(E1=2.5e9, eta0=4.0e12, E2=4.0e8, eta2=8.0e9)
    rng = np.random.default_rng(0)
    out = []
    for length_mm, force in ((300.0, 120.0), (500.0, 80.0)):
        t = np.linspace(0.0, 400.0, 160)
        f = np.where(t < 20.0, force * t / 20.0, force)
        cable = jc.Cable(length=length_mm * 1e-3, diameter=3e-3)
        e = np.asarray(jc.simulate_force_history(truth, cable, t, f).elongation)
        e = e + 2e-6 * rng.standard_normal(e.shape)
        out.append(
            jc.TestData(
                time=t,
                force=f,
                elongation=e,
                metadata={"length_mm": length_mm, "diameter_mm": 3.0},
            )
        )
    return out


@pytest.mark.parametrize("free", [("E1", "E2"), ("eta0", "E2", "eta2")])
def test_a_subset_fit_equals_the_plain_fit(tests, free):
    layout = shared_layout(BURGERS, tests, ALL, drive="force")
    shared = fit_subset(BURGERS, tests, layout, free, size=4, drive="force")
    problem = jc.Problem(BURGERS, tests, fit=free, drive="force")
    plain = jc.fit(problem, jc.LeastSquares(multistart=1))
    assert shared.names == plain.names == free
    np.testing.assert_allclose(shared.values, plain.values, rtol=1e-6)
    np.testing.assert_allclose(shared.stderr, plain.stderr, rtol=1e-4)
    np.testing.assert_allclose(shared.loss, plain.loss, rtol=1e-8)
    # The parameters not freed keep their start values.
    for name in set(ALL) - set(free):
        assert float(getattr(shared.model, name)) == float(getattr(BURGERS, name))


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"free": ("E1", "nope")}, "free"),
        ({"free": ("E1", "E1")}, "free"),
        ({"free": ALL, "size": 3}, "size"),
    ],
)
def test_bad_subsets_name_the_argument(tests, kwargs, match):
    layout = shared_layout(BURGERS, tests, ALL, drive="force")
    args = {"free": ("E1",), "size": 4, **kwargs}
    with pytest.raises(ValueError, match=match):
        fit_subset(BURGERS, tests, layout, args["free"], size=args["size"])


def test_the_stack_reproduces_each_candidate_alone(tests):
    """At their null values the other layers change nothing: a candidate fitted in
    the stack simulates as the candidate alone, and both fits agree."""
    stack = stack_of(BURGERS, ("second_retardation", "sensor_drift"), ALL)
    layout = stack.layout(BURGERS, tests, "force")
    for active in (None, *stack.ids):
        result = stack.fit(
            stack.model(BURGERS, active),
            tests,
            layout,
            active,
            drive="force",
            throw=False,
        )
        alone = BURGERS if active is None else jc.EXTENSIONS[active].wrap(BURGERS)
        problem = jc.Problem(alone, tests, fit=result.names, drive="force")
        plain = jc.fit(problem, jc.LeastSquares(multistart=1), throw=False)
        assert type(result.model) is type(alone)
        assert result.converged == plain.converged
        np.testing.assert_allclose(result.loss, plain.loss, rtol=1e-6)
        if plain.converged:
            np.testing.assert_allclose(result.values, plain.values, rtol=1e-5)
        stacked = stack.model(BURGERS, active)
        for t in tests:
            a = jc.simulate_force_history(stacked, t.cable(), t.time, t.force)
            b = jc.simulate_force_history(alone, t.cable(), t.time, t.force)
            np.testing.assert_allclose(a.elongation, b.elongation, rtol=1e-12)


def test_a_diagnosis_traces_the_fit_kernel_at_most_once(monkeypatch):
    """The base and all seven candidates are one program (traced once per data
    shape; zero times when an earlier test of this process compiled it)."""
    traces = []
    original = _solver._data_derived_start

    def counting(*args):
        traces.append(1)
        return original(*args)

    monkeypatch.setattr(_solver, "_data_derived_start", counting)
    data = _synthetic.hidden_effect_dataset("termination_compliance", seed=5)
    d = jc.diagnose(jc.Problem(jc.IntegratedModel(), data).with_scaled_start())
    assert len([c for c in d.candidates if c.applicable]) >= 5
    assert len(traces) <= 1, f"the fit kernel was traced {len(traces)} times"


def test_switched_off_layers_have_the_base_gradient_under_an_elongation_drive():
    """E_k = inf (SecondRetardation off) once made every tangent of the elongation
    drive NaN (inf times the zero tangent of the cable's area in the Newton solve's
    implicit derivative); every layer off must give the base's gradient."""
    import equinox as eqx
    import jax
    import jax.numpy as jnp

    cable = jc.Cable(length=0.3, diameter=3e-3)
    t = np.linspace(0.0, 60.0, 40)
    e = np.minimum(t / 20.0, 1.0) * 1.5e-3
    stack = stack_of(BURGERS, tuple(jc.EXTENSIONS), ALL)
    assert "second_retardation" in stack.ids

    def force(model, e1):
        path = stack.base_prefix + "E1" if model is not BURGERS else "E1"
        where = lambda m: jc._fit.field_at(m, path)  # noqa: E731
        moved = eqx.tree_at(where, model, e1)
        return jc.simulate_elongation_history(moved, cable, t, e).force

    e1 = jnp.asarray(BURGERS.E1)
    want = jax.jacfwd(lambda x: force(BURGERS, x))(e1)
    got = jax.jacfwd(lambda x: force(stack.model(BURGERS, None), x))(e1)
    assert np.all(np.isfinite(got))
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-12 * np.max(np.abs(want)))


def test_a_model_without_the_layouts_parameters_is_rejected(tests):
    layout = shared_layout(BURGERS, tests, ALL, drive="force")
    with pytest.raises(ValueError, match="model"):
        fit_subset(jc.HookeModel(), tests, layout, ("E1",), size=4, drive="force")
