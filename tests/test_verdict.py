"""The verdict of a diagnosis: named only when a cause explains the
residual, `unexplained` otherwise; covariates in the residual-structure table; the
JSON keys. Small problems, no fits."""

import json
import math

import numpy as np
import pytest

import jaxcable as jc
from jaxcable import Candidate, Diagnosis, residual_structure
from jaxcable.internal import (
    MAX_FLOOR_RATIO,
    MIN_AUTOCORRELATION,
    MIN_EXCESS,
    MIN_EXPLAINED_PCT,
    decide,
    explained_pct,
    explained_rmse_pct,
    rate_of_change,
)


# ----------------------------------------------------------------------------------
# The decision, on numbers.


def test_explained_pct_formula():
    # 100 (b^2 - c^2) / (b^2 - f^2): at the floor 100 %, at the base 0 %.
    assert explained_pct(5.0, 4.0, 3.0) == pytest.approx(100 * (25 - 16) / (25 - 9))
    assert explained_pct(5.0, 3.0, 3.0) == pytest.approx(100.0)
    assert explained_pct(5.0, 5.0, 3.0) == pytest.approx(0.0)
    assert explained_pct(5.0, 6.0, 3.0) < 0
    # No excess, or a candidate that could not be scored: no share.
    assert math.isnan(explained_pct(3.0, 2.0, 3.0))
    assert math.isnan(explained_pct(5.0, math.nan, 3.0))


def test_nothing_to_explain_is_none():
    # The base within MIN_EXCESS x the floor: "none", even with a significant one.
    v = decide(MIN_EXCESS * 1.0, 1.0, [0.9], [True])
    assert v.verdict == "none" and v.named is None
    # No noise estimate: nothing to weigh the excess against.
    assert decide(10.0, math.nan, [1.0], [True]).verdict == "none"


def test_named_within_k_of_the_floor():
    # At k x the floor: named, whatever share of the excess that is...
    floor, base = 1.0, 3.0
    v = decide(base, floor, [math.nan, MAX_FLOOR_RATIO * floor], [False, True])
    assert v.verdict == "named" and v.named == 1
    # ... just above it and short of the share: not named.
    cand = 1.01 * MAX_FLOOR_RATIO * floor
    if explained_pct(base, cand, floor) < MIN_EXPLAINED_PCT:
        assert decide(base, floor, [cand], [True]).verdict == "unexplained"
    # The significance tests still gate a candidate at the floor.
    assert decide(base, floor, [floor], [False]).verdict == "unexplained"


def test_named_by_its_share_of_the_excess_far_above_the_floor():
    # The bundled data's case: 7 x the noise held out, yet 99 % of a 96 x excess.
    floor, base = 1.0, 96.0
    cand = 7.0
    assert cand > MAX_FLOOR_RATIO * floor
    assert explained_pct(base, cand, floor) > MIN_EXPLAINED_PCT
    assert decide(base, floor, [cand], [True]).verdict == "named"


def test_a_wrong_cause_that_explains_most_is_not_named():
    # A slipping clamp taken for stress-nonlinear creep (docs/diagnosis.md): 2.4-3.6
    # x the noise held out, 78-89 % of the excess; a cause is named neither way.
    floor, base = 1.0, 8.0
    for cand in (2.4, 3.6):
        assert cand > MAX_FLOOR_RATIO * floor
        assert 78 <= explained_pct(base, cand, floor) < MIN_EXPLAINED_PCT
        assert decide(base, floor, [cand], [True]).verdict == "unexplained"


def test_partial_fix_is_unexplained():
    # The VHB 4910 case: 26 % held-out gain on a base far above the floor.
    floor, base = 1.0, 20.0
    cand = 0.74 * base
    share = explained_pct(base, cand, floor)
    assert share < MIN_EXPLAINED_PCT
    v = decide(base, floor, [cand, 0.99 * base], [True, False])
    assert v.verdict == "unexplained" and v.named is None
    assert v.explained_pct[0] == pytest.approx(share)
    # No significant candidate at all, a systematic excess: unexplained too...
    v = decide(base, floor, [0.99 * base], [False], MIN_AUTOCORRELATION)
    assert v.verdict == "unexplained"
    # ... but a white one is noise the estimate missed: none.
    v = decide(1.3 * floor, floor, [1.29], [False], 0.9 * MIN_AUTOCORRELATION)
    assert v.verdict == "none"
    # A significant partial candidate is unexplained whatever the autocorrelation.
    assert decide(base, floor, [cand], [True], 0.0).verdict == "unexplained"


def test_the_best_sufficient_candidate_is_named():
    floor, base = 1.0, 10.0
    # Candidate 0 gains more but is not significant; 1 and 2 are, 2 gains more.
    v = decide(base, floor, [1.0, 1.4, 1.2], [False, True, True])
    assert v.verdict == "named" and v.named == 2


# ----------------------------------------------------------------------------------
# Covariates in the residual-structure table.


def _test(n, seed, humidity=True):
    rng = np.random.default_rng(seed)
    t = np.sort(rng.uniform(0, 1000, n))  # uneven sample times
    force = 100 + 50 * np.sin(t / 90)
    extra = {}
    if humidity:
        extra["humidity"] = 50 + 10 * np.sin(t / 150 + seed) + 0.1 * rng.normal(size=n)
    return jc.TestData(
        time=t,
        force=force,
        elongation=1e-3 * force / 100,
        extra=extra,
        metadata={"length_mm": 100.0},
    )


def test_rate_of_change_on_uneven_times_is_robust():
    rng = np.random.default_rng(0)
    t = np.sort(rng.uniform(0, 100, 2000))
    c = 3.0 * t + 0.5 * rng.normal(size=t.size)
    rate = rate_of_change(t, c, half=20)
    assert np.nanmedian(np.abs(rate - 3.0)) < 0.1
    assert np.all(np.isfinite(rate))


def test_structure_finds_a_covariate_rate():
    tests = [_test(400, s) for s in range(3)]
    rng = np.random.default_rng(5)
    # A residual built on purpose from the humidity's rate of change (mechano-
    # sorptive creep) plus white noise.
    residual = []
    for t in tests:
        rate = rate_of_change(t.time, t.extra["humidity"])
        residual.append(2e-5 * rate + 1e-7 * rng.normal(size=t.time.size))
    s = residual_structure(tests, residual)
    corr = s["correlation"]
    assert {"humidity", "d humidity/dt", "|d humidity/dt|"} <= set(corr)
    assert s["strongest"] == "d humidity/dt"
    assert corr["d humidity/dt"] > 0.95
    assert s["covariates"]["humidity"]["used"]
    assert s["covariates"]["humidity"]["tests"] == 3


def test_covariate_in_some_tests_is_used_on_those():
    tests = [_test(300, 0), _test(300, 1, humidity=False), _test(300, 2)]
    residual = [
        1e-6 * t.extra["humidity"] if t.extra else np.zeros(t.time.size) for t in tests
    ]
    s = residual_structure(tests, residual)
    note = s["covariates"]["humidity"]
    assert note["used"] and note["tests"] == 2 and note["of"] == 3
    assert "2 of 3" in note["note"]
    assert s["correlation"]["humidity"] > 0.99


def test_constant_covariate_is_skipped_with_a_reason():
    tests = [_test(200, s, humidity=False) for s in range(2)]
    tests = [
        jc.TestData(
            time=t.time,
            force=t.force,
            elongation=t.elongation,
            extra={"moisture": np.full(t.time.size, 3.0)},
            metadata=dict(t.metadata),
        )
        for t in tests
    ]
    s = residual_structure(tests, [np.sin(t.time) for t in tests])
    assert s["correlation"]["moisture"] is None
    assert not s["covariates"]["moisture"]["used"]
    assert "skipped" in s["covariates"]["moisture"]["note"]


# ----------------------------------------------------------------------------------
# The JSON keys and the summary of an unexplained verdict.


def _candidate(id, held, gain, significant, share):
    return Candidate(
        id, held, gain, held, -50.0, 0.1, 0.01, "1", "n", significant,
        explained_pct=share, unit="mm",
        explained_rmse_pct=explained_rmse_pct(1.0, held, 0.05),
    )  # fmt: skip


def test_json_and_summary_of_an_unexplained_verdict():
    structure = {
        "correlation": {"force": 0.46, "humidity": 0.1, "d humidity/dt": None},
        "strongest": "force",
        "autocorrelation": 0.96,
        "white_noise_band": 0.02,
        "mean": {},
        "unit": "mm",
        "covariates": {},
    }
    d = Diagnosis(
        base_model="IntegratedModel",
        named_cause="unexplained",
        base_heldout_rmse=1.0,
        base_train_rmse=0.9,
        extended_heldout_rmse=1.0,
        gain_pct=0.0,
        effect={},
        candidates=(
            _candidate("stress_nonlinear_creep", 0.74, 26.0, True, 45.3),
            _candidate("hereditary", 0.97, 3.0, False, 6.0),
        ),
        structure=structure,
        noise=0.05,
        split="3-fold by tests",
        holdout=None,
        test_ids=("a", "b"),
        base_fit=None,
        verdict="unexplained",
    )
    doc = json.loads(d.to_json())
    assert doc["verdict"] == "unexplained"
    assert doc["named_cause"] == "unexplained"
    assert [c["explained_pct"] for c in doc["candidates"]] == [45.3, 6.0]
    assert doc["structure"]["correlation"]["force"] == 0.46
    assert doc["structure"]["correlation"]["d humidity/dt"] is None
    assert doc["thresholds"]["max_heldout_over_noise"] == MAX_FLOOR_RATIO
    assert doc["thresholds"]["min_explained_pct"] == MIN_EXPLAINED_PCT
    text = d.summary()
    assert "verdict: unexplained" in text
    # The share on RMSEs, (1 - 0.74) / (1 - 0.05) = 27 %, the one on squares beside
    # it, and what is left.
    assert "stress_nonlinear_creep, explains 27 % of the excess" in text
    assert "(45 % in squares)" in text
    assert "leaving 14.8 x the noise" in text
    assert "lag-1 autocorrelation 0.96" in text
    assert "force (r = 0.46)" in text
    # No cause named: the extended model is the fitted base.
    assert d.extended_fit() is d.base_fit
