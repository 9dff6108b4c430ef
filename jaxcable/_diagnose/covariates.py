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
import numpy as np

from .._fit import FitResult, IdentifiabilityWarning, fit
from .._models import COVARIATE_EXTENSIONS
from .discover import base_start, discover, heldout_rmse_mm
from .discovery import covariates
from .heldout import heldout_start, with_mask
from .result import Candidate
from .scoring import Scoring, fitted_candidate


# The library term of `jaxcable.DiscoveredTerm` that is each form's strain per unit
# of its parameter: its regression coefficient on the base's residual, with the
# base's sensitivities (as the discovery fits it), starts the form's fit. A time
# shift has none.
_LIBRARY_TERM = {"covariate_strain": "c_rate", "mechano_sorptive": "sigma_c_abs_rate"}


def _regression_start(base_fit, tests, held, column, ext_id) -> float | None:
    """The coefficient of the form's library term, or None (no such term, or the
    regression does not keep it)."""
    term = _LIBRARY_TERM.get(ext_id)
    if term is None:
        return None
    found = discover(
        base_fit,
        tests,
        covariate=column,
        held=held,
        terms=(term,),
        min_gain_pct=-math.inf,
        joint_fit=False,
    )
    value = float(found.coefficients[0]) if found.terms else 0.0
    return value if math.isfinite(value) and value != 0.0 else None


def candidate_id(ext_id: str, column: str) -> str:
    """The id of the covariate extension `ext_id` driven by `column`."""
    return f"{ext_id}[{column}]"


def covariate_candidates(
    base_fit: FitResult,
    tests,
    ids,
    *,
    holdout: float,
    base_heldout: float,
    bic_base: float,
    how: Scoring,
    max_steps: int,
    say=lambda message: None,
) -> list[Candidate]:
    """Fit and score every covariate extension of `ids` for every recorded column.

    **Arguments:**

    - `base_fit`: the base model's fit on the training samples of the time split.
    - `tests`: the tests (force-driven; their extra columns are the covariates).
    - `ids`: ids of [`jaxcable.COVARIATE_EXTENSIONS`][] to try.
    - `holdout`: the held-out fraction of the time split.
    - `base_heldout`, `bic_base`: the base's held-out RMSE (mm) and BIC.
    - `how`: the diagnosis's scoring (mm).
    - `max_steps`: Levenberg-Marquardt steps per fit.
    - `say`: told of each fit.

    **Returns:**

    One `Candidate` per column and form (none without a recorded covariate). Each
    starts from the fitted base (per-test values averaged) with the form's start
    value: the regression coefficient of its library term (`_LIBRARY_TERM`), else
    the value fitted alone on the fitted base (from `wrap`'s; a shift's `c_ref` at
    the column's mean); then the base's fitted parameters are refitted with its
    own.
    """
    columns = covariates(tests)
    if not columns or not ids:
        return []
    held = [
        np.arange(len(t.time)) >= heldout_start(len(t.time), holdout) for t in tests
    ]
    train = [with_mask(t, ~h) for t, h in zip(tests, held)]
    base = base_start(base_fit)
    per = ["base." + n for n in getattr(base_fit, "per_test", ())]
    names = [
        n
        for n in dict.fromkeys("base." + n.split("[")[0] for n in base_fit.names)
        if n not in per
    ]
    out = []
    for column in columns:
        record = np.concatenate([np.asarray(t.extra[column], float) for t in tests])
        for ext_id in ids:
            cls = COVARIATE_EXTENSIONS[ext_id]
            start = cls.wrap(base)
            if hasattr(start, "c_ref"):
                mean = jnp.asarray(np.mean(record), jnp.result_type(start.c_ref))
                start = eqx.tree_at(lambda m: m.c_ref, start, mean)
            say(f"fitting candidate {ext_id} ({column})")
            # As for the catalogue, identifiability is reported in the fit.
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", IdentifiabilityWarning)
                options = dict(
                    drive="force",
                    covariate=column,
                    multistart=1,
                    throw=False,
                    max_steps=max_steps,
                )
                # The joint fit stalls near a start off the data's scale (its
                # parameter is linear, scaled by the start; measured from `wrap`'s:
                # a swelling coefficient stayed at its start, m = 1.0e-12 against
                # the 4e-12 hidden). Start at the regression's coefficient, else
                # at the effect fitted alone on the fitted base.
                value = _regression_start(base_fit, tests, held, column, ext_id)
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
                heldout_rmse_mm(result.model, tests, held, column)
                if math.isfinite(result.loss)
                else math.inf
            )
            i = result.names.index(cls.SIZE_FIELD)
            size = (
                result.values[i],
                result.stderr[i],
                cls.SIZE_UNIT.replace("[c]", f"[{column}]"),
                f"{cls.SIZE_FIELD} ({column})",
            )
            note = f"{cls.__name__} driven by the column {column!r}"
            out.append(
                fitted_candidate(
                    candidate_id(ext_id, column),
                    result,
                    heldout,
                    size,
                    note,
                    base_heldout,
                    bic_base,
                    how,
                )
            )
    return out
