"""How a Monte-Carlo runs: [`jaxcable.MonteCarlo`][] (the draws, the statistics kept,
the chunks and the devices), validated at construction."""

from collections.abc import Sequence
from typing import Any

import equinox as eqx
import jax
from jaxtyping import PRNGKeyArray

from .. import _checks
from .inputs import check_key, check_percentiles


# The ways percentiles are computed (see `jaxcable.monte_carlo`).
_STATISTICS = ("auto", "exact", "histogram")


def _levels(percentiles: Sequence[float]) -> tuple[float, ...]:
    return tuple(float(q) for q in check_percentiles(percentiles))


# `jax.Device` is an alias that type checkers do not take for a type: `Any` stands for
# it in the annotations.
def _device_tuple(devices: Sequence[Any] | None):
    return None if devices is None else tuple(devices)


class MonteCarlo(eqx.Module):
    """How [`jaxcable.monte_carlo`][] runs: how many parameter draws, from which key,
    the statistics it keeps, its chunks and its devices.

    **Fields:**

    - `num_draws`: the number of parameter draws (>= 1).
    - `key`: a JAX PRNG key (`jax.random.key(seed)`); no default, for
        reproducibility. Draw i uses `jax.random.fold_in(key, i)`.
    - `percentiles`: the percentile levels to compute, in percent (0-100); default
        (1, 5, 50, 95, 99).
    - `chunk_size`: draws per chunk (rounded up to a multiple of the number of
        devices); default (None) about 2**23 / (cables x samples) per device.
    - `method`: `"auto"` (default), `"exact"` or `"histogram"`: how percentiles are
        computed (see [`jaxcable.monte_carlo`][]).
    - `bins`: histogram bins per (cable, sample) (`method="histogram"`; >= 2,
        default 1024).
    - `keep_draws`: with `method="exact"`, return every draw in
        `MonteCarloResult.elongation` (default False).
    - `devices`: the devices to shard the draws over (default None: `jax.devices()`
        at the call).

    **Raises:**

    `ValueError` (or `TypeError` for a count that is not an integer) naming the
    field.
    """

    num_draws: int = eqx.field(static=True)
    key: PRNGKeyArray = eqx.field(converter=check_key)
    percentiles: tuple[float, ...] = eqx.field(
        default=(1.0, 5.0, 50.0, 95.0, 99.0), static=True, converter=_levels
    )
    chunk_size: int | None = eqx.field(default=None, static=True)
    method: str = eqx.field(default="auto", static=True)
    bins: int = eqx.field(default=1024, static=True)
    keep_draws: bool = eqx.field(default=False, static=True)
    devices: tuple[Any, ...] | None = eqx.field(
        default=None, static=True, converter=_device_tuple
    )

    def __check_init__(self):
        _checks.require_int("num_draws", self.num_draws, 1)
        if self.chunk_size is not None:
            _checks.require_int("chunk_size", self.chunk_size, 1)
        if self.method not in _STATISTICS:
            raise ValueError(
                f"`method` must be 'auto', 'exact' or 'histogram', got {self.method!r}."
            )
        _checks.require_int("bins", self.bins, 2)
        if not isinstance(self.keep_draws, bool):
            raise TypeError(f"`keep_draws` must be a bool, got {self.keep_draws!r}.")
        if self.keep_draws and self.method == "histogram":
            raise ValueError("`keep_draws=True` needs `method='exact'`.")
        if self.devices is not None and (
            not self.devices or not all(isinstance(d, jax.Device) for d in self.devices)
        ):
            raise ValueError(
                "`devices` must be a non-empty list of jax devices, got "
                f"{list(self.devices)!r}."
            )
