"""How a diagnosis looks for a cause, as values: the held-out split
([`jaxcable.HeldOut`][]), the search over candidate extensions of
[`jaxcable.diagnose`][] ([`jaxcable.CandidateSearch`][]) and the sparse regression
of [`jaxcable.discover`][] ([`jaxcable.Discovery`][]); and the one way the
diagnosis's own fits call [`jaxcable.fit`][]; the folds a `HeldOut` makes of the tests."""

import dataclasses
import math
import warnings
from collections.abc import Iterable
from typing import Any, Literal, NamedTuple

import equinox as eqx
import numpy as np

from .._fit import FitResult, IdentifiabilityWarning, fit
from .._io import TestData
from .._models import COVARIATE_EXTENSIONS, EXTENSIONS, discovered, memory
from .._problem import LeastSquares, Problem
from .rule import MIN_GAIN_PCT


def _as_ids(ids) -> Any:
    # A tuple, hashable as a static field; a lone string or a non-sequence is kept
    # for __check_init__ to refuse with the field's name.
    if isinstance(ids, Iterable) and not isinstance(ids, str):
        return tuple(ids)
    return ids


def _int_at_least(name: str, value, low: int) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or value < low:
        raise ValueError(f"`{name}` must be an int >= {low}, got {value!r}.")


def _optional_bool(name: str, value) -> None:
    if value is not None and not isinstance(value, bool):
        raise ValueError(f"`{name}` must be None, True or False, got {value!r}.")


def _one_of(name: str, value, cls: type) -> None:
    if not isinstance(value, cls):
        raise ValueError(
            f"`{name}` must be a jaxcable.{cls.__name__}, got {type(value).__name__}."
        )


class HeldOut(eqx.Module):
    """Which data a diagnosis holds out to score its models on.

    **Fields:**

    - `split`: `"time"` (default): a blocked time split, the last `fraction` of
        every test's samples held out (the model still runs through them; they are
        not fitted). `"tests"`: k-fold cross-validation over whole tests (test i is
        in fold i mod k; one fit per fold and model; needs at least two tests).
    - `fraction`: the held-out fraction of the time split, in (0, 0.9] (default
        0.3).
    - `folds`: k of the split by tests, an int >= 2 and at most the number of
        tests; None (default) one fold per test (leave-one-test-out).

    **Raises:**

    `ValueError` naming the field.
    """

    split: Literal["time", "tests"] = eqx.field(default="time", static=True)
    fraction: float = eqx.field(default=0.3, static=True)
    folds: int | None = eqx.field(default=None, static=True)

    def __check_init__(self):
        if self.split not in ("time", "tests"):
            raise ValueError(f"`split` must be 'time' or 'tests', got {self.split!r}.")
        fraction = self.fraction
        if not (
            isinstance(fraction, (int, float))
            and not isinstance(fraction, bool)
            and 0.0 < fraction <= 0.9
        ):
            raise ValueError(f"`fraction` must be in (0, 0.9], got {fraction!r}.")
        if self.folds is not None:
            _int_at_least("folds", self.folds, 2)

    def describe(self, num_tests: int) -> str:
        """How held-out data are chosen from `num_tests` tests, in words."""
        if self.split == "time":
            return f"last {self.fraction:.0%} of every test's samples"
        if self.folds is None or self.folds == num_tests:
            return "leave-one-test-out"
        return f"{self.folds}-fold by tests"


class CandidateSearch(eqx.Module):
    """The method of [`jaxcable.diagnose`][]: every candidate extension fitted
    around the base and scored on held-out data, round after round.

    **Fields:**

    - `candidates`: extension ids to try; None (default) every one of
        [`jaxcable.EXTENSIONS`][] and of [`jaxcable.COVARIATE_EXTENSIONS`][] (the
        latter tried for each extra column every test records, on the time split of
        force-driven tests, with ids such as `mechano_sorptive[humidity_pct]`).
    - `heldout`: the held-out data ([`jaxcable.HeldOut`][], default the last 30 %
        of every test).
    - `least_squares`: the fits' [`jaxcable.LeastSquares`][] (default one start,
        256 steps): `multistart`, `spread` and `key` are the base fit's (the
        candidates start from it, one start each); `max_steps` every fit's; `solver`
        None (default) the diagnosis's Levenberg-Marquardt, which also stops when a
        step lowers the sum of squares by less than 1e-6 of it.
    - `discover`: look for a discovered term ([`jaxcable.discover`][]): None
        (default) when the verdict would be `"unexplained"` or a named cause leaves
        a recorded covariate unused, True always, False never.
    - `max_rounds`: the most rounds (causes) to look for, an int >= 1 (default 3;
        1: stop after the first cause).
    - `family`: compare the other base models first: None (default) when the base
        is far from the data (held-out RMSE >= `FAMILY_EXCESS` x the noise,
        residual systematic), True always, False never.

    **Raises:**

    `ValueError` naming the field.
    """

    candidates: tuple[str, ...] | None = eqx.field(
        default=None, converter=_as_ids, static=True
    )
    heldout: HeldOut = eqx.field(default_factory=HeldOut)
    least_squares: LeastSquares = eqx.field(
        default_factory=lambda: LeastSquares(multistart=1)
    )
    discover: bool | None = eqx.field(default=None, static=True)
    max_rounds: int = eqx.field(default=3, static=True)
    family: bool | None = eqx.field(default=None, static=True)

    def __check_init__(self):
        if self.candidates is not None:
            if not isinstance(self.candidates, tuple):
                raise ValueError(
                    "`candidates` must be a sequence of extension ids, got "
                    f"{self.candidates!r}."
                )
            known = [*EXTENSIONS, *COVARIATE_EXTENSIONS]
            unknown = [c for c in self.candidates if c not in known]
            if unknown:
                raise ValueError(
                    f"`candidates` names {unknown}; known extensions: {known}."
                )
        _one_of("heldout", self.heldout, HeldOut)
        _one_of("least_squares", self.least_squares, LeastSquares)
        _optional_bool("discover", self.discover)
        _int_at_least("max_rounds", self.max_rounds, 1)
        _optional_bool("family", self.family)

    @property
    def ids(self) -> tuple[str, ...]:
        """The candidate ids to try (every extension's when `candidates` is None)."""
        if self.candidates is None:
            return (*EXTENSIONS, *COVARIATE_EXTENSIONS)
        return self.candidates

    @property
    def one_start(self) -> LeastSquares:
        """The method of a fit from one start (a candidate's, the discovery's, a
        pruned model's): `least_squares`'s steps and solver."""
        return LeastSquares(
            solver=self.least_squares.solver,
            max_steps=self.least_squares.max_steps,
            multistart=1,
        )


class Discovery(eqx.Module):
    """The method of [`jaxcable.discover`][]: a sparse regression of a base's
    residual on a library of terms, then a joint fit of the chosen ones.

    **Fields:**

    - `terms`: the library terms to search (default all of `TERMS` and
        `MEMORY_TERMS`, less the covariate terms when the problem names no
        covariate).
    - `heldout`: the held-out samples that choose the support:
        [`jaxcable.HeldOut`][] with `split="time"` (default the last 30 % of
        every test).
    - `min_gain_pct`: the held-out gain over no term a support needs, % (default
        `MIN_GAIN_PCT` = 5: on noise alone, a term fitted to the training samples
        predicts the held-out ones by chance by at most a few percent).
    - `joint_fit`: fit the chosen terms with the base (default True).
    - `least_squares`: the joint fit's [`jaxcable.LeastSquares`][] (default one
        start).

    **Raises:**

    `ValueError` naming the field.
    """

    terms: tuple[str, ...] | None = eqx.field(
        default=None, converter=_as_ids, static=True
    )
    heldout: HeldOut = eqx.field(default_factory=HeldOut)
    min_gain_pct: float = eqx.field(default=MIN_GAIN_PCT, static=True)
    joint_fit: bool = eqx.field(default=True, static=True)
    least_squares: LeastSquares = eqx.field(
        default_factory=lambda: LeastSquares(multistart=1)
    )

    def __check_init__(self):
        if self.terms is not None:
            library = [*discovered.TERMS, *memory.MEMORY_TERMS]
            unknown = (
                [self.terms]
                if not isinstance(self.terms, tuple)
                else [t for t in self.terms if t not in library]
            )
            if unknown:
                raise ValueError(f"`terms` {unknown} are not in the library {library}.")
        _one_of("heldout", self.heldout, HeldOut)
        if self.heldout.split != "time":
            raise ValueError(
                "`heldout` must be a time split (the discovery scores the last "
                f"samples of every test), got split={self.heldout.split!r}."
            )
        gain = self.min_gain_pct
        if (
            isinstance(gain, bool)
            or not isinstance(gain, (int, float))
            or math.isnan(gain)
        ):
            raise ValueError(f"`min_gain_pct` must be a number, got {gain!r}.")
        if not isinstance(self.joint_fit, bool):
            raise ValueError(
                f"`joint_fit` must be True or False, got {self.joint_fit!r}."
            )
        _one_of("least_squares", self.least_squares, LeastSquares)


def check_arguments(problem, method, method_type: type) -> None:
    """`TypeError` naming `problem` unless it is a [`jaxcable.Problem`][], or
    `method` unless it is a `method_type`."""
    for name, value, cls in (
        ("problem", problem, Problem),
        ("method", method, method_type),
    ):
        if not isinstance(value, cls):
            raise TypeError(
                f"`{name}` must be a jaxcable.{cls.__name__}, got {type(value).__name__}."
            )


def fit_quietly(problem: Problem, method: LeastSquares) -> FitResult:
    """[`jaxcable.fit`][] of `problem` by `method` that does not throw (a failed
    fit has an infinite loss) and reports identifiability in its result instead
    of warning, as every fit of a diagnosis does."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", IdentifiabilityWarning)
        return fit(problem, method, throw=False)


def with_mask(test: TestData, mask: np.ndarray) -> TestData:
    """`test` with only the samples of `mask` weighted (and of its own mask, if any)."""
    own = getattr(test, "mask", None)
    if own is not None:
        mask = mask & np.asarray(own, bool)
    return dataclasses.replace(test, mask=mask)


def heldout_start(n: int, holdout: float) -> int:
    """The first held-out sample of an `n`-sample test under the time split."""
    return int(round(n * (1.0 - holdout)))


def time_split(tests, holdout: float) -> tuple[list, list]:
    """(training tests, held-out tests): the same tests with complementary masks, the
    last `holdout` fraction of each test's samples held out. The whole history still
    drives the model; only the residuals are split."""
    train, held = [], []
    for test in tests:
        n = len(test.time)
        first = np.arange(n) < heldout_start(n, holdout)
        train.append(with_mask(test, first))
        held.append(with_mask(test, ~first))
    return train, held


class Fold(NamedTuple):
    """One fold of a diagnosis: the training tests and the held-out tests (masked
    copies of the diagnosis's tests), and their positions among them."""

    train: list
    held: list
    train_index: list[int]
    held_index: list[int]


def splits(tests, heldout: HeldOut, folds: int) -> list[Fold]:
    """The training and held-out tests of every fold.

    **Arguments:**

    - `tests`: the tests, each with a mask.
    - `heldout`: the split: `"time"`, one fold, `time_split` by its `fraction`;
        `"tests"`, `folds` folds of whole tests, test i held out in fold i mod
        `folds`.
    - `folds`: the number of folds by tests.

    **Returns:**

    One `Fold` per fold.
    """
    if heldout.split == "time":
        every = list(range(len(tests)))
        return [Fold(*time_split(tests, heldout.fraction), every, every)]
    out = []
    for fold in range(folds):
        train = [i for i in range(len(tests)) if i % folds != fold]
        held = [i for i in range(len(tests)) if i % folds == fold]
        out.append(
            Fold([tests[i] for i in train], [tests[i] for i in held], train, held)
        )
    return out
