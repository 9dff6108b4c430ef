"""`jaxcable fit`: a model fitted to measured tests, written as PARAMS.json, with a
summary on stdout and optionally a report folder."""

import contextlib
import os
import pathlib
import warnings

import jax
import numpy as np

from .._cache import exported_programs_dir
from .._fit import (
    FitResult,
    IdentifiabilityWarning,
    cached_fit_kernels,
    fit,
    resolve_drives,
)
from .._models import AbstractCableModel
from .._progress import AbstractProgressMeter
from .._report import FIT_REPORT_FILES, write_report
from .common import CliError, make_folder, progress_meter, require_folder_of
from .data import data_options, describe_tests, read_tests
from .models import names_option, resolve_model
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
    outputs = [("--out", args.out)]
    if args.report:
        outputs += report_files(args.report, FIT_REPORT_FILES)
    refuse_inputs(outputs, input_files(args))
    tests = read_tests(args.data, data_options(args), args.every, meter)
    drives = test_drives(tests, args.drive)
    print(f"read {len(tests)} file(s):")
    print("\n".join(describe_tests(tests, args.every, drives)))
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
    say_replacing([args.out], "--out")
    with write_errors("--out", args.out):
        result.to_json(args.out)
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
            )
        print(
            f"wrote the report to {out}{os.sep}: {', '.join(p.name for p in written)}"
        )
    if failure is not None:
        raise failure
    return 0
