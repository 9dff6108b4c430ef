"""What a lab can run: `TestBudget`, the constraints of a designed test."""

import dataclasses
import math


@dataclasses.dataclass(frozen=True)
class TestBudget:
    """The constraints of the next test (see [`jaxcable.design_test`][]).

    **Fields:**

    - `duration_s`: the test's total duration, s (ramps, holds and rests).
    - `max_force_fraction`: the largest force as a fraction of the cable's breaking
        load (`Cable.breaking_load`), in (0, 1].
    - `speed_mm_per_min`: `(slowest, fastest)` crosshead speed of the tester,
        mm/min (the designed test runs at one speed in this range).
    - `samples`: force samples the tester records (ramps, holds and rests
        together; at least 8 per block).
    - `blocks`: load blocks of the designed test: each ramps up to a level, holds
        it, ramps down to 0 N and rests.
    - `noise_mm`: the elongation noise of the tester, mm (standard deviation);
        None: the RMS residual of the fit's force-driven tests.
    """

    duration_s: float
    max_force_fraction: float = 0.05
    speed_mm_per_min: tuple[float, float] = (1.0, 100.0)
    samples: int = 240
    blocks: int = 2
    noise_mm: float | None = None

    def __post_init__(self):
        if not (
            isinstance(self.duration_s, (int, float)) and 0 < self.duration_s < math.inf
        ):
            raise ValueError(
                f"`budget.duration_s` must be a finite number > 0, got "
                f"{self.duration_s!r}."
            )
        if not 0 < self.max_force_fraction <= 1:
            raise ValueError(
                "`budget.max_force_fraction` must be in (0, 1], got "
                f"{self.max_force_fraction!r}."
            )
        low, high = self.speed_mm_per_min
        if not 0 < low <= high < math.inf:
            raise ValueError(
                "`budget.speed_mm_per_min` must be (slowest, fastest) with 0 < "
                f"slowest <= fastest, got {self.speed_mm_per_min!r}."
            )
        if not isinstance(self.blocks, int) or self.blocks < 1:
            raise ValueError(
                f"`budget.blocks` must be an int >= 1, got {self.blocks!r}."
            )
        if not isinstance(self.samples, int) or self.samples < 8 * self.blocks:
            raise ValueError(
                f"`budget.samples` must be an int >= 8 per block ({8 * self.blocks}), "
                f"got {self.samples!r}."
            )
        if self.noise_mm is not None and not 0 < self.noise_mm < math.inf:
            raise ValueError(
                f"`budget.noise_mm` must be a number > 0, got {self.noise_mm!r}."
            )
