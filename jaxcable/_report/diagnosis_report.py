"""The diagnosis report of `jaxcable diagnose --report DIR` and `jaxcable demo`: the
diagnosis as JSON and markdown, and plots of the residuals before and after the named
extension, of every candidate's held-out gain and of the residuals' structure."""

import dataclasses
import math
import pathlib

import numpy as np

from .._diagnose import MIN_GAIN_PCT, Diagnosis, heldout_start, scored_residuals
from .._drive import FORCE_DRIVEN
from .._files import write_text_atomic
from .._fit import as_test_list
from .plots import panels, residual_axes, save_png, time_axis


# The files of the diagnosis report, in the order `write_diagnosis_report` returns
# them (so that a command can check them against its inputs before writing).
DIAGNOSIS_REPORT_FILES = (
    "diagnosis.json",
    "summary.md",
    "residuals.png",
    "candidates.png",
    "structure.png",
)


def _residuals(result, diagnosis: Diagnosis, tests: list) -> list[np.ndarray]:
    """Model minus measured value of every test's scored channel, in the diagnosis's
    unit (mm of elongation, N of force, or noise units)."""
    drives = diagnosis.drives or (FORCE_DRIVEN,) * len(tests)
    scales = diagnosis.scales or (1.0,) * len(tests)
    factor = 1e3 if diagnosis.unit == "mm" else 1.0
    return [factor * r for r in scored_residuals(result, tests, drives, scales)]


def _plot_residuals(path, diagnosis: Diagnosis, tests: list) -> None:
    """Model minus measured value of each test's scored channel (elongation or force)
    vs time, base and the named extension, one panel per test, the held-out part
    shaded (PNG)."""
    base = _residuals(diagnosis.base_fit, diagnosis, tests)
    named = (
        # Only a named cause has a fit to show: not "none" nor "unexplained".
        diagnosis.candidate(diagnosis.named_cause)
        if diagnosis.verdict == "named"
        else None
    )
    extended = _residuals(named.fit, diagnosis, tests) if named is not None else None
    fig, axes = panels(len(tests), 3.8, 2.7, 0.8)
    for i, (ax, t) in enumerate(zip(axes, tests)):
        x, label, log = time_axis(np.asarray(t.time, float))
        ax.plot(x, base[i], color="0.5", lw=0.8, label="base")
        if extended is not None:
            ax.plot(
                x,
                extended[i],
                color="tab:blue",
                lw=0.8,
                label=f"+ {diagnosis.named_cause}",
            )
        if diagnosis.holdout is not None:
            cut = heldout_start(len(t.time), diagnosis.holdout)
            if cut < len(t.time):
                ax.axvspan(x[cut], x[-1], color="tab:orange", alpha=0.12, lw=0)
        residual_axes(ax, diagnosis.test_ids[i], label, log, diagnosis.unit)
        if i == 0:
            ax.legend(fontsize=8)
    fig.suptitle(
        f"Residuals before/after (held-out part shaded): named cause "
        f"{diagnosis.named_cause}"
    )
    save_png(fig, path)


def _plot_candidates(path, diagnosis: Diagnosis) -> None:
    """The held-out gain of every applicable candidate against the threshold (PNG)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7, 3.6), layout="constrained")
    ax = fig.subplots()
    shown = [c for c in diagnosis.candidates if c.applicable]
    gains = [c.gain_pct if math.isfinite(c.gain_pct) else 0.0 for c in shown]
    colours = ["tab:blue" if c.id == diagnosis.named_cause else "0.6" for c in shown]
    ax.barh([c.id for c in shown], gains, color=colours)
    ax.axvline(MIN_GAIN_PCT, color="tab:red", lw=0.8, ls="--", label="threshold")
    ax.set_xlabel("held-out RMSE gain over the base [%]")
    ax.set_title(
        f"base held-out RMSE {diagnosis.base_heldout_rmse:.3g} {diagnosis.unit}; "
        "named: "
        f"{diagnosis.named_cause}",
        fontsize=10,
    )
    ax.invert_yaxis()
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3, axis="x")
    save_png(fig, path)


def _plot_structure(path, diagnosis: Diagnosis) -> None:
    """The correlation of the base residuals with each test condition (PNG)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7, 3.6), layout="constrained")
    ax = fig.subplots()
    corr = {
        k: v for k, v in diagnosis.structure["correlation"].items() if v is not None
    }
    ax.barh(list(corr), list(corr.values()), color="tab:purple")
    ax.axvline(0, color="0.3", lw=0.5)
    ax.set_xlim(-1, 1)
    ax.set_xlabel("correlation of the base residual with the condition")
    ax.set_title(
        f"lag-1 autocorrelation {diagnosis.structure['autocorrelation']:.2f} "
        f"(white noise: < {diagnosis.structure['white_noise_band']:.2g})",
        fontsize=10,
    )
    ax.invert_yaxis()
    ax.grid(alpha=0.3, axis="x")
    save_png(fig, path)


def _candidate_table(diagnosis: Diagnosis) -> list[str]:
    """Every candidate's scores as the lines of a markdown table."""
    table = [
        f"| candidate | held-out RMSE {diagnosis.unit} | gain % | ΔBIC | size | ± | "
        "unit | significant | explained % of the excess |",
        "| --- | ---: | ---: | ---: | ---: | ---: | --- | --- | ---: |",
    ]
    for c in diagnosis.candidates:
        if not c.applicable:
            table.append(f"| {c.id} | n/a | | | | | | {c.note} | |")
            continue
        table.append(
            f"| {c.id} | {c.heldout_rmse:.4g} | {c.gain_pct:.1f} | "
            f"{c.delta_bic:.1f} | {c.size:.4g} | {c.size_stderr:.2g} | "
            f"{c.size_unit} | {'yes' if c.significant else 'no'} | "
            f"{c.explained_pct:.0f} |"
        )
    return table


def write_diagnosis_report(out, diagnosis: Diagnosis, tests) -> list[pathlib.Path]:
    """Write the diagnosis report to the folder `out` (created if needed).

    Files: `diagnosis.json` ([`jaxcable.Diagnosis.to_json`][]), `summary.md`,
    `residuals.png` (model minus measured value of each test's scored channel vs
    time, in the diagnosis's unit, base and the named extension, before/after,
    held-out part shaded), `candidates.png` (held-out gain
    of every candidate against the threshold) and `structure.png` (correlation of the
    base residuals with each test condition).

    **Arguments:**

    - `out`: the folder.
    - `diagnosis`: the [`jaxcable.Diagnosis`][] of `tests`.
    - `tests`: the tests, as diagnosed.

    **Returns:**

    The paths written.
    """
    out = pathlib.Path(out)
    out.mkdir(parents=True, exist_ok=True)
    whole = [dataclasses.replace(t, mask=None) for t in as_test_list(tests)]
    json_path, summary, residuals_png, candidates_png, structure_png = (
        out / name for name in DIAGNOSIS_REPORT_FILES
    )
    _plot_residuals(residuals_png, diagnosis, whole)
    _plot_candidates(candidates_png, diagnosis)
    _plot_structure(structure_png, diagnosis)

    diagnosis.to_json(json_path)
    write_text_atomic(
        summary,
        "# jaxcable diagnose\n\n```\n"
        + diagnosis.summary()
        + "\n```\n\n"
        + "\n".join(_candidate_table(diagnosis))
        + "\n\n![residuals](residuals.png)\n![candidates](candidates.png)\n"
        + "![structure](structure.png)\n",
    )
    return [json_path, summary, residuals_png, candidates_png, structure_png]
