"""How a measured test is driven: which channel is imposed, which is scored, in which
unit, and which simulation reproduces it.

A test is either force-driven (its force history drives the model and its elongation
is compared with the model's) or elongation-driven (its elongation drives, the force
is solved and compared). Everything that fits, scores, plots or simulates a test asks
its drive value instead of comparing names; the names `"force"` and `"elongation"`
appear only where a drive is read or written (JSON, CSV metadata, the command line).
"""

import abc
from collections.abc import Callable, Sequence
from typing import TypeAlias

import equinox as eqx
import numpy as np

from .simulate import simulate_elongation_history, simulate_force_history
from .state import Trajectory


class AbstractTestDrive(eqx.Module):
    """The drive of a measured test: a value with static fields only, so that drives
    compare equal by value, hash, and are static in a jitted function.

    **Fields:**

    - `name`: the drive's name in files and on the command line.
    - `imposed`: the channel that drives the model (`TestData` attribute).
    - `scored`: the channel compared with the model's (`TestData` attribute).
    - `unit`: the SI unit of the scored channel, `"m"` or `"N"`.
    - `report_unit`, `report_scale`: the unit in which reports print the scored
        channel and its factor from SI (elongations in mm).
    """

    name: eqx.AbstractVar[str]
    imposed: eqx.AbstractVar[str]
    scored: eqx.AbstractVar[str]
    unit: eqx.AbstractVar[str]
    report_unit: eqx.AbstractVar[str]
    report_scale: eqx.AbstractVar[float]

    def imposed_of(self, test) -> np.ndarray:
        """The imposed channel of `test` (anything with `force` and `elongation`)."""
        return getattr(test, self.imposed)

    def scored_of(self, test) -> np.ndarray:
        """The scored channel of `test`, or of a [`jaxcable.Trajectory`][]."""
        return getattr(test, self.scored)

    @property
    def scores_force(self) -> bool:
        """Whether the scored channel is the force (an elongation-driven test)."""
        return self == ELONGATION_DRIVEN

    @abc.abstractmethod
    def simulate(self, model, cable, time, imposed, **kwargs) -> Trajectory:
        """Simulate a test driven by `imposed` (this drive's imposed channel, SI).

        **Arguments:**

        - `model`, `cable`, `time`: as in [`jaxcable.simulate_force_history`][].
        - `imposed`: the imposed channel at each sample, N or m.
        - `**kwargs`: passed on (`mask`, `throw`, `checkpoint`).

        **Returns:**

        A [`jaxcable.Trajectory`][].
        """

    def __str__(self) -> str:
        return self.name


class ChannelDrive(AbstractTestDrive):
    """A drive by one channel, simulated by `simulator` (`simulate_force_history` or
    `simulate_elongation_history`: same positional arguments)."""

    name: str = eqx.field(static=True)
    imposed: str = eqx.field(static=True)
    scored: str = eqx.field(static=True)
    unit: str = eqx.field(static=True)
    report_unit: str = eqx.field(static=True)
    report_scale: float = eqx.field(static=True)
    simulator: Callable[..., Trajectory] = eqx.field(static=True)

    def simulate(self, model, cable, time, imposed, **kwargs) -> Trajectory:
        return self.simulator(model, cable, time, imposed, **kwargs)


# What `drive` arguments take (a `Problem`'s, a fit's, a diagnosis's): `"auto"` or
# None (detected per test), a drive's name or value, or one of these per test.
DriveSpec: TypeAlias = (
    "str | AbstractTestDrive | Sequence[str | AbstractTestDrive] | None"
)


# Force-driven: the force history drives the model, the elongation is scored.
FORCE_DRIVEN = ChannelDrive(
    "force", "force", "elongation", "m", "mm", 1e3, simulate_force_history
)
# Elongation-driven: the elongation drives the model, the solved force is scored.
ELONGATION_DRIVEN = ChannelDrive(
    "elongation", "elongation", "force", "N", "N", 1.0, simulate_elongation_history
)
TEST_DRIVES: dict[str, AbstractTestDrive] = {
    d.name: d for d in (FORCE_DRIVEN, ELONGATION_DRIVEN)
}


def as_test_drive(drive) -> AbstractTestDrive:
    """The drive value of `drive`: a drive value itself, or its name (`"force"`,
    `"elongation"`) as files and the command line write it.

    **Raises:**

    `ValueError` for any other value.
    """
    if isinstance(drive, AbstractTestDrive):
        return drive
    try:
        return TEST_DRIVES[drive]
    except (KeyError, TypeError):
        raise ValueError(
            f"`drive` must be one of {sorted(TEST_DRIVES)} or a drive value, got "
            f"{drive!r}."
        ) from None
