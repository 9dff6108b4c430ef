"""The fit report of `jaxcable fit --report DIR` and `jaxcable demo`: the summary
tables (per-test RMSE, parameters with standard errors, correlations, identifiability)
and `write_report`, which writes them with the plots."""

import csv
import io
import math
import pathlib
from collections.abc import Sequence

import numpy as np

from .._files import write_text_atomic
from .._fit import FitResult, responses
from .._io import TestData
from .._progress import AbstractProgressMeter, NoProgressMeter
from .plots import mask_of, plot_loops, plot_residuals, save_png


# The files of the fit report, in the order `write_report` returns them (so that a
# command can check them against its inputs before writing).
FIT_REPORT_FILES = ("fit_loops.png", "fit_residuals.png", "summary.md", "rmse.csv")
# Written besides them when the report is given a posterior.
POSTERIOR_FILE = "posterior.png"
# Draws shown in each panel of the pair plot (a random subset beyond).
_PAIR_POINTS = 1000


def _g(x: float, digits: int = 4) -> str:
    """`x` to `digits` significant digits; "inf" or "nan" when not finite."""
    return f"{x:.{digits}g}" if math.isfinite(x) else "inf" if x > 0 else "nan"


def summary_markdown(
    result: FitResult,
    tests: Sequence[TestData],
    *,
    title: str = "jaxcable fit",
    notes: Sequence[str] = (),
) -> str:
    """The fit as a markdown document: per-test RMSE, parameters with standard
    errors, the correlation matrix and the identifiability warnings.

    **Arguments:**

    - `result`: the [`jaxcable.FitResult`][] of `tests`.
    - `tests`: the tests, as fitted (their masks mark the fitted samples).
    - `title`: the document's title.
    - `notes`: lines listed under the title.

    **Returns:**

    The markdown text.
    """
    n = int(np.sum(result.num_samples))
    status = result.outcome_text("**not converged**")
    lines = [
        f"# {title}",
        "",
        f"Model `{type(result.model).__name__}`, {len(result.test_ids)} test(s), "
        f"{n} fitted samples, {len(result.names)} fitted parameters; SSR "
        f"{result.loss:.6g} {result.loss_unit}; {status}; best of "
        f"{len(result.start_losses)} "
        "start(s).",
        "",
    ]
    lines += [f"- {note}" for note in notes]
    if notes:
        lines.append("")
    lines += [
        "## Error per test",
        "",
        "RMSE of model minus measured value over the fitted samples, in the test's "
        "scored channel (elongation of a force-driven test, force of an "
        "elongation-driven one); % of the test's peak in that channel.",
        "",
        "| test | file | drive | samples | masked | RMSE | RMSE [%] |",
        "| --- | --- | --- | ---: | ---: | ---: | ---: |",
    ]
    for i, test in enumerate(tests):
        source = pathlib.Path(test.source).name if test.source else ""
        masked = int(np.sum(~mask_of(test)))
        value, unit = result.rmse(i)
        drive = result.drive(i).name
        lines.append(
            f"| {result.test_ids[i]} | {source} | {drive} | "
            f"{int(result.num_samples[i])} | {masked} | {value:.4g} {unit} | "
            f"{result.rmse_percent[i]:.2f} |"
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


def posterior_markdown(posterior) -> str:
    """The posterior summary as a markdown section: mean, sd, 2.5 / 50 / 97.5 %
    quantiles, R-hat and effective sample size of each parameter.

    **Arguments:**

    - `posterior`: a [`jaxcable.Posterior`][].

    **Returns:**

    The markdown text.
    """
    chains, draws = posterior.samples.shape[:2]
    lines = [
        "## Posterior",
        "",
        f"NUTS, {chains} chain(s) x {draws} draws, noise model `{posterior.noise}`; "
        f"{posterior.divergences} divergent transition(s); the pair plot is "
        f"`{POSTERIOR_FILE}` (see `jaxcable.sample_posterior`).",
        "",
        "| parameter | mean | sd | 2.5 % | 50 % | 97.5 % | R-hat | ESS | unit |",
        "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | --- |",
    ]
    for r in posterior.rows():
        cells = [
            _g(float("nan") if r[k] is None else r[k], d)
            for k, d in (("mean", 6), ("sd", 3), ("q2.5", 5), ("q50", 5))
            + (("q97.5", 5), ("rhat", 4), ("ess", 4))
        ]
        lines.append(f"| {r['name']} | " + " | ".join(cells) + f" | {r['unit']} |")
    return "\n".join(lines) + "\n"


def plot_pairs(path: pathlib.Path, posterior, seed: int = 0) -> None:
    """The pair plot of a posterior: each parameter's histogram on the diagonal,
    the draws of every pair below it (at most 1000 draws, chains coloured).

    **Arguments:**

    - `path`: the PNG file to write.
    - `posterior`: a [`jaxcable.Posterior`][].
    - `seed`: the seed of the subset of draws shown.
    """
    from matplotlib.figure import Figure

    samples = np.asarray(posterior.samples, float)
    chains, draws, p = samples.shape
    chain = np.repeat(np.arange(chains), draws)
    flat = samples.reshape(-1, p)
    keep = np.arange(flat.shape[0])
    if keep.size > _PAIR_POINTS:
        keep = np.random.default_rng(seed).choice(keep, _PAIR_POINTS, replace=False)
    size = max(1.6, min(2.4, 14.0 / p))
    fig = Figure(figsize=(size * p, size * p), layout="constrained")
    axes = fig.subplots(p, p, squeeze=False)
    for i in range(p):
        for j in range(p):
            ax = axes[i, j]
            if j > i:
                ax.set_visible(False)
                continue
            if i == j:
                ax.hist(flat[:, i], bins=30, color="0.4")
                ax.set_yticks([])
            else:
                ax.scatter(
                    flat[keep, j],
                    flat[keep, i],
                    s=3,
                    c=chain[keep],
                    cmap="tab10",
                    vmin=0,
                    vmax=9,
                    alpha=0.6,
                    linewidths=0,
                )
            if i == p - 1:
                ax.set_xlabel(f"{posterior.names[j]} [{posterior.units[j]}]")
            if j == 0 and i > 0:
                ax.set_ylabel(f"{posterior.names[i]} [{posterior.units[i]}]")
            ax.tick_params(labelsize=7)
    fig.suptitle("posterior draws (jaxcable.sample_posterior)")
    save_png(fig, path)


def write_report(
    out: pathlib.Path,
    result: FitResult,
    tests: Sequence[TestData],
    *,
    title: str = "jaxcable fit",
    notes: Sequence[str] = (),
    progress_meter: AbstractProgressMeter = NoProgressMeter(),
    posterior=None,
) -> list[pathlib.Path]:
    """Write the fit report to the folder `out` (created if needed).

    Files: `fit_loops.png` (force vs elongation, measured and model, one panel per
    test), `fit_residuals.png` (model minus measured elongation vs time),
    `summary.md` (the tables of [`summary_markdown`][]) and `rmse.csv` (per test:
    id, file, drive, fitted and masked samples, RMSE in mm or N and %); with a
    `posterior`, also `posterior.png` (its pair plot, [`plot_pairs`][]) and its
    summary in `summary.md` ([`posterior_markdown`][]).

    **Arguments:**

    - `out`: the folder.
    - `result`: the [`jaxcable.FitResult`][] of `tests`.
    - `tests`: the tests, as fitted.
    - `title`, `notes`: as in [`summary_markdown`][].
    - `progress_meter`: how to show progress (default none).
    - `posterior`: an optional [`jaxcable.Posterior`][] of the same fit.

    **Returns:**

    The paths written.
    """
    out.mkdir(parents=True, exist_ok=True)
    with progress_meter.bar("report", 3) as bar:
        model = responses(result, tests)
        bar.advance(note="simulated")
        loops, resid = (out / name for name in FIT_REPORT_FILES[:2])
        plot_loops(loops, result, tests, model)
        bar.advance(note=loops.name)
        plot_residuals(resid, result, tests, model)
        bar.advance(note=resid.name)
    summary = out / FIT_REPORT_FILES[2]
    text = summary_markdown(result, tests, title=title, notes=notes)
    if posterior is not None:
        text += "\n" + posterior_markdown(posterior)
    write_text_atomic(summary, text)
    table = out / FIT_REPORT_FILES[3]
    rows = io.StringIO()
    writer = csv.writer(rows, lineterminator="\n")
    writer.writerow(
        [
            "id",
            "file",
            "drive",
            "samples",
            "masked",
            "rmse_mm",
            "rmse_N",
            "rmse_percent",
        ]
    )
    for i, test in enumerate(tests):
        value, unit = result.rmse(i)
        writer.writerow(
            [
                result.test_ids[i],
                pathlib.Path(test.source).name if test.source else "",
                result.drive(i).name,
                int(result.num_samples[i]),
                int(np.sum(~mask_of(test))),
                f"{value:.6g}" if unit == "mm" else "",
                f"{value:.6g}" if unit == "N" else "",
                f"{result.rmse_percent[i]:.6g}",
            ]
        )
    write_text_atomic(table, rows.getvalue())
    if posterior is None:
        return [loops, resid, summary, table]
    pairs = out / POSTERIOR_FILE
    plot_pairs(pairs, posterior)
    return [loops, resid, summary, table, pairs]
