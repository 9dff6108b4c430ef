"""Park et al.'s printed numbers for the 3 mm Dyneema SK78 cable, the model's values
of the same quantities, Park's test protocols and the qualitative cyclic behaviour he
reports. The paper's table of fitted parameters is lost, so the defaults of
[`jaxcable.IntegratedModel`][] are fitted to these numbers instead
(`jaxcable._papers.calibration`).

What each target means in the model (all at 3 mm/min unless stated, 0 <-> 100 N):

- `creep_ratio_300mm`: creep / instantaneous strain (`Trajectory.parts`) at the peak
    of the first ramp of a 300 mm cable (Park Section 4 on Fig. 3: "the amount of
    creep is 4 times larger than the static elongation at a tensile rate of 3 mm/min").
- `residual_300mm`, `residual_100mm`: elongation at 0 N at the end of the first
    unloading (Park Section 4 on Fig. 5).
- `second_test_<L>_<h>h`: Park Table 3, measured as the elongation of a second
    tensile test (0 -> 100 N at 3 mm/min) after a 10-cycle test and a rest of h hours
    (Section 2.1 and 4: "recovery was assessed by measuring elongation in the second
    tensile test"). The model's value is that test simulated as run: elongation at the
    peak of the second test minus elongation at the end of the rest. Park assumed it
    equals the recovery in the rest; the simulation needs no such assumption.
- `peak_300mm_50mm_min`, `peak_300mm_3mm_min` (derived, not printed): elongation at
    100 N of the first ramp of a 300 mm cable. Park gives the RMS error of Fig. 3 in
    mm and in %: 0.20 mm (3.5 %) at 50 mm/min, 0.06 mm (0.72 %) at 3 mm/min. Read as
    a percentage of the peak elongation, the peaks are 0.20 / 0.035 = 5.71 mm and
    0.06 / 0.0072 = 8.33 mm (consistent with the 4x creep ratio: static 1.67 mm,
    creep 6.67 mm, of which the 6.1 mm residual is what the unloading leaves).
"""

import functools
from collections.abc import Sequence
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from .._cable import Cable
from .._drive import (
    Protocol,
    Simulation,
    loop_energies,
    secant_stiffness,
    simulate_rate_test,
)
from .._models import IntegratedModel
from .._results import RESULTS


SLOW_SPEED = 3e-3 / 60  # 3 mm/min, m/s
FAST_SPEED = 50e-3 / 60  # 50 mm/min, m/s
_FORCE = 100.0  # N
CYCLES = 10
REST_HOURS = (24, 48, 72)
# The forces of the cyclic tests, Park Figs. 4 and 6, Table 4.
_SHAPE_FORCES = (100.0, 150.0)  # N


def park_protocol(
    force_max: float,
    *,
    cycles: int = CYCLES,
    samples_per_ramp: int = 50,
    rest_hours: float = 24.0,
    rest_samples: int = 24,
    restretch: bool = True,
) -> Protocol:
    """Park et al.'s long-term recovery protocol (Section 2.1 and 4).

    `cycles` load-unload cycles 0 -> `force_max` -> 0 at constant crosshead speed, a
    rest of `rest_hours` at 0 N, then one more loading and unloading to the same force
    (the re-stretch that measures the recovery).

    **Arguments:**

    - `force_max`: the peak force, N.
    - `cycles`: the cycles before the rest.
    - `samples_per_ramp`: force samples per ramp.
    - `rest_hours`: the rest, h.
    - `rest_samples`: samples of the rest (evenly spaced in time).
    - `restretch`: whether to end with the re-stretch cycle.

    **Returns:**

    The [`jaxcable.Protocol`][].
    """
    pieces = [
        Protocol.cycles(force_max, cycles, samples_per_ramp),
        Protocol.rest(rest_hours * 3600.0, rest_samples),
    ]
    if restretch:
        pieces.append(Protocol.cycles(force_max, 1, samples_per_ramp, start=False))
    return Protocol.concatenate(*pieces)


class Target(NamedTuple):
    """One number printed (or derived from a printed number) in Park et al.

    **Fields:**

    - `name`: identifier, e.g. `"second_test_300mm_48h"`.
    - `value`: the paper's value, in `unit`.
    - `unit`: `"mm"` or `"-"` (a ratio).
    - `source`: where it is printed (section, figure, table).
    - `derived`: True where the value is computed from printed numbers rather than
        printed itself.
    - `quantity`: the simulated quantity compared with it: which test, simulated as
        Park ran it, and what is read from it.
    """

    name: str
    value: float
    unit: str
    source: str
    derived: bool = False
    quantity: str = ""


def _table3(length_mm: int, values: Sequence[float]) -> list[Target]:
    """Park's Table 3 for one cable length, one per rest: the elongation of the
    second tensile test."""
    return [
        Target(
            f"second_test_{length_mm}mm_{h}h",
            v,
            "mm",
            f"Park Table 3, {length_mm} mm, measured: elongation of the second tensile "
            f"test to 100 N after 10 cycles (100 N, 3 mm/min) and {h} h of rest",
            quantity=f"10 cycles 0 <-> 100 N at 3 mm/min, {h} h at 0 N, a second ramp "
            "to 100 N: elongation at its peak minus elongation at the end of the rest",
        )
        for h, v in zip(REST_HOURS, values)
    ]


# The targets, in the order of the fit and of the report.
SK78_TARGETS: tuple[Target, ...] = (
    Target(
        "creep_ratio_300mm",
        4.0,
        "-",
        "Park Sec. 4, on Fig. 3: creep = 4x static elongation at 3 mm/min (300 mm, "
        "0-100 N)",
        quantity="first ramp 0 -> 100 N at 3 mm/min: creep / instantaneous strain "
        "(Trajectory.parts) at 100 N",
    ),
    Target(
        "residual_300mm",
        6.1,
        "mm",
        "Park Sec. 4, on Fig. 5: elongation at 0 N after the first unloading (300 mm, "
        "100 N, 3 mm/min)",
        quantity="first cycle 0 -> 100 -> 0 N at 3 mm/min: elongation at 0 N at the "
        "end of the unloading",
    ),
    Target(
        "residual_100mm",
        1.85,
        "mm",
        "Park Sec. 4, on Fig. 5: elongation at 0 N after the first unloading (100 mm, "
        "100 N, 3 mm/min)",
        quantity="first cycle 0 -> 100 -> 0 N at 3 mm/min: elongation at 0 N at the "
        "end of the unloading",
    ),
    *_table3(100, (2.33, 2.33, 2.36)),
    *_table3(300, (5.05, 5.99, 7.12)),
    Target(
        "peak_300mm_50mm_min",
        0.20 / 0.035,
        "mm",
        "derived from Park Sec. 4 on Fig. 3: RMS error 0.20 mm = 3.5 % of the peak "
        "elongation (300 mm, 100 N, 50 mm/min)",
        derived=True,
        quantity="first ramp 0 -> 100 N at 50 mm/min: elongation at 100 N",
    ),
    Target(
        "peak_300mm_3mm_min",
        0.06 / 0.0072,
        "mm",
        "derived from Park Sec. 4 on Fig. 3: RMS error 0.06 mm = 0.72 % of the peak "
        "elongation (300 mm, 100 N, 3 mm/min)",
        derived=True,
        quantity="first ramp 0 -> 100 N at 3 mm/min: elongation at 100 N",
    ),
)


class TargetRow(NamedTuple):
    """One row of [`jaxcable.papers.sk78_targets_report`][].

    **Fields:**

    - `name`: the target's name (see `SK78_TARGETS`).
    - `paper`: the paper's value, in `unit`.
    - `model`: the model's value, in `unit`.
    - `error`: (model - paper) / paper, %.
    - `unit`, `source`, `quantity`: as in the target.
    """

    name: str
    paper: float
    model: float
    error: float
    unit: str
    source: str
    quantity: str


def _stack(protocols: Sequence[Protocol]) -> Protocol:
    """Protocols of one shape stacked along a leading axis, for `jax.vmap`."""
    return jax.tree_util.tree_map(
        lambda *x: np.stack([np.asarray(v) for v in x]), *protocols
    )


# Cached, and built eagerly even when first called under a trace (Protocol joins its
# pieces with NumPy).
@functools.lru_cache(maxsize=8)
def _protocols(samples_per_ramp: int) -> tuple[Protocol, Protocol]:
    with jax.ensure_compile_time_eval():
        # Park's long-term recovery test as run, one protocol per rest (same shape:
        # the rest is one sample), stacked for one vmapped simulation: 10 cycles, the
        # rest, the second tensile test.
        second = _stack(
            [
                park_protocol(
                    _FORCE,
                    samples_per_ramp=samples_per_ramp,
                    rest_hours=h,
                    rest_samples=1,
                    restretch=True,
                )
                for h in REST_HOURS
            ]
        )
        ramp = Protocol.cycles(_FORCE, cycles=1, samples_per_ramp=samples_per_ramp)
    return second, ramp


def second_test_indices(samples_per_ramp: int) -> tuple[int, int]:
    """The sample indices, in `park_protocol(..., rest_samples=1, restretch=True)`,
    of the end of the rest and of the peak of the second tensile test."""
    rest_end = 2 * CYCLES * samples_per_ramp + 1
    return rest_end, rest_end + samples_per_ramp


def simulate_targets(model: IntegratedModel, samples_per_ramp: int, solver, throw):
    """Simulate Park's tests as he ran them and read the targets from them.

    Pure JAX: jit- and grad-able in `model`.

    **Arguments:**

    - `model`: the model.
    - `samples_per_ramp`: force samples per ramp.
    - `solver`, `throw`: the [`jaxcable.Simulation`][] of
        [`jaxcable.simulate_rate_test`][].

    **Returns:**

    `(values, ok, rest_ends, peaks)`: the model's value of every target (in the order
    of `SK78_TARGETS`), whether the simulation each comes from succeeded, the
    elongation (m) at the end of each rest (24, 48, 72 h) of the 100 mm and of the
    300 mm cable, shape (2, 3), and their elongation at the peak of the second
    tensile test (m), shape (2, 3).
    """
    n = samples_per_ramp
    second, ramp = _protocols(n)
    kwargs = dict(method=Simulation(solver=solver, throw=throw))

    def run(length):
        cable = Cable(length=length, speed=SLOW_SPEED)
        return jax.vmap(lambda p: simulate_rate_test(model, cable, p, **kwargs))(second)

    long_, short = run(0.3), run(0.1)
    fast = simulate_rate_test(
        model, Cable(length=0.3, speed=FAST_SPEED), ramp, **kwargs
    )
    mm = 1e3
    # Sample indices of Protocol.cycles: peak k at (2k + 1) n, valley k at 2 (k + 1) n.
    first_peak, first_valley = n, 2 * n
    rest_end, peak2 = second_test_indices(n)

    def second_test(traj):
        return (traj.elongation[:, peak2] - traj.elongation[:, rest_end]) * mm

    parts = long_.parts
    values = jnp.concatenate(
        [
            jnp.stack(
                [
                    parts.creep[0, first_peak] / parts.instantaneous[0, first_peak],
                    long_.elongation[0, first_valley] * mm,
                    short.elongation[0, first_valley] * mm,
                ]
            ),
            second_test(short),
            second_test(long_),
            jnp.stack(
                [fast.elongation[first_peak] * mm, long_.elongation[0, first_peak] * mm]
            ),
        ]
    )
    ok_long, ok_short = (
        jnp.all(t.result == RESULTS.successful) for t in (long_, short)
    )
    ok_fast = fast.result == RESULTS.successful
    # Which simulation each target comes from, in the order of SK78_TARGETS.
    ok = jnp.stack(
        [ok_long, ok_long, ok_short, *[ok_short] * 3, *[ok_long] * 3, ok_fast, ok_long]
    )
    rest_ends = jnp.stack([t.elongation[:, rest_end] for t in (short, long_)])
    peaks = jnp.stack([t.elongation[:, peak2] for t in (short, long_)])
    return values, ok, rest_ends, peaks


def target_values(model: IntegratedModel, samples_per_ramp: int, solver, throw: bool):
    """The model's value of every target (in the order of SK78_TARGETS) and whether
    the simulation it comes from succeeded. Pure JAX: jit- and grad-able in `model`."""
    values, ok, _, _ = simulate_targets(model, samples_per_ramp, solver, throw)
    return values, ok


def sk78_targets_report(
    model: IntegratedModel | None = None,
    *,
    samples_per_ramp: int = 200,
    solver: optx.AbstractRootFinder | None = None,
) -> list[TargetRow]:
    """Park et al.'s printed targets beside the model's values.

    Simulates, with [`jaxcable.simulate_rate_test`][], Park's tests as he ran them:
    a 10-cycle test (0 <-> 100 N, 3 mm/min), a rest of 24, 48 or 72 h and a second
    tensile test to 100 N, for a 300 mm and a 100 mm cable, and a ramp to 100 N at
    50 mm/min of a 300 mm cable; the module docstring says which simulated quantity
    each target is.

    **Arguments:**

    - `model`: an [`jaxcable.IntegratedModel`][] (default: its default parameters).
    - `samples_per_ramp`: force samples per ramp.
    - `solver`: passed to [`jaxcable.simulate_rate_test`][].

    **Returns:**

    A list of `TargetRow` `(name, paper, model, error, unit, source)`, one per
    target, the error in %. Where a simulation fails (e.g. t_r2 < 0 at 50 mm/min,
    Park Eq. 8), its targets' model value and error are NaN.
    """
    if model is None:
        model = IntegratedModel()
    values, ok = target_values(model, samples_per_ramp, solver, throw=False)
    values = np.where(np.asarray(ok), np.asarray(values), np.nan)
    rows = []
    for target, value in zip(SK78_TARGETS, values):
        error = 100.0 * (value - target.value) / target.value
        rows.append(
            TargetRow(
                target.name,
                target.value,
                float(value),
                float(error),
                target.unit,
                target.source,
                target.quantity,
            )
        )
    return rows


@functools.lru_cache(maxsize=8)
def _shape_protocols(samples_per_ramp: int) -> tuple[Protocol, ...]:
    # Cached and built eagerly, as `_protocols`.
    with jax.ensure_compile_time_eval():
        return tuple(
            Protocol.cycles(force, cycles=CYCLES, samples_per_ramp=samples_per_ramp)
            for force in _SHAPE_FORCES
        )


def cyclic_shape(model: IntegratedModel, samples_per_ramp: int, solver):
    """Secant stiffness (N/m), loop energy (J) and elongation at 0 N (m) of each of
    the 10 cycles at 100 and 150 N (300 mm, 3 mm/min), shape (2, 10) each, and
    whether both simulations succeeded. Pure JAX (the cycle ranges are static)."""
    n = samples_per_ramp
    cable = Cable(length=0.3, speed=SLOW_SPEED)
    cycles = [(2 * k * n, 2 * (k + 1) * n + 1) for k in range(CYCLES)]
    stiffness, energy, valleys, ok = [], [], [], []
    for protocol in _shape_protocols(n):
        method = Simulation(solver=solver, throw=False)
        traj = simulate_rate_test(model, cable, protocol, method=method)
        stiffness.append(secant_stiffness(traj, cycles))
        energy.append(loop_energies(traj, cycles))
        valleys.append(traj.elongation[jnp.array([stop - 1 for _, stop in cycles])])
        ok.append(traj.result == RESULTS.successful)
    return (
        jnp.stack(stiffness),
        jnp.stack(energy),
        jnp.stack(valleys),
        ok[0] & ok[1],
    )


def sk78_qualitative_checks(
    model: IntegratedModel | None = None, *, samples_per_ramp: int = 200
) -> dict[str, dict]:
    """Park's qualitative cyclic behaviour on 10 cycles at 100 and 150 N (300 mm,
    3 mm/min): the secant stiffness rises then converges (Figs. 6-7), the loop energy
    falls (Tables 4-5).

    **Arguments:**

    - `model`: an [`jaxcable.IntegratedModel`][] (default: its default parameters).
    - `samples_per_ramp`: force samples per ramp.

    **Returns:**

    For each force (`"100N"`, `"150N"`) a dict of: `stiffness` (N/m), `energy` (J)
    and `valley` (elongation at 0 N, m) per cycle, and the booleans `stiffness_rises`
    (each cycle stiffer than the one before), `stiffness_converges` (the last rise
    below 1 % and below a tenth of the first), `energy_falls` (each cycle dissipates
    less than the one before, and more than 0), `elongation_grows` (each cycle ends
    longer than the one before).
    """
    if model is None:
        model = IntegratedModel()
    stiffness, energy, valleys, ok = cyclic_shape(model, samples_per_ramp, None)
    if not bool(ok):
        raise ValueError("The 10-cycle simulations of `model` failed.")
    out = {}
    for force, k, e, x in zip(
        _SHAPE_FORCES, *map(np.asarray, (stiffness, energy, valleys))
    ):
        rise = np.diff(k) / k[:-1]
        out[f"{force:.0f}N"] = dict(
            stiffness=k,
            energy=e,
            valley=x,
            stiffness_rises=bool(np.all(rise > 0)),
            stiffness_converges=bool(rise[-1] < 0.01 and rise[-1] < rise[0] / 10),
            energy_falls=bool(np.all(np.diff(e) < 0) and e[-1] > 0),
            elongation_grows=bool(np.all(np.diff(x) > 0)),
        )
    return out
