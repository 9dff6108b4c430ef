"""Force memories that are continuous in the force history.

A measured force is noisy: any model state that switches on the sign of a force change
(a loading/unloading flag, a clock restarted at each reversal, a "time under tension"
that counts a step or not) jumps when the noise flips that sign, and the strain jumps
with it, however small the noise. The models therefore keep only memories that are
Lipschitz-continuous in the force history (sup norm): a perturbation of size d of every
force sample moves each memory by at most a stated multiple of d.

- [`running_max`][]: the largest force so far (moves by at most d).
- [`tension_time_step`][]: the time under tension of a step, the share of time that
  counts as "under tension" (the tension weight min(F / F_on, 1), a ramp from 0 at
  0 N to 1 at F_on; [`tension_force`][]: a tenth of the largest force so far, at least
  1e-4 of the breaking load) integrated exactly over a step with a linear force.
- [`play`][] / [`loading_weight`][]: the play (backlash) operator of half-width r and
  the loading weight w in [0, 1] it defines (1 while the force pushes the band up,
  0 while it pulls it down). Within the band the weight is a function of the force
  alone, so noise smaller than r traces no loop and leaves no drift; it moves by at
  most d / (2 r).
"""

import math

import jax.numpy as jnp
from jaxtyping import Array, Float

from .._cable import Cable


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


def _tension_primitive(force, f_on):
    # G(F) = integral of the tension weight min(F / F_on, 1) from 0 to F (N):
    # F^2 / (2 F_on) below F_on.
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
    `force_prev` to `force` (N), s: the exact integral of the tension weight
    min(F / F_on, 1), F_on = [`tension_force`][], 0 for F <= 0
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


# Below this h / tau the closed form loses digits to cancellation (relative error
# ~2 eps tau / h); its Taylor series, sum_{k>=1} (-1)^(k+1) x^k / (k+1)!, truncated
# after x^9, is exact to rounding there (next term ~5e-17 of the value).
_SERIES_BELOW = 0.1
_RAMP_SERIES = tuple((-1.0) ** (k + 1) / math.factorial(k + 1) for k in range(1, 10))


def ramp_factor(x):
    """1 - (1 - exp(-x)) / x = (x + expm1(-x)) / x, the share of a linear stress ramp
    that a Kelvin-Voigt element has not yet followed after x = h / tau.

    Continued by its Taylor series near x = 0 so that the value (0 at x = 0) and its
    gradient (1/2) stay finite there.
    """
    small = jnp.abs(x) < _SERIES_BELOW
    x_safe = jnp.where(small, 1.0, x)
    direct = (x_safe + jnp.expm1(-x_safe)) / x_safe
    series = jnp.zeros_like(x)
    for c in reversed(_RAMP_SERIES):  # Horner, highest power first
        series = (series + c) * x
    return jnp.where(small, series, direct)


def kelvin_voigt_step(q0, s0, s1, h, E, eta):
    """Exact strain of a Kelvin-Voigt element (spring E parallel to dashpot eta) after a
    step of length h over which the stress goes linearly from s0 to s1.

    Solves eta q' + E q = s(t) in closed form: with tau = eta / E and a = exp(-h / tau),
    q1 = a q0 + (1/E) [s1 - a s0 - (s1 - s0) (tau / h) (1 - a)], written as
    a q0 + (1/E) [s0 (1 - a) + (s1 - s0) (1 - (tau / h)(1 - a))] so that the h -> 0
    limit (q1 = q0) has finite values and gradients. Units: stress and E in Pa, eta in
    Pa s, h in s; q is a strain.
    """
    x = h * E / eta
    decay = jnp.exp(-x)
    return decay * q0 + (-s0 * jnp.expm1(-x) + (s1 - s0) * ramp_factor(x)) / E


def safe_pow(base, exponent):
    """`base**exponent` for `base >= 0`, with finite gradients at `base == 0`."""
    positive = base > 0
    safe = jnp.where(positive, base, 1.0)
    return jnp.where(positive, jnp.exp(exponent * jnp.log(safe)), 0.0)


def relaxation_average(t, tau):
    """(1 - exp(-t / tau)) / t, continued by 1 / tau at t = 0 (finite gradients)."""
    positive = t > 0
    t_safe = jnp.where(positive, t, 1.0)
    return jnp.where(positive, -jnp.expm1(-t_safe / tau) / t_safe, 1.0 / tau)


def retarded(q0, target0, target1, dt, tau):
    """Exact value after `dt` of q' = (target - q) / tau with the target linear over
    the step from `target0` to `target1` (a Kelvin-Voigt element driven by a
    piecewise-linear input); finite values and gradients at dt = 0.

    q1 = a q0 + (1 - a) target0 + (target1 - target0) (1 - (tau / dt)(1 - a)),
    a = exp(-dt / tau).
    """
    x = dt / tau
    return (
        jnp.exp(-x) * q0
        - jnp.expm1(-x) * target0
        + (target1 - target0) * ramp_factor(x)
    )
