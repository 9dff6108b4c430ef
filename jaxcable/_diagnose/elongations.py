"""A model's response over a list of tests: one vmapped simulation, every sample
(masked ones too), in each test's scored channel (the elongation of a force-driven
test, the force of an elongation-driven one), for scoring held-out data, residual
analysis and the reports."""

import dataclasses
from collections.abc import Sequence

import equinox as eqx
import numpy as np

from .._fit import FitResult, pad_tests, residuals
from .._io import TestData
from .._models import AbstractCableModel


# Compiled once per shape: run eagerly, the vmapped scan dispatched op by op.
_residuals = eqx.filter_jit(residuals)


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
    # Every sample weighted, so that the residual (model - measured) is returned at
    # masked samples too; their measured elongation only needs to be finite.
    unmasked = [
        dataclasses.replace(
            t,
            mask=None,
            elongation=np.nan_to_num(np.asarray(t.elongation, float)),
        )
        for t in tests
    ]
    padded = pad_tests(unmasked, drive=drive)
    model = result.model if isinstance(result, FitResult) else result
    params, static = eqx.partition(model, eqx.is_inexact_array)
    r = np.asarray(_residuals(params, static, padded))
    # Back to m or N (the scale is 1, exactly, unless the drives are mixed).
    r = r * np.asarray(padded.scale, float)[:, None]
    return [
        r[i, : t.num_samples] + measured_channel(t, d)
        for i, (t, d) in enumerate(zip(unmasked, padded.drive))
    ]


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
