"""What the simulation gets wrong: [`jaxcable.diagnose`][], round after round of a
pipeline of stages (`stages.py`) over one round state:

1. the plan (`plan.py`, a `Plan`): split every test into a training part and a
   held-out part ([`jaxcable.HeldOut`][]: a blocked time split, the last `fraction`
   of each test's samples; or cross-validation by tests), fix every test's drive
   and residual unit once, and keep the candidates the data can show
   (`applicability`) and the base can carry (`wrap`); the base fitted
   (`base.py`, a `BaseFit`) on the training parts; its residuals on the whole of
   every test analysed for structure (against time under load, force, loading vs
   unloading, cycle number, rest time, cable length, rate, temperature, elapsed
   time; lag-1 autocorrelation against the white-noise band), and the noise
   estimated from the data (`noise.py`);
2. the right family first (`family.py`, the first round): when the base is far
   from the data before any candidate, the other base models are fitted on the
   same split; one clearly better held out (by the significance rule of a
   candidate) becomes the base of the rounds (`Diagnosis.family` says which and
   why);
3. the catalogue (`candidates.py`): every candidate extension
   ([`jaxcable.EXTENSIONS`][]) wrapped around the base is fitted (from the user's
   start values, and from the fitted base where that start fits the training data
   worse than the base did; the base's parameters are refitted with the
   extension's) and scored (`scoring.py`) by its held-out RMSE (the gain over the
   base's, %), by the Bayesian information criterion on the training parts (ΔBIC
   against the base), and by the evidence that its size parameter is not zero
   (|size| / standard error);
4. the covariate candidates (`candidates.py`): the same for the extensions a
   recorded covariate drives ([`jaxcable.COVARIATE_EXTENSIONS`][]);
5. the verdict (the rule in `rule.py`, the `Diagnosis` in `diagnosis.py`):
   `"none"` when the base is within 1.2 x the noise held out (nothing to
   explain); else `"named"`: among the candidates significant on all three counts
   that also come within `MAX_FLOOR_RATIO` x the noise held out or explain at least
   `MIN_EXPLAINED_PCT` % of the base's excess over it, the one of largest held-out
   gain; else `"unexplained"`, the partial candidates listed with the share of the
   excess each explains;
6. discovery (`discover.py`), when the catalogue does not explain the residual;
7. the rounds (`rounds.py`): after a cause is named, the stages again around the
   extended model, until nothing is left to name; then each earlier cause is tried
   out of the final model.
"""

import dataclasses
import warnings

from .._fit import StartMovedWarning, start_failure, start_scaling
from .._problem import Problem
from .._progress import AbstractProgressMeter, NoProgressMeter, check_progress_meter
from .diagnosis import Diagnosis
from .methods import CandidateSearch, check_arguments
from .rounds import diagnose_rounds


def diagnose(
    problem: Problem,
    method: CandidateSearch = CandidateSearch(),
    *,
    progress_meter: AbstractProgressMeter | None = None,
) -> Diagnosis:
    """Find what a model gets wrong on measured data and name the physical cause.

    ```python
    problem = jc.Problem(jc.IntegratedModel(), tests).with_scaled_start()
    diagnosis = jc.diagnose(problem)  # jc.CandidateSearch() by default
    print(diagnosis.summary())
    ```

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
    within `MAX_FLOOR_RATIO` x the noise, nothing more is named, or
    `method.max_rounds` rounds have run. A round with significant candidates none of which is
    sufficient takes the best as a partial cause, kept only when the rounds after
    it explain the rest with it (the rounds). `causes` lists the
    causes in the order found, `cause_gains` each one's held-out gain over its
    round's base, `final_heldout_rmse` what is left, `rounds` every round.

    **Discovery.** When the verdict would be `"unexplained"` (or `method.discover` is True),
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
    is `MIN_GAIN_PCT` % lower (the rounds).

    **Drives.** As in [`jaxcable.fit`][], a force-controlled test is driven by its
    force and scored on its elongation, a displacement-controlled one (relaxation, a
    constant crosshead rate) driven by its elongation and scored on its force. Each
    test's drive is resolved once, on the whole tests (`problem.drive`), and every
    fit and simulation of every fold uses it. The RMSEs, the noise level, BIC and the
    residual structure are all in the scored channels: mm when every test is driven
    by its force, N when every test is driven by its elongation, and, when the
    drives mix, noise units: each test's residual divided by the noise standard
    deviation of its scored channel (estimated once on the whole test, as a mixed
    fit weighs it), so that held-out scores are comparable across channels
    (`Diagnosis.unit`).

    **Arguments:**

    - `problem`: a [`jaxcable.Problem`][]: the base model and its start values (a
        start that fails on a test, outside its domain, not finite or beyond break,
        is moved to the start scaled to the data, [`jaxcable.scaled_start`][], with
        a [`jaxcable.StartMovedWarning`][] that says why; `problem.with_scaled_start()`
        starts there), the measured tests ([`jaxcable.TestData`][] with
        elongation), the base parameters to fit (`fit`; default the model's
        identifiable parameters in the model registry, for the integrated model
        Park's six of `PARK_IDENTIFIABLE`; else all), each test's drive, and the
        extra column the base reads (`covariate`, default none). Its `per_test` and
        `transforms` must be empty.
    - `method`: a [`jaxcable.CandidateSearch`][] (default `jc.CandidateSearch()`):
        the candidates, the held-out split ([`jaxcable.HeldOut`][]), the fits'
        [`jaxcable.LeastSquares`][], when to discover, the most rounds and when to
        check the family.
    - `progress_meter`: how progress is shown: [`jaxcable.NoProgressMeter`][]
        (the default: nothing), [`jaxcable.TextProgressMeter`][] (a bar, and a line
        of news for each fit) or [`jaxcable.CallbackProgressMeter`][].

    **Returns:**

    A [`jaxcable.Diagnosis`][].

    **Raises:**

    `TypeError` naming `problem` or `method` of another type; `ValueError` naming
    what is wrong: too few tests for the split by tests, `folds` above the number
    of tests, a test without elongation, per-test parameters, an empty `fit`, a bad
    `drive`; and the errors of [`jaxcable.fit`][] for bad data.
    """
    check_arguments(problem, method, CandidateSearch)
    meter = check_progress_meter(progress_meter, NoProgressMeter())
    problem = _data_start(problem, meter)
    with meter.bar("diagnosing"):
        return diagnose_rounds(problem, method, meter)


def _data_start(problem: Problem, meter: AbstractProgressMeter) -> Problem:
    """`problem`, its start moved (scaled to the data) only when it fails on a
    test."""
    model, tests, drive = problem.model, problem.tests, problem.drive
    reason = start_failure(model, tests, drive=drive)
    if not reason:
        return problem
    scaling = start_scaling(model, tests, drive=drive)
    note = f"{reason}; moved to the start scaled to the data: {scaling.describe()}"
    warnings.warn(note, StartMovedWarning, stacklevel=3)
    meter.say(f"start moved: {note}")
    return dataclasses.replace(problem, model=scaling.model)
