"""`jaxcable diagnose`: what a model gets wrong on measured tests, the named physical
cause, and the gain on held-out data; with `--out`, the named extended model, fitted,
as a PARAMS.json."""

import os
import pathlib
import sys

import jax

from .._diagnose import Diagnosis, diagnose
from .._models import AbstractCableModel
from .._progress import AbstractProgressMeter
from .._report import DIAGNOSIS_REPORT_FILES, write_diagnosis_report
from .common import CliError, make_folder, progress_meter, require_folder_of
from .fit import (
    exported_kernels,
    input_files,
    named_files,
    read_described,
    report_files,
)
from .models import data_start, resolve_model
from .outputs import refuse_inputs, say_replacing, write_errors


def run_diagnosis(
    model: AbstractCableModel,
    name: str,
    tests,
    *,
    meter: AbstractProgressMeter,
    **options,
) -> Diagnosis:
    """`jaxcable.diagnose` of `tests` with base `model`, its progress shown by `meter`.

    **Arguments:**

    - `model`: the base model and its start values.
    - `name`: its command-line name, for the errors.
    - `tests`: the measured tests.
    - `meter`: the progress meter (its bar and the news of each fit).
    - `options`: the other keyword arguments of `jaxcable.diagnose`.

    **Returns:**

    The diagnosis.
    """
    # Every candidate's fits run as programs exported to the cache (see `run_fit`).
    with exported_kernels():
        try:
            return diagnose(tests, model, progress_meter=meter, **options)
        except ValueError as e:
            raise CliError(
                f"{named_files(tests)}: cannot diagnose with model '{name}': {e}"
            ) from None


def diagnose_command(args) -> int:
    """Run `jaxcable diagnose` with the parsed command line `args`; the exit status."""
    name, model = resolve_model(
        args, per_test_hint="diagnose fits shared parameters; give start values."
    )
    # With --json, stdout carries the one JSON object; everything else goes to stderr.
    log = sys.stderr if args.json else sys.stdout
    meter = progress_meter(args, log)
    if args.out:
        require_folder_of(args.out, "--out")
    if args.report:
        require_folder_of(args.report, "--report")
    inputs = input_files(args)
    reports = report_files(args.report, DIAGNOSIS_REPORT_FILES) if args.report else []
    outputs = [("--out", args.out)] if args.out else []
    refuse_inputs(outputs + reports, inputs)
    # Read as every command reads; the drives resolved (and printed) once here: the
    # diagnosis then fits every fold and candidate with these drives.
    tests, drives = read_described(args, meter, log)
    model = data_start(args, model, tests, [d.drive for d in drives])
    diagnosis = run_diagnosis(
        model,
        name,
        tests,
        meter=meter,
        fit_names=args.fit.split(",") if args.fit else None,
        candidates=args.candidates.split(",") if args.candidates else None,
        split=args.split,
        holdout=args.holdout,
        folds=args.folds,
        multistart=args.starts,
        max_steps=args.max_steps,
        key=jax.random.key(args.seed),
        drive=[d.control for d in drives],
        max_rounds=args.max_rounds,
        family={"auto": None, "always": True, "never": False}[args.family],
    )
    if args.json:
        print(diagnosis.to_json())
    else:
        print(file=log)
        print(diagnosis.summary(), file=log)
    if args.out:
        # The named extended model, fitted (the base's fit when no cause is named).
        say_replacing([args.out], "--out", log)
        with write_errors("--out", args.out):
            diagnosis.extended_fit().to_json(args.out)
        what = (
            f"the base with the named cause(s) {', '.join(diagnosis.causes)}"
            if diagnosis.causes
            else f"the fitted base model: no cause named (verdict {diagnosis.verdict})"
        )
        print(f"wrote {args.out}: {what}", file=log)
    if args.report:
        out = pathlib.Path(args.report)
        make_folder(out, "--report")
        say_replacing([path for _, path in reports], "--report", log)
        with write_errors("--report", out):
            written = write_diagnosis_report(out, diagnosis, tests)
        print(
            f"wrote the report to {out}{os.sep}: {', '.join(p.name for p in written)}",
            file=log,
        )
    return 0
