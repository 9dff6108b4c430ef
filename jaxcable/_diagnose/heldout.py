"""Held-out data: the blocked time split and the cross-validation folds by tests of
[`jaxcable.diagnose`][], the RMSE of a model on the held-out samples, and the noise
level estimated from the data."""

import dataclasses
import math
from typing import Literal

import numpy as np

from .._fit import as_test_list
from .._io import TestData
from .._models import AbstractCableModel
from .elongations import model_elongations


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


def splits(
    tests, split: Literal["time", "tests"], holdout: float, folds: int
) -> list[tuple[list, list]]:
    """The (training tests, held-out tests) of every fold.

    **Arguments:**

    - `tests`: the tests, each with a mask.
    - `split`: `"time"`: one fold, [`time_split`][] by `holdout`; `"tests"`: `folds`
        folds of whole tests, test i held out in fold i mod `folds`.
    - `holdout`: the held-out fraction of the time split.
    - `folds`: the number of folds by tests.

    **Returns:**

    One (training, held-out) pair of test lists per fold.
    """
    if split == "time":
        return [time_split(tests, holdout)]
    return [
        (
            [t for i, t in enumerate(tests) if i % folds != fold],
            [t for i, t in enumerate(tests) if i % folds == fold],
        )
        for fold in range(folds)
    ]


def heldout_rmse(
    model: AbstractCableModel,
    tests,
    *,
    holdout: float = 0.3,
) -> float:
    """The RMSE of a given model on the held-out samples of `diagnose`'s time split
    (the last `holdout` fraction of every test), mm.

    For the data-generating model of synthetic data this is the floor no fitted model
    can beat: the elongation noise plus the response to the force noise the model is
    driven with. The hidden-effect tests compare the named model against it.

    **Arguments:**

    - `model`: the model, with its parameters.
    - `tests`: the tests ([`jaxcable.TestData`][]).
    - `holdout`: the held-out fraction of every test.

    **Returns:**

    The pooled RMSE over all held-out samples, mm.
    """
    tests = as_test_list(tests)
    _, held = time_split(tests, holdout)
    e = model_elongations(model, held)
    sq = sum(float(np.sum((x - t.elongation)[t.mask] ** 2)) for t, x in zip(held, e))
    n = sum(int(np.sum(t.mask)) for t in held)
    return 1e3 * math.sqrt(sq / n)


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
