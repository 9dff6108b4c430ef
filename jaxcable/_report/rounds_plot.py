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
from .plots import residual_axes, save_png, time_axis


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
    unit (mm of elongation, N of force, or noise units); `tests` are the first of
    the diagnosis's."""
    drives = (diagnosis.drives or (FORCE_DRIVEN,) * len(tests))[: len(tests)]
    scales = (diagnosis.scales or (1.0,) * len(tests))[: len(tests)]
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
        final = diagnosis.extended_fit().model
        covariate = next((x.covariate for _, x in causes if x.covariate), None)
        with_term = residuals(final, diagnosis, shown, covariate)
        without = residuals(_without_term(final), diagnosis, shown, covariate)
        for i, t in enumerate(shown):
            a = fig.add_subplot(grid[1, i])
            x, label, log = time_axis(np.asarray(t.time, float))
            # The residual the term removes: measured minus the final model with the
            # term switched off (the other parameters as fitted).
            a.plot(
                x, -without[i], color="0.6", lw=0.8, label="measured - model without it"
            )
            a.plot(
                x,
                with_term[i] - without[i],
                color="tab:green",
                lw=1.0,
                label="discovered term",
            )
            residual_axes(a, diagnosis.test_ids[i], label, log, diagnosis.unit)
            a.set_ylabel(f"elongation [{diagnosis.unit}]")
            if i == 0:
                a.legend(fontsize=7)
    fig.suptitle("Held-out RMSE round by round; the discovered state's strain")
    save_png(fig, path)


def _layer(candidate):
    """The outermost layer of a candidate's fitted model (its own effect)."""
    return candidate.fit.model if candidate.fit is not None else None


def _without_term(model):
    """`model` with every theta of the discovered term in it (at any depth) 0."""
    path, layer = [], model
    while not isinstance(layer, DiscoveredTerm):
        path.append("base")
        layer = layer.base
    names = [n for n in layer.used_fields() if n.startswith("theta")]

    def where(m):
        for step in path:
            m = getattr(m, step)
        return [getattr(m, n) for n in names]

    return eqx.tree_at(where, model, [jnp.zeros_like(x) for x in where(model)])
