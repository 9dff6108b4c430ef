"""The next test to run: `jaxcable.design_test`, a protocol chosen by gradient to
shrink what a fit or a posterior knows least."""

import dataclasses
import math
from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._cable import Cable
from .._drive import Protocol, simulate_force_history
from .._fit import FitResult, field_at
from .._models import AbstractCableModel
from .budget import TestBudget
from .priors import PRIOR_SCALE
from .result import Posterior


@dataclasses.dataclass(frozen=True)
class Knowledge:
    """What is known before the next test, on the scale theta (log x for a positive
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
        """Standard deviation of each theta (relative for a positive parameter)."""
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


def knowledge_of(source, noise_mm: float | None) -> Knowledge:
    """The `Knowledge` of a [`jaxcable.FitResult`][] or a [`jaxcable.Posterior`][];
    `noise_mm` overrides the noise read from the fit."""
    if isinstance(source, Posterior):
        fit = source.fit
        model = source.median_model()
        names = tuple(source.names)
        flat = source.flat
        values = np.median(flat, axis=0)
        log = values > 0
        theta = np.where(log, np.log(np.where(log, flat, 1.0)), flat)
        cov = np.atleast_2d(np.cov(theta, rowvar=False))
    elif isinstance(source, FitResult):
        fit = source
        model = source.model
        names = tuple(source.names)
        values = np.asarray(source.values, float)
        log = values > 0
        s = np.where(log, values, 1.0)
        cov = np.asarray(source.covariance, float) / np.outer(s, s)
    else:
        raise ValueError(
            "`fit_or_posterior` must be a jaxcable.FitResult or a jaxcable.Posterior, "
            f"got {type(source).__name__}."
        )
    if fit.per_test:
        raise ValueError(
            "`fit_or_posterior`: parameters fitted per test cannot be designed for "
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


def protocol_of(
    design: Design, layout: Layout, budget: TestBudget, breaking: float, ramp_time
):
    """The `(Protocol, speed m/s, levels N, holds s, rests s)` of a design; `ramp_time`
    (s, an estimate) is the time the ramps take, the holds and rests share the rest
    of the budget."""
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
    return protocol, speed, levels, holds, rests


def information(knowledge: Knowledge, cable: Cable, time, force):
    """The Fisher information about theta of one force-driven test with these
    sample times (s) and forces (N): J^T J / sigma^2, J the Jacobian of its
    elongations (m) through the simulation."""

    def elongation(theta):
        traj = simulate_force_history(
            knowledge.with_theta(theta), cable, time, force, throw=False
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
