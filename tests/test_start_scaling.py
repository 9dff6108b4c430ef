"""Start values scaled to a data set (`jaxcable.scaled_start`): a start beyond break
is moved, never refused, by the API and by the command line."""

import warnings

import numpy as np
import pytest

import jaxcable as jc
from jaxcable.cli import main


_LENGTH_MM, _DIAMETER_MM = 300.0, 3.0
# A load-controlled test of a stiff joint: 20 times the default Burgers' moduli,
# loaded to 1.2-1.5 kN (its strain ~2 %), with a 7 % breaking strain in its file.
_STIFF = 20.0
_META = {
    "length_mm": _LENGTH_MM,
    "diameter_mm": _DIAMETER_MM,
    "breaking_strain": 0.07,
    "breaking_load_N": 20000.0,
    "control": "force",
}


def _scaled_burgers(c: float, retardation_s: float | None = None) -> jc.BurgersModel:
    """The default Burgers model with every modulus and viscosity times `c`
    (and, if given, its Kelvin-Voigt retardation time)."""
    d = jc.BurgersModel()
    eta2 = float(d.eta2) * c
    if retardation_s is not None:
        eta2 = float(d.E2) * c * retardation_s
    return jc.BurgersModel(
        E1=float(d.E1) * c, eta0=float(d.eta0) * c, E2=float(d.E2) * c, eta2=eta2
    )


def _creep(model, peak, *, seed, noise=2e-6, hold=1800.0, meta=_META, drive="force"):
    """A ramp of 30 s, a hold, an unloading and a rest, simulated and noisy."""
    t = np.concatenate(
        [
            np.linspace(0, 30, 31),
            np.linspace(30, 30 + hold, 61)[1:],
            np.linspace(30 + hold, 60 + hold, 31)[1:],
            np.linspace(60 + hold, 2 * hold, 40)[1:],
        ]
    )
    f = np.interp(t, [0, 30, 30 + hold, 60 + hold, 2 * hold], [0, peak, peak, 0, 0])
    cable = jc.Cable.from_mm(
        length_mm=_LENGTH_MM,
        diameter_mm=_DIAMETER_MM,
        breaking_strain=np.inf,
        breaking_load_N=20000.0,
    )
    e = np.asarray(jc.simulate_force_history(model, cable, t, f).elongation)
    e = e + np.random.default_rng(seed).normal(0.0, noise, e.shape)
    return jc.TestData(
        time=t, force=f, elongation=e, metadata={**meta, "control": drive}
    )


@pytest.fixture(scope="module")
def stiff_joint():
    truth = _scaled_burgers(_STIFF, retardation_s=300.0)
    return [_creep(truth, peak, seed=k) for k, peak in enumerate((1200.0, 1500.0))]


def test_a_start_beyond_break_is_moved_by_diagnose(stiff_joint):
    # The default Burgers start strains this joint beyond its 7 % (a start, not the
    # data: the data stay near 2 %).
    assert max(np.max(t.elongation) / (_LENGTH_MM * 1e-3) for t in stiff_joint) < 0.03
    assert "finitely within the cable's break" in jc.start_failure(
        jc.BurgersModel(), stiff_joint
    )
    with pytest.warns(jc.StartMovedWarning, match="scaled to the data"):
        d = jc.diagnose(
            jc.Problem(jc.BurgersModel(), stiff_joint),
            jc.CandidateSearch(
                candidates=["termination_compliance"], discover=False, max_rounds=1
            ),
        )
    assert d.verdict in ("none", "named", "unexplained")
    # The moved start fits: the base's held-out RMSE within 2 x the noise (2 um).
    assert d.base_heldout_rmse_mm < 2 * 2e-3


def test_a_start_beyond_break_is_moved_by_fit(stiff_joint):
    with pytest.warns(jc.StartMovedWarning):
        r = jc.fit(jc.Problem(jc.BurgersModel(), stiff_joint))
    assert r.converged
    assert "tests[0]" in r.start_note and "moduli x" in r.start_note
    assert "start moved" in r.summary()
    assert jc.FitResult.from_json(r.to_json()).start_note == r.start_note
    assert np.all(r.rmse_mm < 2 * 2e-3)
    # A start that works is the start as given: nothing moved.
    with warnings.catch_warnings():
        warnings.simplefilter("error", jc.StartMovedWarning)
        again = jc.fit(jc.Problem(r.model, stiff_joint))
    assert again.start_note == ""


def test_the_command_line_diagnoses_with_burgers(stiff_joint, tmp_path, capsys):
    files = []
    for k, test in enumerate(stiff_joint):
        files.append(str(tmp_path / f"joint{k}.csv"))
        jc.write_csv(files[-1], test)
    argv = ["diagnose", *files, "--model", "burgers", "--max-rounds", "1"]
    argv += ["--candidates", "termination_compliance", "--quiet"]
    assert main(argv) == 0
    assert "verdict:" in capsys.readouterr().out


@pytest.mark.parametrize("c", [10.0, 0.1])
def test_scaled_start_lands_near_the_true_stiffness(c):
    # Data of the default Burgers model 10 x stiffer or softer, force-driven and
    # elongation-driven: the scaled default is within 1.5 x of the truth's moduli.
    truth = _scaled_burgers(c)
    meta = {**_META, "breaking_strain": np.inf}
    for drive in ("force", "elongation"):
        test = _creep(truth, 100.0 * c, seed=3, noise=0.0, meta=meta, drive=drive)
        scaling = jc.start_scaling(jc.BurgersModel(), test)
        assert 1 / 1.5 < float(scaling.model.E1) / float(truth.E1) < 1.5
        assert 1 / 1.5 < float(scaling.model.E2) / float(truth.E2) < 1.5
        assert scaling.time == 1.0
    # Park's model, scaled to its own data made 10 x stiffer or softer.
    park = jc.IntegratedModel()
    truth = jc.scaled_start(park, _creep(_scaled_burgers(c), 100.0 * c, seed=4))
    stiff = float(truth.E1c) / float(park.E1c)
    assert 1 / 1.5 < stiff / c < 1.5
    # The activation strain is the rope's own: unchanged by the scaling.
    assert float(truth.strain_a) == float(park.strain_a)


def test_the_default_model_on_its_own_data_is_left_as_it_is():
    # At the defaults nothing moves: data of the default Park model give the
    # default back (c = 1 to 1e-6, no time scaling), so the default results stay.
    park = jc.IntegratedModel()
    test = _creep(park, 100.0, seed=5, noise=0.0, meta={**_META, "breaking_strain": 1})
    scaling = jc.start_scaling(park, test)
    assert abs(scaling.stiffness - 1.0) < 1e-6
    assert scaling.time == 1.0
    np.testing.assert_allclose(float(scaling.model.E1c), float(park.E1c), rtol=1e-6)


def test_times_far_beyond_the_holds_are_brought_to_them():
    # A retardation time of 1e6 s cannot show in a test of an hour: it becomes a
    # third of the longest hold, the ratios of the times kept.
    slow = _scaled_burgers(1.0, retardation_s=1e6)
    test = _creep(_scaled_burgers(1.0, retardation_s=100.0), 100.0, seed=6)
    scaling = jc.start_scaling(slow, test)
    hold = scaling.hold_s
    assert 1700.0 < hold < 1900.0
    (tau,) = jc.retardation_times(scaling.model)
    np.testing.assert_allclose(tau, hold / 3, rtol=1e-6)
    # The Maxwell dashpot's viscosity follows the same factor.
    np.testing.assert_allclose(
        float(scaling.model.eta0) / float(slow.eta0),
        scaling.stiffness * scaling.time,
        rtol=1e-9,
    )
