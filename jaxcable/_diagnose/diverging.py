"""Why a candidate diverges: a candidate whose held-out RMSE is far above the base's
(`verdict.MAX_DIVERGENCE`) fits something else on the training samples and runs away
where it extrapolates. Its share of the excess (say -663740 %) measures nothing; the
diagnosis flags it with the test where it departs most and from when."""

import math

import numpy as np

from .._fit import test_id
from .base import BaseFit
from .plan import Plan
from .result import Candidate


def departure(plan: Plan, base: BaseFit, candidate: Candidate) -> str:
    """Where a diverging candidate departs from the data: the test of its worst
    held-out RMSE against the base's, and the first sample of that test where its
    residual exceeds twice the base's largest there.

    **Arguments:**

    - `plan`: the diagnosis's [`Plan`][].
    - `base`: the base's [`BaseFit`][].
    - `candidate`: the diverging candidate (with its fit).

    **Returns:**

    One phrase, e.g. `"on L300-v3-F80: held-out RMSE 40.6 mm against the base's
    0.21 mm, departing from t = 31.2 h (at 0.5 N)"`.
    """
    if candidate.fit is None:
        return "its fit failed"
    how, tests = plan.how, plan.tests
    index = range(len(tests))
    mine = how.residuals(candidate.fit.model, tests, index, candidate.covariate)
    theirs = how.residuals(base.fit.model, tests, index)
    held = (
        [np.asarray(t.mask, bool) for t in plan.time_fold.held]
        if plan.split == "time"
        else [np.ones(len(t.time), bool) for t in tests]
    )
    worst, ratio = 0, -math.inf
    for i, (a, b, h) in enumerate(zip(mine, theirs, held)):
        a, b = np.nan_to_num(a[h], nan=np.inf), np.nan_to_num(b[h])
        if not a.size:
            continue
        r = _rms(a) / max(_rms(b), 1e-300)
        if r > ratio:
            worst, ratio = i, r
    t = tests[worst]
    a, b, h = mine[worst], theirs[worst], held[worst]
    u, f = how.unit, how.factor
    text = (
        f"on {test_id(t, worst)}: held-out RMSE {f * _rms(a[h]):.3g} {u} against "
        f"the base's {f * _rms(b[h]):.3g} {u}"
    )
    limit = 2.0 * float(np.nanmax(np.abs(b))) if np.any(np.isfinite(b)) else 0.0
    away = np.flatnonzero(~(np.abs(a) <= limit))
    if away.size:
        k = int(away[0])
        time = float(np.asarray(t.time)[k]) / 3600.0
        force = float(np.asarray(t.force)[k])
        text += f", departing from t = {time:.3g} h (at {force:.3g} N)"
    return text


def _rms(x) -> float:
    x = np.asarray(x, float)
    return float(np.sqrt(np.mean(x**2))) if x.size else math.nan
