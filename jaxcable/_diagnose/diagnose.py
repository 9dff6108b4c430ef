"""What the simulation gets wrong: the decision of [`jaxcable.diagnose`][].

The workflow:

1. split every test into a training part and a held-out part (a blocked time split:
   the last `holdout` fraction of each test's samples; or cross-validation by tests);
2. fit the base model on the training parts; its residuals on the whole of every test
   are analysed for structure (against time under load, force, loading vs unloading,
   cycle number, rest time, cable length, rate, temperature, elapsed time; lag-1
   autocorrelation against the white-noise band);
3. fit every candidate extension ([`jaxcable.EXTENSIONS`][]) wrapped around the base
   (from the user's start values, and from the fitted base where that start fits the
   training data worse than the base did; the base's parameters are refitted with
   the extension's);
4. score each by its held-out RMSE (the gain over the base's, %), by the Bayesian
   information criterion on the training parts (ΔBIC against the base), and by the
   evidence that its size parameter is not zero (|size| / standard error);
5. the verdict (`verdict.py`): `"none"` when the base is within 1.2 x the noise held
   out (nothing to explain); else `"named"`: among the candidates significant on all
   three counts that also come within `MAX_FLOOR_RATIO` x the noise held out or
   explain at least `MIN_EXPLAINED_PCT` % of the base's excess over it, the one of
   largest held-out gain; else `"unexplained"`, the partial candidates listed with
   the share of the excess each explains.
"""

import dataclasses
import math
from collections.abc import Callable, Sequence
from typing import Literal, NamedTuple

import numpy as np

from .._fit import (
    FitResult,
    LevenbergMarquardt,
    as_test_list,
    declared_parameters,
    test_id,
)
from .._models import (
    COVARIATE_EXTENSIONS,
    EXTENSIONS,
    AbstractCableModel,
    IntegratedModel,
    identifiable,
)
from .covariates import covariate_candidates
from .discovery import describe, discover_term
from .heldout import Fold, splits, with_mask
from .result import MAX_DELTA_BIC, MIN_GAIN_PCT, MIN_SIZE_Z, Candidate, Diagnosis
from .scoring import Scoring, bic, fitted_candidate, noise_floor, scoring
from .stack import stack_fitter, stack_of
from .structure import residual_structure
from .verdict import decide


# The fits stop when an accepted step lowers the sum of squares by less than FTOL of
# it (`LevenbergMarquardt.ftol`): a candidate the data do not show otherwise may
# drift along a flat valley to `max_steps` (bedding-in on the bundled data: 23 or 256
# steps from run to run, as multi-threaded rounding picks the path; 256 steps are
# most of a diagnosis's time). 1e-6 rather than scipy's 1e-8: on the 10-seed matrix
# (110 data sets, benchmarks/diagnose_matrix.py) every verdict is the same and the
# held-out RMSEs move by at most 0.16 %, while the diagnosis runs 20 % faster.
FTOL = 1e-6


class _Score(NamedTuple):
    """One model scored over every fold: RMSE on the held-out and on the training
    samples (in the diagnosis's reported unit), the number of training samples, and
    the fit of every fold."""

    heldout_rmse: float
    train_rmse: float
    num_train: int
    fits: list[FitResult]


def _discovered_candidate(
    found, base_heldout: float, bic_base: float, how
) -> Candidate:
    """The discovered term scored as a candidate (mm: force-driven tests)."""
    # Its size: the best-determined of its terms (a support may carry a weak
    # companion term, which the forward selection kept for a small held-out gain).
    values, errors = np.asarray(found.values, float), np.asarray(found.stderr, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        zs = np.where(errors > 0, np.abs(values) / errors, np.inf)
    k = int(np.nanargmax(np.where(np.isfinite(values), zs, -1.0)))
    size = (values[k], errors[k], found.units[k], f"theta{k} ({found.terms[k]})")
    held = found.heldout_rmse_mm[1]
    return fitted_candidate(
        "discovered", found.fit, held, size, found.equation, base_heldout, bic_base, how
    )


def _applicability(ext_id: str, tests) -> str:
    """Why the data cannot show an effect at all, or "" when they can."""
    if ext_id == "temperature":
        temps = [
            np.asarray(t.temperature, float)
            for t in tests
            if getattr(t, "temperature", None) is not None
        ]
        if len(temps) < len(tests):
            return "not every test records its temperature"
        span = float(np.ptp(np.concatenate(temps)))
        if span < 2.0:
            return f"the tests span {span:.2g} K: no temperature contrast"
    return ""


def _score(
    parts: list[Fold],
    start_models: Callable[[int], list[AbstractCableModel]],
    fitter: Callable,
    *,
    how: Scoring,
    same_tests: bool,
    base_losses: list[float] | None = None,
) -> _Score:
    """Fit and score one model on every fold of `parts`.

    `start_models(k)` gives fold k's start models: the first is fitted; when its
    training SSR is above the base model's on that fold (`base_losses`), the second is
    fitted too and the better kept, so that a candidate never fits its training data
    worse than the base it contains. `fitter(model, tests, index)` fits a start to
    the training tests `index` and gives `(result, model)`: the result to report and
    the fitted model to simulate (the stack, whose simulation one compiled program
    serves for every candidate). Every fit and simulation uses the drives of `how`,
    fixed on the whole tests; the scores are in its units. `same_tests`: the held-out
    tests are the training tests with other masks (the time split), so one
    simulation serves both.
    """
    sq_held = n_held = sq_train = n_train = 0.0
    results = []
    for k, fold in enumerate(parts):
        first, *others = start_models(k)
        result, fitted = fitter(first, fold.train, fold.train_index)
        if base_losses is not None and others and not (result.loss <= base_losses[k]):
            other = fitter(others[0], fold.train, fold.train_index)
            if not (result.loss <= other[0].loss):
                result, fitted = other
        results.append(result)
        if not math.isfinite(result.loss):
            return _Score(math.inf, math.inf, 1, results)
        r_train = how.residuals(fitted, fold.train, fold.train_index)
        # Shared parameters only, so the fitted model runs on any test.
        r_held = (
            r_train if same_tests else how.residuals(fitted, fold.held, fold.held_index)
        )
        for t, r in zip(fold.train, r_train):
            m = np.asarray(t.mask, bool)
            sq_train += float(np.sum(r[m] ** 2))
            n_train += int(m.sum())
        for t, r in zip(fold.held, r_held):
            m = np.asarray(t.mask, bool)
            sq_held += float(np.sum(r[m] ** 2))
            n_held += int(m.sum())
    return _Score(
        how.factor * math.sqrt(sq_held / max(n_held, 1)),
        how.factor * math.sqrt(sq_train / max(n_train, 1)),
        int(n_train),
        results,
    )


def _check_arguments(tests, model, ids, split, holdout, k) -> None:
    """Raise `ValueError` naming the first bad argument of `diagnose`."""
    if not isinstance(model, AbstractCableModel):
        raise ValueError(
            f"`model` must be a jaxcable model, got {type(model).__name__}."
        )
    known = [*EXTENSIONS, *COVARIATE_EXTENSIONS]
    unknown = [c for c in ids if c not in known]
    if unknown:
        raise ValueError(f"`candidates` names {unknown}; known extensions: {known}.")
    if split not in ("time", "tests"):
        raise ValueError(f"`split` must be 'time' or 'tests', got {split!r}.")
    if not (isinstance(holdout, (int, float)) and 0.0 < holdout <= 0.9):
        raise ValueError(f"`holdout` must be in (0, 0.9], got {holdout!r}.")
    if split == "tests" and len(tests) < 2:
        raise ValueError(
            "`split='tests'` (cross-validation by tests) needs >= 2 tests."
        )
    if split == "tests" and not (isinstance(k, int) and 2 <= k <= len(tests)):
        raise ValueError(f"`folds` must be an int in [2, {len(tests)}], got {k!r}.")
    for i, t in enumerate(tests):
        if getattr(t, "elongation", None) is None:
            raise ValueError(
                f"`tests[{i}]` ({test_id(t, i)}) has no elongation to diagnose."
            )


def diagnose(
    tests,
    model: AbstractCableModel | None = None,
    *,
    fit_names: Sequence[str] | None = None,
    candidates: Sequence[str] | None = None,
    split: Literal["time", "tests"] = "time",
    holdout: float = 0.3,
    folds: int | None = None,
    multistart: int = 1,
    max_steps: int = 256,
    key=None,
    progress=None,
    drive="auto",
    discover: bool | None = None,
) -> Diagnosis:
    """Find what a model gets wrong on measured data and name the physical cause.

    See the module's description of the workflow (`jaxcable._diagnose.diagnose`). A
    candidate is significant when (1) its held-out RMSE is at least `MIN_GAIN_PCT` =
    5 % below the base's, (2) ΔBIC = BIC(candidate) - BIC(base) <= -10 on the training
    samples (BIC = n ln(SSR/n) + p ln n), and (3) its size parameter is at least
    `MIN_SIZE_Z` = 3 standard errors from zero. The verdict is `"none"` whenever the
    base model's held-out RMSE is within `MIN_EXCESS` = 1.2 times the noise level
    estimated from the data: there is nothing left to explain. Else a significant
    candidate is named only when it is also sufficient: its held-out RMSE within
    `MAX_FLOOR_RATIO` times the noise, or its share of the base's held-out excess
    over the noise, 100 (base^2 - candidate^2) / (base^2 - noise^2), at least
    `MIN_EXPLAINED_PCT` %; the named cause is the sufficient significant candidate
    of largest held-out gain. Otherwise the verdict, and `named_cause`, is
    `"unexplained"`: every candidate keeps its `explained_pct`.

    **Discovery.** When the verdict would be `"unexplained"` (or `discover=True`),
    [`jaxcable.discover`][] looks for a term the catalogue lacks: a sparse regression
    of the base's residual on a library of terms of the model's own state and of
    every recorded covariate (each extra column in turn), fitted jointly with the
    base; it becomes the candidate `"discovered"`, scored like the others (same
    held-out samples, BIC, size = its best-determined coefficient), and is named
    (`named_cause="discovered"`, the equation in `Diagnosis.discovered`) when it is
    significant and sufficient. It runs on the time split of force-driven tests.

    **Drives.** As in [`jaxcable.fit`][], a force-controlled test is driven by its
    force and scored on its elongation, a displacement-controlled one (relaxation, a
    constant crosshead rate) driven by its elongation and scored on its force. Each
    test's drive is resolved once, on the whole tests (`drive`), and every fit and
    simulation of every fold uses it. The RMSEs, the noise level, BIC and the residual
    structure are all in the scored channels: mm when every test is driven by its
    force, N when every test is driven by its elongation, and, when the drives mix,
    noise units: each test's residual divided by the noise standard deviation of its
    scored channel (estimated once on the whole test, as a mixed fit weighs it), so
    that held-out scores are comparable across channels (`Diagnosis.unit`).

    **Arguments:**

    - `tests`: the measured tests ([`jaxcable.TestData`][] with elongation).
    - `model`: the base model and its start values (default
        [`jaxcable.IntegratedModel`][] with its defaults).
    - `fit_names`: the base parameters to fit (default: the model's identifiable
        parameters in the model registry, for the integrated model Park's six of
        `PARK_IDENTIFIABLE`; else all).
    - `candidates`: extension ids to try (default: all of [`jaxcable.EXTENSIONS`][]
        and of [`jaxcable.COVARIATE_EXTENSIONS`][]; the latter are tried for each
        extra column every test records, on the time split of force-driven tests,
        with ids such as `mechano_sorptive[humidity_pct]`).
    - `split`: `"time"`: a blocked time split, the last `holdout` fraction of every
        test's samples held out (the model still runs through them; they are not
        fitted). `"tests"`: k-fold cross-validation over whole tests (test i is in
        fold i mod k; one fit per fold and candidate; needs at least two tests).
    - `holdout`: the held-out fraction for `split="time"`, in (0, 0.9].
    - `folds`: k for `split="tests"` (default: one fold per test, leave-one-out).
    - `multistart`: starts of the base fit (the candidates start from it).
    - `max_steps`: Levenberg-Marquardt steps per fit.
    - `key`: PRNG key of the multistart perturbations.
    - `progress`: an optional callable `progress(message: str)` told of each fit.
    - `drive`: `"auto"` (default: each test's `metadata['control']`, else detected
        from its data), `"force"`, `"elongation"`, or one of these per test.
    - `discover`: look for a discovered term: None (default) when the verdict would
        be `"unexplained"`, True always, False never.

    **Returns:**

    A [`jaxcable.Diagnosis`][].

    **Raises:**

    `ValueError` naming the argument: an unknown candidate id, a bad `split` or
    `holdout`, too few tests for leave-one-test-out, a bad `drive`; and the errors of
    [`jaxcable.fit`][] for bad data.
    """
    tests = as_test_list(tests)
    if model is None:
        model = IntegratedModel()
    ids = [*EXTENSIONS, *COVARIATE_EXTENSIONS] if candidates is None else [*candidates]
    k = len(tests) if folds is None else folds
    _check_arguments(tests, model, ids, split, holdout, k)
    # The covariates' extensions are fitted apart, on the time split (below).
    covariate_ids = [i for i in ids if i in COVARIATE_EXTENSIONS]
    ids = [i for i in ids if i in EXTENSIONS]
    tests = [
        t
        if getattr(t, "mask", None) is not None
        else with_mask(t, np.ones(len(t.time), bool))
        for t in tests
    ]
    names = tuple(fit_names) if fit_names is not None else identifiable(model)
    if names is None:  # not in the registry: every parameter
        names = tuple(declared_parameters(model))
    say = progress or (lambda message: None)
    # The drives and residual units, once for the whole tests: no fold re-detects.
    how = scoring(tests, drive)
    parts = splits(tests, split, holdout, k)
    settings = dict(how=how, same_tests=split == "time")

    # Which candidates the data can show and the base can carry.
    reasons = {}
    for ext_id in ids:
        reason = _applicability(ext_id, tests)
        if not reason:
            try:
                EXTENSIONS[ext_id].wrap(model)
            except ValueError as e:
                reason = str(e)
        reasons[ext_id] = reason
    # The base and every candidate are one model, each fit a choice of free
    # parameters: one compiled kernel (and one simulation) serves them all.
    stack = stack_of(model, [i for i in ids if not reasons[i]], names)
    solver = LevenbergMarquardt(rtol=1e-6, atol=1e-6, ftol=FTOL)
    fitter = stack_fitter(
        stack, how, model, max_steps=max_steps, key=key, solver=solver
    )

    say(f"fitting the base model {type(model).__name__}")
    base = _score(
        parts,
        lambda k: [stack.model(model, None)],
        fitter(None, multistart),
        **settings,
    )
    base_fit = base.fits[0]
    base_losses = [r.loss for r in base.fits]
    if not math.isfinite(base.heldout_rmse):
        raise RuntimeError(
            f"jaxcable.diagnose: the base model's fit failed ({base_fit.message})."
        )
    bic_base = bic(base.train_rmse, base.num_train, len(base_fit.names), how.factor)

    # The base's residuals over whole tests in their scored channels, for the
    # structure analysis.
    structure = residual_structure(
        tests,
        how.residuals(stack.model(base_fit.model, None), tests, range(len(tests))),
        drives=how.drives,
        unit=how.unit,
    )

    out = []
    for ext_id in ids:
        cls = EXTENSIONS[ext_id]
        if reasons[ext_id] or ext_id not in stack.ids:
            reason = reasons[ext_id] or f"{cls.__name__} cannot wrap the base model"
            out.append(Candidate.not_applicable(ext_id, cls, reason, how.unit))
            continue
        say(f"fitting candidate {ext_id}")
        # From the user's start (not the base fit, which has absorbed part of the
        # effect into the base's parameters and is often a local minimum for the
        # extended model), then from the base fit when that fits the training data
        # worse than the base did. The candidates refit the base's fitted
        # parameters plus their own effect fields, never the extension's fixed ones.
        starts = [stack.model(model, ext_id)] + [
            stack.model(r.model, ext_id) for r in base.fits
        ]
        scored = _score(
            parts,
            lambda k: [starts[0], starts[1 + k]],
            fitter(ext_id),
            base_losses=base_losses,
            **settings,
        )
        result = scored.fits[0]
        size_index = result.names.index(cls.SIZE_FIELD)
        size = float(result.values[size_index])
        stderr = float(result.stderr[size_index])
        held = scored.heldout_rmse
        gain = 100.0 * (base.heldout_rmse - held) / base.heldout_rmse
        delta_bic = (
            bic(scored.train_rmse, scored.num_train, len(result.names), how.factor)
            - bic_base
        )
        z = abs(size) / stderr if stderr > 0 else (math.inf if size != 0 else 0.0)
        significant = bool(
            math.isfinite(held)
            and gain >= MIN_GAIN_PCT
            and delta_bic <= MAX_DELTA_BIC
            and z >= MIN_SIZE_Z
        )
        out.append(
            Candidate(
                ext_id,
                held,
                gain,
                scored.train_rmse,
                delta_bic,
                size,
                stderr,
                cls.SIZE_UNIT,
                cls.SIZE_FIELD,
                significant,
                True,
                "",
                result,
                how.unit,
            )
        )

    if split == "time" and how.unit == "mm":
        out += covariate_candidates(
            base_fit,
            tests,
            covariate_ids,
            holdout=holdout,
            base_heldout=base.heldout_rmse,
            bic_base=bic_base,
            how=how,
            max_steps=max_steps,
            say=say,
        )
    noise = noise_floor(tests, how)

    def verdict_on(candidates):
        return decide(
            base.heldout_rmse,
            noise,
            [c.heldout_rmse for c in candidates],
            [c.significant for c in candidates],
            structure["autocorrelation"],
        )

    decision = verdict_on(out)
    discovered: dict = {}
    wanted = decision.verdict == "unexplained" if discover is None else discover
    if wanted and split == "time" and how.unit == "mm":
        say("discovering a term")
        found, scores = discover_term(base_fit, tests, holdout, max_steps=max_steps)
        if found is not None and found.fit is not None:
            out.append(_discovered_candidate(found, base.heldout_rmse, bic_base, how))
            discovered = {**describe(found), "covariate_scores_mm": scores}
            decision = verdict_on(out)
    out = [
        dataclasses.replace(c, explained_pct=share)
        for c, share in zip(out, decision.explained_pct)
    ]
    if decision.named is not None:
        best = out[decision.named]
        named, extended, gain = best.id, best.heldout_rmse, best.gain_pct
        effect = {
            "parameter": best.size_name,
            "value": best.size,
            "stderr": best.size_stderr,
            "unit": best.size_unit,
        }
    else:
        named = "unexplained" if decision.verdict == "unexplained" else "none"
        extended, gain, effect = base.heldout_rmse, 0.0, {}
    return Diagnosis(
        base_model=type(model).__name__,
        named_cause=named,
        base_heldout_rmse=base.heldout_rmse,
        base_train_rmse=base.train_rmse,
        extended_heldout_rmse=extended,
        gain_pct=gain,
        effect=effect,
        candidates=tuple(out),
        structure=structure,
        noise=noise,
        split=(
            f"last {holdout:.0%} of every test's samples"
            if split == "time"
            else "leave-one-test-out"
            if k == len(tests)
            else f"{k}-fold by tests"
        ),
        holdout=holdout if split == "time" else None,
        test_ids=tuple(test_id(t, i) for i, t in enumerate(tests)),
        base_fit=base_fit,
        unit=how.unit,
        drives=how.drives,
        scales=tuple(float(x) for x in how.scales),
        verdict=decision.verdict,
        discovered=discovered,
    )
