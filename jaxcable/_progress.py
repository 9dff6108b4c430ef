"""The one progress bar of jaxcable: a one-line text bar on stderr."""

import sys
import threading
import time
from typing import TextIO


class Progress:
    """A one-line text progress bar on stderr, for work that takes a while.

    Silent unless `enabled` (the command line enables it when stderr is a terminal and
    `--quiet` is not given), so that logs and pipes get no carriage returns. Work
    without a known number of steps (one compiled fit) shows the elapsed time, redrawn
    by a background thread.

    **Arguments:**

    - `label`: what is being done, e.g. `"reading"`.
    - `total`: the number of steps, or `None` for a spinner with the elapsed time.
    - `enabled`: whether to draw at all.
    - `stream`: where to draw (default `sys.stderr`).
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
    ):
        self.label = label
        self.total = total
        self.enabled = enabled
        self.stream = sys.stderr if stream is None else stream
        self.done = 0
        self.start = time.monotonic()
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
        if self.enabled:
            self._draw(note)

    def close(self) -> None:
        """Stop and erase the bar."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
            self._thread = None
        if self.enabled:
            with self._lock:
                self.stream.write("\r" + " " * self._width + "\r")
                self.stream.flush()
            self.enabled = False

    def _spin(self) -> None:
        while not self._stop.wait(0.25):
            self._draw()

    def _draw(self, note: str = "") -> None:
        elapsed = time.monotonic() - self.start
        if self.total:
            filled = int(self._WIDTH * min(self.done, self.total) / self.total)
            bar = "#" * filled + "." * (self._WIDTH - filled)
            text = f"{self.label} [{bar}] {self.done}/{self.total}"
        else:
            spin = self._SPIN[int(elapsed * 4) % len(self._SPIN)]
            text = f"{self.label} {spin}"
        text += f" {elapsed:.0f} s"
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
