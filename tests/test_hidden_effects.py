"""The hidden effects outside the diagnosis catalogue, and the data sets with two
catalogue effects at once: their data sets have the in-catalogue format, their
contributions the documented size and story, and they are reproducible by seed. (No
diagnosis here: `benchmarks/diagnose_matrix.py --out-of-catalogue` and
`benchmarks/diagnose_rounds.py` run them.)"""

import numpy as np
import pytest

import jaxcable as jc
from jaxcable import papers
from jaxcable.internal import hidden_effects, synthetic


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
        # Irreversible or stress-driven (slip, damage, sorptive creep): never
        # negative; a swelling follows the humidity either way.
        if effect != "lagged_swelling":
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


# ----------------------------------------------------------------------------------
# Effects with a state of their own.


def test_memory_effects_registered():
    assert len(papers.MEMORY_EFFECTS) == 3
    for effect in papers.MEMORY_EFFECTS:
        assert papers.OUT_OF_CATALOGUE[effect]["memory"] is True
    others = set(EFFECTS) - set(papers.MEMORY_EFFECTS)
    assert others and not any(papers.OUT_OF_CATALOGUE[e]["memory"] for e in others)


def _holds(test):
    """The index ranges of the two 1 h creep holds (the force at its peak)."""
    on = test.force > 0.99 * np.max(test.force)
    edges = np.flatnonzero(np.diff(on.astype(int)))
    # Two pre-cycles touch the peak once each; the holds are the two long runs.
    runs = [(a + 1, b + 1) for a, b in zip(edges[::2], edges[1::2])]
    # The two longest, in the order they ran (their durations differ by solved times).
    return sorted(
        sorted(runs, key=lambda r: test.time[r[1] - 1] - test.time[r[0]])[-2:]
    )


def test_cycling_humidity_cycles_strongly(datasets):
    for i, t in enumerate(datasets["saturating_sorptive"]):
        h = t.extra["humidity_pct"]
        assert np.min(h) < 36 and np.max(h) > 74
        # Six to nine wet-dry cycles over the 6 h test: >= 12 crossings of the
        # middle, most of them seen by the records too.
        climate = hidden_effects.cycling_humidity(3, i)
        fine = climate(np.linspace(0, t.time[-1], 20000))
        assert np.sum(np.diff(np.sign(fine - 55.0)) != 0) >= 12
        assert np.sum(np.diff(np.sign(h - 55.0)) != 0) >= 8


def test_saturating_sorptive_steps_shrink(datasets, base):
    """Under a constant load the strain steps with each humidity change, by less
    each time, towards sigma J_ms and never past it; at rest it recovers."""
    size = papers.OUT_OF_CATALOGUE["saturating_sorptive"]["size"]
    area = np.pi * 3e-3**2 / 4
    design = synthetic.HIDDEN_EFFECT_DESIGN
    tests, free = (
        datasets["saturating_sorptive"],
        papers.truth_elongations(None, seed=3),
    )
    truth = papers.truth_elongations("saturating_sorptive", seed=3)
    for (length, _, force, _), t, e, e0 in zip(design, tests, truth, free):
        added = (e - e0) / (length * 1e-3)
        ceiling = size * force / area
        assert np.max(added) <= ceiling * (1 + 1e-9)
        first, _ = _holds(t)
        held = added[first[0] : first[1]]
        # A saturating approach: more than half way after 1 h of cycling...
        assert held[-1] > 0.5 * ceiling
        # ...and the first half hour gains more than the second.
        half = np.searchsorted(t.time[first[0] : first[1]], t.time[first[0]] + 1800)
        assert held[half] - held[0] > held[-1] - held[half]
        # Recovery at rest, with the humidity changes: far below the hold's end.
        rest = first[1] + np.searchsorted(t.time[first[1] :], t.time[first[1]] + 5400)
        assert added[rest] < 0.3 * held[-1]


def test_fatigue_accelerates():
    """D / (1 - D) grows faster cycle after cycle (the stroke runs away), steeply
    with the stress; a history that reaches failure is refused."""
    peak = 160.0
    one = np.array([0.0, peak, 0.0])
    history = np.concatenate([one] + [one[1:]] * 3)
    grown = hidden_effects._fatigue(history, 3e-3)[2::2]
    steps = np.diff(np.concatenate([[0.0], grown]))
    assert np.all(np.diff(steps) > 0)
    # Not failing: D / (1 - D) < 9 (D < 0.9) after the design's four cycles.
    assert 0.3 < grown[-1] < 9.0
    # (80/160)^5 = 1/32 of the damage per cycle at half the force.
    half = hidden_effects._fatigue(history / 2, 3e-3)[2::2]
    assert half[-1] < 0.02 * grown[-1]
    with pytest.raises(ValueError, match="force"):
        hidden_effects._fatigue(np.concatenate([one] + [one[1:]] * 20), 3e-3)


def test_fatigue_effect_is_elastic_and_damaged(datasets, base):
    tests = datasets["fatigue_damage"]
    size = papers.OUT_OF_CATALOGUE["fatigue_damage"]["size"]
    for (length, _, force, _), t, b in zip(synthetic.HIDDEN_EFFECT_DESIGN, tests, base):
        added = t.elongation - b.elongation
        first, second = _holds(t)
        mid = [added[(a + z) // 2] for a, z in (first, second)]
        elastic = size * length * 1e-3 * force / hidden_effects.EA_REF
        # One more cycle before the second hold: more damage, by a larger factor
        # the nearer failure (x 1.4 at small damage, 2.5 -> 3.5 cycles).
        assert mid[1] > (1.8 if force > 150 else 1.3) * mid[0]
        assert mid[1] < 9.0 * elastic
        if force > 150:
            assert mid[1] > 0.5 * elastic
        np.testing.assert_allclose(added[-1], 0.0, atol=1e-12)  # unloaded: none left


def test_lagged_swelling_lags_the_humidity(datasets):
    """alpha L0 (q - h0), q the humidity seen through a first-order lag: against a
    fine explicit integration of the same climate."""
    alpha = papers.OUT_OF_CATALOGUE["lagged_swelling"]["size"]
    tau = hidden_effects.SWELLING_TAU
    t = datasets["lagged_swelling"][1]
    length = synthetic.HIDDEN_EFFECT_DESIGN[1][0] * 1e-3
    climate = hidden_effects.stepped_humidity(3, 1)
    fine = np.linspace(0.0, t.time[-1], 400001)
    h, q = climate(fine), np.empty_like(fine)
    q[0] = h[0]
    dt = fine[1] - fine[0]
    for i in range(1, fine.size):
        q[i] = q[i - 1] + dt * (h[i - 1] - q[i - 1]) / tau
    expected = alpha * length * (np.interp(t.time, fine, q) - h[0])
    added, _ = hidden_effects.effect_elongation(
        "lagged_swelling",
        t.time,
        t.force,
        length=length,
        diameter=3e-3,
        seed=3,
        index=1,
    )
    np.testing.assert_allclose(added, expected, atol=1e-3 * np.max(np.abs(expected)))
    # It lags: the instantaneous alpha L0 (h - h0) is far from it.
    instant = alpha * length * (climate(t.time) - h[0])
    assert np.sqrt(np.mean((instant - added) ** 2)) > 0.1 * np.max(np.abs(added))
    # Load-free: the same at zero force.
    unloaded, _ = hidden_effects.effect_elongation(
        "lagged_swelling",
        t.time,
        0 * t.force,
        length=length,
        diameter=3e-3,
        seed=3,
        index=1,
    )
    np.testing.assert_array_equal(added, unloaded)


# ----------------------------------------------------------------------------------
# Two catalogue effects at once.


def test_pairs_cover_the_catalogue():
    pairs = papers.HIDDEN_PAIRS
    assert len(pairs) >= 10
    assert {e for p in pairs for e in p} == set(jc.EXTENSIONS)
    for pair, multiples in pairs.items():
        assert set(multiples) == set(pair) and pair[0] != pair[1]
        assert all(3.0 <= m <= 10.0 for m in multiples.values())
        for effect, size in zip(pair, papers.pair_sizes(pair)):
            limit = papers.HIDDEN_EFFECTS[effect]["size"]
            strength = limit / size if effect == "second_retardation" else size / limit
            assert strength == pytest.approx(multiples[effect])


def test_pair_model_nests_the_two_effects():
    pair = ("second_retardation", "termination_compliance")
    model = papers.hidden_pair_model(pair, seed=3)
    assert type(model) is jc.EXTENSIONS[pair[1]]
    assert type(model.base) is jc.EXTENSIONS[pair[0]]
    assert model.base.base == papers.hidden_effect_model(None, seed=3)
    size_a, size_b = papers.pair_sizes(pair)
    assert float(model.compliance) == size_b
    assert float(model.base.E_k) == size_a
    assert float(model.base.tau_k) == papers.HIDDEN_EFFECTS[pair[0]]["fixed"]["tau_k"]


def test_pair_dataset_is_the_single_design():
    """With the inner effect at its null size a pair's data set is the outer
    effect's single-effect data set: same design, protocol, noise and seeds."""
    pair = ("termination_compliance", "sensor_drift")
    size = papers.pair_sizes(pair)[1]
    tests = papers.hidden_pair_dataset(pair, seed=3, sizes=(0.0, size))
    single = papers.hidden_effect_dataset("sensor_drift", seed=3, size=size)
    for t, s in zip(tests, single):
        assert t.metadata["hidden_effect"] == "termination_compliance+sensor_drift"
        assert t.metadata["id"] == s.metadata["id"]
        np.testing.assert_array_equal(t.force, s.force)
        np.testing.assert_allclose(t.elongation, s.elongation, atol=1e-12)
    # The noise-free truth: the data within the noise of it.
    truth = papers.pair_truth_elongations(pair, seed=3, sizes=(0.0, size))
    r = np.concatenate([t.elongation - e for t, e in zip(tests, truth)])
    assert 3e-6 < np.sqrt(np.mean(r**2)) < 8e-6


def test_bad_pairs_are_refused():
    with pytest.raises(TypeError, match="pair"):
        papers.hidden_pair_model("sensor_drift", seed=0)
    with pytest.raises(ValueError, match="pair"):
        papers.hidden_pair_dataset(("sensor_drift", "clamp_slip"), seed=0)
    with pytest.raises(ValueError, match="pair"):
        papers.pair_sizes(("sensor_drift", "sensor_drift"))
