"""Slack detection: the stretches of a measured history where the cable carried no load.

A cable (or a specimen) is slack when the crosshead keeps moving but the load cell reads
about zero: before the cable is taut at the start of a test, or at the end of an
unloading whose residual elongation the crosshead overtakes (the VHB 4910 exports end
like this, with the force a little below zero). There the crosshead displacement is not
the cable's elongation, so those samples must not be fitted.

**The rule.** With `F` the force as measured and `e` the elongation (crosshead
displacement):

1. *Threshold.* `threshold = max(0.5 % of the peak force, 3 x the force noise)`, capped
   at 5 % of the peak force. The noise is the robust standard deviation of the
   second differences of `F` (`1.4826 MAD / sqrt(6)`), which a smooth ramp does not
   contribute to. A given `threshold` replaces this.
2. *Low runs.* Maximal runs of consecutive samples with `F < threshold`.
3. *Slack.* A low run is slack when, over the run, (a) the elongation spans at least
   2 % of the test's elongation range and (b) it changes at the crosshead's speed: the
   median `|de/dt|` over the run (the step into the run included) is at least 10 % of
   the reference speed, which is `rate_mm_per_min` from the metadata when given, else
   the 90th percentile of `|de/dt|` over the test. (a) keeps the few samples a taut
   cable spends near zero force at each unloading valley; (b) keeps a rest at zero
   force, where the elongation recovers slowly (recovery data are to be fitted).
4. *Mask.* Slack samples, and any sample with `F < -threshold` (a cable cannot push:
   a reading below the noise band is a slack or tare reading), are masked. Without an
   elongation column only the second kind is.
5. *Clip.* Every negative force is set to 0 in the fitted force (the kernels reject
   negative forces; a slack cable carries zero), the measured force being kept.
"""

import dataclasses
import math

import numpy as np


# The constants of the rule above (module docstring).
SLACK_PEAK_FRACTION = 0.005
SLACK_NOISE_FACTOR = 3.0
SLACK_CAP_FRACTION = 0.05
SLACK_SPAN_FRACTION = 0.02
SLACK_SPEED_FRACTION = 0.1
SLACK_SPEED_PERCENTILE = 90.0


@dataclasses.dataclass(frozen=True)
class SlackStretch:
    """One detected slack stretch (see [`jaxcable.mask_slack`][]).

    **Fields:**

    - `start`, `stop`: sample indices, `stop` exclusive.
    - `lines`: the 1-based first and last line of the stretch in the file, or `None`.
    - `time`: first and last time, s.
    - `elongation`: elongation at the first and last sample, m.
    - `min_force`: the lowest measured force in the stretch, N.
    """

    start: int
    stop: int
    lines: tuple[int, int] | None
    time: tuple[float, float]
    elongation: tuple[float, float]
    min_force: float

    @property
    def num_samples(self) -> int:
        """The number of samples in the stretch."""
        return self.stop - self.start

    def __str__(self) -> str:
        where = (
            f"lines {self.lines[0]}-{self.lines[1]}"
            if self.lines is not None
            else f"samples {self.start}-{self.stop - 1}"
        )
        e0, e1 = (1e3 * e for e in self.elongation)
        return (
            f"{where} ({self.num_samples} samples, t = {self.time[0]:g}-"
            f"{self.time[1]:g} s, elongation {e0:.3g} -> {e1:.3g} mm, force >= "
            f"{self.min_force:.3g} N)"
        )


@dataclasses.dataclass(frozen=True)
class SlackReport:
    """What slack detection found in one test (see [`jaxcable.mask_slack`][]).

    **Fields:**

    - `threshold`: the force threshold used, N.
    - `noise`: the estimated force noise (standard deviation), N.
    - `peak_force`: the largest measured force, N.
    - `speed`: the reference crosshead speed, m/s, or `None` without elongation.
    - `stretches`: the slack stretches, in time order.
    - `negative`: the number of samples outside the stretches masked because their
        force is below `-threshold`.
    - `masked`: the number of masked samples in all.
    - `clipped`: the number of negative forces set to 0.
    """

    threshold: float
    noise: float
    peak_force: float
    speed: float | None
    stretches: tuple[SlackStretch, ...]
    negative: int
    masked: int
    clipped: int

    def __str__(self) -> str:
        n = len(self.stretches)
        head = f"{n} slack stretch{'es' if n != 1 else ''}"
        if n:
            head += ": " + "; ".join(str(s) for s in self.stretches)
        parts = [head]
        if self.negative:
            parts.append(
                f"{self.negative} other samples with force < -{self.threshold:.3g} N"
            )
        parts.append(f"{self.masked} samples masked")
        parts.append(f"{self.clipped} negative forces clipped to 0")
        parts.append(
            f"threshold {self.threshold:.3g} N (peak {self.peak_force:.4g} N, noise "
            f"{self.noise:.3g} N)"
        )
        return "; ".join(parts)


def force_noise(force: np.ndarray) -> float:
    """Robust standard deviation of the noise of a channel (force, N; or any other).

    Second differences remove the signal's level and slope; the median absolute
    deviation ignores the few large ones at turning points.
    """
    if force.size < 3:
        return 0.0
    # Forces near the float range overflow here; the estimate is then inf or NaN,
    # which the slack threshold below ignores (it is capped by the peak force).
    with np.errstate(over="ignore", invalid="ignore"):
        d2 = np.diff(force, 2)
        mad = float(np.median(np.abs(d2 - np.median(d2))))
    return 1.4826 * mad / math.sqrt(6.0)


def _runs(flags: np.ndarray) -> np.ndarray:
    """`(runs, 2)` array of [start, stop) of the runs of True in `flags`."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], flags.astype(np.int8), [0]])))
    return edges.reshape(-1, 2)


def detect_slack(
    time: np.ndarray,
    force: np.ndarray,
    elongation: np.ndarray | None = None,
    *,
    speed: float | None = None,
    threshold: float | None = None,
    lines: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, SlackReport]:
    """Find the slack samples of a history (the rule is in the module docstring).

    **Arguments:**

    - `time`: sample times, s, strictly increasing.
    - `force`: measured force, N.
    - `elongation`: elongation (crosshead displacement), m, or `None`.
    - `speed`: the crosshead speed, m/s, or `None` to estimate it from the data.
    - `threshold`: the force threshold, N, or `None` for the default rule.
    - `lines`: 1-based file line of each sample (for the report), or `None`.

    **Returns:**

    `(mask, fitted_force, report)`: `mask` True where the sample is to be fitted,
    the force with negative values set to 0 (N), and a [`jaxcable.SlackReport`][].
    """
    t = np.asarray(time, dtype=float)
    f = np.asarray(force, dtype=float)
    peak = max(float(np.max(f)), 0.0)
    noise = force_noise(f)
    if threshold is None:
        threshold = max(SLACK_PEAK_FRACTION * peak, SLACK_NOISE_FACTOR * noise)
        if peak > 0:
            threshold = min(threshold, SLACK_CAP_FRACTION * peak)
    threshold = float(threshold)
    if not (math.isfinite(threshold) and threshold >= 0):
        raise ValueError(f"Slack threshold must be finite and >= 0, got {threshold}.")

    slack = np.zeros(f.shape, dtype=bool)
    stretches = []
    reference = None
    if elongation is not None and f.size >= 2:
        e = np.asarray(elongation, dtype=float)
        # Time is strictly increasing in loaded data; errstate only guards other
        # callers from a warning (their inf rates count as moving).
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            rates = np.abs(np.diff(e) / np.diff(t))
        if speed is not None:
            reference = float(speed)
        else:
            reference = float(np.percentile(rates, SLACK_SPEED_PERCENTILE))
        span_min = SLACK_SPAN_FRACTION * float(np.ptp(e))
        for start, stop in _runs(f < threshold):
            if stop - start < 2:
                continue
            span = float(np.ptp(e[start:stop]))
            run_rates = rates[max(start - 1, 0) : stop - 1]
            moving = float(np.median(run_rates)) >= SLACK_SPEED_FRACTION * reference
            if not (span > 0 and span >= span_min and moving):
                continue
            slack[start:stop] = True
            stretches.append(
                SlackStretch(
                    start=int(start),
                    stop=int(stop),
                    lines=None
                    if lines is None
                    else (int(lines[start]), int(lines[stop - 1])),
                    time=(float(t[start]), float(t[stop - 1])),
                    elongation=(float(e[start]), float(e[stop - 1])),
                    min_force=float(np.min(f[start:stop])),
                )
            )
    negative = (f < -threshold) & ~slack
    mask = ~(slack | negative)
    report = SlackReport(
        threshold=threshold,
        noise=noise,
        peak_force=peak,
        speed=reference,
        stretches=tuple(stretches),
        negative=int(np.sum(negative)),
        masked=int(np.sum(~mask)),
        clipped=int(np.sum(f < 0)),
    )
    return mask, np.maximum(f, 0.0), report
