"""How long work reports its progress: the progress meters passed as
`progress_meter=` to [`jaxcable.diagnose`][], [`jaxcable.monte_carlo`][], the reports
and the command line, and the one-line text bar they draw.

A progress meter is a value (like diffrax's `progress_meter`): [`NoProgressMeter`][]
says nothing, [`TextProgressMeter`][] draws a text bar on stderr and prints each
step's news, [`CallbackProgressMeter`][] passes the news to a function. Work opens a bar with `meter.bar(label, total)` (a context manager with
`advance(steps, note)`) and tells of each step with `meter.say(message)`.
"""

import abc
import sys
import threading
import time
from collections.abc import Callable
from typing import TextIO

import equinox as eqx


class Progress:
    """A one-line text progress bar on stderr, for work that takes a while.

    Silent unless `enabled` (the command line enables it when stderr is a terminal and
    `--quiet` is not given), so that logs and pipes get no carriage returns. Work
    without a known number of steps (one compiled fit) shows the elapsed time, redrawn
    by a background thread.

    The bar reads `label [####....] done/total 12 s` (with `eta`, then `ETA 30 s`),
    then the note of the last step.

    **Arguments:**

    - `label`: what is being done, e.g. `"reading"`.
    - `total`: the number of steps, or `None` for a spinner with the elapsed time.
    - `enabled`: whether to draw at all.
    - `stream`: where to draw (default `sys.stderr`).
    - `eta`: with `total`, show the estimated time left, from the mean time of the
        steps after the first one (which, in jitted work, includes the compilation).
    - `keep`: at the end, leave the last line on the stream (ended by a newline)
        instead of erasing it.
    """

    _WIDTH = 24
    _SPIN = "|/-\\"

    def __init__(
        self,
        label: str,
        total: int | None = None,
        *,
        enabled: bool = True,
        stream: TextIO | None = None,
        eta: bool = False,
        keep: bool = False,
    ):
        self.label = label
        self.total = total
        self.enabled = enabled
        self.stream = sys.stderr if stream is None else stream
        self.eta = eta
        self.keep = keep
        self.done = 0
        self.start = time.monotonic()
        # When the first step ended, and how many steps it counted (for the ETA).
        self._first: tuple[float, int] | None = None
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = None
        self._width = 0

    def __enter__(self) -> "Progress":
        if self.enabled:
            self._draw()
            if self.total is None:
                self._thread = threading.Thread(target=self._spin, daemon=True)
                self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def advance(self, steps: int = 1, note: str = "") -> None:
        """Count `steps` more steps done; `note` (e.g. a file name) is shown."""
        self.done += steps
        if self._first is None:
            self._first = (time.monotonic(), self.done)
        if self.enabled:
            self._draw(note)

    def close(self) -> None:
        """Stop and erase the bar (with `keep`, end its line instead)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
            self._thread = None
        if self.enabled:
            with self._lock:
                if self.keep:
                    self.stream.write("\n")
                else:
                    self.stream.write("\r" + " " * self._width + "\r")
                self.stream.flush()
            self.enabled = False

    def _spin(self) -> None:
        while not self._stop.wait(0.25):
            self._draw()

    def _time_left(self, now: float) -> str:
        # The first step is left out of the rate: it includes the compilation.
        if self.total is None or self._first is None or self.done <= self._first[1]:
            return "?"
        first_time, first_done = self._first
        rate = (now - first_time) / (self.done - first_done)
        return f"{rate * max(self.total - self.done, 0):.0f} s"

    def _draw(self, note: str = "") -> None:
        now = time.monotonic()
        elapsed = now - self.start
        if self.total:
            filled = int(self._WIDTH * min(self.done, self.total) / self.total)
            bar = "#" * filled + "." * (self._WIDTH - filled)
            text = f"{self.label} [{bar}] {self.done}/{self.total}"
        else:
            spin = self._SPIN[int(elapsed * 4) % len(self._SPIN)]
            text = f"{self.label} {spin}"
        text += f" {elapsed:.0f} s"
        if self.eta and self.total:
            text += f" ETA {self._time_left(now)}"
        if note:
            text += f"  {note}"
        text = text[:100]
        with self._lock:
            if not self.enabled:
                return
            pad = max(0, self._width - len(text))
            self.stream.write("\r" + text + " " * pad)
            self.stream.flush()
            self._width = len(text)


class AbstractProgressMeter(eqx.Module):
    """How work reports its progress: a bar for work of many steps, and news of
    each step (e.g. which fit runs)."""

    @abc.abstractmethod
    def bar(
        self, label: str, total: int | None = None, *, eta: bool = False, keep=False
    ) -> Progress:
        """A `Progress` bar (a context manager; `advance(steps, note)` counts
        steps) for work of `total` steps (None: unknown, a spinner), labelled
        `label`; with `eta`, the estimated time left; with `keep`, its last line
        left on the stream at the end."""

    @abc.abstractmethod
    def say(self, message: str) -> None:
        """Tell of one step (one line of news)."""


class NoProgressMeter(AbstractProgressMeter):
    """Says nothing: no bar, no news."""

    def bar(self, label, total=None, *, eta=False, keep=False) -> Progress:
        return Progress(label, total, enabled=False)

    def say(self, message: str) -> None:
        del message


class TextProgressMeter(AbstractProgressMeter):
    """A one-line text bar on stderr, and each step's news as a line of text.

    **Fields:**

    - `show_bar`: whether to draw bars (the command line draws them when stderr is
        a terminal and `--quiet` is not given).
    - `log`: where the news is printed, or None (no news).
    - `stream`: where the bars are drawn (default `sys.stderr`).
    """

    show_bar: bool = eqx.field(default=True, static=True)
    log: TextIO | None = eqx.field(default=None, static=True)
    stream: TextIO | None = eqx.field(default=None, static=True)

    def bar(self, label, total=None, *, eta=False, keep=False) -> Progress:
        return Progress(
            label, total, enabled=self.show_bar, stream=self.stream, eta=eta, keep=keep
        )

    def say(self, message: str) -> None:
        if self.log is not None:
            print(message, file=self.log, flush=True)


class CallbackProgressMeter(AbstractProgressMeter):
    """Each step's news passed to a function (e.g. one that prints it with the time
    elapsed); no bar.

    **Fields:**

    - `callback`: called as `callback(message)` for each step.
    """

    callback: Callable[[str], None] = eqx.field(static=True)

    def bar(self, label, total=None, *, eta=False, keep=False) -> Progress:
        return Progress(label, total, enabled=False)

    def say(self, message: str) -> None:
        self.callback(message)


def check_progress_meter(
    meter, default: AbstractProgressMeter
) -> AbstractProgressMeter:
    """`meter`, or `default` when it is None.

    **Raises:**

    `ValueError` naming `progress_meter` when `meter` is not a progress meter.
    """
    if meter is None:
        return default
    if not isinstance(meter, AbstractProgressMeter):
        raise ValueError(
            "`progress_meter` must be a progress meter (NoProgressMeter(), "
            f"TextProgressMeter(), CallbackProgressMeter(f)), got {meter!r}."
        )
    return meter
