"""A model's response over a list of tests, each by its drive: one vmapped simulation
of every sample (masked ones too), for plots, reports and held-out scores."""

import dataclasses
from collections.abc import Sequence

import equinox as eqx
import numpy as np

from .._models import AbstractCableModel
from .._problem import Problem
from .data import pad_tests, resolve_drives
from .problem import residuals
from .result import FitResult


# Compiled once per shape: run eagerly, the vmapped scan dispatched op by op.
_residuals = eqx.filter_jit(residuals)


def model_responses(
    result: FitResult | AbstractCableModel, problem: Problem
) -> list[np.ndarray]:
    """The model's value of each test's scored channel at every sample: the
    elongation (m) of a force-driven test, the force (N) of an elongation-driven one.

    ```python
    result = jc.fit(problem)
    elongation = jc.model_responses(result, problem)
    ```

    **Arguments:**

    - `result`: a [`jaxcable.FitResult`][] of the problem's tests (per-test
        parameters are matched by position), or a model.
    - `problem`: a [`jaxcable.Problem`][]: its tests, its drive (`"auto"`, the
        default, takes the drives of a `FitResult`, else detects them) and its
        covariate (the column set as `Cable.covariate`); its model is not used.

    **Returns:**

    One array per test; NaN throughout a test whose simulation failed.

    **Raises:**

    `TypeError` naming `problem` when it is not a `Problem`.
    """
    if not isinstance(problem, Problem):
        raise TypeError(
            f"`problem` must be a jaxcable.Problem, got {type(problem).__name__}."
        )
    drive = problem.drive
    if isinstance(drive, str) and drive == "auto" and isinstance(result, FitResult):
        drive = list(result.drives) if result.drives else "auto"
    return responses(result, list(problem.tests), drive, problem.covariate)


def responses(
    result: FitResult | AbstractCableModel,
    tests: Sequence,
    drive=None,
    covariate: str | None = None,
) -> list[np.ndarray]:
    """[`jaxcable.model_responses`][] of `tests` by `drive` (None: the result's
    drives, else `"auto"`) and `covariate`: for the package's own callers, which
    score held-out or training slices of tests without a model to make a `Problem`
    of."""
    if drive is None:
        drives = getattr(result, "drives", ())
        drive = list(drives) if drives else "auto"
    drives = [d.drive for d in resolve_drives(tests, drive)]
    # Every sample weighted, so that the residual (model - measured) is returned at
    # masked samples too; their measured (scored) value only needs to be finite.
    unmasked = [
        dataclasses.replace(
            t,
            mask=None,
            elongation=t.elongation
            if d.scores_force
            else np.nan_to_num(np.asarray(t.elongation, float)),
            force=np.nan_to_num(np.asarray(t.force, float)),
        )
        for t, d in zip(tests, drives)
    ]
    padded = pad_tests(unmasked, drive=drives, covariate=covariate)
    model = result.model if isinstance(result, FitResult) else result
    params, static = eqx.partition(model, eqx.is_inexact_array)
    r = (
        np.asarray(_residuals(params, static, padded))
        * np.asarray(padded.scale)[:, None]
    )
    return [
        r[i, : t.num_samples] + d.scored_of(t)
        for i, (t, d) in enumerate(zip(unmasked, drives))
    ]
