"""Discovery: DiscoveredTerm (the base at theta = 0, jit/vmap/grad, the covariate
plumbed through the fit) and `discover` on a hidden mechano-sorptive term and on
noise alone."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxcable as jc

from .helpers import finite_difference_grad, humidity_history


AREA = float(jc.Cable(length=0.3).area)
BASE = jc.BurgersModel(E1=2e9, eta0=2e13, E2=6e9, eta2=6e10)
TERM = "sigma_c_abs_rate"
# Mechano-sorptive creep: 1/(Pa %RH); 100 N, 20 %RH/cycle -> ~3e-3 strain a cycle.
THETA = 2e-13
BASE_FIT = ("E1", "E2")


def _history(seed: int, samples: int = 150):
    return humidity_history(seed, samples)


def _tests(model, seeds=(0, 1, 2), noise=2e-6, covariate=True, samples=150):
    """Force-driven tests of `model` with noisy elongations (m) and a humidity
    column, simulated through the fit's own scan (`jc.residuals` of zero data)."""
    raw = []
    for s in seeds:
        time, force, humidity = _history(s, samples)
        raw.append(
            jc.TestData(
                time=time,
                force=force,
                elongation=np.zeros_like(time),
                extra={"humidity": humidity},
                metadata={"length_mm": 300.0, "control": "force", "id": f"t{s}"},
            )
        )
    padded = jc.pad_tests(raw, drive="force", covariate="humidity")
    params, static = eqx.partition(model, eqx.is_inexact_array)
    clean = np.asarray(jc.residuals(params, static, padded))
    rng = np.random.default_rng(99)
    out = []
    for t, e in zip(raw, clean):
        e = e[: len(t.time)] + noise * rng.normal(size=len(t.time))
        extra = t.extra if covariate else {}
        out.append(jc.TestData(t.time, t.force, e, extra=extra, metadata=t.metadata))
    return out


def test_null_thetas_reproduce_the_base_and_transform_cleanly():
    time, force, humidity = _history(0)
    cable = jc.Cable(length=0.3)
    model = jc.DiscoveredTerm(
        BASE, terms=("sigma", "sigma_rate", "cycles", "time_loaded")
    )
    a = jc.simulate_force_history(BASE, cable, time, force).elongation
    b = jc.simulate_force_history(model, cable, time, force).elongation
    np.testing.assert_array_equal(np.asarray(a), np.asarray(b))

    tests = _tests(jc.DiscoveredTerm(BASE, theta0=THETA, terms=(TERM,)), seeds=(0,))
    padded = jc.pad_tests(tests, drive="force", covariate="humidity")
    true = jc.DiscoveredTerm(BASE, theta0=THETA, terms=(TERM, "sigma"))

    def loss(m):
        p, s = eqx.partition(m, eqx.is_inexact_array)
        return jnp.sum(jc.residuals(p, s, padded) ** 2)

    grad = eqx.filter_jit(eqx.filter_grad(loss))(true)
    fd = finite_difference_grad(loss, true)
    for name in ("theta0", "theta1"):
        g, f = float(getattr(grad, name)), float(getattr(fd, name))
        assert abs(g - f) <= 1e-4 * abs(f) + 1e-30, (name, g, f)
    # vmap over theta: two models in one call, each as simulated alone.
    thetas = jnp.array([0.0, THETA])
    vm = jax.jit(jax.vmap(lambda th: loss(eqx.tree_at(lambda m: m.theta0, true, th))))(
        thetas
    )
    assert np.allclose(vm[1], loss(true), rtol=1e-10) and vm[0] != vm[1]


def test_missing_covariate_column_names_the_test():
    tests = _tests(BASE, seeds=(0,), covariate=False)
    with pytest.raises(ValueError, match="t0.*humidity"):
        jc.pad_tests(tests, covariate="humidity")


@pytest.mark.parametrize(
    "fields, match",
    [
        ({"terms": ["no_such_term"]}, "terms"),
        ({"heldout": jc.HeldOut(split="tests")}, "heldout"),
        ({"min_gain_pct": "5"}, "min_gain_pct"),
        ({"joint_fit": 1}, "joint_fit"),
        ({"least_squares": None}, "least_squares"),
    ],
)
def test_the_discovery_method_names_its_bad_field(fields, match):
    with pytest.raises(ValueError, match=match):
        jc.Discovery(**fields)


def test_discover_takes_a_problem_and_a_discovery():
    tests = _tests(BASE, seeds=(0,))
    with pytest.raises(TypeError, match="problem"):
        jc.discover(None, tests)
    with pytest.raises(TypeError, match="method"):
        jc.discover(None, jc.Problem(BASE, tests), jc.LeastSquares())


@pytest.fixture(scope="module")
def hidden():
    true = jc.DiscoveredTerm(BASE, theta0=THETA, terms=(TERM,))
    tests = _tests(true)
    problem = jc.Problem(BASE, _train(tests), fit=BASE_FIT, drive="force")
    base_fit = jc.fit(problem, jc.LeastSquares(multistart=1))
    return true, tests, base_fit


def _train(tests, holdout=0.3):
    from jaxcable.internal import time_split

    return time_split(tests, holdout)[0]


def test_discover_finds_a_hidden_mechano_sorptive_term(hidden):
    true, tests, base_fit = hidden
    found = jc.discover(base_fit, jc.Problem(BASE, tests, covariate="humidity"))
    assert found.terms[0] == TERM, found.path
    k = found.terms.index(TERM)
    assert abs(found.values[k] - THETA) <= 3 * found.stderr[k], found.equation
    assert "humidity" in found.equation and "1/(Pa [humidity])" in found.equation
    # The data-generating model's held-out gain over the fitted base.
    base_rmse, rmse = found.heldout_rmse_mm
    held = [np.arange(len(t.time)) >= round(0.7 * len(t.time)) for t in tests]
    true_rmse = _rmse(true, tests, held)
    true_gain = 1 - true_rmse / base_rmse
    assert found.gain_pct / 100 >= 0.5 * true_gain, (found.gain_pct, true_gain)


def _rmse(model, tests, held):
    problem = jc.Problem(model, tests, drive="force", covariate="humidity")
    response = jc.model_responses(model, problem)
    sq = sum(
        float(np.sum((r - t.elongation)[h] ** 2))
        for r, t, h in zip(response, tests, held)
    )
    return 1e3 * np.sqrt(sq / sum(int(h.sum()) for h in held))


def test_discover_finds_nothing_in_noise():
    tests = _tests(BASE)
    problem = jc.Problem(BASE, _train(tests), fit=BASE_FIT, drive="force")
    base_fit = jc.fit(problem, jc.LeastSquares(multistart=1))
    found = jc.discover(base_fit, jc.Problem(BASE, tests, covariate="humidity"))
    assert found.terms == () or abs(found.gain_pct) < 5, found.path
    assert found.fit is None or found.gain_pct < 5


def test_diagnosis_discovers_the_term_the_catalogue_lacks(hidden):
    """No catalogued candidate (here: none tried) explains the residual, so the
    diagnosis looks for a term over every recorded covariate and names it."""
    true = hidden[0]
    # Dense enough (600 samples) for the noise estimate of second differences.
    tests = _tests(true, samples=600)
    problem = jc.Problem(BASE, tests, fit=BASE_FIT, drive="force")
    d = jc.diagnose(problem, jc.CandidateSearch(candidates=[]))
    assert d.named_cause == "discovered", d.summary()
    assert d.verdict == "named"
    assert d.discovered["covariate"] == "humidity"
    assert TERM in d.discovered["terms"]
    assert "discovered term (covariate humidity)" in d.summary()
    document = d.to_dict()
    assert document["discovered"]["equation"].startswith("d(eps)/dt = ")
    assert [c["id"] for c in document["candidates"]] == ["discovered"]


def test_discover_finds_cyclic_softening_without_a_covariate():
    """A compliance that grows with the load cycles (strain theta sigma N_cyc, the
    braid's abrasion) hidden in a cycling Burgers cable, no covariate recorded: the
    library's d(sigma N_cyc)/dt is found with its coefficient."""
    theta = 1e-11  # 1/Pa: ~1e-3 strain after the six cycles at 100 N
    true = jc.DiscoveredTerm(BASE, terms=("sigma_cycles_rate",), theta0=theta)
    tests = _tests(true, covariate=False)
    problem = jc.Problem(BASE, _train(tests), fit=BASE_FIT, drive="force")
    base_fit = jc.fit(problem, jc.LeastSquares(multistart=1))
    found = jc.discover(base_fit, jc.Problem(BASE, tests))
    assert "sigma_cycles_rate" in found.terms, found.path
    k = found.terms.index("sigma_cycles_rate")
    assert abs(found.values[k] - theta) <= 3 * found.stderr[k], found.equation
    assert "1/Pa * d(sigma N_cyc)/dt" in found.equation
    assert found.gain_pct > 50, found.heldout_rmse_mm


def test_diagnosis_names_the_covariate_form_and_its_column(hidden):
    """With the covariates' extensions among the candidates, the hidden
    mechano-sorptive creep is named as that form of the recorded column, with its
    coefficient; without a covariate column they are not tried."""
    true = hidden[0]
    tests = _tests(true, samples=600)
    d = jc.diagnose(
        jc.Problem(BASE, tests, fit=BASE_FIT, drive="force"),
        jc.CandidateSearch(candidates=list(jc.COVARIATE_EXTENSIONS), discover=False),
    )
    assert d.named_cause == "mechano_sorptive[humidity]", d.summary()
    named = next(c for c in d.candidates if c.id == d.named_cause)
    assert abs(named.size - THETA) <= 3 * named.size_stderr, d.summary()
    assert named.size_unit == "1/(Pa [humidity])"
    assert {c.id for c in d.candidates} == {
        f"{i}[humidity]" for i in jc.COVARIATE_EXTENSIONS
    }
    bare = [
        jc.TestData(t.time, t.force, t.elongation, metadata=t.metadata) for t in tests
    ]
    d = jc.diagnose(
        jc.Problem(BASE, bare, fit=BASE_FIT, drive="force"),
        jc.CandidateSearch(candidates=["mechano_sorptive"], discover=False),
    )
    assert len(d.candidates) == 0 and "mechano" not in d.named_cause


def test_discover_finds_a_damage_that_runs_away():
    """A compliance that grows with the load cycles as a power of the stress and runs
    away, theta sigma I / (1 - a I) with dI/dN = (sigma / 10 MPa)^4, hidden in a
    cycling Burgers cable (no covariate): the discovery finds that damage with an
    acceleration well above 0 (the run-away, not a damage linear in I), and it
    predicts the held-out samples."""
    from jaxcable.internal import damage_integral, step_inputs

    def largest(tests):
        return max(
            float(damage_integral(step_inputs(t, None), "compliance_cycles", 4.0)[-1])
            for t in tests
        )

    # D = a I reaches 0.7 at the end of the 160 N test: 1 / (1 - D) = 3.3.
    accel = 0.7 / largest(_tests(BASE, covariate=False))
    true = jc.DiscoveredTerm(
        BASE, terms=("compliance_cycles",), theta0=5e-14, rate0=4.0, accel0=accel
    )
    tests = _tests(true, covariate=False)
    problem = jc.Problem(BASE, _train(tests), fit=BASE_FIT, drive="force")
    base_fit = jc.fit(problem, jc.LeastSquares(multistart=1))
    found = jc.discover(base_fit, jc.Problem(BASE, tests))
    assert "compliance_cycles" in found.terms, found.path
    k = found.terms.index("compliance_cycles")
    assert found.accels[k] * largest(tests) >= 0.3, found.equation
    assert "sigma I/(1 - a I), dI/dN = (sigma/10 MPa)^b" in found.equation
    assert found.gain_pct > 50, found.heldout_rmse_mm
