"""Posterior sampling: R-hat and ESS against chains of known mixing, a small NUTS run
that recovers the truth and converges, its conversions (summary, PARAMS.json entry,
CorrelatedParameters for the Monte-Carlo) and argument errors."""

import dataclasses
import json

import jax
import numpy as np
import pytest

import jaxcable as jc
from jaxcable.internal import bulk_ess, split_rhat


TRUTH = jc.BurgersModel(E1=2.0e9, eta0=3.0e11, E2=4.0e8, eta2=2.0e10)
START = jc.BurgersModel(E1=1.5e9, eta0=1.0e11, E2=6.0e8, eta2=1.0e10)
CABLE = jc.Cable.from_mm(length_mm=200.0, diameter_mm=3.0)
NOISE_M = 2e-6


def _creep(force, seed):
    time = np.concatenate([np.linspace(0.0, 10.0, 8), 10 + np.geomspace(1, 900, 24)])
    f = np.minimum(time / 10.0, 1.0) * force
    e = np.asarray(jc.simulate_force_history(TRUTH, CABLE, time, f).elongation)
    e = e + NOISE_M * np.random.default_rng(seed).standard_normal(e.shape)
    return jc.TestData(
        time=time,
        force=f,
        elongation=e,
        metadata={"length_mm": 200.0, "diameter_mm": 3.0, "id": f"creep-{force:g}"},
    )


@pytest.fixture(scope="module")
def posterior():
    tests = [_creep(20.0, 0), _creep(40.0, 1)]
    method = jc.NUTS(
        num_samples=120, num_chains=2, num_warmup=100, key=jax.random.key(1)
    )
    return jc.sample_posterior(jc.Problem(START, tests), method)


def test_rhat_and_ess_know_mixing():
    rng = np.random.default_rng(0)
    iid = rng.standard_normal((4, 1000))
    assert abs(split_rhat(iid) - 1.0) < 0.01
    assert 3000 < bulk_ess(iid) < 5000
    # AR(1) with phi 0.9: ESS per draw (1 - phi) / (1 + phi) = 0.053.
    ar = np.zeros((4, 4000))
    for t in range(1, ar.shape[1]):
        ar[:, t] = 0.9 * ar[:, t - 1] + rng.standard_normal(4)
    assert 0.03 < bulk_ess(ar) / ar.size < 0.08
    # Chains stuck in different places.
    shifted = iid + np.arange(4)[:, None]
    assert split_rhat(shifted) > 1.5


def test_posterior_converges_and_covers(posterior):
    assert posterior.samples.shape == (2, 120, 4)
    assert posterior.names == ("E1", "eta0", "E2", "eta2")
    assert np.all(posterior.rhat < 1.05), posterior.summary()
    assert np.all(posterior.ess > 50), posterior.summary()
    assert posterior.divergences == 0
    truth = np.array([float(getattr(TRUTH, n)) for n in posterior.names])
    low, high = posterior.interval(0.999)
    assert np.all((low < truth) & (truth < high)), posterior.summary()
    # The posterior and the linearised standard errors agree on a well-posed fit.
    ratio = posterior.sd / posterior.fit.stderr
    assert np.all((0.5 < ratio) & (ratio < 2.0)), ratio


def test_conversions(posterior):
    rows = posterior.rows()
    assert [r["name"] for r in rows] == list(posterior.names)
    assert set(rows[0]) == {
        "name", "unit", "mean", "sd", "q2.5", "q50", "q97.5", "rhat", "ess"
    }  # fmt: skip
    assert rows[0]["q2.5"] < rows[0]["q50"] < rows[0]["q97.5"]
    doc = posterior.to_dict()
    assert doc["chains"] == 2 and doc["draws_per_chain"] == 120
    assert "R-hat" in posterior.summary()
    sampler = posterior.correlated_parameters()
    models = jax.vmap(sampler.draw)(jax.random.split(jax.random.key(0), 2000))
    e1 = np.asarray(models.E1)
    assert abs(np.median(e1) / np.median(posterior.flat[:, 0]) - 1) < 0.01
    assert abs(np.std(e1) / posterior.sd[0] - 1) < 0.15


def test_arviz_conversion_or_clear_error(posterior):
    try:
        import arviz_base  # noqa: F401
    except ImportError:
        try:
            import arviz  # noqa: F401
        except ImportError:
            with pytest.raises(ImportError, match="pip install arviz"):
                posterior.to_arviz()
            return
    data = posterior.to_arviz()
    assert "posterior" in str(type(data)).lower() or "posterior" in data.groups


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(noise="gaussian"), "noise"),
        (dict(num_samples=2), "num_samples"),
        (dict(num_chains=0), "num_chains"),
        (dict(prior_scale=-1.0), "prior_scale"),
        (dict(prior_scale=float("nan")), "prior_scale"),
    ],
)
def test_nuts_errors_name_the_field(kwargs, match):
    with pytest.raises(ValueError, match=match):
        jc.NUTS(**kwargs)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(num_warmup=1.5), "num_warmup"),
        (dict(max_doublings=True), "max_doublings"),
        (dict(prior_scale="1"), "prior_scale"),
    ],
)
def test_nuts_type_errors_name_the_field(kwargs, match):
    with pytest.raises(TypeError, match=match):
        jc.NUTS(**kwargs)


def test_errors_name_the_argument():
    problem = jc.Problem(START, [_creep(20.0, 0)])
    with pytest.raises(ValueError, match="start"):
        jc.sample_posterior(problem, start="fit")
    with pytest.raises(ValueError, match="per_test"):
        jc.sample_posterior(jc.Problem(START, problem.tests, per_test=["E1"]))
    with pytest.raises(TypeError, match="method"):
        jc.sample_posterior(problem, jc.LeastSquares())
    with pytest.raises(TypeError, match="problem"):
        jc.sample_posterior(START, jc.NUTS())


def test_fit_command_posterior(tmp_path, posterior):
    from jaxcable.cli import main

    paths = []
    for force, seed in ((20.0, 0), (40.0, 1)):
        path = tmp_path / f"creep-{force:g}.csv"
        jc.write_csv(path, _creep(force, seed))
        paths.append(str(path))
    out, report = tmp_path / "PARAMS.json", tmp_path / "report"
    args = [
        "fit", *paths, "--model", "burgers", "--out", str(out), "--report",
        str(report), "--posterior", "20", "--chains", "2", "--starts", "1", "--quiet",
    ]  # fmt: skip
    assert main(args) == 0
    doc = json.loads(out.read_text())
    rows = doc["posterior"]
    assert [r["name"] for r in rows] == list(posterior.names)
    assert all(r["q2.5"] <= r["q50"] <= r["q97.5"] for r in rows)
    assert (report / "posterior.png").stat().st_size > 0
    assert "## Posterior" in (report / "summary.md").read_text()
    # The file still reads as a fit.
    assert jc.FitResult.from_json(out).names == posterior.names


def test_summary_says_when_the_chains_did_not_mix(posterior):
    assert ("NOT CONVERGED" in posterior.summary()) == (not posterior.converged)
    rhat = np.ones_like(posterior.rhat)
    rhat[1] = 1.3
    stuck = dataclasses.replace(posterior, rhat=rhat, divergences=7)
    assert not stuck.converged
    text = stuck.summary()
    assert "NOT CONVERGED: R-hat > 1.01 for eta0; 7 divergent draws" in text
    assert stuck.to_dict()["converged"] is False
