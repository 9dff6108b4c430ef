"""The hidden effects outside the diagnosis catalogue: their data sets have the
in-catalogue format, their contributions the documented size and story, and they are
reproducible by seed. (No diagnosis here: `benchmarks/diagnose_matrix.py
--out-of-catalogue` runs them.)"""

import numpy as np
import pytest

import jaxcable as jc
from jaxcable import papers
from jaxcable._papers import hidden_effects, synthetic


EFFECTS = list(papers.OUT_OF_CATALOGUE)


def test_out_of_catalogue_is_outside_the_catalogue():
    assert len(EFFECTS) >= 3
    assert not set(EFFECTS) & set(jc.EXTENSIONS)
    assert not set(EFFECTS) & set(papers.HIDDEN_EFFECTS)


@pytest.fixture(scope="module")
def datasets():
    return {e: papers.hidden_effect_dataset(e, seed=3) for e in EFFECTS}


@pytest.fixture(scope="module")
def base():
    """The same seed without an effect: the same base, force and noise."""
    return papers.hidden_effect_dataset(None, seed=3)


@pytest.mark.parametrize("effect", EFFECTS)
def test_format_as_in_catalogue(effect, datasets, base):
    tests = datasets[effect]
    assert len(tests) == len(synthetic.HIDDEN_EFFECT_DESIGN)
    for t, b in zip(tests, base):
        assert t.time.shape == t.force.shape == t.elongation.shape
        assert t.temperature.shape == t.time.shape
        assert t.metadata["hidden_effect"] == effect
        assert t.metadata["control"] == "force"
        assert t.metadata["id"] == b.metadata["id"]
        # The effect changes the elongation only: same protocol, force and noise draw.
        np.testing.assert_array_equal(t.time, b.time)
        np.testing.assert_array_equal(t.force, b.force)
        np.testing.assert_array_equal(t.temperature, b.temperature)
        covariate = papers.OUT_OF_CATALOGUE[effect]["covariate"]
        assert set(t.extra) == ({covariate} if covariate else set())


def test_humidity_is_recorded(datasets):
    for t in datasets["mechano_sorptive"]:
        h = t.extra["humidity_pct"]
        assert h.shape == t.time.shape
        assert np.all((h > 20) & (h < 75))
        # A lab history, not a constant: drift, cycle and step move it by percents.
        assert np.ptp(h) > 3.0
        # Recorded to the logger's 0.1 %RH.
        np.testing.assert_allclose(h * 10, np.round(h * 10), atol=1e-9)
    # Each test has its own history.
    first, second = (t.extra["humidity_pct"] for t in datasets["mechano_sorptive"][:2])
    assert not np.allclose(first[: len(second)], second[: len(first)])


@pytest.mark.parametrize("effect", EFFECTS)
def test_contribution_is_the_effect(effect, datasets, base):
    """Data minus the effect-free data (same seed) is the effect's elongation, and
    the truth helper returns the noise-free data-generating elongation."""
    truth = papers.truth_elongations(effect, seed=3)
    free = papers.truth_elongations(None, seed=3)
    for t, b, e, e0 in zip(datasets[effect], base, truth, free):
        added = t.elongation - b.elongation
        np.testing.assert_allclose(added, e - e0, atol=1e-9)
        assert added[0] == 0.0
        # Irreversible (slip, damage under load, sorptive creep): never negative.
        assert np.min(added) > -1e-9
        np.testing.assert_allclose(t.elongation - e, b.elongation - e0, atol=1e-9)


def test_sizes_as_documented(datasets, base):
    added = {
        e: [t.elongation - b.elongation for t, b in zip(datasets[e], base)]
        for e in EFFECTS
    }
    # Clamp slip: 80 N tests (rows 2 and 3) never slip; at 160 N about 0.1-0.3 mm
    # (k (160 - 100) N over about 2.2 h above the threshold), whatever the length.
    forces = [row[2] for row in synthetic.HIDDEN_EFFECT_DESIGN]
    k = papers.OUT_OF_CATALOGUE["clamp_slip"]["size"]
    for f, a, t in zip(forces, added["clamp_slip"], datasets["clamp_slip"]):
        above = np.clip(t.force - hidden_effects.F_SLIP, 0, None)
        if f < hidden_effects.F_SLIP:
            assert np.max(a) == 0.0
        else:
            hold = k * (f - hidden_effects.F_SLIP) * 2 * 3600
            assert 0.8 * hold < a[-1] < 1.5 * hold
            assert np.all(np.diff(a) >= -1e-12)
            # Slips only above the threshold: below it the two simulations agree to
            # rounding (a solve's state at its root is the last evaluation's moved
            # by its derivative, or the model at the root: equal to ~1e-18 m).
            below = (above[1:] == 0) & (above[:-1] == 0)
            assert np.all(np.abs(np.diff(a)[below]) <= 1e-15)
    # Cyclic softening: s n F L0 / EA_REF; at the last peak n is about 3.5 cycles.
    s = papers.OUT_OF_CATALOGUE["cyclic_softening"]["size"]
    for (length, _, f, _), a in zip(
        synthetic.HIDDEN_EFFECT_DESIGN, added["cyclic_softening"]
    ):
        expected = s * 3.5 * f * length * 1e-3 / hidden_effects.EA_REF
        assert 0.8 * expected < np.max(a) < 1.2 * expected
        assert abs(a[-1]) < 1e-9  # elastic: gone at rest
    # Mechano-sorptive: tens to hundreds of um per test.
    rms = np.sqrt(np.mean(np.concatenate(added["mechano_sorptive"]) ** 2))
    assert 20e-6 < rms < 1e-3


def test_size_scales_the_effect(base):
    for effect in EFFECTS:
        size = papers.OUT_OF_CATALOGUE[effect]["size"]
        one = papers.hidden_effect_dataset(effect, seed=3, size=size)
        two = papers.hidden_effect_dataset(effect, seed=3, size=2 * size)
        for a, b, z in zip(one, two, base):
            np.testing.assert_allclose(
                b.elongation - z.elongation,
                2 * (a.elongation - z.elongation),
                atol=1e-9,
            )


@pytest.mark.parametrize("effect", EFFECTS)
def test_reproducible_by_seed(effect, datasets):
    again = papers.hidden_effect_dataset(effect, seed=3)
    other = papers.hidden_effect_dataset(effect, seed=4)
    for a, b, c in zip(datasets[effect], again, other):
        np.testing.assert_array_equal(a.elongation, b.elongation)
        for name in a.extra:
            np.testing.assert_array_equal(a.extra[name], b.extra[name])
        assert not np.array_equal(a.elongation, c.elongation)


def test_truth_driven_by_the_records(datasets):
    """Driven by the recorded force and humidity, the true model stays within a few
    noise levels of the data (the floor a diagnosis can reach)."""
    tests = datasets["mechano_sorptive"]
    truth = papers.truth_elongations("mechano_sorptive", seed=3, tests=tests)
    r = np.concatenate([t.elongation - e for t, e in zip(tests, truth)])
    assert np.sqrt(np.mean(r**2)) < 30e-6


def test_unknown_effect_is_refused():
    with pytest.raises(ValueError, match="mechano_sorptive"):
        hidden_effects.effect_elongation(
            "creep_rupture", [0.0, 1.0], [0.0, 1.0], length=0.1, diameter=3e-3
        )
    with pytest.raises(ValueError, match="effect"):
        papers.hidden_effect_model("clamp_slip", seed=0)
