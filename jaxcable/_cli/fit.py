"""`jaxcable fit`: a model fitted to measured tests, written as PARAMS.json, with a
summary on stdout and optionally a report folder; with `--each`, every file fitted
on its own (one `jaxcable.fit_each`), one PARAMS.json per file and a summary table."""

import contextlib
import csv
import dataclasses
import io
import json
import os
import pathlib
import warnings

import numpy as np

from .._cache import exported_programs_dir
from .._files import write_text_atomic
from .._fit import (
    FitResult,
    IdentifiabilityWarning,
    cached_fit_kernels,
    fit,
    fit_each,
)
from .._problem import LeastSquares, Problem
from .._progress import AbstractProgressMeter
from .._report import FIT_REPORT_FILES, write_report
from .._uncertainty import NUTS, Posterior, sample_posterior
from .common import (
    CliError,
    least_squares,
    make_folder,
    nuts,
    progress_meter,
    refused,
    require_folder_of,
)
from .data import DataFiles, data_options, input_files, read_described
from .limits import with_strain_from_load
from .models import ModelChoice, data_start, names_option, resolve_model
from .numbers import at_least
from .outputs import refuse_inputs, report_files, say_replacing, write_errors


@dataclasses.dataclass(frozen=True)
class FitRequest:
    """What `jaxcable fit` was asked, as the values its flags give.

    **Fields:**

    - `model`: `--model` and `--params`.
    - `data`: the data files and how to read them.
    - `fit`, `per_test`: the `--fit` and `--per-test` lists as given (None: not
        given).
    - `method`: `--starts`, `--max-steps` and `--seed` as the least-squares method.
    - `posterior`: the sampler of `--posterior` and `--chains`, or None.
    - `out`, `each`, `report`: `--out`, `--each`, `--report`.
    - `quiet`: `--quiet`.
    """

    model: ModelChoice
    data: DataFiles
    fit: str | None
    per_test: str | None
    method: LeastSquares
    posterior: NUTS | None = None
    out: str = "params.json"
    each: bool = False
    report: str | None = None
    quiet: bool = False


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
    problem: Problem, name: str, method: LeastSquares, meter: AbstractProgressMeter
) -> FitResult:
    """`jaxcable.fit` of `problem` by `method`, its progress shown by `meter`.

    **Arguments:**

    - `problem`: the start model, the measured tests with their drives, and the
        parameters to fit (and those fitted per test).
    - `name`: the model's command-line name, for the errors.
    - `method`: the least-squares method (`--starts`, `--max-steps`, `--seed`).
    - `meter`: the progress meter.

    **Returns:**

    The fit, converged or not; identifiability warnings are in its `warnings` (and
    printed with its summary), not issued.
    """
    tests = problem.tests
    n = sum(int(np.sum(np.asarray(t.mask))) for t in tests)
    label = f"fitting {name} to {len(tests)} test(s), {n} samples"
    with (
        meter.bar(label),
        warnings.catch_warnings(),
        exported_kernels(),
    ):
        warnings.simplefilter("ignore", IdentifiabilityWarning)
        with refused(f"{named_files(tests)}: cannot fit model '{name}'"):
            return fit(problem, method, throw=False)


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
    request = FitRequest(
        model=ModelChoice(args.model, args.params),
        data=DataFiles(tuple(args.data), data_options(args), args.every, args.drive),
        fit=args.fit,
        per_test=args.per_test,
        method=least_squares(args),
        posterior=nuts(args) if args.posterior else None,
        out=args.out,
        each=args.each,
        report=args.report,
        quiet=args.quiet,
    )
    return fit_files(request)


def fit_files(request: FitRequest) -> int:
    """`jaxcable fit` as `request` asks: the fit written as PARAMS.json (one per
    file with `each`), its summary printed, and the report written; the exit
    status (1 when the fit failed or did not converge)."""
    meter = progress_meter(request.quiet)
    name, model = resolve_model(
        request.model,
        per_test_hint="use a plain {name: value} file of start values with --params.",
    )
    fit_names = names_option(request.fit, "--fit", model, name)
    per_test = names_option(request.per_test, "--per-test", model, name)
    require_folder_of(request.out, "--out")
    if request.posterior and (request.each or per_test):
        raise CliError(
            "--posterior: not available with --each or --per-test (the posterior "
            "samples one shared parameter set)."
        )
    outputs = _each_outputs(request) if request.each else _fit_outputs(request)
    refuse_inputs(outputs, input_files(request.data, request.model.params))
    tests, drives = read_described(request.data, meter)
    if request.each:
        # One problem per file, each with its test's drive; the same start and names.
        problems = [
            Problem(model, (t,), fit_names or None, tuple(per_test), drive=(d.drive,))
            for t, d in zip(tests, drives)
        ]
        return each_files(problems, name, request, outputs, meter)
    problem = Problem(
        model,
        tests,
        fit=fit_names or None,
        per_test=tuple(per_test),
        drive=[d.drive for d in drives],
    )
    problem = data_start(problem, request.model)
    result = run_fit(problem, name, request.method, meter)
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
    with_strain_from_load(problem.tests, result.models)
    posterior = None
    if request.posterior and failure is None:
        posterior = run_posterior(problem, name, request.posterior, result)
        print(posterior.summary())
        print()
    elif request.posterior:
        print("--posterior: not sampled, the fit did not converge.")
    say_replacing([request.out], "--out")
    with write_errors("--out", request.out):
        write_params(request.out, result, posterior)
    print(f"wrote {request.out}")
    if request.report:
        # Said before the folder is made: a folder that cannot be made holds no file.
        say_replacing([path for _, path in outputs[1:]], "--report")
        _write_fit_report(request, name, result, posterior, problem.tests, meter)
    if failure is not None:
        raise failure
    return 0


def _fit_outputs(request: FitRequest) -> list[tuple[str, str | pathlib.Path]]:
    """(option, path) of the files a fit writes: `--out`, then the report's."""
    outputs: list[tuple[str, str | pathlib.Path]] = [("--out", request.out)]
    if request.report:
        names = FIT_REPORT_FILES + ((_POSTERIOR_PNG,) if request.posterior else ())
        outputs += report_files(request.report, names)
    return outputs


def _write_fit_report(request, name, result, posterior, tests, meter) -> None:
    """The `--report` folder of a fit (and of its posterior, if any)."""
    out = pathlib.Path(request.report)
    make_folder(out, "--report")
    notes = [f"files: {', '.join(str(p) for p in request.data.paths)}"]
    if not request.data.reading.options.detect_slack:
        notes.append("slack detection off (--no-slack)")
    if request.data.every > 1:
        notes.append(f"1 sample in {request.data.every} fitted (--every)")
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
    print(f"wrote the report to {out}{os.sep}: {', '.join(p.name for p in written)}")


# The pair plot `write_report` adds for a posterior (`jaxcable._report`'s
# POSTERIOR_FILE).
_POSTERIOR_PNG = "posterior.png"


def run_posterior(
    problem: Problem, name: str, method: NUTS, result: FitResult
) -> Posterior:
    """`jaxcable.sample_posterior` of `problem` by `method`, started from the fit
    `result`; said on stdout first."""
    print(
        f"sampling the posterior: {method.num_chains} chains x "
        f"{method.num_samples} draws (NUTS)"
    )
    with refused(f"--posterior: cannot sample model '{name}'"):
        return sample_posterior(problem, method, start=result)


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


def add_out_options(parser) -> None:
    """`--out`, `--each` and the posterior options of `jaxcable fit`."""
    group = parser.add_argument_group("posterior")
    group.add_argument(
        "--posterior",
        type=at_least(4),
        metavar="N",
        help="after the fit, sample the Bayesian posterior of the fitted parameters "
        "by NUTS (jaxcable.sample_posterior): N draws per chain; its summary (mean, "
        "sd, 2.5/50/97.5 %%, R-hat, ESS) is printed, added to PARAMS.json ("
        "'posterior', 'posterior_sampler') and, with --report, to summary.md with a pair plot "
        "(posterior.png)",
    )
    group.add_argument(
        "--chains",
        type=at_least(2),
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


def _each_outputs(request: FitRequest) -> list[tuple[str, str | pathlib.Path]]:
    """(option, path) of the files `--each` writes: one PARAMS.json per data file,
    then summary.csv; fails when two files would write the same PARAMS.json."""
    if request.report:
        raise CliError("--report: not available with --each (one fit per file).")
    folder = pathlib.Path(request.out)
    if folder.exists() and not folder.is_dir():
        raise CliError(f"--out {folder}: is a file; with --each it is a folder.")
    seen: dict[str, str] = {}
    for path in request.data.paths:
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


def each_files(
    problems: list[Problem], name: str, request: FitRequest, outputs, meter
) -> int:
    """`jaxcable fit --each`: the `problems`, one per data file, fitted by one
    `jaxcable.fit_each`; writes FILE.PARAMS.json per fitted file and summary.csv to
    the `--out` folder (`outputs`, [`_each_outputs`][]); the exit status (1 when a
    fit failed or did not converge)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", IdentifiabilityWarning)
        with refused(f"cannot fit model '{name}'"):
            results = fit_each(problems, request.method, progress_meter=meter)
    header, rows = _summary_rows(request.data.paths, results)
    print()
    _print_summary(header, rows)
    print()
    folder = pathlib.Path(request.out)
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
