"""The next test to run: `jaxcable.design_test`, a protocol chosen by gradient to
shrink what a fit or a posterior knows least."""

import dataclasses
import json
import math
import os
from collections.abc import Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._cable import Cable
from .._drive import (
    Protocol,
    Simulation,
    simulate_force_history,
    simulate_rate_test,
)
from .._files import write_text_atomic
from .._fit import FitResult, field_at
from .._models import AbstractCableModel, parameter_info
from .budget import TestBudget
from .methods import TestDesign
from .priors import PRIOR_SCALE
from .result import Posterior


# Park's standard protocol: 10 load-unload cycles (Park et al., Section 2.1).
PARK_CYCLES = 10
# A candidate design may fail to simulate (a ramp that does not reach its level):
# the optimiser sees the failure as a non-finite criterion instead of an error.
QUIET = Simulation(throw=False)


@dataclasses.dataclass(frozen=True)
class Knowledge:
    """What is known before the next test, on the scale theta (log x for a log-scaled
    parameter, x otherwise): the reference model, the names, their values and
    covariance in theta, and the elongation noise of a force-driven test (m)."""

    model: AbstractCableModel
    names: tuple[str, ...]
    values: np.ndarray
    log: np.ndarray
    covariance: np.ndarray
    noise_m: float

    @property
    def sd(self) -> np.ndarray:
        """Standard deviation of each theta (relative for a log-scaled parameter)."""
        return np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))

    def precision(self) -> np.ndarray:
        """The information about theta, the prior's (ln 10 per parameter) included
        so that a parameter the data do not determine keeps a finite variance."""
        cov = 0.5 * (self.covariance + self.covariance.T)
        cov = np.where(np.isfinite(cov), cov, 0.0)
        w, v = np.linalg.eigh(cov)
        inv_w = np.where(w > 1e-300, 1.0 / np.maximum(w, 1e-300), 0.0)
        return (v * inv_w) @ v.T + np.eye(len(w)) / PRIOR_SCALE**2

    def with_theta(self, theta) -> AbstractCableModel:
        """The reference model with the parameters set from theta (traceable)."""
        x = jnp.where(jnp.asarray(self.log), jnp.exp(theta), theta)
        dtypes = [jnp.result_type(field_at(self.model, n)) for n in self.names]
        return eqx.tree_at(
            lambda m: [field_at(m, n) for n in self.names],
            self.model,
            [x[i].astype(d) for i, d in enumerate(dtypes)],
        )

    @property
    def theta(self) -> np.ndarray:
        return np.where(self.log, np.log(np.abs(self.values)), self.values)


def _log_scaled(model, names, values) -> np.ndarray:
    """Which parameters theta holds as logarithms: the positive ones a fit
    reparameterises by log (a signed effect, such as a drift rate, stays linear, so
    that the linearisation can take it through 0)."""
    out = []
    for name, value in zip(names, values):
        *path, field = name.split(".")
        owner = field_at(model, ".".join(path)) if path else model
        info = parameter_info(type(owner), field)
        transform = "log" if info is None else info.transform
        out.append(value > 0 and transform in ("log", "log1"))
    return np.array(out, bool)


def knowledge_of(source, noise_mm: float | None) -> Knowledge:
    """The `Knowledge` of a [`jaxcable.FitResult`][] or a [`jaxcable.Posterior`][];
    `noise_mm` overrides the noise read from the fit."""
    if isinstance(source, Posterior):
        fit = source.fit
        model = source.median_model()
        names = tuple(source.names)
        flat = source.flat
        values = np.median(flat, axis=0)
        log = _log_scaled(model, names, values)
        theta = np.where(log, np.log(np.where(log, flat, 1.0)), flat)
        cov = np.atleast_2d(np.cov(theta, rowvar=False))
    elif isinstance(source, FitResult):
        fit = source
        model = source.model
        names = tuple(source.names)
        values = np.asarray(source.values, float)
        log = _log_scaled(model, names, values)
        s = np.where(log, values, 1.0)
        cov = np.asarray(source.covariance, float) / np.outer(s, s)
    else:
        raise ValueError(
            "`known` must be a jaxcable.FitResult or a jaxcable.Posterior (a test "
            "that separates two candidates: jaxcable.design_discriminating_test), "
            f"got {type(source).__name__}."
        )
    if fit.per_test:
        raise ValueError(
            "`known`: parameters fitted per test cannot be designed for "
            f"({list(fit.per_test)}); fit them shared."
        )
    if noise_mm is None:
        rmse = np.asarray(fit.rmse_mm, float)
        rmse = rmse[np.isfinite(rmse)]
        if not rmse.size:
            raise ValueError(
                "`budget.noise_mm`: the fit has no force-driven test to read the "
                "elongation noise from; give it."
            )
        noise_mm = float(np.median(rmse))
    return Knowledge(model, names, values, log, cov, 1e-3 * noise_mm)


def _unit(x, low, high):
    """x in (low, high) from an unconstrained value."""
    return low + (high - low) * jax.nn.sigmoid(x)


@dataclasses.dataclass(frozen=True)
class Layout:
    """The designed test's structure (static): blocks of ramp up, hold, ramp down,
    rest, each with its sample counts."""

    blocks: int
    ramp_samples: int
    hold_samples: int

    @classmethod
    def of(cls, budget: TestBudget) -> "Layout":
        per_block = budget.samples // budget.blocks
        ramp = max(2, per_block // 4)
        return cls(budget.blocks, ramp, max(2, (per_block - 2 * ramp) // 2))

    def directions(self) -> np.ndarray:
        r, h = self.ramp_samples, self.hold_samples
        block = [1] * r + [0] * h + [-1] * r + [0] * h
        return np.array([0] + block * self.blocks)


class Design(eqx.Module):
    """The design variables, unconstrained: the load levels, the hold and rest
    durations (shares of the time left by the ramps) and the crosshead speed."""

    levels: jax.Array
    shares: jax.Array
    speed: jax.Array

    @classmethod
    def start(cls, layout: Layout, variant: int = 0) -> "Design":
        """A first design: levels near the largest force (the information grows
        with the load); variant 0: equal holds and rests at the middle of the speed
        range; 1: slow, long rests; 2: fast, long holds (other starts for a
        criterion with several optima)."""
        k = layout.blocks
        tilt = {0: 0.0, 1: -1.0, 2: 1.0}[variant]
        return cls(
            levels=jnp.linspace(2.0, 1.0, k) if k > 1 else jnp.full(1, 2.0),
            shares=jnp.concatenate([jnp.full(k, tilt), jnp.full(k, -tilt)]),
            speed=jnp.asarray(-2.0 * tilt),
        )


def with_speed(cable: Cable, speed) -> Cable:
    """`cable` at the crosshead `speed` (m/s, traceable)."""
    return eqx.tree_at(lambda c: c.speed, cable, jnp.asarray(speed, cable.speed.dtype))


def optimise(grad, design: Design, steps: int, learning_rate: float):
    """Adam on `design` for `loss(design, ramp_time) -> (value, spent)`, `spent` the
    ramps' duration the simulation found (s), which the next step's protocol
    assumes; `grad` is `jax.jit(jax.value_and_grad(loss, has_aux=True))` (made once
    by the caller, so that several starts share its compilation). The best design
    seen, its ramp time and its loss.

    **Raises:**

    `ValueError` (on `budget`) when the starting design fails to simulate.
    """
    import optax

    optimiser = optax.apply_if_finite(optax.adam(learning_rate), 5)
    # optax types its parameters as arrays or containers of them; a Module is one.
    params: Any = design
    state = optimiser.init(params)
    (value, ramp_time), _ = grad(params, 0.0)
    if not np.isfinite(float(value)):
        raise ValueError(
            "`budget`: the starting design fails to simulate (the cable breaks or a "
            "ramp does not reach its level); lower `max_force_fraction`."
        )
    best = (float(value), params, float(ramp_time))
    for _ in range(steps):
        (value, spent), g = grad(params, ramp_time)
        if np.isfinite(float(value)) and float(value) < best[0]:
            best = (float(value), params, float(ramp_time))
        if np.isfinite(float(spent)):
            ramp_time = float(spent)
        updates, state = optimiser.update(g, state, params)
        params = optax.apply_updates(params, updates)
    return best[1], best[2], best[0]


def designed_protocol(method: TestDesign, cable: Cable, criterion, variants=(0,)):
    """Adam on the design variables from each start `variants` (see
    `Design.start`), the best design kept: `(protocol, cable at its speed, (levels
    N, holds s, rests s), layout)`.

    `criterion(protocol, cable at its speed) -> (value, trajectory)`, the value to
    minimise (traceable) and the rate-driven simulation of the protocol, whose
    duration the next step's ramps assume."""
    budget = method.budget
    layout = Layout.of(budget)

    def build(d, ramp_time):
        return protocol_of(d, layout, budget, cable, ramp_time)

    def loss(d, ramp_time):
        protocol, c, *_ = build(d, ramp_time)
        value, traj = criterion(protocol, c)
        spent = traj.time[-1] - jnp.sum(protocol.duration)
        return value, spent

    grad = jax.jit(jax.value_and_grad(loss, has_aux=True))
    found = [
        optimise(grad, Design.start(layout, v), method.steps, method.learning_rate)
        for v in variants
    ]
    # The first of the lowest losses (each is finite: optimise refuses a start that
    # does not simulate).
    design, ramp_time, _ = min(found, key=lambda f: f[2])
    protocol, c, *parts = build(design, ramp_time)
    return protocol, c, parts, layout


def standard_protocol(model, cable: Cable, budget: TestBudget, duration: float):
    """Park's standard protocol of the same duration, the designed test's yardstick:
    `PARK_CYCLES` cycles to the budget's largest force at `cable`'s speed (clipped
    to the tester's range), then a rest that fills `duration` (s). Returns
    `(protocol, cable at that speed)`."""
    layout = Layout.of(budget)
    low, high = budget.speed_mm_per_min
    usual = with_speed(cable, np.clip(float(cable.speed), low / 6e4, high / 6e4))
    cycles = Protocol.cycles(
        budget.max_force_fraction * float(cable.breaking_load),
        PARK_CYCLES,
        layout.ramp_samples,
    )
    cyc = simulate_rate_test(model, usual, cycles, method=QUIET)
    rest = max(duration - float(cyc.time[-1]), 1.0)
    standard = Protocol.concatenate(
        cycles, Protocol.rest(rest, max(2, budget.samples - cycles.num_samples))
    )
    return standard, usual


@dataclasses.dataclass(frozen=True)
class DesignedProtocol:
    """What every designed test holds: the protocol, the cable at its speed and the
    protocol file (see [`jaxcable.DesignedTest`][])."""

    protocol: Protocol
    cable: Cable
    document: dict

    def why(self) -> str:
        """One paragraph: why this test."""
        raise NotImplementedError

    def to_json(self, path: str | os.PathLike | None = None) -> str:
        """The protocol file (JSON text), written to `path` when given."""
        text = json.dumps(self.document, indent=2)
        if path is not None:
            write_text_atomic(path, text + "\n")
        return text

    def with_document(self, cable: Cable, parts, layout: "Layout", id: str):
        """The same outcome with its protocol file: `parts` the designed
        `(levels N, holds s, rests s)`, `cable` the cable as given (its speed is
        this test's)."""
        document = protocol_document(cable, self.cable.speed, parts, layout, self.why())
        document["id"] = id
        return dataclasses.replace(self, document=document)


def protocol_document(cable, speed, parts, layout, why: str) -> dict:
    """The protocol file of a design (`jaxcable simulate` runs it): its blocks'
    `parts`, `(levels N, holds s, rests s)`, at the crosshead `speed` (m/s)."""
    segments = []
    for f, h, r in zip(*(np.asarray(x) for x in parts)):
        segments += [
            {"ramp_to_N": round(float(f), 3), "samples": layout.ramp_samples},
            {"hold_s": round(float(h), 3), "samples": layout.hold_samples},
            {"ramp_to_N": 0.0, "samples": layout.ramp_samples},
            {"rest_s": round(float(r), 3), "samples": layout.hold_samples},
        ]
    return {
        "id": "designed-test",
        "description": why,
        "length_mm": round(1e3 * float(cable.length), 6),
        "diameter_mm": round(1e3 * float(cable.diameter), 6),
        "rate_mm_per_min": round(float(speed) * 6e4, 4),
        "segments": segments,
    }


def check_design_arguments(method: TestDesign, cable: Cable) -> None:
    """Raise `ValueError` naming the first bad argument of a design function."""
    for name, value, kind in (("method", method, TestDesign), ("cable", cable, Cable)):
        if not isinstance(value, kind):
            raise ValueError(
                f"`{name}` must be a jaxcable.{kind.__name__}, got "
                f"{type(value).__name__}."
            )


def protocol_of(
    design: Design, layout: Layout, budget: TestBudget, cable: Cable, ramp_time
):
    """The `(Protocol, cable at the designed speed, levels N, holds s, rests s)` of a
    design; `ramp_time` (s, an estimate) is the time the ramps take, the holds and
    rests share the rest of the budget."""
    breaking = float(cable.breaking_load)
    levels = _unit(design.levels, 0.05, 1.0) * budget.max_force_fraction * breaking
    share = jax.nn.softmax(design.shares)
    free = jnp.maximum(budget.duration_s - ramp_time, 0.05 * budget.duration_s)
    durations = share * free
    holds, rests = durations[: layout.blocks], durations[layout.blocks :]
    low, high = (math.log(v / 6e4) for v in budget.speed_mm_per_min)
    speed = jnp.exp(_unit(design.speed, low, high))
    r, h = layout.ramp_samples, layout.hold_samples
    frac = jnp.arange(1, r + 1) / r
    forces, durs = [jnp.zeros(1)], [jnp.zeros(1)]
    for k in range(layout.blocks):
        f = levels[k]
        forces += [f * frac, jnp.full(h, f), f * (1 - frac), jnp.zeros(h)]
        durs += [jnp.zeros(r), jnp.full(h, holds[k] / h)]
        durs += [jnp.zeros(r), jnp.full(h, rests[k] / h)]
    force = jnp.concatenate(forces)
    protocol = Protocol(
        force=force,
        direction=layout.directions(),
        duration=jnp.concatenate(durs),
        mask=np.ones(force.shape, bool),
    )
    return protocol, with_speed(cable, speed), levels, holds, rests


def information(knowledge: Knowledge, cable: Cable, time, force):
    """The Fisher information about theta of one force-driven test with these
    sample times (s) and forces (N): J^T J / sigma^2, J the Jacobian of its
    elongations (m) through the simulation."""

    def elongation(theta):
        traj = simulate_force_history(
            knowledge.with_theta(theta), cable, time, force, method=QUIET
        )
        return traj.elongation

    jac = jax.jacfwd(elongation)(jnp.asarray(knowledge.theta))
    return jac.T @ jac / knowledge.noise_m**2


def log_det_subset(precision, targets: np.ndarray):
    """log det of the covariance (the inverse of `precision`) of `targets`: the
    D_s-optimality criterion, lower is better."""
    cov = jnp.linalg.inv(precision)
    sub = cov[jnp.ix_(targets, targets)]
    return jnp.linalg.slogdet(sub)[1]


def default_targets(knowledge: Knowledge, targets: Sequence[str] | None) -> np.ndarray:
    """The indices of the parameters to learn about: `targets` by name, else the
    least identified one and those within a factor 3 of its standard deviation (of
    theta after the prior; at most 3)."""
    if targets is not None:
        names = list(targets)
        unknown = [n for n in names if n not in knowledge.names]
        if unknown or not names:
            raise ValueError(
                f"`targets` must name fitted parameters {list(knowledge.names)}, got "
                f"{names}."
            )
        return np.array([knowledge.names.index(n) for n in names])
    sd = np.sqrt(np.diag(np.linalg.inv(knowledge.precision())))
    order = np.argsort(-sd)
    keep = [i for i in order if sd[i] >= sd[order[0]] / 3.0][:3]
    return np.array(sorted(keep))
