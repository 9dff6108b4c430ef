"""Cycle-by-cycle measures of a simulated (or measured) cyclic test: the hysteresis
energy and the secant stiffness Park et al. report per cycle (Tables 4-5, Figs. 6-7).
"""

from collections.abc import Sequence

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._checks import is_concrete
from .state import Trajectory


# One value per load-unload cycle (an alias keeps the jaxtyping string out of
# annotations, where linters parse it as a forward reference).
PerCycle = Float[Array, " cycles"]


def _one_cable(traj: Trajectory) -> None:
    if jnp.ndim(traj.force) != 1:
        raise ValueError(
            f"Expected the Trajectory of one cable (1-d `force`), got shape "
            f"{jnp.shape(traj.force)}; index or `jax.vmap` over a batch."
        )


def split_cycles(traj: Trajectory, *, tolerance: float = 0.0) -> list[tuple[int, int]]:
    """Index ranges of the complete load-unload cycles of a trajectory.

    A cycle is a loading branch (force rising) followed by an unloading branch (force
    falling), found from the reversals of the force. It runs from the sample where
    the loading begins (the force minimum before it) to the sample where the unloading
    ends (the next minimum), both included; holds at the peak belong to the cycle,
    holds and rests after the unloading do not. Consecutive cycles share their
    boundary sample. A trailing loading branch without its unloading is not a cycle.

    `traj.force` must be concrete (not traced): call this outside `jit`, e.g. once on
    a trajectory of the same protocol, and pass the result to
    [`jaxcable.loop_energies`][] and [`jaxcable.secant_stiffness`][] inside `jit`.

    **Arguments:**

    - `traj`: a [`jaxcable.Trajectory`][] of one cable.
    - `tolerance`: force changes of at most this (N) count as holds (for noisy,
        measured forces).

    **Returns:**

    A list of `(start, stop)` pairs, Python slices `force[start:stop]` of each cycle.
    """
    _one_cable(traj)
    force = np.asarray(traj.force, dtype=float)
    mask = np.asarray(traj.mask, dtype=bool)
    # Padding samples repeat the last valid sample: as holds they split nothing.
    force = np.where(mask, force, force[mask][-1] if mask.any() else 0.0)
    delta = np.diff(force)
    sign = np.where(delta > tolerance, 1, np.where(delta < -tolerance, -1, 0))
    cycles = []
    start = None  # sample where the current loading branch began
    previous = 0  # last nonzero direction
    last_move = 0  # index of the last sample reached by a nonzero step
    for i, s in enumerate(sign):
        if s == 0:
            continue
        if s > 0 and previous <= 0:
            if previous < 0 and start is not None:
                cycles.append((start, last_move + 1))
            start = i
        previous = s
        last_move = i + 1
    if previous < 0 and start is not None:
        cycles.append((start, last_move + 1))
    return cycles


def loop_energies(
    traj: Trajectory, cycles: Sequence[tuple[int, int]] | None = None
) -> PerCycle:
    r"""Energy dissipated in each load-unload cycle, J.

    Hysteresis is not a model of its own: the loop emerges from creep, hardening and
    recovery, and its energy is how it is reported.

    The area of the force-elongation loop, \oint F dx, by the trapezoid rule over the
    samples of the cycle: the net work done on the cable from the start of the loading
    to the end of the unloading. With creep the loop does not close (the cable ends
    longer, Park Fig. 2); the open loop's net work is what Park Tables 4-5 compare,
    and it should fall over the cycles of a cyclic test as dynamic creep dies out.

    **Arguments:**

    - `traj`: a [`jaxcable.Trajectory`][] of one cable.
    - `cycles`: the `(start, stop)` index ranges of the cycles; by default
        [`jaxcable.split_cycles`][]`(traj)`. Pass them precomputed to differentiate
        through this function (the ranges are static).

    **Returns:**

    The dissipated energy of each cycle, J (N m), shape `(cycles,)`.
    """
    _one_cable(traj)
    if cycles is None:
        cycles = split_cycles(traj)
    energies = []
    for start, stop in cycles:
        f = traj.force[start:stop]
        x = traj.elongation[start:stop]
        energies.append(jnp.sum(0.5 * (f[1:] + f[:-1]) * jnp.diff(x)))
    return _stack(energies, traj.elongation)


def secant_stiffness(
    traj: Trajectory, cycles: Sequence[tuple[int, int]] | None = None
) -> PerCycle:
    """Secant stiffness of the loading branch of each cycle, N/m.

    (F_max - F_min) / (x(F_max) - x(F_min)) on the loading branch, with x the
    elongation: the averaged gradient from the initial force (0 N) to the end force
    (100 or 150 N) by which Park et al. measure the hardening over the cycles
    (Section 4, Figs. 6-7). It rises over a cyclic test and then converges.

    **Arguments:**

    - `traj`: a [`jaxcable.Trajectory`][] of one cable.
    - `cycles`: as in [`jaxcable.loop_energies`][].

    **Returns:**

    The secant stiffness of each cycle, N/m, shape `(cycles,)`.
    """
    _one_cable(traj)
    if cycles is None:
        cycles = split_cycles(traj)
    force = np.asarray(traj.force) if is_concrete(traj.force) else None
    stiffness = []
    for start, stop in cycles:
        # The loading branch ends at the first sample of the peak (a peak hold
        # would add creep at constant force to the denominator).
        if force is not None:
            peak = start + int(np.argmax(force[start:stop]))
        else:
            peak = start + jnp.argmax(traj.force[start:stop])
        f = traj.force
        x = traj.elongation
        stiffness.append((f[peak] - f[start]) / (x[peak] - x[start]))
    return _stack(stiffness, traj.elongation)


def _stack(values: list, like: ArrayLike) -> PerCycle:
    if not values:
        return jnp.zeros((0,), jnp.result_type(like))
    return jnp.stack(values)
