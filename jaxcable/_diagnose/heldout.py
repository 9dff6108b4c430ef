"""Held-out data: the blocked time split and the cross-validation folds by tests of
[`jaxcable.diagnose`][]."""

import dataclasses
from typing import Literal, NamedTuple

import numpy as np

from .._io import TestData


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
