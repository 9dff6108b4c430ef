"""The diagnosis report of `jaxcable diagnose --report DIR` and `jaxcable demo`: the
diagnosis as JSON and markdown, and plots of the residuals before and after the named
extension, of every candidate's held-out gain and of the residuals' structure."""

import dataclasses
import math
import pathlib

import numpy as np

from .._diagnose import MIN_GAIN_PCT, Diagnosis, heldout_start
from .._files import write_text_atomic
from .._fit import as_test_list
from .plots import panels, residual_axes, save_png, time_axis
from .rounds_plot import cause_fits, plot_rounds, residuals


# The files of the diagnosis report, in the order `write_diagnosis_report` returns
# them (so that a command can check them against its inputs before writing).
DIAGNOSIS_REPORT_FILES = (
    "diagnosis.json",
    "summary.md",
    "residuals.png",
    "candidates.png",
    "structure.png",
    "rounds.png",
)


def _plot_residuals(path, diagnosis: Diagnosis, tests: list) -> None:
    """Model minus measured value of each test's scored channel (elongation or force)
    vs time: the base, then after each cause kept (in the order found), one panel
    per test, the held-out part shaded (PNG)."""
    base = residuals(diagnosis.base_fit, diagnosis, tests)
    after = [
        (c.id, residuals(c.fit, diagnosis, tests, c.covariate or r.covariate))
        for r, c in cause_fits(diagnosis)
    ]
    fig, axes = panels(len(tests), 3.8, 2.7, 0.8)
    for i, (ax, t) in enumerate(zip(axes, tests)):
        x, label, log = time_axis(np.asarray(t.time, float))
        ax.plot(x, base[i], color="0.5", lw=0.8, label="base")
        for k, (name, values) in enumerate(after):
            ax.plot(x, values[i], color=f"C{k}", lw=0.8, label=f"+ {name}")
        if diagnosis.holdout is not None:
            cut = heldout_start(len(t.time), diagnosis.holdout)
            if cut < len(t.time):
                ax.axvspan(x[cut], x[-1], color="tab:orange", alpha=0.12, lw=0)
        residual_axes(ax, diagnosis.test_ids[i], label, log, diagnosis.unit)
        if i == 0:
            ax.legend(fontsize=8)
    fig.suptitle(
        "Residuals before/after (held-out part shaded): "
        + (", ".join(diagnosis.causes) or diagnosis.named_cause)
    )
    save_png(fig, path)


def _plot_candidates(path, diagnosis: Diagnosis) -> None:
    """The held-out gain of every applicable candidate against the threshold (PNG)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7, 3.6), layout="constrained")
    ax = fig.subplots()
    shown = [c for c in diagnosis.candidates if c.applicable]
    # A diverging candidate is drawn at -100 %, hatched: its gain measures nothing.
    gains = [
        -100.0 if c.diverging else c.gain_pct if math.isfinite(c.gain_pct) else 0.0
        for c in shown
    ]
    colours = ["tab:blue" if c.id in diagnosis.causes else "0.6" for c in shown]
    bars = ax.barh([c.id for c in shown], gains, color=colours)
    for bar, c in zip(bars, shown):
        if c.diverging:
            bar.set_hatch("//")
            bar.set_facecolor("white")
            bar.set_edgecolor("tab:red")
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
        "unit | significant | explained % of the excess (RMSE) | (squares) |",
        "| --- | ---: | ---: | ---: | ---: | ---: | --- | --- | ---: | ---: |",
    ]
    for c in diagnosis.candidates:
        if not c.applicable:
            table.append(f"| {c.id} | n/a | | | | | | {c.note} | | |")
            continue
        if c.diverging:
            table.append(
                f"| {c.id} | {c.heldout_rmse:.4g} | | | | | | diverges: "
                f"{c.diverging} | | |"
            )
            continue
        table.append(
            f"| {c.id} | {c.heldout_rmse:.4g} | {c.gain_pct:.1f} | "
            f"{c.delta_bic:.1f} | {c.size:.4g} | {c.size_stderr:.2g} | "
            f"{c.size_unit} | {'yes' if c.significant else 'no'} | "
            f"{c.explained_rmse_pct:.0f} | {c.explained_pct:.0f} |"
        )
    return table


def _notes(diagnosis: Diagnosis) -> list[str]:
    """What the numbers are measured against: the noise and where it comes from,
    and the reference of every fitted time shift (its base is the material
    there)."""
    u = diagnosis.unit
    noise = (
        f"{diagnosis.noise * 1e3:.3g} um" if u == "mm" else f"{diagnosis.noise:.3g} {u}"
    )
    lines = [f"- Noise: {noise}, from the {diagnosis.noise_source}."]
    named = set(diagnosis.causes) | {diagnosis.named_cause}
    for c in diagnosis.candidates:
        ref = c.reference if c.applicable else {}
        if not ref:
            continue
        whose = "the named model's base" if c.id in named else "its base"
        if ref["field"] == "T_ref":
            at = f"{ref['celsius']:.1f} °C"
            why = c.note.split(":")[0] if c.note else f"reference {at}"
        else:
            at = f"{ref['value']:.4g}"
            why = f"reference {at} (the median of {c.covariate!r})"
        lines.append(f"- {c.id}: {why}: {whose} is the material at {at}.")
    return lines


def write_diagnosis_report(out, diagnosis: Diagnosis, tests) -> list[pathlib.Path]:
    """Write the diagnosis report to the folder `out` (created if needed).

    Files: `diagnosis.json` ([`jaxcable.Diagnosis.to_json`][]), `summary.md` (the
    summary, the noise and where it comes from, each time shift's reference),
    `residuals.png` (model minus measured value of each test's scored channel vs
    time, in the diagnosis's unit, base and the named extension, before/after,
    held-out part shaded), `candidates.png` (held-out gain
    of every candidate against the threshold), `structure.png` (correlation of the
    base residuals with each test condition) and `rounds.png` (the held-out RMSE
    round by round; a discovered term beside the residual it removes).

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
    json_path, summary, residuals_png, candidates_png, structure_png, rounds_png = (
        out / name for name in DIAGNOSIS_REPORT_FILES
    )
    _plot_residuals(residuals_png, diagnosis, whole)
    _plot_candidates(candidates_png, diagnosis)
    _plot_structure(structure_png, diagnosis)
    plot_rounds(rounds_png, diagnosis, whole)

    diagnosis.to_json(json_path)
    write_text_atomic(
        summary,
        "# jaxcable diagnose\n\n```\n"
        + diagnosis.summary()
        + "\n```\n\n"
        + "\n".join(_notes(diagnosis))
        + "\n\n"
        + "\n".join(_candidate_table(diagnosis))
        + "\n\n![residuals](residuals.png)\n![candidates](candidates.png)\n"
        + "![structure](structure.png)\n![rounds](rounds.png)\n",
    )
    return [
        json_path,
        summary,
        residuals_png,
        candidates_png,
        structure_png,
        rounds_png,
    ]
