"""What the simulation gets wrong: the decision of [`jaxcable.diagnose`][], in
named stages, each a function with a typed result:

1. choose the candidates (`plan.py`, a `Plan`): split every test into a training
   part and a held-out part (a blocked time split: the last `holdout` fraction of
   each test's samples; or cross-validation by tests), fix every test's drive and
   residual unit once, and keep the candidates the data can show
   (`applicability`) and the base can carry (`wrap`);
2. fit the base (`base.py`, a `BaseFit`) on the training parts; its residuals on
   the whole of every test are analysed for structure (against time under load,
   force, loading vs unloading, cycle number, rest time, cable length, rate,
   temperature, elapsed time; lag-1 autocorrelation against the white-noise band);
3. score the catalogue (`catalogue.py`): fit every candidate extension
   ([`jaxcable.EXTENSIONS`][]) wrapped around the base (from the user's start
   values, and from the fitted base where that start fits the training data worse
   than the base did; the base's parameters are refitted with the extension's) and
   score each (`scoring.py`) by its held-out RMSE (the gain over the base's, %), by
   the Bayesian information criterion on the training parts (ΔBIC against the
   base), and by the evidence that its size parameter is not zero (|size| /
   standard error);
4. the covariate candidates (`covariates.py`): the same for the extensions a
   recorded covariate drives ([`jaxcable.COVARIATE_EXTENSIONS`][]);
5. discovery (`discover.py`), when the catalogue does not explain the residual;
6. the verdict (`outcome.py`, the `Diagnosis`; the rule in `verdict.py`): `"none"`
   when the base is within 1.2 x the noise held out (nothing to explain); else
   `"named"`: among the candidates significant on all three counts that also come
   within `MAX_FLOOR_RATIO` x the noise held out or explain at least
   `MIN_EXPLAINED_PCT` % of the base's excess over it, the one of largest held-out
   gain; else `"unexplained"`, the partial candidates listed with the share of the
   excess each explains;
7. the rounds (`rounds.py`): after a cause is named, stages 1-6 again around the
   extended model, until nothing is left to name.

The right family first (`family.py`): when the first round's base is far from the
data before any candidate, the other base models are fitted on the same split;
one clearly better held out (by the significance rule of a candidate) becomes the
base of the rounds (`Diagnosis.family` says which and why).
"""

import warnings
from collections.abc import Sequence
from typing import Literal

from .._fit import StartMovedWarning, start_failure, start_scaling
from .._models import AbstractCableModel, IntegratedModel
from .._progress import AbstractProgressMeter, NoProgressMeter, check_progress_meter
from .result import Diagnosis
from .rounds import check_max_rounds, diagnose_rounds


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
    progress_meter: AbstractProgressMeter | None = None,
    drive="auto",
    discover: bool | None = None,
    max_rounds: int = 3,
    family: bool | None = None,
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

    **The right family first.** When the base's held-out RMSE is at least
    `FAMILY_EXCESS` = 10 x the noise and its residual systematic (lag-1
    autocorrelation >= 0.5), the other base models (integrated, five-element,
    Burgers, Bouc-Wen, Findley's power law) are fitted on the same split before any
    candidate; one whose held-out RMSE is `MIN_GAIN_PCT` % lower with ΔBIC <= -10
    (the best such) becomes the base of the rounds. `Diagnosis.family` gives each
    family's held-out RMSE and BIC and the family chosen, with the reason.

    **Every cause in turn.** After a cause is named, the diagnosis looks again with
    the extended model as its base (the named effect's parameters free with the
    base's), at every candidate not yet named, until the held-out RMSE left is
    within `MAX_FLOOR_RATIO` x the noise, nothing more is named, or `max_rounds`
    rounds have run. A round with significant candidates none of which is
    sufficient takes the best as a partial cause, kept only when the rounds after
    it explain the rest with it (`jaxcable._diagnose.rounds`). `causes` lists the
    causes in the order found, `cause_gains` each one's held-out gain over its
    round's base, `final_heldout_rmse` what is left, `rounds` every round.

    **Discovery.** When the verdict would be `"unexplained"` (or `discover=True`),
    [`jaxcable.discover`][] looks for a term the catalogue lacks: a sparse regression
    of the base's residual on a library of terms of the model's own state and of
    every recorded covariate (each extra column in turn), fitted jointly with the
    base; it becomes the candidate `"discovered"`, scored like the others (same
    held-out samples, BIC, size = its best-determined coefficient), and is named
    (`named_cause="discovered"`, the equation in `Diagnosis.discovered`) when it is
    significant and sufficient. It runs on the time split of force-driven tests. It
    runs too when the named cause leaves more than `MIN_EXCESS` x the noise and
    reads none of the recorded covariates, or reads one through a covariate form
    (without memory); the term is then named instead only when its held-out RMSE
    is `MIN_GAIN_PCT` % lower (`jaxcable._diagnose.rounds`).

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
        [`jaxcable.IntegratedModel`][] with its defaults scaled to the data,
        [`jaxcable.scaled_start`][]). A start that fails on a test (outside its
        domain, not finite, beyond break) is moved to the start scaled to the data,
        with a [`jaxcable.StartMovedWarning`][] that says why.
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
    - `progress_meter`: how progress is shown: [`jaxcable.NoProgressMeter`][]
        (the default: nothing), [`jaxcable.TextProgressMeter`][] (a bar, and a line
        of news for each fit) or [`jaxcable.CallbackProgressMeter`][].
    - `drive`: `"auto"` (default: each test's `metadata['control']`, else detected
        from its data), a drive ([`jaxcable.FORCE_DRIVEN`][],
        [`jaxcable.ELONGATION_DRIVEN`][]) or its name, or one of these per test.
    - `discover`: look for a discovered term: None (default) when the verdict would
        be `"unexplained"` (or a covariate is unused, above), True always, False
        never.
    - `max_rounds`: the most rounds (causes) to look for, >= 1 (1: stop after the
        first cause).
    - `family`: compare the other base models (`jaxcable._diagnose.family`): None
        (default) when the base is far from the data (held-out RMSE >=
        `FAMILY_EXCESS` x the noise, residual systematic), True always, False
        never.

    **Returns:**

    A [`jaxcable.Diagnosis`][].

    **Raises:**

    `ValueError` naming the argument: an unknown candidate id, a bad `split` or
    `holdout`, too few tests for leave-one-test-out, a bad `drive`; and the errors of
    [`jaxcable.fit`][] for bad data.
    """
    check_max_rounds(max_rounds)
    if family is not None and not isinstance(family, bool):
        raise ValueError(f"`family` must be None, True or False, got {family!r}.")
    meter = check_progress_meter(progress_meter, NoProgressMeter())
    model = _data_start(model, tests, drive, meter)
    options = dict(
        split=split,
        holdout=holdout,
        folds=folds,
        drive=drive,
        multistart=multistart,
        max_steps=max_steps,
        key=key,
        discover=discover,
        family=family,
    )
    with meter.bar("diagnosing"):
        return diagnose_rounds(
            tests,
            model,
            fit_names=fit_names,
            candidates=candidates,
            max_rounds=max_rounds,
            options=options,
            progress_meter=meter,
        )


def _data_start(model, tests, drive, meter: AbstractProgressMeter):
    """The start of a diagnosis: the default model scaled to the data when `model`
    is None; else `model`, moved (scaled to the data) only when it fails on a test."""
    if model is None:
        return start_scaling(IntegratedModel(), tests, drive=drive).model
    reason = start_failure(model, tests, drive=drive)
    if not reason:
        return model
    scaling = start_scaling(model, tests, drive=drive)
    note = f"{reason}; moved to the start scaled to the data: {scaling.describe()}"
    warnings.warn(note, StartMovedWarning, stacklevel=3)
    meter.say(f"start moved: {note}")
    return scaling.model
