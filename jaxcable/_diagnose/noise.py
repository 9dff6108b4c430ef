"""The noise a diagnosis weighs every residual against, estimated from the data, and
where the estimate comes from.

**The rule.** For each test, from its scored channel x (the elongation of a
force-driven test, the force of an elongation-driven one):

1. The second differences: sigma_2 = median |x[i+1] - 2 x[i] + x[i-1]| / 0.6745 /
    sqrt(6) (white noise has second differences of variance 6 sigma^2; a signal's
    own curvature between dense samples is far smaller, and the median ignores the
    reversals).
2. Is the record *smooth* (filtered, interpolated, digitised, processed)? White
    noise makes consecutive second differences alternate in sign (their
    correlation is -2/3: a change of sign at 73 % of the samples); a smooth
    record's follow its curvature. The record is smooth when its second
    differences change sign at fewer than `MIN_ALTERNATION` = 30 % of the samples,
    when more than `MAX_FLAT` = 50 % of them are zero (piecewise linear:
    interpolated between digitised points; or repeated values: a logger that
    holds its last reading), when its values lie on a grid and sigma_2 is below
    the grid's step / sqrt(12). (Not detected: a record filtered by a running
    mean, which keeps the sign changes of white noise while its second
    differences fall below its scatter, 3.7 x for a 9-sample boxcar. Comparing
    sigma_2 with the base residual's short-range scatter would catch it, but a
    poor base's misfit between sparse samples looks the same: a Burgers base on
    the hidden-effect generator's noisy records scatters 4.2 x above sigma_2.)
3. On a noisy record sigma_2 is the estimate. On a smooth one sigma_2 measures the
    processing, not the noise, and the estimate is the largest of, each reported
    by name:

    - *instrument resolution*: a record whose values lie on a grid of step q (every
      change a whole number of steps) cannot know its value better than
      q / sqrt(12);
    - *the white part of the base residual*: the RMS scatter of the fitted base
      model's residual (model - data, every sample) about its own running mean
      over 2 h + 1 samples (h = max(3, n / 100)), corrected for the mean's own
      share: what no model can follow at short range, the smooth part of the
      misfit removed (a filtered noise of shorter correlation stays at its full
      size; a resampled record keeps its resampling error, largest where the
      signal turns, which is why the RMS and not a robust scatter);
    - sigma_2 itself.

The diagnosis's noise is the median over tests of each test's estimate (in the
reported unit); its source names the estimate most tests used and why ("white part
of the base residual (record smooth: second differences 40x below)"). A record of
white noise keeps sigma_2, as before: its second differences alternate (at 50 % of
the samples at the least on the hidden-effect generator's sparse records, 252 tests
of three seeds). A floor never lowers the estimate below sigma_2.
"""

import math
from collections import Counter

import numpy as np

from .._drive import FORCE_DRIVEN, as_test_drive
from .._fit import as_test_list
from .._models import AbstractCableModel


# A record is smooth when its second differences change sign at fewer than this
# share of the samples (white noise: 73 %; the hidden-effect generator's sparse
# records, where the signal's curvature competes: 50 % at the least over 252 tests
# of 3 seeds; a low-passed (Gaussian, 3 samples) or resampled record: 7-28 %)...
MIN_ALTERNATION = 0.3
# ... or when more than this share of them are zero (piecewise linear, or repeated
# values).
MAX_FLAT = 0.5
# Values on a grid: at least this share of the changes is a whole number of steps,
# to within this fraction of a step.
GRID_SHARE = 0.95
GRID_TOLERANCE = 0.05
SOURCE_SECOND_DIFFERENCES = "second differences"


class Noise(float):
    """A noise estimate (a float, in the diagnosis's reported unit) with its source.

    **Fields:**

    - `source`: where the value comes from, in words ("second differences",
        "quantisation step 0.01 mm", "white part of the base residual (record
        smooth: second differences 40x below)").
    - `smooth`: whether the record was found smooth (the second differences
        replaced).
    """

    source: str
    smooth: bool

    def __new__(
        cls, value: float, source: str = SOURCE_SECOND_DIFFERENCES, smooth=False
    ):
        out = super().__new__(cls, value)
        out.source = source
        out.smooth = bool(smooth)
        return out


def _scored(test, drive) -> np.ndarray:
    """The finite samples of the scored channel of `test` under `drive`."""
    x = np.asarray(as_test_drive(drive).scored_of(test), float)
    return x[np.isfinite(x)]


def second_difference_noise(x) -> float | None:
    """sigma_2 of a sequence `x`: median |second difference| / 0.6745 / sqrt(6); None
    for fewer than 5 samples."""
    x = np.asarray(x, float)
    if x.size < 5:
        return None
    return float(np.median(np.abs(np.diff(x, 2))) / 0.6745 / math.sqrt(6.0))


def grid_step(x) -> float | None:
    """The step q of the grid the values of `x` lie on (every change a whole number
    of steps, `GRID_SHARE` of them to within `GRID_TOLERANCE` of a step), or None."""
    d = np.abs(np.diff(np.asarray(x, float)))
    scale = float(np.max(np.abs(x))) if np.size(x) else 0.0
    d = d[d > 1e-9 * scale]
    if d.size < 5:
        return None
    # The smallest change that recurs (a noise-free record's smallest changes are
    # single rounding accidents: the 2nd percentile is one of many).
    q = float(np.percentile(d, 2.0))
    if not q > 0:
        return None
    ratio = d / q
    near = np.abs(ratio - np.round(ratio)) <= GRID_TOLERANCE
    return q if float(np.mean(near)) >= GRID_SHARE else None


class _Signature:
    """What a record's second differences say about it: the share that change
    sign, the share that are zero, its grid step and sigma_2."""

    def __init__(self, x: np.ndarray):
        d2 = np.diff(x, 2)
        scale = float(np.max(np.abs(x))) if x.size else 0.0
        # Float rounding of a record written to ~7 digits, and of a float32
        # simulation, is no curvature.
        zero = np.abs(d2) <= 1e-7 * max(scale, 1e-300)
        self.flat = float(np.mean(zero)) if d2.size else 0.0
        signs = np.sign(d2[~zero])
        self.alternation = (
            float(np.mean(signs[1:] != signs[:-1])) if signs.size > 1 else 0.0
        )
        self.sigma2 = second_difference_noise(x)
        self.step = grid_step(x)

    def why_smooth(self) -> str:
        """Why the record is smooth, in words; "" when it is not."""
        if self.flat > MAX_FLAT:
            return (
                f"{self.flat:.0%} of its second differences are zero: piecewise "
                "linear or repeated values"
            )
        if self.alternation < MIN_ALTERNATION:
            return (
                f"its second differences change sign at {self.alternation:.0%} of "
                "the samples (white noise: 73 %)"
            )
        if (
            self.step is not None
            and self.sigma2 is not None
            and self.sigma2 < self.step / math.sqrt(12.0)
        ):
            return "its values lie on a grid finer than their noise shows"
        return ""


def white_part(residual) -> float | None:
    """The white part of a residual (model - data, one test, every sample): its
    RMS scatter about its own running mean over 2 h + 1 samples, h = max(3, n /
    100), corrected for the mean's own share (sqrt((2h + 1) / 2h)). The RMS, not
    a robust scatter: a smooth record's processing error sits where the signal
    turns (an interpolation's at the load steps), and it is the record's noise.

    **Arguments:**

    - `residual`: the residual, m or N.

    **Returns:**

    The scatter; None for fewer than 2 h + 1 finite samples.
    """
    r = np.asarray(residual, float)
    r = r[np.isfinite(r)]
    h = max(3, r.size // 100)
    w = 2 * h + 1
    if r.size < w:
        return None
    mean = np.convolve(r, np.ones(w) / w, mode="valid")
    scatter = r[h : r.size - h] - mean
    return float(np.sqrt(np.mean(scatter**2))) * math.sqrt(w / (w - 1.0))


def test_noise(test, drive, residual=None, unit=("mm", 1e3)):
    """One test's noise estimate (m or N) and its source, by the rule of this
    module.

    **Arguments:**

    - `test`: a [`jaxcable.TestData`][].
    - `drive`: its drive (value or name): the channel scored is the other one.
    - `residual`: the fitted base model's residual of the test in the channel's
        unit (model - data, every sample), or None (the data alone: no white part).
    - `unit`: (name, factor) of the unit the source names a step in.

    **Returns:**

    `(value, source, smooth)`; `(None, "", False)` for fewer than 5 samples.
    """
    sig = _Signature(_scored(test, drive))
    if sig.sigma2 is None:
        return None, "", False
    why = sig.why_smooth()
    if not why:
        return sig.sigma2, SOURCE_SECOND_DIFFERENCES, False
    white = None if residual is None else white_part(residual)
    name, factor = unit
    floors = [(sig.sigma2, f"second differences (record smooth: {why})")]
    if sig.step is not None:
        step = f"{sig.step * factor:.3g} {name}".strip()
        floors.append(
            (sig.step / math.sqrt(12.0), f"quantisation step {step} (step / sqrt(12))")
        )
    if white is not None:
        # "40x below" says it in one number; zero second differences say why.
        ratio = white / sig.sigma2 if sig.sigma2 > 0 else math.inf
        below = (
            f"second differences {ratio:.3g}x below" if 1 < ratio < math.inf else why
        )
        floors.append(
            (white, f"white part of the base residual (record smooth: {below})")
        )
    value, source = max(floors, key=lambda f: f[0])
    return value, source, True


def channel_noise(test, drive) -> float | None:
    """The noise of a test's scored channel (m or N) from the data alone: the second
    differences' estimate sigma_2, floored on a quantised record at its step /
    sqrt(12) (see the module's rule; the white part of a base residual needs a
    fit: [`noise_floor`][]); None for fewer than 5 samples."""
    return test_noise(test, drive)[0]


def noise_floor(tests, scoring, base=None) -> Noise:
    """The noise of the scored channels estimated from the data, in the reported
    unit, with its source (the rule of `jaxcable._diagnose.noise`).

    **Arguments:**

    - `tests`: the diagnosis's tests.
    - `scoring`: its `Scoring` (each test's drive and residual unit).
    - `base`: the fitted base (a model, or the diagnosis's `BaseFit`), whose
        residual's white part floors a smooth record; None: the data alone.

    **Returns:**

    A [`Noise`][]: the median over tests of each test's estimate / its residual
    unit, times the reported unit's factor; its `source` the estimate most tests
    used (NaN, source "no test of 5 samples", when none has 5 samples).
    """
    tests = as_test_list(tests)
    unit = {"mm": ("mm", 1e3), "N": ("N", 1.0)}.get(scoring.unit, ("", 1.0))
    residuals = [None] * len(tests)
    smooth_data = any(
        _Signature(_scored(t, d)).why_smooth() for t, d in zip(tests, scoring.drives)
    )
    if base is not None and smooth_data:
        # The base's simulation, only for a smooth record: a noisy one is as before.
        residuals = scoring.residuals(_model_of(base), tests, range(len(tests)))
    values, sources, smooth = [], [], 0
    for t, d, s, r in zip(tests, scoring.drives, scoring.scales, residuals):
        # Residuals come in residual units (divided by the scale): back to m or N.
        value, source, flagged = test_noise(
            t, d, None if r is None else np.asarray(r) * s, unit
        )
        if value is None:
            continue
        values.append(value / s)
        sources.append(source)
        smooth += flagged
    if not values:
        return Noise(float("nan"), "no test of 5 samples")
    source = Counter(sources).most_common(1)[0][0]
    if smooth and len(values) > 1:
        source = f"{source}; smooth: {smooth} of {len(values)} tests"
    return Noise(scoring.factor * float(np.median(values)), source, smooth > 0)


def _model_of(base):
    """The model of a fitted base: a model as it is; a `BaseFit`'s fit in its stack
    (every candidate off: the base exactly, through the stack's compiled
    simulation)."""
    if isinstance(base, AbstractCableModel):
        return base
    return base.stack.model(base.fit.model, None)


def noise_level(tests) -> float:
    """A robust estimate of the elongation noise, m: [`channel_noise`][] of each
    test's elongation, the median over tests."""
    values = [
        noise
        for t in as_test_list(tests)
        if (noise := channel_noise(t, FORCE_DRIVEN)) is not None
    ]
    return float(np.median(values)) if values else float("nan")
