"""Force memories that are continuous in the force history.

A measured force is noisy: any model state that switches on the sign of a force change
(a loading/unloading flag, a clock restarted at each reversal, a "time under tension"
that counts a step or not) jumps when the noise flips that sign, and the strain jumps
with it, however small the noise. The models therefore keep only memories that are
Lipschitz-continuous in the force history (sup norm): a perturbation of size d of every
force sample moves each memory by at most a stated multiple of d.

- [`running_max`][]: the largest force so far (moves by at most d).
- [`tension_weight`][] / [`tension_time_step`][]: the share of time that counts as
  "under tension", a ramp from 0 at 0 N to 1 at F_on (`tension_force`: a tenth of
  the largest force so far, at least 1e-4 of the breaking load; time at F < F_on
  counts F / F_on of its duration), integrated exactly over a step with a linear
  force.
- [`play`][] / [`loading_weight`][]: the play (backlash) operator of half-width r and
  the loading weight w in [0, 1] it defines (1 while the force pushes the band up,
  0 while it pulls it down). Within the band the weight is a function of the force
  alone, so noise smaller than r traces no loop and leaves no drift; it moves by at
  most d / (2 r).
"""

import jax.numpy as jnp
from jaxtyping import Array, Float

from ._cable import Cable


# The force below which time only partly counts as under tension: the larger of a share
# of the breaking load (2000 N by default: 0.2 N) and a share of the largest force so
# far. Time at a force F < F_on counts F / F_on of its duration. With the second share
# the first loading counts fully (F = F_max there), Park's unloadings count fully down
# to a tenth of their peak, and a load cell's readings near 0 N during an hours-long
# rest (noise, or a reading that escapes a zero suppression) count in proportion to
# how small they are against the load that made the creep: the equivalent force I / T
# is then not diluted by a 1 N blip in a rest after a 150 N test.
TENSION_SHARE = 1e-4
TENSION_FRACTION = 0.1


def tension_force(cable: Cable, force_max: Float[Array, ""]) -> Float[Array, ""]:
    """F_on, N: max(`TENSION_SHARE` x breaking load, `TENSION_FRACTION` x `force_max`)."""
    return jnp.maximum(
        TENSION_SHARE * cable.breaking_load, TENSION_FRACTION * force_max
    )


def tension_weight(
    force: Float[Array, ""], cable: Cable, force_max: Float[Array, ""]
) -> Float[Array, ""]:
    """Share of time that counts as under tension at `force` (N): min(F / F_on, 1)
    with F_on = [`tension_force`][]; 0 for F <= 0. Dimensionless."""
    return jnp.clip(force / tension_force(cable, force_max), 0.0, 1.0)


def _tension_primitive(force, f_on):
    # G(F) = integral of tension_weight from 0 to F (N): F^2 / (2 F_on) below F_on.
    f = jnp.maximum(force, 0.0)
    return jnp.where(f < f_on, 0.5 * f * f / f_on, f - 0.5 * f_on)


def tension_time_step(
    force_prev: Float[Array, ""],
    force: Float[Array, ""],
    dt: Float[Array, ""],
    cable: Cable,
    force_max: Float[Array, ""],
) -> Float[Array, ""]:
    """Time under tension of a step of `dt` s over which the force goes linearly from
    `force_prev` to `force` (N), s: the exact integral of [`tension_weight`][]
    (dt (G(F1) - G(F0)) / (F1 - F0), G its primitive; the weight at the mean force
    when the force barely changes). `force_max`: the largest force so far, this
    step's included, N."""
    f_on = tension_force(cable, force_max)
    change = force - force_prev
    # Below this change the chord is replaced by the midpoint value (both agree to
    # ~change^2 / F_on^2 relative), keeping the quotient and its gradient finite.
    small = jnp.abs(change) < 1e-6 * f_on
    safe = jnp.where(small, 1.0, change)
    chord = (
        _tension_primitive(force, f_on) - _tension_primitive(force_prev, f_on)
    ) / safe
    mid = jnp.clip(0.5 * (force + force_prev) / f_on, 0.0, 1.0)
    return jnp.where(small, mid, chord) * dt


def running_max(previous: Float[Array, ""], force: Float[Array, ""]):
    """The largest force so far, N."""
    return jnp.maximum(previous, force)


def play(
    previous: Float[Array, ""], x: Float[Array, ""], radius: Float[Array, ""]
) -> Float[Array, ""]:
    """The play (backlash) operator: `previous` moved just enough to lie within
    `radius` of `x` (same units as `x`)."""
    return jnp.clip(previous, x - radius, x + radius)


def loading_weight(
    centre: Float[Array, ""], x: Float[Array, ""], radius: Float[Array, ""]
) -> Float[Array, ""]:
    """Loading weight (x - centre + radius) / (2 radius) in [0, 1] of the play band
    centred at `centre` (the output of [`play`][]): 1 on loading, 0 on unloading."""
    return jnp.clip((x - centre + radius) / (2.0 * radius), 0.0, 1.0)
