"""The load cell's reading as the cable's force: its sign (a cell that reads tension
as negative) and its offset at rest (a cell not zeroed before the test), each
corrected only where the record itself shows it, with a note saying so.

**Sign** (`force_sign="auto"`). The force is read with its sign flipped when the
record is a tension test written with tension negative: the force is predominantly
negative (more than half the readings below zero, and the reading of largest
magnitude negative) while the elongation grows from its first value (its median
change positive, its largest change positive), and the two move together (their
correlation at most -0.3: the force grows in magnitude as the elongation grows).
A compression test (force and elongation both going negative) has a positive
correlation and an elongation that shrinks: it is read as written. `force_sign=1`
reads every file as written, `-1` flips every file.

**Tare** (`tare=True`). The rest plateau is the first samples while the elongation
has not yet moved (within 3 x its own noise or 0.1 % of its range of its first
value), at least 5 of them, with the force constant within the noise (its standard
deviation at most 3 x the force noise of the record, from its second differences).
With the test's direction d (the sign of the reading of largest magnitude: +1 in
tension), the rest reading r = d x the plateau's median is an offset, removed, when

- r < -band: the cable at rest would push (a tension test whose cell reads below
  zero before it is loaded), or
- r > band, the test loads above it (max d F > r + m, m = max(band, 10 % of r)),
  comes back to the rest elongation (or short of it) and reads less there (d F <
  r - m), and yet the cell never reads zero (min d F > band). A preload is held,
  left for zero, or left at a larger elongation (a creep test's recovery at a
  lower load); a test that starts at its load (a creep record at its mean load)
  never loads well above it. The rule cannot tell an offset from a preload that
  the specimen loses for good without going slack (a set, a Mullins softening, or
  the grips' inertia in fast cycles reading below it): `tare=False` keeps it.

`band` is the slack threshold of [`jaxcable.mask_slack`][]: max(0.5 % of the
peak |F|, 3 x the force noise), at most 5 % of the peak. A zeroed cell (|r| <=
band) and a test that starts loaded (a preloaded creep or relaxation test: r > band,
never undercut, or undercut down to zero) keep their readings.
"""

import dataclasses
import math

import numpy as np

from .slack import (
    SLACK_CAP_FRACTION,
    SLACK_NOISE_FACTOR,
    SLACK_PEAK_FRACTION,
    force_noise,
)
from .testdata import TestData


# The constants of the rules above (module docstring).
SIGN_CORRELATION = -0.3
REST_MIN_SAMPLES = 5
REST_NOISE_FACTOR = 3.0
REST_RANGE_FRACTION = 1e-3
REST_MOVE_FRACTION = 0.1
FORCE_SIGNS = ("auto", 1, -1)


def check_force_sign(value) -> int | str:
    """`force_sign` as `"auto"`, `1` or `-1` (`"+1"` and `"-1"` read too)."""
    if isinstance(value, str) and value.strip() in ("auto", "+1", "1", "-1"):
        text = value.strip()
        return "auto" if text == "auto" else int(text)
    if not isinstance(value, bool) and value in (1, -1):
        return int(value)
    raise ValueError(f"`force_sign` must be 'auto', 1 or -1, got {value!r}.")


def _band(force: np.ndarray, noise: float) -> float:
    """The slack threshold of `mask_slack` for these readings, N."""
    peak = float(np.max(np.abs(force)))
    band = max(SLACK_PEAK_FRACTION * peak, SLACK_NOISE_FACTOR * noise)
    return min(band, SLACK_CAP_FRACTION * peak) if peak > 0 else band


def _tension_negative(force: np.ndarray, elongation: np.ndarray) -> str | None:
    """Why the record reads tension as negative (the sign rule), or None."""
    change = elongation - elongation[0]
    below = float(np.mean(force < 0))
    if not (below > 0.5 and -np.min(force) > np.max(force)):
        return None
    if not (np.median(change) > 0 and np.max(change) > -np.min(change)):
        return None
    if np.std(force) == 0 or np.std(elongation) == 0:
        return None
    r = float(np.corrcoef(force, elongation)[0, 1])
    if not r <= SIGN_CORRELATION:
        return None
    return (
        f"{below:.0%} of the readings below zero, down to {np.min(force):.4g} N, "
        f"while the elongation grows from its start; correlation {r:.2f}"
    )


def _still(elongation: np.ndarray) -> float:
    """How far the elongation may be from a value and still be at it, m."""
    return max(
        REST_NOISE_FACTOR * force_noise(elongation),
        REST_RANGE_FRACTION * float(np.ptp(elongation)),
    )


def _rest(force: np.ndarray, elongation: np.ndarray, noise: float) -> int:
    """The number of samples of the rest plateau (0 when there is none)."""
    moved = np.flatnonzero(np.abs(elongation - elongation[0]) > _still(elongation))
    n = int(moved[0]) if moved.size else elongation.size
    if n < REST_MIN_SAMPLES or n == elongation.size:
        return 0
    if np.std(force[:n]) > REST_NOISE_FACTOR * noise:
        return 0
    return n


def _back_at_rest(elongation: np.ndarray, n: int) -> np.ndarray:
    """The samples after the rest plateau (its first `n`) at or short of the rest
    elongation (on the side away from the test's largest excursion)."""
    change = elongation - elongation[0]
    side = 1.0 if np.max(change) >= -np.min(change) else -1.0
    back = side * change <= _still(elongation)
    back[:n] = False
    return back


def _tare(force: np.ndarray, elongation: np.ndarray, lines) -> tuple[float, str]:
    """The offset to remove from `force` (0 for none) and a note ('' for none)."""
    noise = force_noise(force)
    n = _rest(force, elongation, noise)
    if not n:
        return 0.0, ""
    band = _band(force, noise)
    direction = 1.0 if np.max(force) >= -np.min(force) else -1.0
    level = float(np.median(force[:n]))
    tension = direction * force
    rest, lowest, highest = direction * level, np.min(tension), np.max(tension)
    back = _back_at_rest(elongation, n)
    at_back = float(np.min(tension[back])) if back.any() else math.inf
    margin = max(band, REST_MOVE_FRACTION * abs(rest))
    where = f"lines {lines[0]}-{lines[n - 1]}" if lines is not None else f"{n} samples"
    at_rest = (
        f"the load cell read {level:.4g} N at rest ({where}, the elongation not yet "
        f"moving, the force constant within {np.std(force[:n]):.2g} N)"
    )
    if rest < -band:
        why = "a cable at rest cannot push"
    elif (
        rest > band and band < lowest and at_back < rest - margin < highest - 2 * margin
    ):
        why = (
            "the test loads above it, comes back to the rest elongation and reads "
            f"less there (down to {direction * at_back:.4g} N), without the cell ever "
            "reading zero: an offset, not a preload"
        )
    else:
        if abs(rest) <= band:
            return 0.0, ""
        if lowest <= band:
            reason = "the cell reads zero later: it is zeroed"
        elif not back.any():
            reason = "the test never comes back to the rest elongation"
        elif at_back >= rest - margin:
            reason = "the test reads as much at the rest elongation later"
        else:
            reason = "the test never loads well above it"
        return 0.0, f"{at_rest} is kept as a load the test starts with ({reason})"
    return level, f"force tared by {-level:+.4g} N: {at_rest}; {why}"


def correct_load_cell(
    data: TestData, force_sign: int | str = "auto", tare: bool = True
) -> TestData:
    """`data` with its force read as the cable's tension: its sign and its offset
    at rest corrected where the record shows them (rules in the module docstring),
    each correction, and each rest reading kept, said in `notes`.

    **Arguments:**

    - `data`: a [`jaxcable.TestData`][] as read (before [`jaxcable.mask_slack`][]:
        a slack mask is dropped, to be found again on the corrected force).
    - `force_sign`: `"auto"` (the sign rule), `1` (as written) or `-1` (flipped).
    - `tare`: whether an offset at rest is looked for and removed.

    **Returns:**

    A new [`jaxcable.TestData`][] (the same where nothing is corrected or there is
    no finite force, e.g. an elongation history).
    """
    sign = check_force_sign(force_sign)
    measured = data.force if data.force_raw is None else data.force_raw
    if not np.all(np.isfinite(measured)) or measured.size < 3:
        return data
    force, notes = measured, []
    e = data.elongation
    if sign == -1:
        force = -force
        notes.append("force read with its sign flipped (force_sign=-1)")
    elif sign == "auto" and e is not None:
        why = _tension_negative(force, e)
        if why is not None:
            force = -force
            notes.append(
                f"force read with its sign flipped: the load cell reads tension as "
                f"negative ({why}); force_sign=1 (--force-sign +1) reads it as written"
            )
    if tare and e is not None:
        offset, note = _tare(force, e, data.lines)
        if offset:
            force = force - offset
            note += "; tare=False (--no-tare) reads it as written"
        if note:
            notes.append(note)
    if not notes:
        return data
    if force is measured:  # a rest reading kept: only its note
        return dataclasses.replace(data, notes=(*data.notes, *notes))
    return dataclasses.replace(
        data,
        force=force,
        force_raw=None,
        slack_report=None,
        mask=None,
        notes=(*data.notes, *notes),
    )
