"""The units a diagnosis scores in: each test's drive, fixed once on the whole tests,
and its residual unit (the `scale` of [`jaxcable.residuals`][]), so that every fold,
candidate and held-out score of one diagnosis is in the same unit.

Every test scored in its elongation (all force-driven): m, reported in mm. Every test
scored in its force (all elongation-driven): N. Tests of both kinds: each residual
divided by the noise standard deviation of its test's scored channel, dimensionless
("noise" units), as in a mixed [`jaxcable.fit`][].
"""

import math
from typing import NamedTuple

import numpy as np

from .._fit import as_test_list, pad_tests, resolve_drives
from .._io import ControlDetection
from .elongations import measured_channel, scored_residuals
from .result import MAX_DELTA_BIC, MIN_GAIN_PCT, MIN_SIZE_Z, Candidate


# How a diagnosis reports a residual unit: its name and the factor from the residual
# unit (m, N, or dimensionless) to it.
_REPORTED = {"m": ("mm", 1e3), "N": ("N", 1.0), "1": ("noise", 1.0)}


class Scoring(NamedTuple):
    """The drive and residual unit of every test of a diagnosis.

    **Fields:**

    - `drives`: each test's drive, `"force"` or `"elongation"`.
    - `scales`: each test's residual unit (1, or the noise standard deviation of its
        scored channel when the drives are mixed), m or N.
    - `unit`: the reported unit: `"mm"`, `"N"` or `"noise"`.
    - `factor`: reported unit per residual unit (1e3 for mm, else 1).
    - `controls`: each test's [`jaxcable.ControlDetection`][] (the reason).
    """

    drives: tuple[str, ...]
    scales: np.ndarray
    unit: str
    factor: float
    controls: tuple[ControlDetection, ...]

    def residuals(self, result, tests, index) -> list[np.ndarray]:
        """Model minus measured value of `tests` (the tests `index` of the diagnosis,
        any masks) in residual units, every sample."""
        return scored_residuals(
            result,
            tests,
            [self.drives[i] for i in index],
            [float(self.scales[i]) for i in index],
        )


def scoring(tests, drive="auto") -> Scoring:
    """The [`Scoring`][] of a diagnosis of `tests` under `drive` (`"auto"`,
    `"force"`, `"elongation"`, or one per test; see [`jaxcable.fit`][]).

    **Raises:**

    `ValueError` naming `drive` (an unknown name, a list of another length) or the
    errors of [`jaxcable.pad_tests`][] for bad data.
    """
    tests = as_test_list(tests)
    controls = tuple(resolve_drives(tests, drive))
    drives = tuple(c.control for c in controls)
    # The whole tests' residual units, as a fit of all of them would weigh them:
    # fixed here, so that a fold holding out the tests of one drive still scores
    # in the diagnosis's unit.
    padded = pad_tests(tests, drive=list(drives))
    unit, factor = _REPORTED[padded.units[0]]
    return Scoring(drives, np.asarray(padded.scale, float), unit, factor, controls)


def channel_noise(test, drive: str) -> float | None:
    """A robust estimate of the noise of a test's scored channel (m or N): the median
    absolute second difference, / 0.6745 / sqrt(6) (for white noise the second
    difference has variance 6 sigma^2; the signal's own curvature between dense
    samples is far smaller and the median ignores the reversals); None for fewer
    than 5 samples."""
    x = measured_channel(test, drive)
    if x.size < 5:
        return None
    return float(np.median(np.abs(np.diff(x, 2))) / 0.6745 / math.sqrt(6.0))


def noise_floor(tests, scoring: Scoring) -> float:
    """The noise of the scored channels estimated from the data, in the reported
    unit: the median over tests of [`channel_noise`][] / the test's residual unit
    (mm, N, or about 1 in noise units)."""
    values = [
        noise / s
        for t, d, s in zip(as_test_list(tests), scoring.drives, scoring.scales)
        if (noise := channel_noise(t, d)) is not None
    ]
    return scoring.factor * float(np.median(values)) if values else float("nan")


def bic(rmse: float, n: int, p: int, per_unit: float) -> float:
    """The Bayesian information criterion n ln(SSR / n) + p ln n, SSR in residual
    units (`rmse` / `per_unit`: per_unit is 1e3 for an RMSE in mm of residuals in m)."""
    return n * math.log(max((rmse * (1.0 / per_unit)) ** 2, 1e-300)) + p * math.log(n)


def fitted_candidate(
    candidate_id: str,
    result,
    heldout: float,
    size: tuple[float, float, str, str],
    note: str,
    base_heldout: float,
    bic_base: float,
    how: Scoring,
):
    """A candidate fitted outside the catalogue's stack (a discovered term, a
    covariate's extension) scored as the catalogue's are: held-out gain, ΔBIC on
    the training samples, z of its size.

    **Arguments:**

    - `candidate_id`: its id in the diagnosis.
    - `result`: its [`jaxcable.FitResult`][] on the training samples (force-driven
        tests: residuals in m).
    - `heldout`: its held-out RMSE, mm.
    - `size`: `(value, standard error, unit, name)` of its size parameter.
    - `note`: what to show beside it (an equation, the covariate).
    - `base_heldout`, `bic_base`: the base's held-out RMSE (mm) and BIC.
    - `how`: the diagnosis's [`Scoring`][].

    **Returns:**

    A `Candidate`.
    """
    n = int(np.sum(result.num_samples))
    loss = float(result.loss)
    train = 1e3 * math.sqrt(loss / max(n, 1)) if math.isfinite(loss) else math.inf
    delta_bic = bic(train, n, len(result.names), how.factor) - bic_base
    value, stderr, unit, name = float(size[0]), float(size[1]), size[2], size[3]
    z = abs(value) / stderr if stderr > 0 else (math.inf if value != 0 else 0.0)
    gain = 100.0 * (base_heldout - heldout) / base_heldout
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
    )
