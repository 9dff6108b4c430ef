"""The rounds of a diagnosis in pictures: the held-out RMSE round by round against the
noise, and each discovered term beside the residual it removes (its state's strain
against time, the round's base residual under it)."""

import math

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._diagnose import MAX_FLOOR_RATIO, Diagnosis, scored_residuals
from .._drive import FORCE_DRIVEN
from .._models import DiscoveredTerm
from .plots import save_png, time_axis


def rounds_of(diagnosis: Diagnosis) -> tuple[Diagnosis, ...]:
    """The rounds of `diagnosis` (itself when it had one)."""
    return diagnosis.rounds or (diagnosis,)


def cause_fits(diagnosis: Diagnosis):
    """`(round, candidate)` of every cause kept, in the order found."""
    out = []
    for r in rounds_of(diagnosis):
        if r.verdict == "named" and r.accepted and r.named_cause in diagnosis.causes:
            out.append((r, r.candidate(r.named_cause)))
    return out


def residuals(result, diagnosis: Diagnosis, tests, covariate=None) -> list:
    """Model minus measured value of every test's scored channel, in the diagnosis's
    unit (mm of elongation, N of force, or noise units)."""
    drives = diagnosis.drives or (FORCE_DRIVEN,) * len(tests)
    scales = diagnosis.scales or (1.0,) * len(tests)
    factor = 1e3 if diagnosis.unit == "mm" else 1.0
    values = scored_residuals(result, tests, drives, scales, covariate=covariate)
    return [factor * r for r in values]


def plot_rounds(path, diagnosis: Diagnosis, tests: list) -> None:
    """`rounds.png`: the held-out RMSE after each round against the noise (and
    `MAX_FLOOR_RATIO` x it); below, for a discovered term among the causes, its
    elongation on each test (the term's state times its coefficient) over the
    residual of its round's base, which it removes."""
    from matplotlib.figure import Figure

    causes = cause_fits(diagnosis)
    discovered = [(r, c) for r, c in causes if isinstance(_layer(c), DiscoveredTerm)]
    shown = tests[:4] if discovered else []
    fig = Figure(figsize=(3.6 * max(len(shown), 2), 3.2 * (1 + bool(shown)) + 0.4))
    fig.set_layout_engine("constrained")
    grid = fig.add_gridspec(1 + bool(shown), max(len(shown), 1))
    ax = fig.add_subplot(grid[0, :])
    steps = [diagnosis.base_heldout_rmse] + [c.heldout_rmse for _, c in causes]
    labels = ["base"] + [f"+ {c.id}" for _, c in causes]
    if causes and math.isfinite(diagnosis.final_heldout_rmse):
        steps[-1] = diagnosis.final_heldout_rmse
    ax.plot(range(len(steps)), steps, "o-", color="tab:blue")
    ax.axhline(diagnosis.noise, color="0.4", lw=0.8, ls=":", label="noise")
    ax.axhline(
        MAX_FLOOR_RATIO * diagnosis.noise,
        color="tab:red",
        lw=0.8,
        ls="--",
        label=f"{MAX_FLOOR_RATIO:g} x noise",
    )
    ax.set_xticks(range(len(steps)), labels, fontsize=8)
    ax.set_yscale("log")
    ax.set_ylabel(f"held-out RMSE [{diagnosis.unit}]")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    ax.set_title(
        "causes: " + (", ".join(diagnosis.causes) or diagnosis.named_cause),
        fontsize=10,
    )
    if shown:
        r, c = discovered[0]
        term = _layer(c)
        off = _without_term(c.fit.model, term)
        with_term = residuals(c.fit.model, diagnosis, shown, c.covariate)
        without = residuals(off, diagnosis, shown, c.covariate)
        before = residuals(r.base_fit, diagnosis, shown, r.covariate)
        for i, t in enumerate(shown):
            a = fig.add_subplot(grid[1, i])
            x, label, log = time_axis(np.asarray(t.time, float))
            a.plot(x, -before[i], color="0.6", lw=0.8, label="measured - base")
            a.plot(
                x,
                with_term[i] - without[i],
                color="tab:green",
                lw=1.0,
                label="discovered term",
            )
            if log:
                a.set_xscale("symlog")
            a.set_xlabel(label)
            a.set_title(diagnosis.test_ids[i], fontsize=8)
            if i == 0:
                a.set_ylabel(diagnosis.unit)
                a.legend(fontsize=7)
    fig.suptitle("Held-out RMSE round by round; the discovered state's strain")
    save_png(fig, path)


def _layer(candidate):
    """The outermost layer of a candidate's fitted model (its own effect)."""
    return candidate.fit.model if candidate.fit is not None else None


def _without_term(model: DiscoveredTerm, term: DiscoveredTerm):
    """`model` (the discovered term around its base) with every theta 0."""
    names = [n for n in term.used_fields() if n.startswith("theta")]
    return eqx.tree_at(
        lambda m: [getattr(m, n) for n in names],
        model,
        [jnp.zeros_like(getattr(model, n)) for n in names],
    )
