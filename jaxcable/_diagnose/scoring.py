"""Every score of a diagnosis, in one place: a model's response in each test's scored
channel (one vmapped simulation, every sample, masked ones too), the units a
diagnosis scores in (each test's drive, fixed once on the whole tests, and its
residual unit: the `scale` of [`jaxcable.residuals`][]), the pooled RMSE of
residuals over held-out or training samples, the noise estimated from the data
(`jaxcable._diagnose.noise`, re-exported here), BIC,
and the significance of a fitted candidate.

Every test scored in its elongation (all force-driven): m, reported in mm. Every test
scored in its force (all elongation-driven): N. Tests of both kinds: each residual
divided by the noise standard deviation of its test's scored channel, dimensionless
("noise" units), as in a mixed [`jaxcable.fit`][].
"""

import math
from collections.abc import Callable, Sequence
from typing import NamedTuple

import numpy as np

from .._drive import FORCE_DRIVEN, AbstractTestDrive, DriveSpec, as_test_drive
from .._fit import (
    FitResult,
    as_test_list,
    pad_tests,
    resolve_drives,
    responses,
)
from .._io import ControlDetection, TestData
from .._models import AbstractCableModel
from .diagnosis import Candidate
from .methods import Fold, time_split
from .noise import (
    Noise as Noise,
    channel_noise as channel_noise,
    noise_floor as noise_floor,
    noise_level as noise_level,
)
from .rule import MAX_DELTA_BIC, MIN_GAIN_PCT, MIN_SIZE_Z


# How a diagnosis reports a residual unit: its name and the factor from the residual
# unit (m, N, or dimensionless) to it.
_REPORTED = {"m": ("mm", 1e3), "N": ("N", 1.0), "1": ("noise", 1.0)}


def measured_channel(test, drive) -> np.ndarray:
    """The scored channel of `test` under `drive` (a drive value or name): its
    elongation (m) when driven by its force, its force (N) when driven by its
    elongation."""
    return np.asarray(as_test_drive(drive).scored_of(test), float)


def _drive_names(drive):
    """`drive` as the fits take it: `"auto"`, a name, or one name per test."""
    if isinstance(drive, str) and drive == "auto":
        return drive
    if isinstance(drive, (str, AbstractTestDrive)):
        return as_test_drive(drive).name
    return [as_test_drive(d).name for d in drive]


def model_outputs(
    result: FitResult | AbstractCableModel,
    tests: Sequence[TestData],
    drive: DriveSpec = FORCE_DRIVEN,
    covariate: str | None = None,
) -> list[np.ndarray]:
    """The fitted model's value of every test's scored channel at every sample,
    masked samples included, in one vmapped simulation: the elongation (m) of a
    force-driven test, the force (N) of an elongation-driven one.

    **Arguments:**

    - `result`: a [`jaxcable.FitResult`][] of these `tests` (per-test parameters are
        matched by position), or a model.
    - `tests`: the tests, as fitted.
    - `drive`: a drive value or name (default force-driven), or one per test (as
        [`jaxcable.fit`][]; `"auto"` detects).
    - `covariate`: the extra column set as `Cable.covariate`, or None.

    **Returns:**

    One array per test, m or N; NaN throughout a test whose simulation failed.
    """
    return responses(result, tests, _drive_names(drive), covariate)


def model_elongations(
    result: FitResult | AbstractCableModel,
    tests: Sequence[TestData],
) -> list[np.ndarray]:
    """The fitted model's elongation (m) at every sample of every test, masked samples
    included, in one vmapped simulation, every test driven by its force.

    **Arguments:**

    - `result`: a [`jaxcable.FitResult`][] of these `tests` (per-test parameters are
        matched by position), or a model.
    - `tests`: the tests, as fitted.

    **Returns:**

    One array per test, m; NaN throughout a test whose simulation failed.
    """
    return model_outputs(result, tests, FORCE_DRIVEN)


def scored_residuals(
    result: FitResult | AbstractCableModel,
    tests: Sequence[TestData],
    drives: Sequence,
    scales: Sequence[float],
    covariate: str | None = None,
) -> list[np.ndarray]:
    """Model minus measured value of each test's scored channel at every sample,
    divided by the test's residual unit `scales[i]` (1: m or N; in a diagnosis
    mixing drives, the noise of the test's scored channel: dimensionless).

    **Arguments:**

    - `result`: a [`jaxcable.FitResult`][] or a model.
    - `tests`: the tests.
    - `drives`: each test's drive (value or name).
    - `scales`: each test's residual unit.
    - `covariate`: the extra column set as `Cable.covariate`, or None.

    **Returns:**

    One array per test (NaN where the measured value is missing or the simulation
    failed).
    """
    values = model_outputs(result, tests, list(drives), covariate)
    return [
        (v - measured_channel(t, d)) / s
        for v, t, d, s in zip(values, tests, drives, scales)
    ]


class Scoring(NamedTuple):
    """The drive and residual unit of every test of a diagnosis.

    **Fields:**

    - `drives`: each test's drive value ([`jaxcable.FORCE_DRIVEN`][] or
        [`jaxcable.ELONGATION_DRIVEN`][]).
    - `scales`: each test's residual unit (1, or the noise standard deviation of its
        scored channel when the drives are mixed), m or N.
    - `unit`: the reported unit: `"mm"`, `"N"` or `"noise"`.
    - `factor`: reported unit per residual unit (1e3 for mm, else 1).
    - `controls`: each test's [`jaxcable.ControlDetection`][] (the reason).
    - `covariate`: the extra column every model of the diagnosis is driven by
        (`Cable.covariate`), None when its base reads none: after a round names a
        covariate's extension, every later model carries it.
    """

    drives: tuple[AbstractTestDrive, ...]
    scales: np.ndarray
    unit: str
    factor: float
    controls: tuple[ControlDetection, ...]
    covariate: str | None = None

    @property
    def drive_names(self) -> list[str]:
        """Each test's drive by name, as the fits take it."""
        return [d.name for d in self.drives]

    def residuals(self, result, tests, index, covariate=None) -> list[np.ndarray]:
        """Model minus measured value of `tests` (the tests `index` of the diagnosis,
        any masks) in residual units, every sample; driven by `covariate` (default
        the diagnosis's)."""
        return scored_residuals(
            result,
            tests,
            [self.drives[i] for i in index],
            [float(self.scales[i]) for i in index],
            covariate=covariate or self.covariate,
        )

    def rmse(self, result, tests, index, held=None, covariate=None) -> float:
        """The pooled RMSE of `result` on `tests` (the tests `index`), in the
        reported unit, over the samples each test's own mask keeps, and of those
        only the ones of `held` (one boolean array per test) when given."""
        masks = [
            np.asarray(t.mask, bool)
            if held is None
            else h
            if getattr(t, "mask", None) is None
            else h & np.asarray(t.mask, bool)
            for t, h in zip(tests, held or [None] * len(tests))
        ]
        residual = self.residuals(result, tests, index, covariate)
        return pooled_rmse(residual, masks, self.factor)


def scoring(tests, drive: DriveSpec = "auto", covariate: str | None = None) -> Scoring:
    """The [`Scoring`][] of a diagnosis of `tests` under `drive` (`"auto"`, a drive
    name or value, or one per test; see [`jaxcable.fit`][]), its models driven by the
    extra column `covariate` (or none).

    **Raises:**

    `ValueError` naming `drive` (an unknown name, a list of another length) or the
    errors of [`jaxcable.pad_tests`][] for bad data.
    """
    tests = as_test_list(tests)
    controls = tuple(resolve_drives(tests, drive))
    drives = tuple(as_test_drive(c.control) for c in controls)
    # The whole tests' residual units, as a fit of all of them would weigh them:
    # fixed here, so that a fold holding out the tests of one drive still scores
    # in the diagnosis's unit.
    padded = pad_tests(tests, drive=[d.name for d in drives])
    unit, factor = _REPORTED[padded.units[0]]
    scale = np.asarray(padded.scale, float)
    return Scoring(drives, scale, unit, factor, controls, covariate)


def force_scoring(tests, covariate: str | None = None) -> Scoring:
    """The [`Scoring`][] of force-driven `tests` in mm (residual unit m), as the
    discovery and the covariates' candidates score, without detecting drives."""
    n = len(tests)
    return Scoring((FORCE_DRIVEN,) * n, np.ones(n), "mm", 1e3, (), covariate)


def pooled_rmse(residuals, masks, factor: float = 1.0) -> float:
    """`factor` x the RMSE of `residuals` pooled over the samples of `masks` (one
    boolean array per residual); 0 when no sample is kept."""
    sq, n = 0.0, 0
    for r, m in zip(residuals, masks):
        m = np.asarray(m, bool)
        sq += float(np.sum(r[m] ** 2))
        n += int(m.sum())
    return factor * math.sqrt(sq / max(n, 1))


def heldout_rmse(
    model: AbstractCableModel,
    tests,
    *,
    holdout: float = 0.3,
    drive="auto",
) -> float:
    """The RMSE of a given model on the held-out samples of `diagnose`'s time split
    (the last `holdout` fraction of every test), in the unit `diagnose` reports.

    For the data-generating model of synthetic data this is the floor no fitted model
    can beat: the elongation noise plus the response to the force noise the model is
    driven with. The hidden-effect tests compare the named model against it.

    **Arguments:**

    - `model`: the model, with its parameters.
    - `tests`: the tests ([`jaxcable.TestData`][]).
    - `holdout`: the held-out fraction of every test.
    - `drive`: each test's drive, as in [`jaxcable.diagnose`][] (default `"auto"`).

    **Returns:**

    The pooled RMSE over all held-out samples: mm when every test is driven by its
    force (its elongation scored), N when every test is driven by its elongation,
    noise units (each residual / its scored channel's noise) when the drives mix.
    """
    tests = as_test_list(tests)
    how = scoring(tests, drive)
    _, held = time_split(tests, holdout)
    return how.rmse(model, held, range(len(held)))


class Score(NamedTuple):
    """One model scored over every fold: RMSE on the held-out and on the training
    samples (in the diagnosis's reported unit), the number of training samples, and
    the fit of every fold."""

    heldout_rmse: float
    train_rmse: float
    num_train: int
    fits: list[FitResult]


def score_folds(
    parts: list[Fold],
    start_models: Callable[[int], list[AbstractCableModel]],
    fitter: Callable,
    *,
    how: Scoring,
    same_tests: bool,
    base_losses: list[float] | None = None,
) -> Score:
    """Fit and score one model on every fold of `parts`.

    **Arguments:**

    - `parts`: the folds.
    - `start_models`: `start_models(k)` gives fold k's start models: the first is
        fitted; when its training SSR is above the base model's on that fold
        (`base_losses`), the second is fitted too and the better kept, so that a
        candidate never fits its training data worse than the base it contains.
    - `fitter`: `fitter(model, tests, index)` fits a start to the training tests
        `index` and gives `(result, model)`: the result to report and the fitted
        model to simulate (the stack, whose simulation one compiled program serves
        for every candidate).
    - `how`: the drives of every fit and simulation, fixed on the whole tests; the
        scores are in its units.
    - `same_tests`: the held-out tests are the training tests with other masks
        (the time split), so one simulation serves both.
    - `base_losses`: the base model's training SSR on each fold, or None.

    **Returns:**

    A [`Score`][] (infinite RMSEs when a fit failed).
    """
    held, held_masks, train, train_masks = [], [], [], []
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
            return Score(math.inf, math.inf, 1, results)
        r_train = how.residuals(fitted, fold.train, fold.train_index)
        # Shared parameters only, so the fitted model runs on any test.
        r_held = (
            r_train if same_tests else how.residuals(fitted, fold.held, fold.held_index)
        )
        train += r_train
        train_masks += [t.mask for t in fold.train]
        held += r_held
        held_masks += [t.mask for t in fold.held]
    return Score(
        pooled_rmse(held, held_masks, how.factor),
        pooled_rmse(train, train_masks, how.factor),
        int(sum(int(np.asarray(m, bool).sum()) for m in train_masks)),
        results,
    )


def bic(rmse: float, n: int, p: int, per_unit: float) -> float:
    """The Bayesian information criterion n ln(SSR / n) + p ln n, SSR in residual
    units (`rmse` / `per_unit`: per_unit is 1e3 for an RMSE in mm of residuals in m)."""
    return n * math.log(max((rmse * (1.0 / per_unit)) ** 2, 1e-300)) + p * math.log(n)


class BaseScore(NamedTuple):
    """What a candidate is compared with: the base's held-out RMSE (reported unit)
    and its BIC on the training samples."""

    heldout_rmse: float
    bic: float


def scored_candidate(
    candidate_id: str,
    result: FitResult,
    score: tuple[float, float, int],
    size: tuple[float, float, str, str],
    note: str,
    base: BaseScore,
    how: Scoring,
    covariate: str | None = None,
) -> Candidate:
    """A fitted candidate scored: held-out gain over the base, ΔBIC on the training
    samples, z of its size, and whether it is significant on all three counts.

    **Arguments:**

    - `candidate_id`: its id in the diagnosis.
    - `result`: its [`jaxcable.FitResult`][] on the training samples.
    - `score`: `(held-out RMSE, training RMSE, training samples)`, RMSEs in the
        reported unit.
    - `size`: `(value, standard error, unit, name)` of its size parameter.
    - `note`: what to show beside it (an equation, the covariate; "" for none).
    - `base`: the base's [`BaseScore`][].
    - `how`: the diagnosis's [`Scoring`][].
    - `covariate`: the extra column the candidate reads (default the diagnosis's).

    **Returns:**

    A `Candidate`.
    """
    heldout, train, n = score
    delta_bic = bic(train, n, len(result.names), how.factor) - base.bic
    value, stderr, unit, name = float(size[0]), float(size[1]), size[2], size[3]
    z = abs(value) / stderr if stderr > 0 else (math.inf if value != 0 else 0.0)
    gain = 100.0 * (base.heldout_rmse - heldout) / base.heldout_rmse
    significant = bool(
        math.isfinite(heldout)
        and gain >= MIN_GAIN_PCT
        and delta_bic <= MAX_DELTA_BIC
        and z >= MIN_SIZE_Z
    )
    return Candidate(
        candidate_id,
        heldout,
        gain,
        train,
        delta_bic,
        value,
        stderr,
        unit,
        name,
        significant,
        True,
        note,
        result,
        how.unit,
        covariate=covariate or how.covariate,
    )


def training_score(result: FitResult, heldout: float) -> tuple[float, float, int]:
    """`(held-out RMSE, training RMSE, training samples)` of a candidate fitted
    outside the catalogue's stack on force-driven tests: the training RMSE (mm) from
    the fit's loss (residuals in m)."""
    n = int(np.sum(result.num_samples))
    loss = float(result.loss)
    train = 1e3 * math.sqrt(loss / max(n, 1)) if math.isfinite(loss) else math.inf
    return heldout, train, n


def size_of(result: FitResult, field: str, unit: str, name: str | None = None):
    """`(value, standard error, unit, name)` of the fitted parameter `field`."""
    i = result.names.index(field)
    return result.values[i], result.stderr[i], unit, name or field
