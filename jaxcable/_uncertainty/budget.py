"""What a lab can run: `TestBudget`, the constraints of a designed test."""

import dataclasses
import math

from .._checks import require_int, require_number


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
        require_number("budget.duration_s", self.duration_s, 0.0, strict=True)
        fraction = require_number("budget.max_force_fraction", self.max_force_fraction)
        if not 0 < fraction <= 1:
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
        require_int("budget.blocks", self.blocks, 1)
        # At least 8 samples per block: a ramp up and down and a hold and a rest of
        # two samples each.
        require_int("budget.samples", self.samples, 8 * self.blocks)
        if self.noise_mm is not None:
            require_number("budget.noise_mm", self.noise_mm, 0.0, strict=True)
