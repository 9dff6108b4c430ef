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


# A Kelvin-Voigt element over a step of x = h / tau needs the decay less one,
# expm1(-x), and the ramp factor R(x) = (x + expm1(-x)) / x. Both come from one
# `exp` (XLA's `expm1` costs an exp, a log and a division; these run several times per
# sample in every scan). Below `_series_below(dtype)`, R is its Taylor series
# sum_{k>=1} (-1)^(k+1) x^k / (k+1)! (the closed form loses digits to cancellation
# there, relative error ~ eps / (x R)) and expm1(-x) = x (R - 1) exactly; above it,
# exp(-x) - 1 has no cancellation (relative error < eps / (1 - exp(-x)), 10 eps at
# x = 0.1) and R's closed form is accurate to ~eps / (x R) (200 eps at x = 0.1, 35 eps
# at 0.25). The series is truncated where its next term is below the dtype's
# rounding of R: float64 after x^9 below 0.1 (next term < 3e-16 of R), float32 after
# x^6 below 0.25 (< 2e-8 of R).
_RAMP_SERIES = tuple((-1.0) ** (k + 1) / math.factorial(k + 1) for k in range(1, 10))


def _series_below(dtype) -> tuple[float, tuple[float, ...]]:
    """The threshold of the series and its coefficients, highest power first."""
    if jnp.finfo(dtype).bits > 32:
        return 0.1, tuple(reversed(_RAMP_SERIES))
    return 0.25, tuple(reversed(_RAMP_SERIES[:6]))


def relaxation_terms(x):
    """(expm1(-x), R(x)) for x = h / tau >= 0, with one `exp`: the decay of a
    Kelvin-Voigt element over the step, less one, and the ramp factor
    R(x) = 1 - (1 - exp(-x)) / x, the share of a linear stress ramp that it has not
    yet followed. Finite values and gradients at x = 0 (R(0) = 0, R'(0) = 1/2)."""
    below, coefficients = _series_below(x.dtype)
    small = jnp.abs(x) < below
    x_safe = jnp.where(small, 1.0, x)
    decay_m1 = jnp.exp(-x_safe) - 1.0
    series = jnp.zeros_like(x)
    for c in coefficients:  # Horner
        series = (series + c) * x
    return (
        jnp.where(small, x * (series - 1.0), decay_m1),
        jnp.where(small, series, (x_safe + decay_m1) / x_safe),
    )


def kelvin_voigt_step(q0, s0, s1, h, E, eta):
    """Exact strain of a Kelvin-Voigt element (spring E parallel to dashpot eta) after a
    step of length h over which the stress goes linearly from s0 to s1.

    Solves eta q' + E q = s(t) in closed form: with tau = eta / E and a = exp(-h / tau),
    q1 = a q0 + (1/E) [s1 - a s0 - (s1 - s0) (tau / h) (1 - a)], written as
    a q0 + (1/E) [s0 (1 - a) + (s1 - s0) (1 - (tau / h)(1 - a))] so that the h -> 0
    limit (q1 = q0) has finite values and gradients. Units: stress and E in Pa, eta in
    Pa s, h in s; q is a strain.
    """
    decay_m1, ramp = relaxation_terms(h * E / eta)
    return q0 + decay_m1 * q0 + (-s0 * decay_m1 + (s1 - s0) * ramp) / E


def safe_pow(base, exponent):
    """`base**exponent` for `base >= 0`, with finite gradients at `base == 0`."""
    positive = base > 0
    safe = jnp.where(positive, base, 1.0)
    return jnp.where(positive, jnp.exp(exponent * jnp.log(safe)), 0.0)


def relaxation_average(t, tau):
    """(1 - exp(-t / tau)) / t, continued by 1 / tau at t = 0 (finite gradients)."""
    x = t / tau
    decay_m1, ramp = relaxation_terms(x)
    # (1 - R) / tau while R is small; -expm1(-x) / t where 1 - R would cancel (large x).
    small = x < 1.0
    return jnp.where(small, (1.0 - ramp) / tau, -decay_m1 / jnp.where(small, 1.0, t))


def retarded(q0, target0, target1, dt, tau):
    """Exact value after `dt` of q' = (target - q) / tau with the target linear over
    the step from `target0` to `target1` (a Kelvin-Voigt element driven by a
    piecewise-linear input); finite values and gradients at dt = 0.

    q1 = a q0 + (1 - a) target0 + (target1 - target0) (1 - (tau / dt)(1 - a)),
    a = exp(-dt / tau), written with the one transcendental expm1(-dt / tau) = a - 1.
    """
    decay_m1, ramp = relaxation_terms(dt / tau)
    return q0 + decay_m1 * (q0 - target0) + (target1 - target0) * ramp
