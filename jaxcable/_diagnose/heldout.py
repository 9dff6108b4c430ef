"""Held-out data: the blocked time split and the cross-validation folds by tests of
[`jaxcable.diagnose`][], the RMSE of a model on the held-out samples, and the noise
level estimated from the data."""

import dataclasses
import math
from typing import Literal, NamedTuple

import numpy as np

from .._fit import as_test_list
from .._io import TestData
from .._models import AbstractCableModel
from .scoring import scoring


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


def splits(
    tests, split: Literal["time", "tests"], holdout: float, folds: int
) -> list[Fold]:
    """The training and held-out tests of every fold.

    **Arguments:**

    - `tests`: the tests, each with a mask.
    - `split`: `"time"`: one fold, [`time_split`][] by `holdout`; `"tests"`: `folds`
        folds of whole tests, test i held out in fold i mod `folds`.
    - `holdout`: the held-out fraction of the time split.
    - `folds`: the number of folds by tests.

    **Returns:**

    One [`Fold`][] per fold.
    """
    if split == "time":
        every = list(range(len(tests)))
        return [Fold(*time_split(tests, holdout), every, every)]
    out = []
    for fold in range(folds):
        train = [i for i in range(len(tests)) if i % folds != fold]
        held = [i for i in range(len(tests)) if i % folds == fold]
        out.append(
            Fold([tests[i] for i in train], [tests[i] for i in held], train, held)
        )
    return out


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
    r = how.residuals(model, held, range(len(held)))
    sq = sum(float(np.sum(x[t.mask] ** 2)) for t, x in zip(held, r))
    n = sum(int(np.sum(t.mask)) for t in held)
    return how.factor * math.sqrt(sq / n)


def noise_level(tests) -> float:
    """A robust estimate of the elongation noise, m: the median absolute second
    difference of each test's elongation, / 0.6745 / sqrt(6) (for white noise the
    second difference has variance 6 sigma^2; the signal's own curvature between
    dense samples is far smaller and the median ignores the reversals), the median
    over tests."""
    values = []
    for t in as_test_list(tests):
        e = np.asarray(t.elongation, float)
        if e.size >= 5:
            d2 = np.diff(e, 2)
            values.append(np.median(np.abs(d2)) / 0.6745 / math.sqrt(6.0))
    return float(np.median(values)) if values else float("nan")
