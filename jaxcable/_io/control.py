"""Which channel a test imposed: force control (the force history is the input, the
elongation the response) or displacement control (the elongation is the input, the
force the response), from the file's `# control:` metadata or from the data.

A tensile test's controlled channel is the one that follows the machine's program:
it is held constant during holds and changes at a constant rate during ramps, while
the other channel creeps or relaxes. [`jaxcable.detect_control`][] measures both
signs of that and names the channel, with its evidence.
"""

from typing import NamedTuple

import numpy as np

from .._drive import TEST_DRIVES, AbstractTestDrive
from .slack import force_noise as noise_std
from .vocabulary import CONTROL_WORDS


CONTROLS = tuple(TEST_DRIVES)

# The detection's windows: the history is cut into this many blocks of samples (fewer
# for a short history, so that a block has _MIN_BLOCK samples).
_WINDOWS = 40
_MIN_BLOCK = 6
# A channel is held in a window when it moves by less than this many noise standard
# deviations (plus _HELD_SHARE of its range), and moves when its change exceeds
# _MOVING times that (a relaxing force late in a hold still moves).
_HELD_NOISE = 4.0
_HELD_SHARE = 2e-3
_MOVING = 3.0
# ... and when its mean over the window is within this many standard errors (of a
# difference of two window means) of a neighbouring window's mean.
_LEVEL_NOISE = 3.0
# In a window where both move, the channel whose straight-line fit leaves less than
# 1 / _LINEAR_RATIO of the other's relative misfit is the one following a ramp.
_LINEAR_RATIO = 3.0
# A channel whose straight-line fit over the whole test leaves less than _STRAIGHT of
# its range (and _STRAIGHT_RATIO times less than the other's) is the programmed one.
_STRAIGHT = 1e-3
_STRAIGHT_RATIO = 10.0
# The detection names a channel when its evidence is at least _DECISIVE times the
# other's, and at least _MIN_WINDOWS windows.
_DECISIVE = 2.0
_MIN_WINDOWS = 3


def control_name(value: str, place: str) -> str:
    """The canonical control (`"force"` or `"elongation"`) of a metadata value or an
    argument, accepting the common names (load, displacement, extension, position,
    stroke, strain, ...).

    **Raises:**

    `ValueError` starting with `place` for any other value.
    """
    words = str(value).strip().lower().replace("_", " ").split()
    if words and words[-1] == "control":
        words = words[:-1]
    key = " ".join(words)
    for mode, vocabulary in CONTROL_WORDS.items():
        if key in vocabulary:
            return mode
    raise ValueError(
        f"{place}: {value!r} is not a control mode; use 'force' (load control) or "
        "'elongation' (displacement, extension or position control)."
    )


class ControlDetection(NamedTuple):
    """Which channel drives a test, and why.

    **Fields:**

    - `control`: the drive's name, `"force"` or `"elongation"` (its value:
        `drive`).
    - `reason`: one line for a report: where the answer came from (the caller, the
        file's metadata, or the data with its evidence).
    - `force_windows`: windows where the force is held while the elongation moves, plus
        windows where the force follows a straight line and the elongation does not
        (0 when not detected from the data).
    - `elongation_windows`: the same with the channels exchanged.
    - `detected`: True when the answer came from the data.
    """

    control: str
    reason: str
    force_windows: int = 0
    elongation_windows: int = 0
    detected: bool = False

    @property
    def drive(self) -> AbstractTestDrive:
        """The drive value of `control` ([`jaxcable.FORCE_DRIVEN`][] or
        [`jaxcable.ELONGATION_DRIVEN`][])."""
        return TEST_DRIVES[self.control]


def _window_evidence(t, x, y) -> tuple[int, int]:
    """(windows for x, windows for y): held-while-the-other-moves plus
    straight-while-the-other-curves, over `_WINDOWS` blocks of samples."""
    n = t.size
    windows = max(1, min(_WINDOWS, n // _MIN_BLOCK))
    edges = np.unique(np.linspace(0, n, windows + 1).astype(int))
    channels, noises = [], []
    for z in (x, y):
        span = float(np.ptp(z)) or 1.0
        noises.append(noise_std(z))
        channels.append((z, span, _HELD_NOISE * noises[-1] + _HELD_SHARE * span))
    votes = [0, 0]
    pairs = [(a, b) for a, b in zip(edges[:-1], edges[1:]) if b - a >= 4]
    # A channel is held only where its level also stays with those of the windows
    # two before and after: a slow, noisy ramp (a force rising by less than its
    # noise band per window) changes level from window to window, a hold does not.
    levels = [[float(np.mean(z[a:b])) for a, b in pairs] for z, _, _ in channels]
    for k, (a, b) in enumerate(pairs):
        tw = t[a:b] - t[a]
        changes, misfits, steady = [], [], []
        for c, (z, span, held) in enumerate(channels):
            zw = z[a:b]
            changes.append((float(np.ptp(zw)), span, held))
            coef = np.polyfit(tw, zw, 1)
            misfit = float(np.sqrt(np.mean((zw - np.polyval(coef, tw)) ** 2)))
            misfits.append(misfit / max(float(np.ptp(zw)), 1e-300))
            near = [levels[c][j] for j in (k - 2, k + 2) if 0 <= j < len(pairs)]
            band = _LEVEL_NOISE * noises[c] * np.sqrt(2.0 / (b - a))
            band += _HELD_SHARE * span
            steady.append(all(abs(levels[c][k] - m) <= band for m in near))
        moving = [c > _MOVING * h for c, _, h in changes]
        held = [c < h and s for (c, _, h), s in zip(changes, steady)]
        # Changing level from window to window, if within the noise band in this
        # one: a slow ramp of a noisy channel.
        drifting = [m or not s for m, s in zip(moving, steady)]
        for i in (0, 1):
            j = 1 - i
            if held[i] and moving[j]:
                votes[i] += 1
            elif moving[i] and drifting[j] and misfits[i] * _LINEAR_RATIO < misfits[j]:
                votes[i] += 1
    return votes[0], votes[1]


def _channel(value, name: str) -> np.ndarray:
    """`value` as a 1-D float array, or a `TypeError`/`ValueError` naming `name`."""
    if isinstance(value, str | bytes) or value is None:
        raise TypeError(f"`{name}` must be an array of numbers, got {value!r}.")
    try:
        array = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise TypeError(f"`{name}` must be an array of numbers.") from None
    if array.ndim != 1:
        raise ValueError(f"`{name}` must be 1-dimensional, got shape {array.shape}.")
    return array


def _constant_rate(t, f, e) -> str | None:
    """The channel that follows one straight line over the whole test (a test at
    one crosshead speed or load rate, a yield plateau included) while the other
    does not, or None."""
    misfits = []
    for z in (f, e):
        span = float(np.ptp(z))
        if span == 0:
            return None
        coef = np.polyfit(t - t[0], z, 1)
        misfits.append(float(np.sqrt(np.mean((z - np.polyval(coef, t - t[0])) ** 2))))
        misfits[-1] /= span
    for name, mine, other in (
        ("force", *misfits),
        ("elongation", *misfits[::-1]),
    ):
        if mine < _STRAIGHT and other > _STRAIGHT_RATIO * mine:
            return name
    return None


def detect_control(
    time: np.ndarray, force: np.ndarray, elongation: np.ndarray
) -> ControlDetection:
    """Detect which channel a test imposed, from the data alone.

    A channel that follows one straight line in time over the whole test (its
    linear fit leaves less than 0.1 % of its range, and ten times less than the
    other's: a test at one crosshead speed or load rate) is named. Otherwise the
    history is cut into 40 blocks of samples (of at least 6). A block votes for the
    force when the force is held (moves by less than 4 noise standard deviations
    plus 0.2 % of its range, and its mean stays within 3 standard errors of those
    of the blocks two before and after) while the elongation moves (by more than 3
    times its own such threshold), or when the force moves, the elongation moves
    or changes level from block to block, and the force is the straight line (a
    linear fit in time leaves less than a third of the elongation's relative
    misfit): a hold or a ramp of the machine's program. Likewise for the elongation. The channel with at least twice
    the other's votes, and at least 3, is named; otherwise the evidence is
    ambiguous and the force is returned (jaxcable's historical drive), which the
    reason says.

    **Arguments:**

    - `time`: sample times, s.
    - `force`: force, N.
    - `elongation`: elongation (any length unit).

    **Returns:**

    A [`jaxcable.ControlDetection`][].
    """
    t, f, e = (
        _channel(value, name)
        for value, name in (
            (time, "time"),
            (force, "force"),
            (elongation, "elongation"),
        )
    )
    if not t.shape == f.shape == e.shape:
        raise ValueError(
            f"`time`, `force` and `elongation` must have one length, got "
            f"{t.size}, {f.size} and {e.size}."
        )
    ok = np.isfinite(t) & np.isfinite(f) & np.isfinite(e)
    t, f, e = t[ok], f[ok], e[ok]
    if t.size < 8:
        return ControlDetection(
            "force", "too few samples to detect the control: force (the default)"
        )
    whole = _constant_rate(t, f, e)
    if whole is not None:
        return ControlDetection(
            whole,
            f"detected {whole} control (it follows one straight line in time over "
            "the whole test: a constant rate)",
            detected=True,
        )
    votes_f, votes_e = _window_evidence(t, f, e)
    evidence = f"{votes_f} windows for force, {votes_e} for elongation"
    for name, mine, other in (
        ("force", votes_f, votes_e),
        ("elongation", votes_e, votes_f),
    ):
        if mine >= _MIN_WINDOWS and mine >= _DECISIVE * other:
            return ControlDetection(
                name, f"detected {name} control ({evidence})", votes_f, votes_e, True
            )
    return ControlDetection(
        "force",
        f"control ambiguous ({evidence}): force (the default); name it with "
        "--drive or a '# control:' line",
        votes_f,
        votes_e,
        True,
    )


def resolve_control(test, requested) -> ControlDetection:
    """The control of one test: `requested` (a drive value, its name `"force"` or
    `"elongation"`, or `None` / `"auto"`), else the test's `metadata['control']`,
    else detected from its data.

    **Raises:**

    `ValueError` naming `drive` for an unknown `requested`.
    """
    if isinstance(requested, AbstractTestDrive):
        return ControlDetection(requested.name, f"{requested.name} (given)")
    if requested is not None and requested != "auto":
        name = control_name(requested, "`drive`")
        return ControlDetection(name, f"{name} (given)")
    metadata = getattr(test, "metadata", None) or {}
    if "control" in metadata:
        name = control_name(metadata["control"], "metadata 'control'")
        return ControlDetection(name, f"{name} (the file's 'control' line)")
    elongation = getattr(test, "elongation", None)
    if elongation is None:
        return ControlDetection("force", "force (the test has no elongation)")
    # The masked samples (a slack cable) follow neither the program nor the cable;
    # the force as measured, not clipped at zero, follows the program.
    mask = getattr(test, "mask", None)
    keep = slice(None) if mask is None or not np.any(mask) else np.asarray(mask)
    force = getattr(test, "force_raw", None)
    force = test.force if force is None else force
    return detect_control(
        np.asarray(test.time)[keep],
        np.asarray(force)[keep],
        np.asarray(elongation)[keep],
    )
