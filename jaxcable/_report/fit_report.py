"""The fit report of `jaxcable fit --report DIR` and `jaxcable demo`: plots of measured
vs model elongation, residuals, and summary tables; and the command line's progress bar.
"""

import csv
import dataclasses
import math
import pathlib
from collections.abc import Sequence

import equinox as eqx
import numpy as np

from .._fit import FitResult, pad_tests, residuals
from .._io import TestData
from .._models import AbstractCableModel
from .._progress import Progress as Progress


# ----------------------------------------------------------------------------------
# Model curves

# Compiled once per shape: run eagerly, the vmapped scan dispatched op by op.
_residuals = eqx.filter_jit(residuals)


def model_elongations(
    result: FitResult | AbstractCableModel,
    tests: Sequence[TestData],
) -> list[np.ndarray]:
    """The fitted model's elongation (m) at every sample of every test, masked samples
    included, in one vmapped simulation.

    **Arguments:**

    - `result`: a [`jaxcable.FitResult`][] of these `tests` (per-test parameters are
        matched by position), or a model.
    - `tests`: the tests, as fitted.

    **Returns:**

    One array per test, m; NaN throughout a test whose simulation failed.
    """
    # Every sample weighted, so that the residual (model - measured) is returned at
    # masked samples too; their measured elongation only needs to be finite.
    unmasked = [
        dataclasses.replace(
            t,
            mask=None,
            elongation=np.nan_to_num(np.asarray(t.elongation, float)),
        )
        for t in tests
    ]
    padded = pad_tests(unmasked)
    model = result.model if isinstance(result, FitResult) else result
    params, static = eqx.partition(model, eqx.is_inexact_array)
    r = np.asarray(_residuals(params, static, padded))
    return [r[i, : t.num_samples] + t.elongation for i, t in enumerate(unmasked)]


# ----------------------------------------------------------------------------------
# Plots


def _grid(n: int) -> tuple[int, int]:
    cols = min(n, 4)
    return math.ceil(n / cols), cols


def _time_axis(time: np.ndarray) -> tuple[np.ndarray, str, bool]:
    """(time in a readable unit, axis label, log scale?). A history whose span is
    far longer than its samples suggest (a long rest sampled sparsely after densely
    sampled cycles) is shown on a log axis of the time since its start, so that the
    cycles are not squeezed into a spike."""
    t = time - time[0]
    span = float(t[-1]) if t.size else 0.0
    dt = np.diff(t)
    log = dt.size > 2 and span > 20 * dt.size * float(np.median(dt))
    if span > 3 * 3600:
        scale, unit = 3600, "h"
    elif span > 3 * 60:
        scale, unit = 60, "min"
    else:
        scale, unit = 1, "s"
    if log:
        # Time 0 has no place on a log axis; the first sample is not drawn.
        return np.where(t > 0, t, np.nan) / scale, f"time since start [{unit}]", True
    return t / scale, f"time [{unit}]", False


def plot_loops(
    path, result: FitResult, tests: Sequence[TestData], model: Sequence[np.ndarray]
) -> None:
    """Force vs elongation, measured and model, one panel per test (PNG)."""
    # The object-oriented API, not pyplot: no global backend or figure state.
    from matplotlib.figure import Figure

    rows, cols = _grid(len(tests))
    fig = Figure(figsize=(3.6 * cols, 3.0 * rows + 0.6), layout="constrained")
    axes = np.atleast_1d(fig.subplots(rows, cols, squeeze=False)).ravel()
    for i, (test, e_model) in enumerate(zip(tests, model)):
        ax = axes[i]
        mask = test.mask
        e = 1e3 * test.elongation
        ax.plot(e, test.force, color="0.55", lw=0.8, label="measured")
        if not mask.all():
            ax.plot(
                np.where(mask, np.nan, e),
                test.force,
                color="tab:orange",
                lw=0.8,
                label="masked (not fitted)",
            )
        ax.plot(1e3 * e_model, test.force, color="tab:blue", lw=1.0, label="model")
        ax.set_title(
            f"{result.test_ids[i]}\nRMSE {result.rmse_mm[i]:.3g} mm "
            f"({result.rmse_percent[i]:.3g} %)",
            fontsize=9,
        )
        ax.set_xlabel("elongation [mm]")
        ax.set_ylabel("force [N]")
        ax.grid(alpha=0.3)
        if i == 0:
            ax.legend(fontsize=8)
    for ax in axes[len(tests) :]:
        ax.set_visible(False)
    fig.suptitle(f"{type(result.model).__name__}: measured vs model")
    fig.savefig(path, dpi=90)


def plot_residuals(
    path, result: FitResult, tests: Sequence[TestData], model: Sequence[np.ndarray]
) -> None:
    """Model minus measured elongation vs time, one panel per test (PNG)."""
    from matplotlib.figure import Figure

    rows, cols = _grid(len(tests))
    fig = Figure(figsize=(3.6 * cols, 2.6 * rows + 0.6), layout="constrained")
    axes = np.atleast_1d(fig.subplots(rows, cols, squeeze=False)).ravel()
    for i, (test, e_model) in enumerate(zip(tests, model)):
        ax = axes[i]
        t, label, log = _time_axis(test.time)
        r = 1e3 * (e_model - test.elongation)
        ax.plot(t, np.where(test.mask, r, np.nan), color="tab:blue", lw=0.8)
        if not test.mask.all():
            ax.plot(
                t,
                np.where(test.mask, np.nan, r),
                color="tab:orange",
                lw=0.8,
                label="masked (not fitted)",
            )
            ax.legend(fontsize=8)
        ax.axhline(0.0, color="0.3", lw=0.6)
        ax.set_title(result.test_ids[i], fontsize=9)
        if log:
            ax.set_xscale("log")
        ax.set_xlabel(label)
        ax.set_ylabel("model - measured [mm]")
        ax.grid(alpha=0.3)
    for ax in axes[len(tests) :]:
        ax.set_visible(False)
    fig.suptitle(f"{type(result.model).__name__}: residuals")
    fig.savefig(path, dpi=90)


# ----------------------------------------------------------------------------------
# Tables


def _g(x: float, digits: int = 4) -> str:
    return f"{x:.{digits}g}" if math.isfinite(x) else "inf" if x > 0 else "nan"


def summary_markdown(
    result: FitResult,
    tests: Sequence[TestData],
    *,
    title: str = "jaxcable fit",
    notes: Sequence[str] = (),
) -> str:
    """The fit as a markdown document: per-test RMSE, parameters with standard
    errors, the correlation matrix and the identifiability warnings."""
    n = int(np.sum(result.num_samples))
    status = (
        f"converged in {result.num_steps} steps"
        if result.converged
        else f"**not converged** ({result.message})"
    )
    lines = [
        f"# {title}",
        "",
        f"Model `{type(result.model).__name__}`, {len(result.test_ids)} test(s), "
        f"{n} fitted samples, {len(result.names)} fitted parameters; SSR "
        f"{result.loss:.6g} m²; {status}; best of {len(result.start_losses)} "
        "start(s).",
        "",
    ]
    lines += [f"- {note}" for note in notes]
    if notes:
        lines.append("")
    lines += [
        "## Error per test",
        "",
        "RMSE of model minus measured elongation over the fitted samples; % of the "
        "test's peak elongation.",
        "",
        "| test | file | samples | masked | RMSE [mm] | RMSE [%] |",
        "| --- | --- | ---: | ---: | ---: | ---: |",
    ]
    for i, test in enumerate(tests):
        source = pathlib.Path(test.source).name if test.source else ""
        masked = int(np.sum(~test.mask))
        lines.append(
            f"| {result.test_ids[i]} | {source} | {int(result.num_samples[i])} | "
            f"{masked} | {result.rmse_mm[i]:.4f} | {result.rmse_percent[i]:.2f} |"
        )
    lines += [
        "",
        "## Parameters",
        "",
        "Standard errors from the Jacobian at the optimum (see `jaxcable.fit`).",
        "",
        "| parameter | value | ± std err | rel. [%] | unit |",
        "| --- | ---: | ---: | ---: | --- |",
    ]
    for name, v, s, r, u in zip(
        result.names,
        result.values,
        result.stderr,
        result.relative_error,
        result.units,
    ):
        lines.append(f"| {name} | {_g(v, 6)} | {_g(s, 3)} | {_g(100 * r, 3)} | {u} |")
    if len(result.names) > 1:
        lines += [
            "",
            "## Correlation",
            "",
            "| | " + " | ".join(result.names) + " |",
            "| --- |" + " ---: |" * len(result.names),
        ]
        for name, row in zip(result.names, result.correlation):
            lines.append(f"| {name} | " + " | ".join(f"{c:+.3f}" for c in row) + " |")
    lines += ["", "## Identifiability", ""]
    if result.warnings:
        lines += [f"- {w}" for w in result.warnings]
    else:
        lines.append("No parameter flagged.")
    return "\n".join(lines) + "\n"


def write_report(
    out: pathlib.Path,
    result: FitResult,
    tests: Sequence[TestData],
    *,
    title: str = "jaxcable fit",
    notes: Sequence[str] = (),
    progress: bool = False,
) -> list[pathlib.Path]:
    """Write the fit report to the folder `out` (created if needed).

    Files: `fit_loops.png` (force vs elongation, measured and model, one panel per
    test), `fit_residuals.png` (model minus measured elongation vs time),
    `summary.md` (the tables of [`summary_markdown`][]) and `rmse.csv` (per test:
    id, file, fitted and masked samples, RMSE in mm and %).

    **Returns:**

    The paths written.
    """
    out.mkdir(parents=True, exist_ok=True)
    with Progress("report", 3, enabled=progress) as bar:
        model = model_elongations(result, tests)
        bar.advance(note="simulated")
        loops, resid = out / "fit_loops.png", out / "fit_residuals.png"
        plot_loops(loops, result, tests, model)
        bar.advance(note=loops.name)
        plot_residuals(resid, result, tests, model)
        bar.advance(note=resid.name)
    summary = out / "summary.md"
    summary.write_text(
        summary_markdown(result, tests, title=title, notes=notes), encoding="utf-8"
    )
    table = out / "rmse.csv"
    with open(table, "w", newline="", encoding="utf-8") as f:
        writer = csv.writer(f, lineterminator="\n")
        writer.writerow(["id", "file", "samples", "masked", "rmse_mm", "rmse_percent"])
        for i, test in enumerate(tests):
            writer.writerow(
                [
                    result.test_ids[i],
                    pathlib.Path(test.source).name if test.source else "",
                    int(result.num_samples[i]),
                    int(np.sum(~test.mask)),
                    f"{result.rmse_mm[i]:.6g}",
                    f"{result.rmse_percent[i]:.6g}",
                ]
            )
    return [loops, resid, summary, table]
