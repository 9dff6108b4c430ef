"""`jaxcable diagnose`: what a model gets wrong on measured tests, the named physical
cause, and the gain on held-out data."""

import os
import pathlib
import sys

import jax

from .._diagnose import diagnose
from .._models import AbstractCableModel
from .._progress import Progress
from .._report import DIAGNOSIS_REPORT_FILES, write_diagnosis_report
from .common import CliError, make_folder, require_folder_of, show_progress
from .data import data_options, describe_tests, read_tests
from .fit import (
    exported_kernels,
    input_files,
    named_files,
    report_files,
    test_drives,
)
from .models import resolve_model
from .outputs import refuse_inputs, say_replacing, write_errors


def run_diagnosis(
    model: AbstractCableModel, name: str, tests, *, progress: bool, log, **options
):
    """`jaxcable.diagnose` of `tests` with base `model`, its log printed to `log`.

    **Arguments:**

    - `model`: the base model and its start values.
    - `name`: its command-line name, for the errors.
    - `tests`: the measured tests.
    - `progress`: whether to draw a progress bar.
    - `log`: the stream for the diagnosis's progress messages.
    - `options`: the other keyword arguments of `jaxcable.diagnose`.

    **Returns:**

    The diagnosis.
    """
    # Every candidate's fits run as programs exported to the cache (see `run_fit`).
    with Progress("diagnosing", enabled=progress), exported_kernels():
        try:
            return diagnose(
                tests,
                model,
                progress=lambda message: print(message, file=log, flush=True),
                **options,
            )
        except ValueError as e:
            raise CliError(
                f"{named_files(tests)}: cannot diagnose with model '{name}': {e}"
            ) from None


def diagnose_command(args) -> int:
    """Run `jaxcable diagnose` with the parsed command line `args`; the exit status."""
    progress = show_progress(args)
    # With --json, stdout carries the one JSON object; everything else goes to stderr.
    log = sys.stderr if args.json else sys.stdout
    name, model = resolve_model(
        args, per_test_hint="diagnose fits shared parameters; give start values."
    )
    outputs = []
    if args.report:
        require_folder_of(args.report, "--report")
        outputs = report_files(args.report, DIAGNOSIS_REPORT_FILES)
        refuse_inputs(outputs, input_files(args))
    tests = read_tests(args.data, data_options(args), args.every, progress)
    # Resolved (and printed) once here: the diagnosis then fits every fold and
    # candidate with these drives.
    drives = test_drives(tests, args.drive)
    print(f"read {len(tests)} file(s):", file=log)
    print("\n".join(describe_tests(tests, args.every, drives)), file=log)
    diagnosis = run_diagnosis(
        model,
        name,
        tests,
        progress=progress,
        log=log,
        fit_names=args.fit.split(",") if args.fit else None,
        candidates=args.candidates.split(",") if args.candidates else None,
        split=args.split,
        holdout=args.holdout,
        folds=args.folds,
        multistart=args.starts,
        max_steps=args.max_steps,
        key=jax.random.key(args.seed),
        drive=[d.control for d in drives],
    )
    if args.json:
        print(diagnosis.to_json())
    else:
        print(file=log)
        print(diagnosis.summary(), file=log)
    if args.report:
        out = pathlib.Path(args.report)
        make_folder(out, "--report")
        say_replacing([path for _, path in outputs], "--report", log)
        with write_errors("--report", out):
            written = write_diagnosis_report(out, diagnosis, tests)
        print(
            f"wrote the report to {out}{os.sep}: {', '.join(p.name for p in written)}",
            file=log,
        )
    return 0
