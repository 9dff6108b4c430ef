"""The discovery stage of a diagnosis: [`jaxcable.discover`][] over no covariate
and every recorded one (or the one its base reads), the best option fitted jointly
with the base and scored like the catalogue's candidates."""

import dataclasses
import math
import warnings
from typing import Any

from .._fit import IdentifiabilityWarning
from .._progress import AbstractProgressMeter
from .base import BaseFit
from .discover import discover
from .plan import Plan
from .result import Candidate
from .scoring import scored_candidate, training_score


@dataclasses.dataclass(frozen=True)
class Discovered:
    """The discovery stage of a diagnosis.

    **Fields:**

    - `candidate`: the discovered term scored as a candidate (`"discovered"`).
    - `description`: the term for [`jaxcable.Diagnosis`][]`.discovered`: the
        equation, terms, covariate, coefficients with standard errors and units,
        held-out RMSEs and gain, and every covariate option's held-out residual
        RMSE (`covariate_scores_mm`).
    """

    candidate: Candidate
    description: dict[str, Any]


def discovery_stage(
    plan: Plan, base: BaseFit, *, max_steps: int, progress_meter: AbstractProgressMeter
) -> Discovered | None:
    """The best discovered term over no covariate and each recorded one, scored.

    The regression (no joint fit) runs for each covariate option; the option whose
    chosen support leaves the least held-out residual is fitted jointly with the
    base ([`jaxcable.discover`][]) and scored like the catalogue's candidates (same
    held-out samples, BIC, size = its best-determined coefficient). It runs on the
    time split of force-driven tests.

    **Arguments:**

    - `plan`: the diagnosis's [`Plan`][].
    - `base`: the base model's [`BaseFit`][] on the training samples.
    - `max_steps`: Levenberg-Marquardt steps of the joint fit.
    - `progress_meter`: told of the stage.

    **Returns:**

    A [`Discovered`][], or None when no option found a term or its fit failed.
    """
    tests, base_fit = plan.tests, base.fit
    progress_meter.say("discovering a term")
    held = [t.mask for t in plan.time_fold.held]
    scores: dict[str, float] = {}
    best, best_score = None, math.inf
    # A base driven by a covariate (named in an earlier round) reads it in every
    # option: the library's covariate terms are then that column's.
    options = [plan.how.covariate] if plan.how.covariate else [None, *plan.columns]
    for covariate in options:
        found = discover(
            base_fit, tests, covariate=covariate, held=held, joint_fit=False
        )
        if not found.terms:
            continue
        score = dict(found.path)[found.support]
        scores[covariate or "-"] = score
        if score < best_score:
            best, best_score = covariate, score
    if not scores:
        return None
    # As for the catalogue's candidates, identifiability is reported in the
    # candidate's fit, not warned about.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", IdentifiabilityWarning)
        found = discover(
            base_fit,
            tests,
            covariate=best,
            held=held,
            multistart=1,
            max_steps=max_steps,
        )
    if found.fit is None:
        return None
    description = {**found.describe(), "covariate_scores_mm": scores}
    size = found.size()
    score = training_score(found.fit, found.heldout_rmse_mm[1])
    candidate = scored_candidate(
        "discovered",
        found.fit,
        score,
        size,
        found.equation,
        base.against,
        plan.how,
        covariate=best,
    )
    return Discovered(candidate, description)
