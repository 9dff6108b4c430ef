"""The rule of a diagnosis, and every threshold it uses (each defined here, once):
a catalogue cause is named only when it explains the
residual, not merely when it improves it.

Three outcomes:

- `"none"`: the base model already predicts the held-out data to within `MIN_EXCESS`
  (1.2) times the noise floor estimated from the data: there is nothing to explain.
- `"named"`: a candidate is significant (held-out gain >= 5 %, ΔBIC <= -10, size >= 3
  standard errors; see `jaxcable.diagnose`) *and sufficient*: its held-out RMSE is
  within `MAX_FLOOR_RATIO` = k times the noise floor, or it explains at least
  `MIN_EXPLAINED_PCT` = S % of the base's held-out excess over the floor. Among those,
  the one of largest held-out gain is named.
- `"unexplained"`: the base's excess is significant but no candidate is both: the
  partial candidates are listed with the share of the excess each explains. When no
  candidate is even significant, the excess must also be systematic: the base
  residual's lag-1 autocorrelation at least `MIN_AUTOCORRELATION` (0.5); a white
  residual above the estimated noise is noise the estimate missed (the second
  differences miss the model's response to the force noise it is driven with, e.g.
  a Burgers truth scored in N at 1.3 x the estimate), so the verdict is `"none"`.

The excess is measured in squares, in the scored units: the base's held-out mean
square minus the floor's. A candidate's explained share is

    explained_pct = 100 (base^2 - candidate^2) / (base^2 - floor^2),

100 % when the candidate reaches the floor, 0 % when it does no better than the base.

**How k and S were chosen** (docs/diagnosis.md has the tables). Measured with
`benchmarks/diagnose_matrix.py` on the hidden effects of
`jaxcable.papers.hidden_effect_dataset` at their documented sizes (seeds 100-109: 70
in-catalogue and 30 out-of-catalogue data sets), the bundled data and the 15 VHB 4910
tests of notebook 03 (force-driven, 3-fold by tests); "noise" is `Diagnosis.noise`,
the estimate from the data:

| data | best significant candidate | held-out / noise | explained_pct |
| --- | --- | ---: | ---: |
| 7 in-catalogue effects x 10 seeds | the hidden one | 0.81-1.48 | 52-157 |
| bundled data (compliance) | termination_compliance | 7.0 | 99 |
| `clamp_slip` (outside), 10 seeds | stress_nonlinear_creep (wrong) | 2.40-3.61 | 78-89 |
| `cyclic_softening` (outside), 10 seeds | discovered (partial) | 6.2-9.8 | 37-70 |
| VHB 4910 | stress_nonlinear_creep (24.5 % gain, lag-1 r 0.98) | 1.1e5 | 43 |
| hidden second_retardation, runner-up | sensor_drift | 3.0-3.2 | 48-51 |

k = 2 lies between 1.48 (every in-catalogue effect is named through k) and 2.40 (the
closest wrong cause); S = 95 % between 89 % (the largest share a wrong cause
explained) and 99 % (the bundled data, named through S at 7 x the noise).
"""

import math
from collections.abc import Sequence
from typing import NamedTuple


# Significance thresholds of a candidate (see `jaxcable.diagnose`): its held-out gain
# over the base, %; ΔBIC on the training samples; |size| / standard error. The same
# gain keeps a support of the discovery ([`jaxcable.Discovery`][]): on noise alone, a
# term fitted to the training samples predicts the held-out ones by chance by at most
# a few percent.
MIN_GAIN_PCT = 5.0
MAX_DELTA_BIC = -10.0
MIN_SIZE_Z = 3.0
# The held-out gain, %, of a known candidate a round may go on with when its size is
# within MIN_SIZE_Z standard errors (`partial_cause` of the rounds).
MIN_PARTIAL_GAIN_PCT = 2.0 * MIN_GAIN_PCT
# Nothing is named while the base already predicts the held-out data to within 20 % of
# the noise level estimated from the data: what is left is noise, and a candidate that
# "explains" it is fitting the noise's realisation (measured: a 10 J/mol activation
# energy, 0.03 % of time scaling, took 9 % off a base held-out RMSE of 1.1 x noise).
MIN_EXCESS = 1.2
# A significant candidate is named when its held-out RMSE is within k x the floor...
MAX_FLOOR_RATIO = 2.0
# ... or when it explains at least S % of the base's excess over the floor.
MIN_EXPLAINED_PCT = 95.0
# A candidate whose held-out RMSE is more than this multiple of the base's diverges:
# its fit compensates something else on the training samples and runs away where it
# extrapolates (a drift rate fitted on hours of load carried over a 72 h rest). Its
# share of the excess is no measure of anything; it is flagged, not ranked.
MAX_DIVERGENCE = 2.0
# With no significant candidate, an excess is "unexplained" only when systematic: a
# smooth error s on white noise sigma has lag-1 autocorrelation s^2 / (s^2 + sigma^2),
# 0.5 where s = sigma (a base at sqrt(2) x the noise).
MIN_AUTOCORRELATION = 0.5


def thresholds() -> dict[str, float]:
    """The thresholds of the rule by their names in the JSON of a diagnosis."""
    return {
        "min_gain_pct": MIN_GAIN_PCT,
        "max_delta_bic": MAX_DELTA_BIC,
        "min_size_z": MIN_SIZE_Z,
        "min_excess_over_noise": MIN_EXCESS,
        "max_heldout_over_noise": MAX_FLOOR_RATIO,
        "min_explained_pct": MIN_EXPLAINED_PCT,
        "min_autocorrelation_unexplained": MIN_AUTOCORRELATION,
        "max_divergence": MAX_DIVERGENCE,
    }


class Verdict(NamedTuple):
    """The decision on the scored candidates.

    **Fields:**

    - `verdict`: `"named"`, `"none"` or `"unexplained"`.
    - `named`: the index of the named candidate in the sequence given, or None.
    - `explained_pct`: the explained share of the excess of every candidate, %
        (NaN where its RMSE is not finite, or the base has no excess).
    """

    verdict: str
    named: int | None
    explained_pct: tuple[float, ...]


def explained_pct(base: float, candidate: float, floor: float) -> float:
    """The share of the base's held-out excess over the noise floor a candidate
    explains, %: 100 (base^2 - candidate^2) / (base^2 - floor^2).

    **Arguments:**

    - `base`: the base model's held-out RMSE.
    - `candidate`: the candidate's held-out RMSE, in the same unit.
    - `floor`: the noise floor, in the same unit.

    **Returns:**

    The share, % (above 100 when the candidate beats the floor, negative when it is
    worse than the base); NaN when an input is not finite or the base is not above
    the floor (no excess to share).
    """
    if not all(math.isfinite(x) for x in (base, candidate, floor)):
        return math.nan
    excess = base * base - floor * floor
    if excess <= 0.0:
        return math.nan
    return 100.0 * (base * base - candidate * candidate) / excess


def explained_rmse_pct(base: float, candidate: float, floor: float) -> float:
    """The share of the base's held-out excess over the noise floor a candidate
    explains, measured on the RMSEs themselves, %: 100 (base - candidate) / (base -
    floor). Unlike [`explained_pct`][] (on squares) it does not call a residual of
    10 x the noise 99 % explained when the base was at 100 x.

    **Arguments:**

    - `base`, `candidate`, `floor`: held-out RMSEs of the base and the candidate,
        and the noise floor, in one unit.

    **Returns:**

    The share, %; NaN when an input is not finite or the base is not above the
    floor.
    """
    if not all(math.isfinite(x) for x in (base, candidate, floor)):
        return math.nan
    if base <= floor:
        return math.nan
    return 100.0 * (base - candidate) / (base - floor)


def diverges(base: float, candidate: float) -> bool:
    """Whether a candidate's held-out RMSE is more than `MAX_DIVERGENCE` x the
    base's (or not finite while the base's is)."""
    if not math.isfinite(base):
        return False
    return not (math.isfinite(candidate) and candidate <= MAX_DIVERGENCE * base)


def sufficient(base: float, candidate: float, floor: float) -> bool:
    """Whether a candidate explains enough to be named: its held-out RMSE within
    `MAX_FLOOR_RATIO` x `floor`, or its explained share at least
    `MIN_EXPLAINED_PCT`.

    **Arguments:**

    - `base`, `candidate`, `floor`: held-out RMSEs of the base and the candidate,
        and the noise floor, in one unit.

    **Returns:**

    True when the candidate is sufficient.
    """
    if not (math.isfinite(candidate) and math.isfinite(floor)):
        return False
    share = explained_pct(base, candidate, floor)
    return candidate <= MAX_FLOOR_RATIO * floor or (
        math.isfinite(share) and share >= MIN_EXPLAINED_PCT
    )


def decide(
    base: float,
    floor: float,
    heldout: Sequence[float],
    significant: Sequence[bool],
    autocorrelation: float = math.nan,
) -> Verdict:
    """The verdict on scored candidates, from numbers alone.

    **Arguments:**

    - `base`: the base model's held-out RMSE.
    - `floor`: the noise floor estimated from the data, same unit.
    - `heldout`: every candidate's held-out RMSE, same unit (NaN: not applicable).
    - `significant`: whether each passed the three significance tests (gain,
        ΔBIC, size z).
    - `autocorrelation`: the base residual's lag-1 autocorrelation (NaN: unknown,
        taken as systematic).

    **Returns:**

    A [`Verdict`][]: `"none"` when `base` <= `MIN_EXCESS` x `floor` or `floor` is
    not finite (no noise estimate, nothing to weigh the excess against); else
    `"named"` with the significant, sufficient candidate of lowest held-out RMSE
    (largest gain); else `"unexplained"`, but `"none"` when no candidate is
    significant and `autocorrelation` < `MIN_AUTOCORRELATION` (no systematic
    residual).
    """
    shares = tuple(explained_pct(base, h, floor) for h in heldout)
    if not (math.isfinite(floor) and base > MIN_EXCESS * floor):
        return Verdict("none", None, shares)
    able = [
        i
        for i, (h, s) in enumerate(zip(heldout, significant))
        if s and sufficient(base, h, floor)
    ]
    if able:
        return Verdict("named", min(able, key=lambda i: heldout[i]), shares)
    if not any(significant) and autocorrelation < MIN_AUTOCORRELATION:
        return Verdict("none", None, shares)
    return Verdict("unexplained", None, shares)
