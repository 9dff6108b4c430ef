"""The plots of the reports: panel grids, a readable time axis, and per-test plots of
force vs elongation (measured and model) and of the residuals against time.

Figures use matplotlib's object-oriented API, not pyplot: no global backend or figure
state, and `Figure.savefig` renders PNG with Agg, into a temporary file renamed over
the target (`save_png`): a run cut short leaves the old plot, never half a PNG.
"""

import math
import os
from collections.abc import Sequence

import numpy as np

from .._files import atomic_path
from .._fit import FitResult
from .._io import TestData


def mask_of(test: TestData) -> np.ndarray:
    """`test.mask`, which a TestData always holds once built (all True unless set)."""
    assert test.mask is not None
    return test.mask


def save_png(fig, path: str | os.PathLike, dpi: int = 90) -> None:
    """Write the matplotlib figure `fig` to `path` as PNG, atomically."""
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=dpi)


def panels(n: int, width: float, height: float, title_height: float):
    """A figure of `n` panels, at most four a row, and its first `n` axes.

    **Arguments:**

    - `n`: the number of panels.
    - `width`, `height`: the size of one panel, inches.
    - `title_height`: the height added for the figure's title, inches.

    **Returns:**

    `(figure, axes)`, the panels beyond `n` of the last row hidden.
    """
    from matplotlib.figure import Figure

    cols = min(n, 4)
    rows = math.ceil(n / cols)
    fig = Figure(
        figsize=(width * cols, height * rows + title_height), layout="constrained"
    )
    axes = np.atleast_1d(fig.subplots(rows, cols, squeeze=False)).ravel()
    for ax in axes[n:]:
        ax.set_visible(False)
    return fig, axes[:n]


def time_axis(time: np.ndarray) -> tuple[np.ndarray, str, bool]:
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


def residual_axes(ax, title: str, label: str, log: bool, unit: str = "mm") -> None:
    """Label a panel of model minus measured value against time: the zero line,
    the title, the time axis (`label`, log scale when `log`), a grid, and the
    residual's `unit` (mm of elongation, N of force, or noise units)."""
    ax.axhline(0.0, color="0.3", lw=0.6)
    ax.set_title(title, fontsize=9)
    if log:
        ax.set_xscale("log")
    ax.set_xlabel(label)
    ax.set_ylabel(f"model - measured [{unit}]")
    ax.grid(alpha=0.3)


def plot_loops(
    path, result: FitResult, tests: Sequence[TestData], model: Sequence[np.ndarray]
) -> None:
    """Force vs elongation, measured and model, one panel per test (PNG). `model` is
    each test's scored channel ([`jaxcable.model_responses`][]): the model's
    elongation under the measured force, or its force at the measured elongation."""
    fig, axes = panels(len(tests), 3.6, 3.0, 0.6)
    for i, (ax, test, response) in enumerate(zip(axes, tests, model)):
        mask = mask_of(test)
        # A fitted test has an elongation (the fit's Problem requires it).
        assert test.elongation is not None
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
        drive = result.drive(i)
        # The model's value replaces the scored channel (in the plot's units).
        axes_of = {"elongation": e, "force": test.force}
        axes_of[drive.scored] = drive.report_scale * response
        ax.plot(
            axes_of["elongation"],
            axes_of["force"],
            color="tab:blue",
            lw=1.0,
            label="model",
        )
        value, unit = result.rmse(i)
        ax.set_title(
            f"{result.test_ids[i]}\nRMSE {value:.3g} {unit} "
            f"({result.rmse_percent[i]:.3g} %)",
            fontsize=9,
        )
        ax.set_xlabel("elongation [mm]")
        ax.set_ylabel("force [N]")
        ax.grid(alpha=0.3)
        if i == 0:
            ax.legend(fontsize=8)
    fig.suptitle(f"{type(result.model).__name__}: measured vs model")
    save_png(fig, path)


def plot_residuals(
    path, result: FitResult, tests: Sequence[TestData], model: Sequence[np.ndarray]
) -> None:
    """Model minus measured elongation (mm; force, N, for an elongation-driven test)
    vs time, one panel per test (PNG)."""
    fig, axes = panels(len(tests), 3.6, 2.6, 0.6)
    for i, (ax, test, response) in enumerate(zip(axes, tests, model)):
        t, label, log = time_axis(test.time)
        drive = result.drive(i)
        r = drive.report_scale * (response - drive.scored_of(test))
        unit = drive.report_unit
        mask = mask_of(test)
        ax.plot(t, np.where(mask, r, np.nan), color="tab:blue", lw=0.8)
        if not mask.all():
            ax.plot(
                t,
                np.where(mask, np.nan, r),
                color="tab:orange",
                lw=0.8,
                label="masked (not fitted)",
            )
            ax.legend(fontsize=8)
        residual_axes(ax, result.test_ids[i], label, log, unit)
    fig.suptitle(f"{type(result.model).__name__}: residuals")
    save_png(fig, path)
