"""`jaxcable fit`: a model fitted to measured tests, written as PARAMS.json, with a
summary on stdout and optionally a report folder; with `--each`, every file fitted
on its own (one `jaxcable.fit_each`), one PARAMS.json per file and a summary table."""

import argparse
import contextlib
import csv
import io
import json
import os
import pathlib
import warnings

import jax
import numpy as np

from .._cache import exported_programs_dir
from .._files import write_text_atomic
from .._fit import (
    FitResult,
    IdentifiabilityWarning,
    cached_fit_kernels,
    fit,
    fit_each,
    resolve_drives,
)
from .._models import AbstractCableModel
from .._progress import AbstractProgressMeter
from .._report import FIT_REPORT_FILES, write_report
from .._uncertainty import Posterior, sample_posterior
from .common import CliError, make_folder, progress_meter, require_folder_of
from .data import data_options, describe_tests, read_measured
from .limits import limits_note, with_strain_from_load
from .models import data_start, names_option, resolve_model
from .outputs import refuse_inputs, say_replacing, write_errors


def input_files(args) -> list[tuple[str, str]]:
    """(what, path) of the files a fit or diagnosis reads: its data and `--params`."""
    inputs = [("DATA.csv", str(path)) for path in args.data]
    if args.params:
        inputs.append(("--params", args.params))
    return inputs


def report_files(folder, names) -> list[tuple[str, pathlib.Path]]:
    """(option, path) of the files of a `--report` folder; fails when the folder is
    an existing file."""
    if os.path.exists(folder) and not os.path.isdir(folder):
        raise CliError(f"--report {folder}: is a file, not a folder.")
    return [("--report", pathlib.Path(folder) / name) for name in names]


def named_files(tests) -> str:
    """The files of `tests`, for an error about all of them."""
    names = [str(t.source) for t in tests if t.source]
    if len(names) > 3:
        return f"{names[0]} and {len(names) - 1} other files"
    return ", ".join(names) or "the data"


def exported_kernels() -> contextlib.AbstractContextManager:
    """Within it, fits run their kernel as a program exported to the per-user cache
    (traced and lowered once, not once per process); a no-op when the cache is off."""
    directory = exported_programs_dir()
    if directory is None:
        return contextlib.nullcontext()
    return cached_fit_kernels(directory)


def run_fit(
    model: AbstractCableModel,
    name: str,
    tests,
    *,
    fit_names: list[str],
    per_test: list[str],
    args,
    meter: AbstractProgressMeter,
    drive="auto",
) -> FitResult:
    """`jaxcable.fit` with the command line's solver options.

    **Arguments:**

    - `model`: the model and its start values.
    - `name`: its command-line name, for the errors.
    - `tests`: the measured tests.
    - `fit_names`, `per_test`: the parameters to fit, and those fitted per test
        (empty: the defaults of `jaxcable.fit`).
    - `args`: the parsed command line (`starts`, `max_steps`, `seed`).
    - `meter`: the progress meter.
    - `drive`: the drive of every test (see `jaxcable.fit`).

    **Returns:**

    The fit, converged or not; identifiability warnings are in its `warnings` (and
    printed with its summary), not issued.
    """
    n = sum(int(np.sum(t.mask)) for t in tests)
    label = f"fitting {name} to {len(tests)} test(s), {n} samples"
    with (
        meter.bar(label),
        warnings.catch_warnings(),
        exported_kernels(),
    ):
        warnings.simplefilter("ignore", IdentifiabilityWarning)
        try:
            return fit(
                model,
                tests,
                fit=fit_names or None,
                per_test=per_test or None,
                multistart=args.starts,
                max_steps=args.max_steps,
                key=jax.random.key(args.seed),
                throw=False,
                drive=drive,
            )
        except ValueError as e:
            raise CliError(
                f"{named_files(tests)}: cannot fit model '{name}': {e}"
            ) from None


def test_drives(tests, drive: str):
    """Each test's drive with its reason (`--drive`, the file's `control` line, or
    detected from the data)."""
    try:
        return resolve_drives(tests, drive)
    except ValueError as e:
        raise CliError(f"--drive: {e}") from None


def read_described(args, meter: AbstractProgressMeter, log=None):
    """(tests, drives with their reasons) of the data files, read as every command
    reads them, after printing one line per file (and what limits the material) on
    `log` (default stdout); fails naming file, line and column where a
    force-driven test's force is negative beyond its noise."""
    measured = read_measured(args.data, data_options(args), args.every, meter)
    tests = [test for test, _ in measured]
    drives = test_drives(tests, args.drive)
    for (_, error), drive in zip(measured, drives):
        if error is not None and drive.control == "force":
            raise CliError(error)
    print(f"read {len(tests)} file(s):", file=log)
    print("\n".join(describe_tests(tests, args.every, drives)), file=log)
    note = limits_note(tests)
    if note:
        print(note, file=log)
    return tests, drives


def fit_failure(result: FitResult) -> CliError | None:
    """The error to exit with (status 1) when the fit failed or did not converge."""
    if not np.isfinite(result.loss):
        return CliError(
            "the fit failed from every start (the residuals were not finite at any "
            "start); try other start values (--params) or fewer parameters (--fit).",
            status=1,
        )
    if not result.converged:
        return CliError(
            f"the fit did not converge ({result.message}); the best start was "
            "written for inspection. Try more --max-steps, other start values "
            "(--params) or fewer parameters (--fit).",
            status=1,
        )
    return None


def fit_command(args) -> int:
    """Run `jaxcable fit` with the parsed command line `args`; the exit status."""
    meter = progress_meter(args)
    name, model = resolve_model(
        args,
        per_test_hint="use a plain {name: value} file of start values with --params.",
    )
    fit_names = names_option(args.fit, "--fit", model, name)
    per_test = names_option(args.per_test, "--per-test", model, name)
    require_folder_of(args.out, "--out")
    if args.posterior and (args.each or per_test):
        raise CliError(
            "--posterior: not available with --each or --per-test (the posterior "
            "samples one shared parameter set)."
        )
    if args.each:
        return each_command(args, meter, model, name, fit_names, per_test)
    outputs = [("--out", args.out)]
    if args.report:
        names = FIT_REPORT_FILES + ((_POSTERIOR_PNG,) if args.posterior else ())
        outputs += report_files(args.report, names)
    refuse_inputs(outputs, input_files(args))
    tests, drives = read_described(args, meter)
    model = data_start(args, model, tests, [d.drive for d in drives])
    result = run_fit(
        model,
        name,
        tests,
        fit_names=fit_names,
        per_test=per_test,
        args=args,
        meter=meter,
        drive=[d.drive for d in drives],
    )
    failure = fit_failure(result)
    print()
    print(result.summary())
    print()
    # A fit that failed from every start has nothing worth writing; an unconverged
    # one is written for inspection, then reported.
    if failure is not None and not np.isfinite(result.loss):
        raise failure
    # What a file's breaking load means for the fitted material (said, not imposed:
    # the next simulation with this PARAMS.json imposes it).
    with_strain_from_load(tests, result.models)
    posterior = None
    if args.posterior and failure is None:
        posterior = run_posterior(model, name, tests, fit_names, args, drives, result)
        print(posterior.summary())
        print()
    elif args.posterior:
        print("--posterior: not sampled, the fit did not converge.")
    say_replacing([args.out], "--out")
    with write_errors("--out", args.out):
        write_params(args.out, result, posterior)
    print(f"wrote {args.out}")
    if args.report:
        out = pathlib.Path(args.report)
        make_folder(out, "--report")
        notes = [f"files: {', '.join(str(p) for p in args.data)}"]
        if args.no_slack:
            notes.append("slack detection off (--no-slack)")
        if args.every > 1:
            notes.append(f"1 sample in {args.every} fitted (--every)")
        say_replacing([path for _, path in outputs[1:]], "--report")
        with write_errors("--report", out):
            written = write_report(
                out,
                result,
                tests,
                title=f"jaxcable fit: model '{name}'",
                notes=notes,
                progress_meter=meter,
                posterior=posterior,
            )
        print(
            f"wrote the report to {out}{os.sep}: {', '.join(p.name for p in written)}"
        )
    if failure is not None:
        raise failure
    return 0


# The pair plot `write_report` adds for a posterior (`jaxcable._report`'s
# POSTERIOR_FILE).
_POSTERIOR_PNG = "posterior.png"


def run_posterior(model, name, tests, fit_names, args, drives, result) -> Posterior:
    """`jaxcable.sample_posterior` started from the fit `result`, with
    `args.posterior` draws per chain, `args.chains` chains, as many warm-up steps
    (at least 200) and the key of `--seed`."""
    n = args.posterior
    print(f"sampling the posterior: {args.chains} chains x {n} draws (NUTS)")
    try:
        return sample_posterior(
            model,
            tests,
            fit=fit_names or None,
            drive=[d.drive for d in drives],
            num_samples=n,
            num_chains=args.chains,
            num_warmup=max(n, 200),
            key=jax.random.key(args.seed),
            start=result,
        )
    except ValueError as e:
        raise CliError(f"--posterior: cannot sample model '{name}': {e}") from None


def write_params(path, result: FitResult, posterior: Posterior | None) -> None:
    """Write PARAMS.json: the fit's, with the posterior's summary when there is one:
    `posterior`, one entry per parameter (mean, sd, q2.5, q50, q97.5, rhat, ess),
    and `posterior_sampler`, the sampler's settings and outcome."""
    if posterior is None:
        result.to_json(path)
        return
    document = json.loads(result.to_json())
    # Lists and strings only: the reader of PARAMS.json takes every object at the
    # top level for a wrapped model.
    summary = posterior.to_dict()
    document["posterior"] = summary.pop("parameters")
    document["posterior_sampler"] = [{k: v} for k, v in summary.items()]
    write_text_atomic(path, json.dumps(document, indent=2) + "\n")


def _at_least(low: int):
    """An argparse `type`: an integer >= `low` (draws or chains)."""

    def parse(text: str) -> int:
        shown = text if len(text) <= 30 else f"{text[:20]}... ({len(text)} characters)"
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{shown!r} is not an integer") from None
        if value < low:
            raise argparse.ArgumentTypeError(f"{shown} must be at least {low}")
        return value

    return parse


def add_out_options(parser) -> None:
    """`--out`, `--each` and the posterior options of `jaxcable fit`."""
    group = parser.add_argument_group("posterior")
    group.add_argument(
        "--posterior",
        type=_at_least(4),
        metavar="N",
        help="after the fit, sample the Bayesian posterior of the fitted parameters "
        "by NUTS (jaxcable.sample_posterior): N draws per chain; its summary (mean, "
        "sd, 2.5/50/97.5 %%, R-hat, ESS) is printed, added to PARAMS.json ("
        "'posterior', 'posterior_sampler') and, with --report, to summary.md with a pair plot "
        "(posterior.png)",
    )
    group.add_argument(
        "--chains",
        type=_at_least(2),
        default=4,
        metavar="N",
        help="chains of --posterior (default: 4)",
    )
    parser.add_argument(
        "--out",
        metavar="PARAMS.json",
        required=True,
        help="the file to write; with --each, the folder to write FILE.PARAMS.json "
        "(FILE: each data file's name without its suffix) and summary.csv to",
    )
    parser.add_argument(
        "--each",
        action="store_true",
        help="fit every data file on its own (one parameter set per file, all solved "
        "at once by jaxcable.fit_each) instead of one parameter set to all of them",
    )


def _each_outputs(args) -> list[tuple[str, pathlib.Path]]:
    """(option, path) of the files `--each` writes: one PARAMS.json per data file,
    then summary.csv; fails when two files would write the same PARAMS.json."""
    if args.report:
        raise CliError("--report: not available with --each (one fit per file).")
    folder = pathlib.Path(args.out)
    if folder.exists() and not folder.is_dir():
        raise CliError(f"--out {folder}: is a file; with --each it is a folder.")
    seen: dict[str, str] = {}
    for path in args.data:
        stem = pathlib.Path(path).stem
        if stem in seen:
            raise CliError(
                f"--each: {seen[stem]} and {path} would both write "
                f"{stem}.PARAMS.json; give the files distinct names."
            )
        seen[stem] = str(path)
    names = [f"{stem}.PARAMS.json" for stem in seen] + ["summary.csv"]
    return [("--out", folder / name) for name in names]


def _summary_rows(paths, results: list[FitResult]) -> tuple[list[str], list[list]]:
    """The summary table: (header, rows) of file, result, RMSE (in the scored
    channel's unit) and every fitted parameter (SI)."""
    header = ["file", "result", "rmse", "rmse_unit", *results[0].names]
    rows = []
    for path, result in zip(paths, results):
        rmse, unit = result.rmse(0)
        # The result's name as PARAMS.json writes it.
        name = json.loads(result.to_json())["result"]
        rows.append([pathlib.Path(path).name, name, rmse, unit, *result.values])
    return header, rows


def _print_summary(header: list[str], rows: list[list]) -> None:
    width = max(len(header[0]), *(len(r[0]) for r in rows))
    print(
        f"{header[0]:<{width}} {header[1]:<20} {'rmse':>10}      "
        + "".join(f"{h[:11]:>12}" for h in header[4:])
    )
    for file, result, rmse, unit, *values in rows:
        print(
            f"{file:<{width}} {result[:20]:<20} {rmse:>10.4g} {unit:<4} "
            + "".join(f"{v:>12.5g}" for v in values)
        )


def each_command(args, meter, model, name: str, fit_names, per_test) -> int:
    """`jaxcable fit --each`: every data file fitted on its own by one
    `jaxcable.fit_each`; writes FILE.PARAMS.json per fitted file and summary.csv to
    the `--out` folder; the exit status (1 when a fit failed or did not converge)."""
    outputs = _each_outputs(args)
    refuse_inputs(outputs, input_files(args))
    tests, drives = read_described(args, meter)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", IdentifiabilityWarning)
        try:
            results = fit_each(
                model,
                [[t] for t in tests],
                fit=fit_names or None,
                per_test=per_test or None,
                multistart=args.starts,
                max_steps=args.max_steps,
                key=jax.random.key(args.seed),
                drive=[d.drive for d in drives],
                progress_meter=meter,
            )
        except ValueError as e:
            raise CliError(f"cannot fit model '{name}': {e}") from None
    header, rows = _summary_rows(args.data, results)
    print()
    _print_summary(header, rows)
    print()
    folder = pathlib.Path(args.out)
    make_folder(folder, "--out")
    say_replacing([path for _, path in outputs], "--out")
    written = 0
    with write_errors("--out", folder):
        for (_, path), result in zip(outputs, results):
            # A fit that failed has nothing worth writing (as without --each).
            if np.isfinite(result.loss):
                result.to_json(path)
                written += 1
        table = io.StringIO()
        csv.writer(table, lineterminator="\n").writerows([header, *rows])
        write_text_atomic(outputs[-1][1], table.getvalue())
    print(f"wrote {written} PARAMS.json file(s) and summary.csv to {folder}{os.sep}")
    failed = [row[0] for row, r in zip(rows, results) if not r.converged]
    if failed:
        shown = ", ".join(failed[:5]) + (", ..." if len(failed) > 5 else "")
        raise CliError(
            f"{len(failed)} of {len(results)} fits failed or did not converge "
            f"({shown}); see summary.csv. Try more --max-steps, other start values "
            "(--params) or fewer parameters (--fit).",
            status=1,
        )
    return 0
