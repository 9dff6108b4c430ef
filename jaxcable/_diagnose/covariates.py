"""The candidates a recorded covariate drives ([`jaxcable.COVARIATE_EXTENSIONS`][]):
each form wrapped around the fitted base, for each extra column that every test
records, fitted with the base's parameters on the training samples of the time split
and scored on the held-out ones as the catalogue's candidates are. Their ids name
the column: `covariate_strain[humidity_pct]`, `mechano_sorptive[humidity_pct]`,
`covariate_shift[humidity_pct]`."""

import math
import warnings

import equinox as eqx
import jax.numpy as jnp

from .._drive import FORCE_DRIVEN
from .._fit import IdentifiabilityWarning, fit
from .._models import COVARIATE_EXTENSIONS, with_data_reference
from .._progress import AbstractProgressMeter
from .base import BaseFit
from .discover import term_coefficient
from .library import base_fit_names, base_start
from .plan import Plan
from .result import Candidate
from .scoring import scored_candidate, size_of, training_score


def candidate_id(ext_id: str, column: str) -> str:
    """The id of the covariate extension `ext_id` driven by `column`."""
    return f"{ext_id}[{column}]"


def covariate_candidates(
    plan: Plan, base: BaseFit, *, max_steps: int, progress_meter: AbstractProgressMeter
) -> tuple[Candidate, ...]:
    """Fit and score every covariate extension of `plan.covariate_ids` for every
    recorded column of `plan.columns`, on the time split of force-driven tests
    (residuals in m, scores in mm).

    **Arguments:**

    - `plan`: the diagnosis's [`Plan`][].
    - `base`: the base model's [`BaseFit`][] on the training samples.
    - `max_steps`: Levenberg-Marquardt steps per fit.
    - `progress_meter`: told of each fit.

    **Returns:**

    One `Candidate` per column and form (none without a recorded covariate). Each
    starts from the fitted base (per-test values averaged) with the form's start
    value: the regression coefficient of its library term (`LIBRARY_TERM`), else
    the value fitted alone on the fitted base (from `wrap`'s; a shift's `c_ref` at
    the column's median); then the base's fitted parameters are refitted with its
    own.
    """
    tests, ids, columns, how = plan.tests, plan.covariate_ids, plan.columns, plan.how
    base_fit = base.fit
    start_base = base_start(base_fit)
    names, per = base_fit_names(base_fit)
    if not columns or not ids:
        return ()
    train, held = plan.time_fold.train, [t.mask for t in plan.time_fold.held]
    out = []
    for column in columns:
        for ext_id in ids:
            cls = COVARIATE_EXTENSIONS[ext_id]
            # A shift's reference at the column's median: the base is the
            # material at that level, the shift carries only the contrast.
            start = with_data_reference(cls.wrap(start_base), tests, column)
            progress_meter.say(f"fitting candidate {ext_id} ({column})")
            # As for the catalogue, identifiability is reported in the fit.
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", IdentifiabilityWarning)
                options = dict(
                    drive=FORCE_DRIVEN.name,
                    covariate=column,
                    multistart=1,
                    throw=False,
                    max_steps=max_steps,
                )
                # The joint fit stalls near a start off the data's scale (its
                # parameter is linear, scaled by the start: a swelling coefficient
                # stayed at its `wrap` start, m = 1.0e-12 against the 4e-12
                # hidden). Start at the regression coefficient of its library
                # term (`LIBRARY_TERM`: its strain per unit of the form's
                # parameter), else at the effect fitted alone on the fitted base.
                value = (
                    None
                    if cls.LIBRARY_TERM is None
                    else term_coefficient(
                        base_fit, tests, held, column, cls.LIBRARY_TERM
                    )
                )
                if value is not None:
                    dtype = jnp.result_type(getattr(start, cls.SIZE_FIELD))
                    start = eqx.tree_at(
                        lambda m: getattr(m, cls.SIZE_FIELD),
                        start,
                        jnp.asarray(value, dtype),
                    )
                else:
                    alone = fit(start, train, fit=[*cls.EFFECT_FIELDS], **options)
                    if math.isfinite(alone.loss) and alone.loss < base_fit.loss:
                        start = alone.model
                result = fit(
                    start,
                    train,
                    fit=[*names, *cls.EFFECT_FIELDS],
                    per_test=per or None,
                    **options,
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
