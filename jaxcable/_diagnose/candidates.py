"""The candidates of a diagnosis, fitted around the base and scored like it: the
catalogue's extensions ([`jaxcable.EXTENSIONS`][]), the forms a recorded covariate
drives ([`jaxcable.COVARIATE_EXTENSIONS`][], their ids naming the column:
`covariate_strain[humidity_pct]`, `mechano_sorptive[humidity_pct]`,
`covariate_shift[humidity_pct]`), and the discovered term ([`jaxcable.discover`][]
over no covariate and every recorded one); and why a candidate diverges.

A candidate whose held-out RMSE is far above the base's (`MAX_DIVERGENCE`) fits
something else on the training samples and runs away where it extrapolates. Its
share of the excess (say -663740 %) measures nothing; the diagnosis flags it with the
test where it departs most and from when.
"""

import dataclasses
import math
from typing import Any

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._drive import FORCE_DRIVEN
from .._fit import test_id
from .._models import (
    COVARIATE_EXTENSIONS,
    EXTENSIONS,
    AbstractCableModel,
    with_data_reference,
)
from .._problem import LeastSquares, Problem
from .._progress import AbstractProgressMeter
from .base import BaseFit
from .diagnosis import Candidate, shift_reference
from .discover import discover_terms, term_coefficient
from .library import base_fit_names, base_start
from .methods import Discovery, fit_quietly
from .plan import Plan
from .scoring import score_folds, scored_candidate, size_of, training_score


def score_catalogue(
    plan: Plan,
    model: AbstractCableModel,
    base: BaseFit,
    *,
    progress_meter: AbstractProgressMeter,
) -> tuple[Candidate, ...]:
    """Fit and score every catalogue candidate of `plan` around the base `model`;
    those the data cannot show or the base cannot carry are not applicable."""
    stack, losses = base.stack, [r.loss for r in base.score.fits]
    out = []
    for ext_id in plan.ids:
        cls = EXTENSIONS[ext_id]
        if plan.reasons[ext_id] or ext_id not in stack.ids:
            reason = (
                plan.reasons[ext_id] or f"{cls.__name__} cannot wrap the base model"
            )
            out.append(Candidate.not_applicable(ext_id, cls, reason, plan.how.unit))
            continue
        progress_meter.say(f"fitting candidate {ext_id}")
        # From the user's start (not the base fit, which has absorbed part of the
        # effect into the base's parameters and is often a local minimum for the
        # extended model), then from the base fit when that fits the training data
        # worse than the base did. The candidates refit the base's fitted
        # parameters plus their own effect fields, never the extension's fixed ones.
        starts = [
            stack.model(m, ext_id) for m in [model, *(r.model for r in base.score.fits)]
        ]
        try:
            scored, note = _score_at_reference(plan, base, ext_id, starts, losses)
        except ValueError as first:
            # The start given fails on a test (a base of another family, a start
            # outside the extension's domain): from the fitted base alone.
            try:
                starts = [starts[1], *starts[1:]]
                scored, note = _score_at_reference(plan, base, ext_id, starts, losses)
            except ValueError:
                reason = f"its fit failed: {str(first).splitlines()[0]}"
                out.append(Candidate.not_applicable(ext_id, cls, reason, plan.how.unit))
                continue
            note = (
                note + "; " if note else ""
            ) + "from the fitted base (the start fails)"
        result = scored.fits[0]
        out.append(
            scored_candidate(
                ext_id,
                result,
                (scored.heldout_rmse, scored.train_rmse, scored.num_train),
                size_of(result, cls.SIZE_FIELD, cls.SIZE_UNIT),
                note,
                base.against,
                plan.how,
            )
        )
    return tuple(out)


def _score_at_reference(plan: Plan, base: BaseFit, ext_id: str, starts, losses):
    """`(score, note)` of the candidate `ext_id` from `starts` (the stack with it
    on, from the user's start and from each fold's base fit).

    A time shift (a = 1 at its reference) is also scored with its reference at the
    data's median temperature ([`jaxcable.with_data_reference`][]): the base's time
    scales that are not refitted (eta0, t_c, the Eq. 8 lambdas) belong to the
    shift's reference, off by a(T) for the whole data when that is not the data's
    (1.28 for 60 kJ/mol at 23 °C against the default 20 °C). The one that fits the
    training data better is kept (the median on a tie); the note says which."""

    def score(models):
        return score_folds(
            plan.parts,
            lambda k: [models[0], models[1 + k]],
            base.fitter(ext_id),
            base_losses=losses,
            how=plan.how,
            same_tests=plan.split == "time",
        )

    moved = [with_data_reference(m, plan.tests) for m in starts]
    median = shift_reference(base.stack.own_model(moved[0], ext_id))
    own = shift_reference(base.stack.own_model(starts[0], ext_id))
    if not median or abs(median["value"] - own["value"]) < 0.05:
        return score(moved), _reference_note(median, "the tests' median")
    at_median, as_given = score(moved), score(starts)
    if as_given.train_rmse < at_median.train_rmse:
        return as_given, _reference_note(
            own,
            f"the start's; it fits the training data better than at the "
            f"tests' median, {median['value'] - 273.15:.1f} °C",
        )
    return at_median, _reference_note(median, "the tests' median")


def _reference_note(ref: dict, why: str) -> str:
    """The note of a time shift's candidate: where its reference is, and why."""
    if ref.get("field") != "T_ref":
        return ""
    at = f"{ref['celsius']:.1f} °C"
    return f"reference {at} ({why}): its base is the material at {at}"


def candidate_id(ext_id: str, column: str) -> str:
    """The id of the covariate extension `ext_id` driven by `column`."""
    return f"{ext_id}[{column}]"


def covariate_candidates(
    plan: Plan,
    base: BaseFit,
    method: LeastSquares,
    progress_meter: AbstractProgressMeter,
) -> tuple[Candidate, ...]:
    """Fit and score every covariate extension of `plan.covariate_ids` for every
    recorded column of `plan.columns`, on the time split of force-driven tests
    (residuals in m, scores in mm).

    **Arguments:**

    - `plan`: the diagnosis's `Plan`.
    - `base`: the base model's `BaseFit` on the training samples.
    - `method`: the fits' [`jaxcable.LeastSquares`][] (one start).
    - `progress_meter`: told of each fit.

    **Returns:**

    One `Candidate` per column and form (none without a recorded covariate). Each
    starts from the fitted base (per-test values averaged) with the form's start
    value (`_covariate_start`); then the base's fitted parameters are refitted with
    its own.
    """
    tests, how = plan.tests, plan.how
    names, per = base_fit_names(base.fit)
    if not plan.columns or not plan.covariate_ids:
        return ()
    held = [t.mask for t in plan.time_fold.held]
    out = []
    for column in plan.columns:
        for ext_id in plan.covariate_ids:
            cls = COVARIATE_EXTENSIONS[ext_id]
            progress_meter.say(f"fitting candidate {ext_id} ({column})")
            start = _covariate_start(plan, base, cls, column, method)
            result = fit_quietly(
                Problem(
                    start,
                    plan.time_fold.train,
                    fit=[*names, *cls.EFFECT_FIELDS],
                    per_test=per,
                    drive=FORCE_DRIVEN.name,
                    covariate=column,
                ),
                method,
            )
            heldout = (
                how.rmse(result.model, tests, range(len(tests)), held, column)
                if math.isfinite(result.loss)
                else math.inf
            )
            unit = cls.SIZE_UNIT.replace("[c]", f"[{column}]")
            size = size_of(result, cls.SIZE_FIELD, unit, f"{cls.SIZE_FIELD} ({column})")
            note = f"{cls.__name__} driven by the column {column!r}"
            score = training_score(result, heldout)
            out.append(
                scored_candidate(
                    candidate_id(ext_id, column),
                    result,
                    score,
                    size,
                    note,
                    base.against,
                    how,
                    covariate=column,
                )
            )
    return tuple(out)


def _covariate_start(
    plan: Plan, base: BaseFit, cls: type, column: str, method: LeastSquares
) -> AbstractCableModel:
    """The start of the covariate form `cls` driven by `column`: the fitted base
    wrapped, its size at the regression coefficient of its library term
    (`LIBRARY_TERM`: its strain per unit of the form's parameter), else at the
    effect fitted alone on the fitted base when that fits the training data better
    than the base did (from `wrap`'s values; a shift's `c_ref` at the column's
    median)."""
    # A shift's reference at the column's median: the base is the material at that
    # level, the shift carries only the contrast.
    start = with_data_reference(cls.wrap(base_start(base.fit)), plan.tests, column)
    # The joint fit stalls near a start off the data's scale (its parameter is
    # linear, scaled by the start: a swelling coefficient stayed at its `wrap`
    # start, m = 1.0e-12 against the 4e-12 hidden).
    held = [t.mask for t in plan.time_fold.held]
    value = (
        None
        if cls.LIBRARY_TERM is None
        else term_coefficient(base.fit, plan.tests, held, column, cls.LIBRARY_TERM)
    )
    if value is not None:
        dtype = jnp.result_type(getattr(start, cls.SIZE_FIELD))
        return eqx.tree_at(
            lambda m: getattr(m, cls.SIZE_FIELD), start, jnp.asarray(value, dtype)
        )
    alone = fit_quietly(
        Problem(
            start,
            plan.time_fold.train,
            fit=cls.EFFECT_FIELDS,
            drive=FORCE_DRIVEN.name,
            covariate=column,
        ),
        method,
    )
    if math.isfinite(alone.loss) and alone.loss < base.fit.loss:
        return alone.model
    return start


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


def discovered_candidate(
    plan: Plan,
    base: BaseFit,
    method: LeastSquares,
    progress_meter: AbstractProgressMeter,
) -> Discovered | None:
    """The best discovered term over no covariate and each recorded one, scored.

    The regression (no joint fit) runs for each covariate option; the option whose
    chosen support leaves the least held-out residual is fitted jointly with the
    base ([`jaxcable.discover`][]) and scored like the catalogue's candidates (same
    held-out samples, BIC, size = its best-determined coefficient). It runs on the
    time split of force-driven tests.

    **Arguments:**

    - `plan`: the diagnosis's `Plan`.
    - `base`: the base model's `BaseFit` on the training samples.
    - `method`: the joint fit's [`jaxcable.LeastSquares`][] (one start).
    - `progress_meter`: told of the stage.

    **Returns:**

    A `Discovered`, or None when no option found a term or its fit failed.
    """
    tests, base_fit = plan.tests, base.fit
    progress_meter.say("discovering a term")
    held = [t.mask for t in plan.time_fold.held]
    scores: dict[str, float] = {}
    best, best_score = None, math.inf
    # A base driven by a covariate (named in an earlier round) reads it in every
    # option: the library's covariate terms are then that column's.
    options = [plan.how.covariate] if plan.how.covariate else [None, *plan.columns]
    regression = Discovery(joint_fit=False)
    for covariate in options:
        found = discover_terms(base_fit, tests, covariate, held, regression)
        if not found.terms:
            continue
        score = dict(found.path)[found.support]
        scores[covariate or "-"] = score
        if score < best_score:
            best, best_score = covariate, score
    if not scores:
        return None
    # As for the catalogue's candidates, identifiability is reported in the
    # candidate's fit, not warned about (`fit_quietly`).
    found = discover_terms(base_fit, tests, best, held, Discovery(least_squares=method))
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


def departure(plan: Plan, base: BaseFit, candidate: Candidate) -> str:
    """Where a diverging candidate departs from the data: the test of its worst
    held-out RMSE against the base's, and the first sample of that test where its
    residual exceeds twice the base's largest there.

    **Arguments:**

    - `plan`: the diagnosis's `Plan`.
    - `base`: the base's `BaseFit`.
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
