"""The inputs of a Monte-Carlo: time-stamped force histories (`ForceHistory`), and the
checks of the arguments of `monte_carlo` (key, counts, percentile levels, devices, and
the cables and their loads, brought to one cable axis) before anything is compiled."""

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, PRNGKeyArray

from .. import _checks
from .._cable import CABLE_FIELDS, Cable
from .._drive import Protocol, check_history


class ForceHistory(eqx.Module):
    """Time-stamped force histories, one per cable (as a CDPR logs its cables).

    **Arguments:**

    - `time`: sample times, s, shape `(cables, samples)` or `(samples,)` (shared by
        all cables); strictly increasing along samples.
    - `force`: cable forces, N, shape `(cables, samples)` or `(samples,)`.
    - `mask`: optional, False marks padding samples (histories of different lengths).

    The three are broadcast to one shape.
    """

    time: Float[Array, "*cables samples"]
    force: Float[Array, "*cables samples"]
    mask: Bool[Array, "*cables samples"]

    def __init__(
        self,
        time: Float[ArrayLike, "*cables samples"],
        force: Float[ArrayLike, "*cables samples"],
        mask: Bool[ArrayLike, "*cables samples"] | None = None,
    ):
        time = jnp.asarray(time)
        force = jnp.asarray(force)
        mask = jnp.ones((), bool) if mask is None else jnp.asarray(mask, bool)
        try:
            shape = np.broadcast_shapes(time.shape, force.shape, mask.shape)
        except ValueError:
            raise ValueError(
                f"`time` {time.shape}, `force` {force.shape} and `mask` {mask.shape} "
                "must have one shape (a 1-D `time` is shared by all cables)."
            ) from None
        if len(shape) not in (1, 2) or shape[-1] == 0:
            raise ValueError(
                "`time` and `force` must have shape (samples,) or (cables, samples) "
                f"with at least one sample, got {shape}."
            )
        self.time = jnp.broadcast_to(time, shape)
        self.force = jnp.broadcast_to(force, shape)
        self.mask = jnp.broadcast_to(mask, shape)


def check_key(key) -> PRNGKeyArray:
    """Raise `ValueError` unless `key` is one JAX PRNG key (a typed key, or the raw
    uint32 data of one); return it as a typed key."""
    if not isinstance(key, jax.Array) and not isinstance(key, np.ndarray):
        raise ValueError(
            "`key` must be a JAX PRNG key, e.g. `jax.random.key(0)`, got "
            f"{type(key).__name__}."
        )
    if jnp.issubdtype(key.dtype, jax.dtypes.prng_key):
        if key.shape != ():
            raise ValueError(
                f"`key` must be one key (shape ()), got shape {key.shape}."
            )
        assert isinstance(key, jax.Array)  # NumPy has no key dtype
        return key
    if key.dtype == jnp.uint32 and key.shape == (2,):
        return jax.random.wrap_key_data(jnp.asarray(key))
    raise ValueError(
        "`key` must be a JAX PRNG key (`jax.random.key(seed)`), got an array of dtype "
        f"{key.dtype} and shape {key.shape}."
    )


def check_percentiles(percentiles) -> np.ndarray:
    """Raise `ValueError` unless `percentiles` is a non-empty 1-D sequence of finite
    levels in [0, 100]; return them as a float array."""
    q = np.asarray(percentiles, dtype=float)
    if q.ndim != 1 or q.size == 0:
        raise ValueError(
            f"`percentiles` must be a non-empty 1-D sequence, got {percentiles!r}."
        )
    _checks.require_finite("percentiles", q)
    if np.any((q < 0) | (q > 100)):
        raise ValueError(f"`percentiles` must lie in [0, 100] (percent), got {q}.")
    return q


# `jax.Device` is an alias that type checkers do not take for a type: `Any` stands for
# it in the annotation.
def check_devices(devices) -> list[Any]:
    """The devices to shard over (default `jax.devices()`: every device of every
    host); raise `ValueError` unless they are a non-empty list of jax devices."""
    if devices is None:
        devices = jax.devices()
    devices = list(devices)
    if not devices or not all(isinstance(d, jax.Device) for d in devices):
        raise ValueError(
            f"`devices` must be a non-empty list of jax devices, got {devices!r}."
        )
    return devices


def check_cables(cables) -> Cable:
    """Check the cables of a Monte-Carlo and broadcast their fields to one axis.

    **Arguments:**

    - `cables`: a [`jaxcable.Cable`][] whose fields are scalars or 1-D (one value per
        cable).

    **Returns:**

    The cables with every field of shape `(cables,)`, in one floating-point dtype.
    """
    if not isinstance(cables, Cable):
        raise ValueError(
            f"`cables` must be a jaxcable.Cable (fields of shape (cables,)), got "
            f"{type(cables).__name__}."
        )
    names = [n for n in CABLE_FIELDS if getattr(cables, n) is not None]
    shapes = {n: jnp.shape(getattr(cables, n)) for n in names}
    if any(len(s) > 1 for s in shapes.values()):
        raise ValueError(
            f"`cables` fields must be scalars or 1-D (one value per cable), got {shapes}."
        )
    try:
        shape = np.broadcast_shapes(*shapes.values())
    except ValueError:
        raise ValueError(
            f"`cables` fields must have one length (one value per cable), got {shapes}."
        ) from None
    n = shape[0] if shape else 1
    dtype = jnp.result_type(float, cables.length)
    return Cable(
        **{
            n_: jnp.broadcast_to(jnp.asarray(getattr(cables, n_), dtype), (n,))
            for n_ in names
        }
    )


def _cable(cables: Cable, j: int) -> Cable:
    # The j-th cable of checked cables.
    return jax.tree_util.tree_map(lambda x: x[j], cables)


def check_loads(
    loads, cables: Cable
) -> tuple[Protocol | ForceHistory, int | None, int]:
    """Check the loads of a Monte-Carlo against the cables.

    **Arguments:**

    - `loads`: a [`jaxcable.ForceHistory`][] or a [`jaxcable.Protocol`][], of shape
        `(samples,)` (shared by all cables) or `(cables, samples)`.
    - `cables`: the checked cables (see `check_cables`).

    **Returns:**

    The loads in the cables' dtype, the cable axis of their arrays for `vmap` (0, or
    None when one load is shared), and the number of samples.
    """
    ncables = cables.length.shape[0]
    dtype = cables.length.dtype
    if isinstance(loads, Protocol):
        force = np.asarray(loads.force)
        if force.ndim not in (1, 2) or (force.ndim == 2 and force.shape[0] != ncables):
            raise ValueError(
                f"`loads.force` must have shape (samples,) or ({ncables}, samples) for "
                f"{ncables} cables, got {force.shape}."
            )
        limit = np.asarray(cables.breaking_load)
        over = force > (limit[:, None] if force.ndim == 2 else limit.min())
        if np.any(over):
            idx = np.argwhere(over)[0].tolist()
            raise ValueError(
                f"`loads.force` exceeds a cable's breaking load at index {idx}: "
                f"{force[tuple(idx)]:g} N."
            )
        axis = 0 if force.ndim == 2 else None
        # tree_at, not the constructor, which takes one 1-D protocol.
        loads = eqx.tree_at(
            lambda p: (p.force, p.direction, p.duration, p.mask),
            loads,
            (
                jnp.asarray(loads.force, dtype),
                jnp.asarray(loads.direction, jnp.int32),
                jnp.asarray(loads.duration, dtype),
                jnp.asarray(loads.mask, bool),
            ),
        )
        return loads, axis, force.shape[-1]
    if isinstance(loads, ForceHistory):
        t = np.asarray(loads.time)
        if t.ndim == 2 and t.shape[0] != ncables:
            raise ValueError(
                f"`loads.time` has {t.shape[0]} histories for {ncables} cables; give "
                "one per cable, or one 1-D history shared by all."
            )
        for j in range(ncables):
            if t.ndim == 2:
                tj, fj, mj = loads.time[j], loads.force[j], loads.mask[j]
            else:
                tj, fj, mj = loads.time, loads.force, loads.mask
            try:
                check_history(_cable(cables, j), tj, fj, mj, "force")
            except ValueError as e:
                raise ValueError(f"`loads` (cable {j}): {e}") from None
            if t.ndim == 1:
                break
        axis = 0 if t.ndim == 2 else None
        loads = ForceHistory(
            jnp.asarray(loads.time, dtype), jnp.asarray(loads.force, dtype), loads.mask
        )
        return loads, axis, t.shape[-1]
    raise ValueError(
        "`loads` must be a jaxcable.Protocol (rate-driven test) or a "
        f"jaxcable.ForceHistory (time-stamped forces), got {type(loads).__name__}."
    )
