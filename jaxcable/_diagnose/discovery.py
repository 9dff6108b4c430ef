"""The `discovered` candidate of [`jaxcable.diagnose`][]: when no catalogued cause
explains the residual, [`jaxcable.discover`][] looks for the term that does, over
every recorded covariate, and the term is scored like the catalogue's candidates."""

import math
import warnings
from typing import Any

import numpy as np

from .._fit import FitResult, IdentifiabilityWarning
from .discover import DiscoveryResult, discover
from .heldout import heldout_start


def covariates(tests) -> list[str]:
    """The extra columns every test records, numeric and not constant in all of
    them: each may drive a discovered term."""
    common = None
    for t in tests:
        names = set(getattr(t, "extra", None) or {})
        common = names if common is None else common & names
    out = []
    for name in sorted(common or ()):
        values = [np.asarray(t.extra[name], float) for t in tests]
        if all(np.all(np.isfinite(v)) for v in values) and any(
            np.ptp(v) > 0 for v in values
        ):
            out.append(name)
    return out


def discover_term(
    base_fit: FitResult,
    tests,
    holdout: float,
    **fit_kwargs,
) -> tuple[DiscoveryResult | None, dict[str, float]]:
    """The best discovered term over no covariate and each recorded one.

    The regression (no joint fit) runs for each covariate option; the option whose
    chosen support leaves the least held-out residual is fitted jointly with the
    base ([`jaxcable.discover`][]).

    **Arguments:**

    - `base_fit`: the base model's fit on the training samples (time split).
    - `tests`: the tests (force-driven).
    - `holdout`: the held-out fraction of the time split.
    - `fit_kwargs`: passed on to the joint fit.

    **Returns:**

    `(result, scores)`: the [`jaxcable.DiscoveryResult`][] of the chosen covariate
    (None when no option found a term), and the held-out residual RMSE (mm) of
    every option's best support, by covariate (`"-"`: none).
    """
    held = [
        np.arange(len(t.time)) >= heldout_start(len(t.time), holdout) for t in tests
    ]
    scores: dict[str, float] = {}
    best, best_score = None, math.inf
    for covariate in [None, *covariates(tests)]:
        found = discover(
            base_fit, tests, covariate=covariate, held=held, joint_fit=False
        )
        if not found.terms:
            continue
        score = dict(found.path)[found.terms]
        scores[covariate or "-"] = score
        if score < best_score:
            best, best_score = covariate, score
    if not scores:
        return None, scores
    options = {"multistart": 1, **fit_kwargs}
    # As for the catalogue's candidates, identifiability is reported in the
    # candidate's fit, not warned about.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", IdentifiabilityWarning)
        found = discover(base_fit, tests, covariate=best, held=held, **options)
    return found, scores


def describe(found: DiscoveryResult) -> dict[str, Any]:
    """The discovered term for a [`jaxcable.Diagnosis`][]: the equation, terms,
    covariate, coefficients with standard errors and units."""
    return {
        "equation": found.equation,
        "terms": list(found.terms),
        "covariate": found.covariate,
        "values": [float(v) for v in found.values],
        "stderr": [float(s) for s in found.stderr],
        "units": list(found.units),
        "heldout_rmse_mm": [float(x) for x in found.heldout_rmse_mm],
        "gain_pct": float(found.gain_pct),
    }
