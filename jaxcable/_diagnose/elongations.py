"""A model's elongations over a list of tests: one vmapped simulation, every sample
(masked ones too), for scoring held-out data, residual analysis and the reports."""

import dataclasses
from collections.abc import Sequence

import equinox as eqx
import numpy as np

from .._fit import FitResult, pad_tests, residuals
from .._io import TestData
from .._models import AbstractCableModel


# Compiled once per shape: run eagerly, the vmapped scan dispatched op by op.
_residuals = eqx.filter_jit(residuals)


def model_elongations(
    result: FitResult | AbstractCableModel,
    tests: Sequence[TestData],
) -> list[np.ndarray]:
    """The fitted model's elongation (m) at every sample of every test, masked samples
    included, in one vmapped simulation.

    **Arguments:**

    - `result`: a [`jaxcable.FitResult`][] of these `tests` (per-test parameters are
        matched by position), or a model.
    - `tests`: the tests, as fitted.

    **Returns:**

    One array per test, m; NaN throughout a test whose simulation failed.
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
    # The diagnosis scores elongations: every test is driven by its force.
    padded = pad_tests(unmasked, drive="force")
    model = result.model if isinstance(result, FitResult) else result
    params, static = eqx.partition(model, eqx.is_inexact_array)
    r = np.asarray(_residuals(params, static, padded))
    return [r[i, : t.num_samples] + t.elongation for i, t in enumerate(unmasked)]
