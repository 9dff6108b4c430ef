"""`jaxcable diagnose`: what a model gets wrong on measured tests, the named physical
cause, and the gain on held-out data; with `--out`, the named extended model, fitted,
as a PARAMS.json."""

import dataclasses
import os
import pathlib
import sys

from .._diagnose import CandidateSearch, Diagnosis, HeldOut, diagnose
from .._problem import Problem
from .._progress import AbstractProgressMeter
from .._report import DIAGNOSIS_REPORT_FILES, write_diagnosis_report
from .common import (
    least_squares,
    make_folder,
    progress_meter,
    refused,
    require_folder_of,
)
from .data import DataFiles, data_options, input_files, read_described
from .fit import exported_kernels, named_files
from .models import ModelChoice, data_start, resolve_model
from .outputs import refuse_inputs, report_files, say_replacing, write_errors


@dataclasses.dataclass(frozen=True)
class DiagnoseRequest:
    """What `jaxcable diagnose` was asked, as the values its flags give.

    **Fields:**

    - `model`: `--model` and `--params` (the base model).
    - `data`: the data files and how to read them.
    - `fit`: the base parameters to fit (`--fit`); None: the default set.
    - `search`: how the cause is looked for: the candidates, the held-out data,
        the fits and the rounds.
    - `json`, `out`, `report`: `--json`, `--out`, `--report`.
    - `quiet`: `--quiet`.
    """

    model: ModelChoice
    data: DataFiles
    fit: tuple[str, ...] | None
    search: CandidateSearch
    json: bool = False
    out: str | None = None
    report: str | None = None
    quiet: bool = False


def run_diagnosis(
    problem: Problem, name: str, search: CandidateSearch, meter: AbstractProgressMeter
) -> Diagnosis:
    """`jaxcable.diagnose` of `problem` by `search`, its progress shown by
    `meter`.

    **Arguments:**

    - `problem`: the base model and its start values, the measured tests with their
        drives, and the base parameters to fit.
    - `name`: the model's command-line name, for the errors.
    - `search`: the candidates, held-out data, fits and rounds.
    - `meter`: the progress meter (its bar and the news of each fit).

    **Returns:**

    The diagnosis.
    """
    # Every candidate's fits run as programs exported to the cache (see `run_fit`).
    where = f"{named_files(problem.tests)}: cannot diagnose with model '{name}'"
    with exported_kernels(), refused(where):
        return diagnose(problem, search, progress_meter=meter)


def diagnose_command(args) -> int:
    """Run `jaxcable diagnose` with the parsed command line `args`; the exit status."""
    request = DiagnoseRequest(
        model=ModelChoice(args.model, args.params),
        data=DataFiles(tuple(args.data), data_options(args), args.every, args.drive),
        fit=tuple(args.fit.split(",")) if args.fit else None,
        search=candidate_search(args),
        json=args.json,
        out=args.out,
        report=args.report,
        quiet=args.quiet,
    )
    return diagnose_files(request)


def candidate_search(args) -> CandidateSearch:
    """The search of the parsed command line `args`: `--candidates`, the held-out
    data (`--split`, `--holdout`, `--folds`), the solver flags, `--max-rounds` and
    `--family`; a value the search refuses is an error naming its flags."""
    with refused("--holdout, --folds"):
        heldout = HeldOut(split=args.split, fraction=args.holdout, folds=args.folds)
    candidates = tuple(args.candidates.split(",")) if args.candidates else None
    with refused("--candidates"):
        return CandidateSearch(
            candidates=candidates,
            heldout=heldout,
            least_squares=least_squares(args),
            max_rounds=args.max_rounds,
            family={"auto": None, "always": True, "never": False}[args.family],
        )


def diagnose_files(request: DiagnoseRequest) -> int:
    """`jaxcable diagnose` as `request` asks: the diagnosis printed (one JSON object
    with `json`, the log then on stderr), the extended model and the report
    written; the exit status."""
    name, model = resolve_model(
        request.model,
        per_test_hint="diagnose fits shared parameters; give start values.",
    )
    # With --json, stdout carries the one JSON object; everything else goes to stderr.
    log = sys.stderr if request.json else sys.stdout
    meter = progress_meter(request.quiet, log)
    if request.out:
        require_folder_of(request.out, "--out")
    if request.report:
        require_folder_of(request.report, "--report")
    inputs = input_files(request.data, request.model.params)
    reports = (
        report_files(request.report, DIAGNOSIS_REPORT_FILES) if request.report else []
    )
    outputs = [("--out", request.out)] if request.out else []
    refuse_inputs(outputs + reports, inputs)
    # Read as every command reads; the drives resolved (and printed) once here: the
    # diagnosis then fits every fold and candidate with these drives.
    tests, drives = read_described(request.data, meter, log)
    problem = Problem(model, tests, fit=request.fit, drive=[d.control for d in drives])
    problem = data_start(problem, request.model)
    diagnosis = run_diagnosis(problem, name, request.search, meter)
    if request.json:
        print(diagnosis.to_json())
    else:
        print(file=log)
        print(diagnosis.summary(), file=log)
    if request.out:
        _write_extended(request.out, diagnosis, log)
    if request.report:
        out = pathlib.Path(request.report)
        make_folder(out, "--report")
        say_replacing([path for _, path in reports], "--report", log)
        with write_errors("--report", out):
            written = write_diagnosis_report(out, diagnosis, tests)
        print(
            f"wrote the report to {out}{os.sep}: {', '.join(p.name for p in written)}",
            file=log,
        )
    return 0


def _write_extended(path: str, diagnosis: Diagnosis, log) -> None:
    """`--out`: the named extended model, fitted (the base's fit when no cause is
    named), said on `log`."""
    say_replacing([path], "--out", log)
    with write_errors("--out", path):
        diagnosis.extended_fit().to_json(path)
    what = (
        f"the base with the named cause(s) {', '.join(diagnosis.causes)}"
        if diagnosis.causes
        else f"the fitted base model: no cause named (verdict {diagnosis.verdict})"
    )
    print(f"wrote {path}: {what}", file=log)
