"""A model's response over a list of tests: one vmapped simulation, every sample
(masked ones too), in each test's scored channel (the elongation of a force-driven
test, the force of an elongation-driven one), for scoring held-out data, residual
analysis and the reports."""

from collections.abc import Sequence

import numpy as np

from .._fit import FitResult, model_responses
from .._io import TestData
from .._models import AbstractCableModel


def measured_channel(test, drive: str) -> np.ndarray:
    """The scored channel of `test` under `drive`: its elongation (m) when driven by
    its force, its force (N) when driven by its elongation."""
    return np.asarray(test.elongation if drive == "force" else test.force, float)


def model_outputs(
    result: FitResult | AbstractCableModel,
    tests: Sequence[TestData],
    drive="force",
) -> list[np.ndarray]:
    """The fitted model's value of every test's scored channel at every sample,
    masked samples included, in one vmapped simulation: the elongation (m) of a
    force-driven test, the force (N) of an elongation-driven one.

    **Arguments:**

    - `result`: a [`jaxcable.FitResult`][] of these `tests` (per-test parameters are
        matched by position), or a model.
    - `tests`: the tests, as fitted.
    - `drive`: `"force"` (default), `"elongation"`, or one of these per test (as
        [`jaxcable.fit`][]; `"auto"` detects).

    **Returns:**

    One array per test, m or N; NaN throughout a test whose simulation failed.
    """
    return model_responses(result, tests, drive)


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
    return model_outputs(result, tests, "force")


def scored_residuals(
    result: FitResult | AbstractCableModel,
    tests: Sequence[TestData],
    drives: Sequence[str],
    scales: Sequence[float],
) -> list[np.ndarray]:
    """Model minus measured value of each test's scored channel at every sample,
    divided by the test's residual unit `scales[i]` (1: m or N; in a diagnosis
    mixing drives, the noise of the test's scored channel: dimensionless).

    **Arguments:**

    - `result`: a [`jaxcable.FitResult`][] or a model.
    - `tests`: the tests.
    - `drives`: each test's drive, `"force"` or `"elongation"`.
    - `scales`: each test's residual unit.

    **Returns:**

    One array per test (NaN where the measured value is missing or the simulation
    failed).
    """
    values = model_outputs(result, tests, list(drives))
    return [
        (v - measured_channel(t, d)) / s
        for v, t, d, s in zip(values, tests, drives, scales)
    ]
