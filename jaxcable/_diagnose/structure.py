"""The structure of a fit's residuals: per-sample test conditions (time under load,
force, loading vs unloading, cycle number, rest time, cable length, rate, elapsed time)
and covariates (the temperature record and every extra numeric column of a test, each
with its rate of change d c/dt and absolute rate |d c/dt|), the residuals' correlation
with each, and their lag-1 autocorrelation against the white-noise band."""

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from .._drive import FORCE_DRIVEN, AbstractTestDrive, as_test_drive
from .._fit import as_test_list


def _features(
    test, drive: AbstractTestDrive | str = FORCE_DRIVEN
) -> dict[str, np.ndarray]:
    """Per-sample explanatory variables of a residual, from the test's own record.
    Cycles and the loading/unloading/hold branches follow the channel the test
    imposed (`drive`): a relaxing force in a hold of the elongation is a hold."""
    time = np.asarray(test.time, float)
    force = np.asarray(test.force, float)
    n = time.size
    loaded = force > 0.05 * max(float(force.max()), 1e-12)
    dt = np.diff(time, prepend=time[0])
    under_load = np.cumsum(np.where(loaded, dt, 0.0))
    # Time since the force last was loaded (0 while loaded): the rest time.
    last = np.maximum.accumulate(np.where(loaded, np.arange(n), -1))
    rest = np.where(last >= 0, time - time[np.maximum(last, 0)], time - time[0])
    imposed = np.asarray(as_test_drive(drive).imposed_of(test), float)
    # Cycle number: upward crossings of half the peak so far.
    up = (imposed[1:] >= 0.5 * imposed.max()) & (imposed[:-1] < 0.5 * imposed.max())
    cycle = np.concatenate([[0], np.cumsum(up)])
    slope = np.gradient(imposed, time) if n > 1 else np.zeros(n)
    scale = np.median(np.abs(slope[slope != 0])) if np.any(slope != 0) else 1.0
    branch = np.where(slope > 0.1 * scale, 1.0, np.where(slope < -0.1 * scale, -1, 0))
    cable = test.cable()
    out = {
        "time under load": under_load,
        "force": force,
        "loading vs unloading": branch,
        "cycle number": cycle.astype(float),
        "rest time": rest,
        "cable length": np.full(n, float(cable.length)),
        "rate": np.full(n, float(cable.speed)),
        "elapsed time": time - time[0],
    }
    return out


def test_covariates(test) -> dict[str, np.ndarray]:
    """A test's covariates: its temperature record (`"temperature"`) and every extra
    numeric column (`TestData.extra`, by its name), per sample."""
    out = {}
    if getattr(test, "temperature", None) is not None:
        out["temperature"] = np.asarray(test.temperature, float)
    for name, values in getattr(test, "extra", {}).items():
        # A column named like a condition would shadow it: keep both, apart.
        key = name if name not in _CONDITIONS else f"{name} (column)"
        out[key] = np.asarray(values, float)
    return out


_CONDITIONS = (
    "time under load",
    "force",
    "loading vs unloading",
    "cycle number",
    "rest time",
    "cable length",
    "rate",
    "elapsed time",
    "temperature",
)


def rate_of_change(time: np.ndarray, values: np.ndarray, half: int = 0) -> np.ndarray:
    """d values / d time at every sample, robust to the covariate's noise and to
    uneven sample times: the slope of a least-squares line through the samples
    within `half` samples either side (default: n / 100, at least 2), on the sample
    times themselves. NaN samples are left out of every window.

    **Arguments:**

    - `time`: the sample times, s, increasing.
    - `values`: the covariate at each sample.
    - `half`: the window's half-width in samples (0: the default).

    **Returns:**

    The rate at each sample, in the covariate's unit per s (NaN where its window
    holds fewer than two finite samples at distinct times).
    """
    t = np.asarray(time, float)
    c = np.asarray(values, float)
    n = t.size
    if half <= 0:
        half = max(2, n // 100)
    ok = np.isfinite(c) & np.isfinite(t)

    # Windowed sums by cumulative sums: one pass, any length.
    def window_sum(x):
        cs = np.concatenate([[0.0], np.cumsum(np.where(ok, x, 0.0))])
        lo = np.clip(np.arange(n) - half, 0, n)
        hi = np.clip(np.arange(n) + half + 1, 0, n)
        return cs[hi] - cs[lo]

    # Centred on each sample's time, so the sums stay well conditioned.
    t0 = t - t[0] if n else t
    cc = np.where(ok, c, 0.0)
    s0 = window_sum(np.ones(n))
    st, sc = window_sum(t0), window_sum(cc)
    stt, stc = window_sum(t0 * t0), window_sum(t0 * cc)
    with np.errstate(invalid="ignore", divide="ignore"):
        var = stt - st * st / np.maximum(s0, 1)
        slope = (stc - st * sc / np.maximum(s0, 1)) / var
    span = max(float(t0.max()) if n else 0.0, 1e-300)
    valid = (s0 >= 2) & (var > 1e-24 * span * span)
    # The windowed sums' round-off, not a rate: a constant covariate has none.
    size = float(np.abs(cc).max()) if n else 0.0
    slope = np.where(np.abs(slope) <= 1e-9 * size * n / span, 0.0, slope)
    return np.where(valid, slope, np.nan)


def residual_structure(
    tests,
    residual: Sequence[np.ndarray],
    *,
    drives: Sequence[AbstractTestDrive | str] | None = None,
    unit: str = "mm",
) -> dict[str, Any]:
    """How the residuals of a fit depend on the test conditions.

    **Arguments:**

    - `tests`: the tests ([`jaxcable.TestData`][]), their masks marking the samples
        to use.
    - `residual`: model minus measured value of each test's scored channel: the
        elongation, m (`unit="mm"`), the force, N (`unit="N"`), or either divided by
        its noise (`unit="noise"`).
    - `drives`: each test's drive, a value or name (default: all force-driven); the
        branches and cycles follow the imposed channel.
    - `unit`: the reported unit of the residuals, `"mm"`, `"N"` or `"noise"`.

    **Returns:**

    `{"correlation": {feature: Pearson r of residual and feature over all samples},
    "strongest": the feature of largest |r|, "autocorrelation": pooled lag-1
    autocorrelation of the residuals, "white_noise_band": 1.96 / sqrt(n), "mean":
    {"loading", "unloading", "hold"}: mean residual on each branch, in `unit`,
    "unit", "mean_mm": the same in mm (None unless `unit` is mm), and "covariates":
    {covariate: {"tests": how many tests record it, "of": how many tests, "used":
    True when correlated, "note": on which tests, or why it was skipped}}}`. Each
    covariate c (the temperature record, every extra column) gives three features:
    `c`, `d c/dt` and `|d c/dt|` (`rate_of_change`, per s). A covariate some
    tests lack is correlated on the tests that record it, its note says so. Features
    constant over the data (one length, one temperature) have no correlation (None).
    """
    tests = as_test_list(tests)
    if drives is None:
        drives = [FORCE_DRIVEN] * len(tests)
    columns: dict[str, list] = {}
    # Per covariate: its three features' samples and the residuals on its tests.
    recorded: dict[str, list] = {}
    rs, lag = [], []
    for test, r, drive in zip(tests, residual, drives):
        r = np.asarray(r, float)
        own = getattr(test, "mask", None)
        mask = np.ones(r.shape, bool) if own is None else np.asarray(own, bool)
        keep = mask & np.isfinite(r)
        for name, values in _features(test, drive).items():
            columns.setdefault(name, [])
            columns[name].append(values[keep])
        time = np.asarray(test.time, float)
        for name, values in test_covariates(test).items():
            rate = rate_of_change(time, values)
            recorded.setdefault(name, []).append(
                (values[keep], rate[keep], np.abs(rate[keep]), r[keep])
            )
        rs.append(r[keep])
        rc = r[keep] - r[keep].mean() if keep.any() else r[keep]
        if rc.size > 2:
            lag.append((rc[1:] * rc[:-1]).sum() / max((rc * rc).sum(), 1e-300))
    r_all = np.concatenate(rs)
    correlation = {
        name: _correlation(np.concatenate(parts), r_all)
        for name, parts in columns.items()
    }
    notes = {}
    for name, parts in recorded.items():
        r_on = np.concatenate([p[3] for p in parts])
        labels = (name, f"d {name}/dt", f"|d {name}/dt|")
        for j, label in enumerate(labels):
            correlation[label] = _correlation(
                np.concatenate([p[j] for p in parts]), r_on
            )
        used = any(correlation[label] is not None for label in labels)
        if not used:
            note = "constant over the data: skipped"
        elif len(parts) < len(tests):
            note = (
                f"recorded in {len(parts)} of {len(tests)} tests: correlated on those"
            )
        else:
            note = "recorded in every test"
        notes[name] = {
            "tests": len(parts),
            "of": len(tests),
            "used": used,
            "note": note,
        }
    valid = {k: abs(v) for k, v in correlation.items() if v is not None}
    branch = np.concatenate(columns["loading vs unloading"])
    factor = 1e3 if unit == "mm" else 1.0
    mean = {
        label: float(factor * r_all[branch == b].mean())
        if np.any(branch == b)
        else None
        for label, b in (("loading", 1), ("unloading", -1), ("hold", 0))
    }
    return {
        "correlation": correlation,
        "strongest": max(valid, key=valid.__getitem__) if valid else None,
        "autocorrelation": float(np.mean(lag)) if lag else float("nan"),
        "white_noise_band": 1.96 / math.sqrt(max(r_all.size, 1)),
        "mean_mm": dict(mean) if unit == "mm" else dict.fromkeys(mean),
        "mean": mean,
        "unit": unit,
        "covariates": notes,
    }


def _correlation(x: np.ndarray, r: np.ndarray) -> float | None:
    """Pearson r of `x` and `r` over the samples where `x` is finite; None when fewer
    than three are, or `x` is constant over them (nothing to correlate)."""
    ok = np.isfinite(x)
    x, r = x[ok], r[ok]
    if x.size < 3 or np.ptp(x) <= 1e-12 * max(np.abs(x).max(), 1e-300):
        return None
    if np.ptp(r) == 0.0:
        return None
    return float(np.corrcoef(x, r)[0, 1])
