"""The structure of a fit's residuals: per-sample test conditions (time under load,
force, loading vs unloading, cycle number, rest time, cable length, rate, elapsed time,
temperature), the residuals' correlation with each, and their lag-1 autocorrelation
against the white-noise band."""

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from .._fit import as_test_list


def _features(test, drive: str = "force") -> dict[str, np.ndarray]:
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
    imposed = force if drive == "force" else np.asarray(test.elongation, float)
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
    if getattr(test, "temperature", None) is not None:
        out["temperature"] = np.asarray(test.temperature, float)
    return out


def residual_structure(
    tests,
    residual: Sequence[np.ndarray],
    *,
    drives: Sequence[str] | None = None,
    unit: str = "mm",
) -> dict[str, Any]:
    """How the residuals of a fit depend on the test conditions.

    **Arguments:**

    - `tests`: the tests ([`jaxcable.TestData`][]), their masks marking the samples
        to use.
    - `residual`: model minus measured value of each test's scored channel: the
        elongation, m (`unit="mm"`), the force, N (`unit="N"`), or either divided by
        its noise (`unit="noise"`).
    - `drives`: each test's drive (default: all `"force"`); the branches and cycles
        follow the imposed channel.
    - `unit`: the reported unit of the residuals, `"mm"`, `"N"` or `"noise"`.

    **Returns:**

    `{"correlation": {feature: Pearson r of residual and feature over all samples},
    "strongest": the feature of largest |r|, "autocorrelation": pooled lag-1
    autocorrelation of the residuals, "white_noise_band": 1.96 / sqrt(n), "mean":
    {"loading", "unloading", "hold"}: mean residual on each branch, in `unit`,
    "unit", and "mean_mm": the same in mm (None unless `unit` is mm)}`. Features
    constant over the data (one length, one temperature) have no correlation (None).
    """
    tests = as_test_list(tests)
    if drives is None:
        drives = ["force"] * len(tests)
    columns: dict[str, list] = {}
    rs, lag = [], []
    for test, r, drive in zip(tests, residual, drives):
        r = np.asarray(r, float)
        own = getattr(test, "mask", None)
        mask = np.ones(r.shape, bool) if own is None else np.asarray(own, bool)
        keep = mask & np.isfinite(r)
        for name, values in _features(test, drive).items():
            columns.setdefault(name, [])
            columns[name].append(values[keep])
        rs.append(r[keep])
        rc = r[keep] - r[keep].mean() if keep.any() else r[keep]
        if rc.size > 2:
            lag.append((rc[1:] * rc[:-1]).sum() / max((rc * rc).sum(), 1e-300))
    r_all = np.concatenate(rs)
    correlation = {}
    for name, parts in columns.items():
        if len(parts) != len(rs):  # a feature some tests lack (temperature)
            continue
        x = np.concatenate(parts)
        if x.size < 3 or np.ptp(x) <= 1e-12 * max(np.abs(x).max(), 1e-300):
            correlation[name] = None
            continue
        correlation[name] = float(np.corrcoef(x, r_all)[0, 1])
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
        "strongest": max(valid, key=valid.get) if valid else None,
        "autocorrelation": float(np.mean(lag)) if lag else float("nan"),
        "white_noise_band": 1.96 / math.sqrt(max(r_all.size, 1)),
        "mean_mm": dict(mean) if unit == "mm" else dict.fromkeys(mean),
        "mean": mean,
        "unit": unit,
    }
