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
