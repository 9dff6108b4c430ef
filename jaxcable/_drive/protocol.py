"""[`jaxcable.Protocol`][]: the force samples of a rate-driven test (ramps, holds,
rests, cycles), with its constructors, joining and padding."""

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from .. import _checks
from .._arrays import field_array


class Protocol(eqx.Module):
    """A rate-driven test: the force samples a tensile tester passes through.

    On a ramp (`direction` +1 or -1) the crosshead moves at the cable's constant
    `speed`, and the time at which each force sample is reached is unknown: it is
    solved per sample by Newton's method inside the scan (Park Eq. 6). On a hold
    (`direction` 0) the force is held for a given `duration`.
    Build protocols with the constructors below and join them with
    [`jaxcable.Protocol.concatenate`][]; pad with [`jaxcable.Protocol.pad`][] to vmap
    over protocols of different lengths.

    **Fields:**

    - `force`: force at each sample, N.
    - `direction`: +1 loading ramp, -1 unloading ramp (time solved), 0 hold.
    - `duration`: duration of a hold sample, s (ignored on ramps).
    - `mask`: False for padding samples, which leave the state unchanged.
    """

    force: Float[Array, " samples"] = eqx.field(converter=field_array)
    direction: Int[Array, " samples"] = eqx.field(converter=field_array)
    duration: Float[Array, " samples"] = eqx.field(converter=field_array)
    mask: Bool[Array, " samples"] = eqx.field(converter=field_array)

    def __check_init__(self):
        shapes = {
            n: jnp.shape(getattr(self, n))
            for n in ("force", "direction", "duration", "mask")
        }
        if len(set(shapes.values())) != 1:
            raise ValueError(f"Protocol fields must share one shape, got {shapes}.")
        if _checks.is_concrete(self.force, self.direction, self.duration):
            _checks.require_samples("Protocol.force", self.force)
            _checks.require_positive("Protocol.force", self.force, allow_zero=True)
            _checks.require_positive(
                "Protocol.duration", self.duration, allow_zero=True
            )
            d = np.asarray(self.direction)
            if not np.all(np.isin(d, (-1, 0, 1))):
                raise ValueError(
                    f"`Protocol.direction` must be -1, 0 or +1, got {np.unique(d)}."
                )

    @property
    def num_samples(self) -> int:
        return int(jnp.shape(self.force)[-1])

    @staticmethod
    def start(force: float = 0.0) -> "Protocol":
        """A single sample at `force` at time 0 (the initial condition, N)."""
        return _segment([force], [0], [0.0])

    @staticmethod
    def ramp(force_from: float, force_to: float, samples: int) -> "Protocol":
        """A constant-speed ramp from `force_from` to `force_to` (N), `samples` samples
        equally spaced in force, excluding `force_from` (the previous sample)."""
        if samples < 1:
            raise ValueError(f"`samples` must be >= 1, got {samples}.")
        if force_to == force_from:
            raise ValueError(
                f"A ramp needs force_to != force_from, got {force_from} twice."
            )
        force = np.linspace(force_from, force_to, samples + 1)[1:]
        direction = 1 if force_to > force_from else -1
        return _segment(force, [direction] * samples, [0.0] * samples)

    @staticmethod
    def hold(force: float, duration: float, samples: int = 1) -> "Protocol":
        """Hold `force` (N) for `duration` seconds, in `samples` equal steps."""
        if samples < 1:
            raise ValueError(f"`samples` must be >= 1, got {samples}.")
        _checks.require_positive("duration", duration, allow_zero=True)
        return _segment(
            [force] * samples, [0] * samples, [duration / samples] * samples
        )

    @staticmethod
    def rest(duration: float, samples: int = 1) -> "Protocol":
        """A rest at zero force for `duration` seconds (e.g. 24 h = 86400 s)."""
        return Protocol.hold(0.0, duration, samples)

    @staticmethod
    def cycles(
        force_max: float,
        cycles: int = 1,
        samples_per_ramp: int = 1000,
        *,
        force_min: float = 0.0,
        hold: float = 0.0,
        start: bool = True,
    ) -> "Protocol":
        """`cycles` load-unload cycles between `force_min` and `force_max` (N).

        The first ramp starts from 0 N; each later one from `force_min`. Each ramp has
        `samples_per_ramp` samples (Park sampled 2000 points per cycle). `hold` holds
        the peak force for that many seconds. `start` prepends the sample at 0 N, t = 0.
        """
        if cycles < 1:
            raise ValueError(f"`cycles` must be >= 1, got {cycles}.")
        parts = [Protocol.start()] if start else []
        low = 0.0
        for _ in range(cycles):
            parts.append(Protocol.ramp(low, force_max, samples_per_ramp))
            if hold > 0:
                parts.append(Protocol.hold(force_max, hold, 1))
            parts.append(Protocol.ramp(force_max, force_min, samples_per_ramp))
            low = force_min
        return Protocol.concatenate(*parts)

    @staticmethod
    def concatenate(*protocols: "Protocol") -> "Protocol":
        """Join protocols one after the other."""
        if not protocols:
            raise ValueError("`concatenate` needs at least one Protocol.")
        return Protocol(
            force=np.concatenate([np.asarray(p.force) for p in protocols]),
            direction=np.concatenate([np.asarray(p.direction) for p in protocols]),
            duration=np.concatenate([np.asarray(p.duration) for p in protocols]),
            mask=np.concatenate([np.asarray(p.mask) for p in protocols]),
        )

    def pad(self, samples: int) -> "Protocol":
        """Pad with masked samples to `samples` in all (for vmapping over protocols)."""
        extra = samples - self.num_samples
        if extra < 0:
            raise ValueError(
                f"Cannot pad a protocol of {self.num_samples} samples to {samples}."
            )
        if extra == 0:
            return self
        last = float(np.asarray(self.force)[-1])
        pad = _segment([last] * extra, [0] * extra, [0.0] * extra, mask=False)
        return Protocol.concatenate(self, pad)


def _segment(force, direction, duration, mask=True) -> Protocol:
    n = len(force)
    return Protocol(
        force=np.asarray(force, dtype=float),
        direction=np.asarray(direction, dtype=np.int32),
        duration=np.asarray(duration, dtype=float),
        mask=np.full(n, mask, dtype=bool),
    )
