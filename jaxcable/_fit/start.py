"""A model's start values scaled to a data set: [`jaxcable.scaled_start`][].

A start far from the data (a 3 mm rope's moduli for a thin braid or a soft polymer,
retardation times of hours for a test of a minute) either fails (a strain beyond
break, a flow that runs away) or leaves a fit in a flat valley. The scaling moves it
into the data's own range by two factors, each applied to every parameter by the
power its field declares (`jaxcable._models.fields.parameter`'s `stiffness` and
`time`), so that the ratios between the model's moduli, and between its times, stay
as they were.
"""

import dataclasses
import math
import warnings

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._cable import Cable
from .._drive import DriveSpec, Simulation, simulate_force_history
from .._models import (
    AbstractCableModel,
    AbstractExtension,
    AbstractFiveElement,
    BurgersModel,
    IntegratedModel,
    field_facts,
)
from .data import as_test_list, resolve_drives


class StartMovedWarning(UserWarning):
    """A start that failed on a test was replaced by the start scaled to the data
    ([`jaxcable.scaled_start`][])."""


# The first loading: the samples up to where the force first reaches this share of
# its largest value before it first falls by `_DROP` of the test's peak.
_REACHED = 0.98
_DROP = 0.05
# The first loading is taken on this many samples (every k-th of a longer one,
# padded): one compiled simulation serves every test and every iterate.
_POINTS = 64
# Secant iterations of the stiffness factor, and its range.
_ITERATIONS = 4
_RANGE = 1e4
# A hold or rest: the driving channel within this share of the test's peak.
_HOLD_SHARE = 0.02
# The model's longest retardation time is "far off" beyond this many times the
# longest hold (its creep cannot show in the data); it is then set to this share
# of the hold.
_TOO_SLOW = 10.0
_TARGET = 1.0 / 3.0


@dataclasses.dataclass(frozen=True)
class StartScaling:
    """How [`jaxcable.scaled_start`][] moved a start.

    **Fields:**

    - `model`: the scaled model.
    - `stiffness`: c, the factor of every modulus (and of every parameter by its
        declared stiffness power).
    - `time`: s, the factor of every retardation time and viscosity (1: the times
        were not far off).
    - `hold_s`: the data's longest hold or rest, s (its longest test when it has
        none).
    - `retardation_s`: the start's longest retardation time, s (NaN: it has none).
    """

    model: AbstractCableModel
    stiffness: float
    time: float
    hold_s: float
    retardation_s: float

    def describe(self) -> str:
        """One line: the two factors and why."""
        text = f"moduli x {self.stiffness:.4g} (first loading)"
        if self.time != 1.0:
            text += (
                f", times x {self.time:.4g} (longest retardation "
                f"{self.retardation_s:.3g} s against a longest hold of "
                f"{self.hold_s:.3g} s)"
            )
        return text


def _layers(model: AbstractCableModel):
    """`model` and the models it wraps, outermost first."""
    while True:
        yield model
        if not isinstance(model, AbstractExtension):
            return
        model = model.base


def _scaled(model: AbstractCableModel, stiffness: float, time: float):
    """`model` with every declared field of every layer multiplied by
    stiffness**k time**j (k, j its declared powers)."""
    if isinstance(model, AbstractExtension):
        model = eqx.tree_at(
            lambda m: m.base, model, _scaled(model.base, stiffness, time)
        )
    for name, facts in field_facts(type(model)).items():
        factor = stiffness**facts.stiffness * time**facts.time
        if factor != 1.0:
            value = getattr(model, name)
            model = eqx.tree_at(
                lambda m: getattr(m, name), model, value * jnp.asarray(factor)
            )
    return model


def retardation_times(model: AbstractCableModel) -> list[float]:
    """The creep (retardation) times of `model` and the models it wraps, s: Park's
    t_c, t_e and t_r1; Burgers' eta2 / E2; the five-element model's eta_k / E_k of
    its loading elements; and any other declared field in s that follows a time
    scaling (an extra element's tau_k). A flow (a Maxwell dashpot) is no retardation.

    **Arguments:**

    - `model`: any model with scalar parameters.

    **Returns:**

    The times, s (empty for a model with none, e.g. Hooke or Bouc-Wen).
    """
    out = []
    for layer in _layers(model):
        if isinstance(layer, IntegratedModel):
            out += [layer.t_c, layer.t_e, layer.t_r1]
        elif isinstance(layer, BurgersModel):
            out.append(layer.eta2 / layer.E2)
        elif isinstance(layer, AbstractFiveElement):
            # Both five-element models declare Table 1's fields, in orders of their
            # own, so that the abstract class cannot declare them.
            out += [layer.eta_L2 / layer.E_L2, layer.eta_L3 / layer.E_L3]  # pyright: ignore[reportAttributeAccessIssue]
        else:
            facts = field_facts(type(layer))
            out += [
                getattr(layer, n) for n, f in facts.items() if f.unit == "s" and f.time
            ]
    values = [float(np.asarray(t)) for t in out]
    return [t for t in values if math.isfinite(t) and t > 0]


def _first_loading(force: np.ndarray) -> int:
    """The index where the first loading ends (see `_REACHED`, `_DROP`)."""
    peak = float(np.max(force))
    running = np.maximum.accumulate(force)
    fallen = np.flatnonzero(force < running - _DROP * peak)
    stop = int(fallen[0]) if fallen.size else force.shape[0]
    first = float(np.max(force[:stop]))
    return max(int(np.flatnonzero(force[:stop] >= _REACHED * first)[0]), 1)


def _longest_hold(time: np.ndarray, channel: np.ndarray) -> float:
    """The longest run of samples over which `channel` stays within `_HOLD_SHARE`
    of its peak of the run's first value, s."""
    tolerance = _HOLD_SHARE * float(np.max(np.abs(channel)))
    best, start = 0.0, 0
    for i in range(1, channel.shape[0] + 1):
        if i == channel.shape[0] or abs(channel[i] - channel[start]) > tolerance:
            best = max(best, float(time[i - 1] - time[start]))
            start = i
    return best


@dataclasses.dataclass(frozen=True)
class _Loading:
    """One test's first loading on `_POINTS` samples: time (s), force (N), the
    measured strain, which samples count (False: padding), and the cable
    (unbreakable, for the start's simulation)."""

    time: np.ndarray
    force: np.ndarray
    strain: np.ndarray
    mask: np.ndarray
    cable: Cable


def _loading(test) -> _Loading | None:
    """The first loading of `test`, or None when it has none (no rise of force):
    its own samples, every k-th of a longer one (no interpolation: for data of the
    model itself the start's strain is the data's exactly), padded."""
    if test.elongation is None:
        # Nothing to scale by: the fit names the test that lacks it.
        return None
    time = np.asarray(test.time, float)
    force = np.maximum(np.asarray(test.force, float), 0.0)
    cable = test.cable()
    strain = np.asarray(test.elongation, float) / float(cable.length)
    end = _first_loading(force)
    if not force[end] > 0:
        return None
    index = np.unique(np.round(np.linspace(0, end, min(end + 1, _POINTS))).astype(int))
    pad = _POINTS - index.shape[0]
    index = np.concatenate([index, np.full(pad, index[-1])])
    mask = np.arange(_POINTS) < _POINTS - pad
    # The padding samples leave the state as it is; their times still increase.
    t = time[index] + np.maximum(np.arange(_POINTS) - (_POINTS - pad - 1), 0) * 1e-3
    f = force[index]
    # The start's own strain, whatever it is: the scaling measures it. (A breaking
    # strain of 1 keeps Park's hardening in its domain; the load limit is the
    # cable's or twice the loading's peak.)
    limit = max(float(cable.breaking_load), 2.0 * float(np.max(f)))
    free = eqx.tree_at(
        lambda c: (c.breaking_strain, c.breaking_load),
        cable,
        (jnp.asarray(1.0), jnp.asarray(limit)),
    )
    return _Loading(t, f, strain[index], mask, free)


def _strain_of(model, loading: _Loading) -> np.ndarray:
    """The start's strain over a first loading (NaN where it fails)."""
    traj = simulate_force_history(
        model,
        loading.cable,
        loading.time,
        loading.force,
        mask=loading.mask,
        method=Simulation(throw=False),
    )
    return np.asarray(traj.strain, float)[loading.mask]


def _factor(model, loadings: list[_Loading]) -> float:
    """The stiffness factor c that matches the start's first loadings to the
    data's in the least-squares sense (geometric mean over the tests)."""
    logs = []
    for loading in loadings:
        measured = (loading.strain - loading.strain[0])[loading.mask]
        log_c = 0.0
        for _ in range(_ITERATIONS):
            strain = _strain_of(_scaled(model, math.exp(log_c), 1.0), loading)
            if not np.all(np.isfinite(strain)):
                # A start that does not even load finitely: ten times stiffer.
                log_c += math.log(10.0)
                continue
            m = strain - strain[0]
            g = float(np.dot(m, measured) / np.dot(m, m)) if np.any(m) else math.nan
            if not (math.isfinite(g) and g > 0):
                break
            # A stiffer model strains less: d ~ m / c.
            log_c = float(
                np.clip(log_c - math.log(g), -math.log(_RANGE), math.log(_RANGE))
            )
            if abs(math.log(g)) < 1e-3:
                break
        logs.append(log_c)
    return math.exp(float(np.mean(logs))) if logs else 1.0


def start_scaling(
    model: AbstractCableModel, tests, *, drive: DriveSpec = "auto"
) -> StartScaling:
    """[`jaxcable.scaled_start`][], with the factors it applied.

    **Arguments:**

    - `model`, `tests`, `drive`: as in [`jaxcable.scaled_start`][].

    **Returns:**

    A [`jaxcable.StartScaling`][].
    """
    if not isinstance(model, AbstractCableModel):
        raise ValueError(
            f"`model` must be a jaxcable model, got {type(model).__name__}."
        )
    test_list = as_test_list(tests)
    drives = [d.drive for d in resolve_drives(test_list, drive)]
    loadings = [x for x in map(_loading, test_list) if x is not None]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        stiffness = _factor(model, loadings)
    holds, spans = [], []
    for test, d in zip(test_list, drives):
        time = np.asarray(test.time, float)
        spans.append(float(time[-1] - time[0]))
        channels = [np.asarray(test.force, float)]
        if test.elongation is not None and d.scores_force:
            channels.append(np.asarray(test.elongation, float))
        holds += [_longest_hold(time, c) for c in channels]
    hold = max(holds) if holds and max(holds) > 0 else max(spans)
    times = retardation_times(model)
    longest = max(times) if times else math.nan
    time_factor = 1.0
    if times and longest > _TOO_SLOW * hold:
        time_factor = _TARGET * hold / longest
    scaled = _scaled(model, stiffness, time_factor)
    return StartScaling(scaled, stiffness, time_factor, hold, longest)


def scaled_start(model: AbstractCableModel, tests, *, drive: DriveSpec = "auto"):
    """`model` with its start values scaled to a data set: its stiffness to the
    data's first loading, its retardation times to the data's holds when they are
    far off.

    **Stiffness.** The first loading of each test runs from its first sample to
    where the force first reaches 98 % of its largest value before it first falls
    (by 5 % of the test's peak force): a creep test's ramp, a cycle's first rise.
    The model is driven by that measured force (force-driven, whatever drives the
    test: a relaxation's first loading is a force history too; at most 64 of its
    samples, every k-th of a longer loading) and a factor c is found that matches its strain rise to the measured
    one in the least-squares sense, d ~ m / c (d, m the measured and the model's
    strain above the first sample): c <- c <m, m> / <m, d>, iterated 4 times for a
    nonlinear model, within [1e-4, 1e4], a start that does not load finitely made
    ten times stiffer. Over several tests c is the geometric mean. Every field is
    multiplied by c to its declared stiffness power: every modulus and viscosity by
    c (so their ratios stay), a compliance (Bouc-Wen's z_y, a termination
    compliance) by 1 / c; the parameters measured against the stiffness (Park's
    activation strain, the hardening) are unchanged. For a linear model this
    divides every strain at a given force by c; for Park's model it is the same
    material at c times the stiffness per nominal area (a thinner braid of the same
    fibre).

    **Time.** The data's time scale T is its longest hold or rest: the longest run
    over which a test's force (or, for an elongation-driven test, its elongation)
    stays within 2 % of its peak of the run's first value; the longest test when
    none. When the model's longest retardation time (`retardation_times`: Park's
    t_c, t_e, t_r1; Burgers' eta2 / E2; the five-element eta_k / E_k) exceeds 10 T,
    its creep cannot show in the data, and every field is multiplied by s to its
    declared time power (every retardation time and viscosity, Park's Eq. 8
    lambdas) with s = T / (3 x that time): the longest retardation time becomes T / 3
    and the ratios stay. Shorter times are kept (a creep faster than the sampling
    still shows as a step).

    **Arguments:**

    - `model`: any model of the registry (extensions around a base included), with
        scalar parameters: its start values.
    - `tests`: a [`jaxcable.TestData`][] or a sequence of them, with elongation.
    - `drive`: each test's drive, as a [`jaxcable.Problem`][]'s `drive` (it chooses
        the channel whose holds count).

    **Returns:**

    The scaled model (the same class and structure).

    **Raises:**

    `ValueError` naming `model` or `tests`.
    """
    return start_scaling(model, tests, drive=drive).model


@eqx.filter_jit
def _finite_per_test(problem, u):
    return jnp.all(jnp.isfinite(problem.residuals(u)), axis=1)


def start_failure(
    model: AbstractCableModel, tests, *, drive: DriveSpec = "auto"
) -> str:
    """Why `model`'s start values fail on `tests`, or "" when they do not: outside
    their domain for a test's cable, or a simulation of a test that is not finite
    or goes beyond break (as [`jaxcable.fit`][] would find them).

    **Arguments:**

    - `model`, `tests`, `drive`: the fields of a [`jaxcable.Problem`][].

    **Returns:**

    The reason, naming the first test it fails on, or "".
    """
    from .data import test_id
    from .problem import StartError, make_problem

    test_list = as_test_list(tests)
    try:
        problem, u = make_problem(model, test_list, None, None, None, drive)
    except StartError as e:
        return str(e)
    ok = np.asarray(_finite_per_test(problem, u))
    if ok.all():
        return ""
    i = int(np.flatnonzero(~ok)[0])
    return (
        f"the start does not simulate finitely within the cable's break on "
        f"tests[{i}] ({test_id(test_list[i], i)})"
    )
