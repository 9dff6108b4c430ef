"""The time of a record that counts cycles instead: a fatigue machine's cycle count
(`cycles` in `columns`) and the test frequency give the time, t = N / f.

**Bursts.** Fatigue machines log in bursts: all the samples of one cycle (40-60 at
200 Hz in the CCFatigue records of `tests/data/real/`), at cycles spaced
logarithmically (1, 2, ... 10, 20, ... 100 000), every sample of a burst carrying
the same count. Between two bursts the load kept cycling between its minimum and
maximum, thousands of times, unrecorded. A history that kept the burst samples and
joined them by straight lines would hold the load for those thousands of cycles at
whatever phase a burst happened to end on (3.3 kN in a 1.5-10.5 kN cycle), neither
the cycle nor its mean. So each burst, a run of samples with one count, is read as
one sample: the mean of its samples (force, elongation, any other column read) at
t = N / f, the time after N cycles. The force history is then the cycle's mean load,
held between the bursts, and the elongation the cycle's mean elongation: the
ratcheting (the mean strain growing with the cycles) that a creep model predicts
under the mean load. What a creep model driven by the mean load cannot see is the
cyclic part: the extra creep of the peaks where the flow is nonlinear in stress
(Eyring's sinh), cyclic softening, the hysteresis within a cycle. It stays in the
residual, as an effect the diagnosis may name or leave unexplained; the note of the
test gives the load's range within the bursts so that a user can judge. A record
with one sample per count (a peak-valley logger's one row per cycle) is read sample
by sample at t = N / f.
"""

import numpy as np

from .parsing import ColumnMap
from .testdata import where


def _burst_range(values: np.ndarray, starts: np.ndarray, columns) -> str:
    """The force's (or stress's) typical minimum, mean and maximum within a burst,
    in N (MPa), for the note; '' without a force column."""
    for position, column in enumerate(columns):
        if column.quantity in ("force", "stress"):
            break
    else:
        return ""
    unit = "N" if column.quantity == "force" else "MPa"
    x = values[:, position] * column.to_si
    low = np.minimum.reduceat(x, starts)
    high = np.maximum.reduceat(x, starts)
    mean = np.add.reduceat(x, starts) / np.diff(np.append(starts, x.size))
    return (
        f"; within a burst '{column.name}' cycled between {np.median(low):.4g} and "
        f"{np.median(high):.4g} {unit} (median over the bursts), their mean "
        f"{np.median(mean):.4g} {unit} is the load the history holds between bursts: "
        "the cyclic part (the peaks' extra creep, softening) is not in it"
    )


def cycles_to_time(
    values: np.ndarray,
    line_numbers: np.ndarray,
    columns: list[ColumnMap],
    frequency_hz: float | None,
    path,
) -> tuple[np.ndarray, np.ndarray, list[ColumnMap], tuple[str, ...]]:
    """The rows of a record with a cycle count (a column read as "cycles") as
    timed samples: each run of rows with one count (a burst) becomes one row, the
    mean of its rows, and the count becomes the time N / `frequency_hz` (rule and
    reasons in the module docstring).

    **Arguments:**

    - `values`, `line_numbers`: the parsed rows (file units) and their lines.
    - `columns`: the column map.
    - `frequency_hz`: the test frequency, Hz, or `None`.
    - `path`: the file, for errors.

    **Returns:**

    `(values, line_numbers, columns, notes)`: unchanged, with no note, where no
    column is a cycle count; else one row per burst (its line the burst's first),
    the cycle column read as the time in s, and one note saying how.

    **Raises:**

    `ValueError` naming the file (line, column) where a cycle count has no
    frequency, a frequency has no cycle count, or the count goes back.
    """
    found = [i for i, c in enumerate(columns) if c.quantity == "cycles"]
    if not found:
        if frequency_hz is not None:
            raise ValueError(
                f"{path}: frequency_hz (--frequency-hz) is given but no column is "
                "read as a cycle count (name it 'cycles' in columns=..., "
                "--columns)."
            )
        return values, line_numbers, columns, ()
    (position,) = found  # a second cycle column is refused with the columns
    column = columns[position]
    if frequency_hz is None:
        raise ValueError(
            f"{where(path, None, column.name, column.position)}: a cycle count, "
            "not a time; pass options=ReadOptions(frequency_hz=...) (--frequency-hz "
            "on the command line), the test frequency, to read the time as N / f."
        )
    count = values[:, position]
    back = np.flatnonzero(np.diff(count) < 0)
    if back.size:
        i = int(back[0]) + 1
        raise ValueError(
            f"{where(path, int(line_numbers[i]), column.name, column.position)}: "
            f"the cycle count goes back ({count[i]:g} follows {count[i - 1]:g} on "
            f"line {int(line_numbers[i - 1])})."
        )
    starts = np.flatnonzero(np.concatenate([[True], np.diff(count) > 0]))
    sizes = np.diff(np.append(starts, count.size))
    reduced = np.add.reduceat(values, starts, axis=0) / sizes[:, None]
    timed = columns.copy()
    timed[position] = column._replace(quantity="time", to_si=1.0 / frequency_hz)
    head = (
        f"time = the cycle count '{column.name}' / {frequency_hz:g} Hz (the time "
        "after N cycles)"
    )
    if sizes.max() == 1:
        return values, line_numbers, timed, (head,)
    note = (
        f"{head}; its {count.size} rows come in {starts.size} bursts of one count "
        f"each ({int(np.median(sizes))} samples, one cycle), each read as one sample, "
        "the mean of the burst" + _burst_range(values, starts, columns)
    )
    return reduced, line_numbers[starts], timed, (note,)
