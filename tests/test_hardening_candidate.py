"""A thin braid near 40 % of its break at its true diameter: fitted and diagnosed
(stress measured against the rope's own stiffness), and Park's hardening (Eq. 1-2)
named when it is hidden in the data."""

import math
import warnings

import numpy as np
import pytest

import jaxcable as jc


# A 0.23 mm braid, 500 mm long, breaking at 200 N, cycled 5-80 N (40 % of its
# break): 1.9 GPa of nominal stress at the peak.
_DIAMETER_MM, _LENGTH_MM, _BREAK_N = 0.23, 500.0, 200.0
_NOISE_M = 1e-5
# The braid's moduli per nominal area: 100 x the 3 mm rope's (a peak strain ~3 %).
_STIFFER = 100.0
_META = {
    "length_mm": _LENGTH_MM,
    "diameter_mm": _DIAMETER_MM,
    "breaking_load_N": _BREAK_N,
    "breaking_strain": 0.1,
    "control": "force",
}


def _braid_model(beta: float) -> jc.IntegratedModel:
    """Park's default model with every modulus and viscosity 100 x (its activation
    strain kept) and hardening `beta`."""
    d = jc.IntegratedModel()
    scaled = {
        name: float(getattr(d, name)) * _STIFFER
        for name in ("E1c", "E1r", "E2c", "eta0", "E2r", "E3r")
    }
    return jc.IntegratedModel(**scaled, beta=beta)


def _braid_test(model, seed: int) -> jc.TestData:
    """8 force-controlled cycles 5-80 N of 40 s, sampled every second, noisy."""
    t = np.arange(0.0, 8 * 40.0 + 0.5, 1.0)
    phase = (t % 40.0) / 40.0
    f = 5.0 + 75.0 * np.where(phase < 0.5, 2 * phase, 2 - 2 * phase)
    cable = jc.Cable.from_mm(
        length_mm=_LENGTH_MM,
        diameter_mm=_DIAMETER_MM,
        breaking_load_N=_BREAK_N,
        breaking_strain=0.1,
    )
    e = np.asarray(jc.simulate_force_history(model, cable, t, f).elongation)
    e = e + np.random.default_rng(seed).normal(0.0, _NOISE_M, e.shape)
    return jc.TestData(time=t, force=f, elongation=e, metadata=dict(_META))


@pytest.fixture(scope="module")
def plain():
    return [_braid_test(_braid_model(0.0), seed=1)]


@pytest.fixture(scope="module")
def hardened():
    return [_braid_test(_braid_model(100.0), seed=1)]


def test_the_hardening_check_is_a_strain():
    # Eq. 1 hardens below F = E1c A: at the defaults a 0.23 mm braid breaking at
    # 200 N is past it (E1c A = 108 N), which a breaking strain <= 1 makes harmless;
    # with neither limit (inf) only hardening fails, never the plain model.
    thin = jc.Cable.from_mm(length_mm=500.0, diameter_mm=0.23, breaking_load_N=200.0)
    unbounded = jc.Cable.from_mm(
        length_mm=500.0,
        diameter_mm=0.23,
        breaking_load_N=200.0,
        breaking_strain=math.inf,
    )
    ok, out = jc.RESULTS.successful, jc.RESULTS.parameter_out_of_domain
    assert jc.IntegratedModel().check(thin) == ok
    assert jc.IntegratedModel(beta=1.0).check(thin) == ok
    assert jc.IntegratedModel().check(unbounded) == ok
    assert jc.IntegratedModel(beta=1.0).check(unbounded) == out
    # The flow's activation stress follows the rope's stiffness.
    braid = _braid_model(0.0)
    assert float(braid.sigma_a) == pytest.approx(_STIFFER * 4e7, rel=1e-12)


def test_fit_runs_at_the_true_diameter(plain):
    # The default start flows past break on this braid (1.9 GPa against a 40 MPa
    # activation stress): it is moved, and the fit reaches the noise.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", jc.IdentifiabilityWarning)
        with pytest.warns(jc.StartMovedWarning):
            r = jc.fit(jc.Problem(jc.IntegratedModel(), plain))
    assert r.converged and r.start_note
    assert r.rmse_mm[0] < 1.5 * _NOISE_M * 1e3


def test_diagnose_names_a_hidden_hardening(hardened):
    problem = jc.Problem(jc.IntegratedModel(), hardened).with_scaled_start()
    d = jc.diagnose(problem, jc.CandidateSearch(max_rounds=1, discover=False))
    assert d.named_cause == "hardening"
    assert d.final_heldout_rmse_mm < 1.5 * d.noise_mm
    fit = d.candidate("hardening").fit
    beta = dict(zip(fit.names, fit.values))["beta"]
    assert 80.0 < beta < 120.0


def test_diagnose_does_not_name_hardening_without_it(plain):
    problem = jc.Problem(jc.IntegratedModel(), plain).with_scaled_start()
    d = jc.diagnose(problem, jc.CandidateSearch(max_rounds=1, discover=False))
    assert d.named_cause != "hardening"
    assert not d.candidate("hardening").significant
