"""`jaxcable design`: the next test to run, designed from a fit (or a posterior) of
measured tests, written as a protocol file that `jaxcable simulate` and a tester
run."""

import argparse
import dataclasses

import numpy as np

from .. import _checks
from .._diagnose import CandidateSearch, Diagnosis
from .._models import EXTENSIONS
from .._problem import LeastSquares, Problem
from .._uncertainty import (
    NUTS,
    TestBudget,
    TestDesign,
    design_discriminating_test,
    design_test,
)
from .common import (
    CliError,
    least_squares,
    nuts,
    progress_meter,
    refused,
    require_folder_of,
)
from .data import DataFiles, data_options, read_described
from .diagnose import run_diagnosis
from .fit import (
    fit_failure,
    run_fit,
    run_posterior,
)
from .limits import strain_at_load, with_strain_from_load
from .models import ModelChoice, data_start, names_option, resolve_model
from .numbers import at_least, fraction, positive_float, positive_int, seed
from .outputs import refuse_inputs, say_replacing, write_errors


DESCRIPTION = (
    "Fit a model to the measured tests (as 'jaxcable fit'), then design the next "
    "test: ramps to load levels, holds, ramps down and rests at one crosshead "
    "speed, chosen by gradient through the model to shrink the uncertainty of the "
    "least identified parameters most (D_s-optimal Fisher information; see "
    "jaxcable.design_test), within the lab's limits: total duration, largest force "
    "as a fraction of the breaking load, speed range, samples. Writes the test as "
    "a protocol file and prints what it is expected to gain beside Park's "
    "standard 10-cycle protocol of the same duration, and why. With --separate "
    "A,B: the test that best tells two candidate causes apart after a diagnosis "
    "(T-optimal)."
)


def _speeds(text: str) -> tuple[float, float]:
    """An argparse `type`: the speed range MIN,MAX, mm/min, 0 < MIN <= MAX."""
    parts = text.split(",")
    try:
        low, high = (float(p) for p in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{text!r} is not two numbers MIN,MAX (mm/min)"
        ) from None
    try:
        _checks.require_number("MIN", low, 0.0, strict=True)
        _checks.require_number("MAX", high, low)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} needs 0 < MIN <= MAX") from None
    return low, high


_positive = positive_float
_fraction = fraction
_int = positive_int


def add_design_command(commands, add_model_options, add_data_options, add_drive):
    """The `jaxcable design` subparser (the shared option builders of the parser
    passed in, to add the same model, data and drive options as `jaxcable fit`)."""
    parser = commands.add_parser(
        "design",
        help="design the next test to run (a protocol file)",
        description=DESCRIPTION,
    )
    parser.set_defaults(run=design_command)
    parser.add_argument("data", nargs="+", metavar="DATA.csv", help="measured tests")
    add_model_options(parser, "start values, as for 'jaxcable fit'")
    parser.add_argument(
        "--out", metavar="NEXT.json", required=True, help="the protocol file to write"
    )
    add_data_options(parser)
    add_drive(parser, "of each test")
    what = parser.add_argument_group("what is known")
    what.add_argument("--fit", metavar="NAMES", help="parameters to fit")
    what.add_argument("--starts", type=_int, default=4, metavar="N")
    what.add_argument("--seed", type=seed, default=0, metavar="N")
    what.add_argument("--max-steps", type=_int, default=256, metavar="N")
    what.add_argument("--every", type=_int, default=1, metavar="K")
    what.add_argument("--quiet", action="store_true")
    what.add_argument(
        "--posterior",
        type=at_least(4),
        metavar="N",
        help="design from the posterior (N NUTS draws per chain) instead of the "
        "fit's linearised covariance",
    )
    what.add_argument("--chains", type=_int, default=4, metavar="N")
    lab = parser.add_argument_group("the lab's limits")
    lab.add_argument(
        "--duration-s",
        type=_positive,
        metavar="S",
        help="total duration of the test, s (default: that of the longest measured "
        "test, a duration the lab has shown it can run and the data's own time "
        "scale, so that the designed test and Park's 10-cycle yardstick are "
        "compared on what the lab does)",
    )
    lab.add_argument(
        "--max-force-fraction",
        type=_fraction,
        default=0.05,
        metavar="X",
        help="largest force as a fraction of the breaking load (default 0.05)",
    )
    lab.add_argument(
        "--speed",
        type=_speeds,
        default=(1.0, 100.0),
        metavar="MIN,MAX",
        help="crosshead speed range, mm/min (default 1,100)",
    )
    lab.add_argument("--samples", type=_int, default=240, metavar="N")
    lab.add_argument("--blocks", type=_int, default=2, metavar="N")
    lab.add_argument(
        "--noise-mm",
        type=_positive,
        metavar="X",
        help="elongation noise, mm (default: the fit's RMS residual; with only "
        "elongation-driven tests, its force residual through the fitted cable's "
        "compliance at the peak force)",
    )
    lab.add_argument("--targets", metavar="NAMES", help="parameters to learn about")
    lab.add_argument(
        "--separate",
        metavar="ID,ID",
        help="instead, the test that best separates two candidate causes (extension "
        "ids, as 'jaxcable diagnose --candidates'): both are fitted by a diagnosis "
        "of the data, then the test is designed to tell them apart "
        "(jaxcable.design_discriminating_test)",
    )
    lab.add_argument("--design-steps", type=_int, default=40, metavar="N")


@dataclasses.dataclass(frozen=True)
class Lab:
    """The lab's limits of the designed test (the fields of `jaxcable.TestBudget`;
    None: from the data, as `--duration-s` and `--noise-mm` say)."""

    duration_s: float | None
    max_force_fraction: float
    speed_mm_per_min: tuple[float, float]
    samples: int
    blocks: int
    noise_mm: float | None


@dataclasses.dataclass(frozen=True)
class DesignRequest:
    """What `jaxcable design` was asked, as the values its flags give.

    **Fields:**

    - `model`, `data`: as for `jaxcable fit`.
    - `out`: `--out`, the protocol file to write.
    - `separate`: `--separate` as given, or None.
    - `fit`, `targets`: `--fit` and `--targets` as given (None: not given).
    - `method`: the least-squares method of the fit.
    - `posterior`: the sampler of `--posterior` and `--chains`, or None.
    - `lab`: the lab's limits.
    - `steps`: `--design-steps`.
    - `quiet`: `--quiet`.
    """

    model: ModelChoice
    data: DataFiles
    out: str
    separate: str | None
    fit: str | None
    targets: str | None
    method: LeastSquares
    posterior: NUTS | None
    lab: Lab
    steps: int
    quiet: bool = False


def design_command(args) -> int:
    """Run `jaxcable design` with the parsed command line `args`; the exit status."""
    method = least_squares(args)
    lab = Lab(
        args.duration_s,
        args.max_force_fraction,
        args.speed,
        args.samples,
        args.blocks,
        args.noise_mm,
    )
    request = DesignRequest(
        model=ModelChoice(args.model, args.params),
        data=DataFiles(tuple(args.data), data_options(args), args.every, args.drive),
        out=args.out,
        separate=args.separate,
        fit=args.fit,
        targets=args.targets,
        method=method,
        posterior=nuts(args) if args.posterior else None,
        lab=lab,
        steps=args.design_steps,
        quiet=args.quiet,
    )
    return design_next(request)


def design_next(request: DesignRequest) -> int:
    """`jaxcable design` as `request` asks: the known tests fitted (or diagnosed,
    with `separate`), the next test designed and written; the exit status."""
    meter = progress_meter(request.quiet)
    name, model = resolve_model(
        request.model, per_test_hint="design needs shared parameters."
    )
    fit_names = names_option(request.fit, "--fit", model, name)
    targets = names_option(request.targets, "--targets", model, name) or None
    require_folder_of(request.out, "--out")
    refuse_inputs(
        [("--out", request.out)], [("DATA.csv", str(p)) for p in request.data.paths]
    )
    separate = _pair(request.separate, targets)
    tests, drives = read_described(request.data, meter)
    problem = Problem(
        model, tests, fit=fit_names or None, drive=[d.drive for d in drives]
    )
    problem = data_start(problem, request.model)
    lab = request.lab
    if lab.duration_s is None:
        lab = dataclasses.replace(lab, duration_s=longest_duration(tests))
        print(f"--duration-s: {lab.duration_s:.6g} s, the longest measured test's")
    if separate:
        search = CandidateSearch(
            candidates=tuple(separate),
            least_squares=request.method,
            discover=False,
            max_rounds=1,
        )
        known = run_diagnosis(problem, name, search, meter)
        print()
        print(known.summary())
        print()
        return _design_and_write(known, tests, request, lab, None)
    result = run_fit(problem, name, request.method, meter)
    print()
    print(result.summary())
    print()
    failure = fit_failure(result)
    if failure is not None:
        raise failure
    known = result
    # A breaking load without a breaking strain: the fitted model's strain there.
    tests = with_strain_from_load(tests, result.models)
    if lab.noise_mm is None and all(d.control != "force" for d in drives):
        lab = dataclasses.replace(lab, noise_mm=noise_through_compliance(result, tests))
    if request.posterior:
        problem = dataclasses.replace(problem, tests=tests)
        known = run_posterior(problem, name, request.posterior, result)
        print(known.summary())
        print()
    return _design_and_write(known, tests, request, lab, targets)


def longest_duration(tests) -> float:
    """The duration of the longest of `tests`, s (first to last sample): the
    default duration of a designed test."""
    return max(float(t.time[-1] - t.time[0]) for t in tests)


def noise_through_compliance(result, tests) -> float | None:
    """The elongation noise, mm, of tests that are all elongation-driven (their fit
    scores force): the RMS force residual of the first test seen through the
    fitted cable's compliance at its peak force (the strain of a ramp to it at the
    crosshead speed); printed. None where the model does not reach that force."""
    rmse_N, _ = result.rmse(0)
    test = tests[0]
    cable = test.cable()
    peak = test.peak_force()
    strain = strain_at_load(result.models[0], cable, peak) if peak > 0 else None
    if strain is None:
        return None
    noise = 1e3 * rmse_N * strain * float(cable.length) / peak
    print(
        f"--noise-mm: {noise:.3g} mm, the fit's force residual ({rmse_N:.3g} N) "
        f"through the fitted cable's compliance at {peak:.4g} N"
    )
    return noise


def _pair(text: str | None, targets) -> list[str] | None:
    """The two extension ids of `--separate` (command-line names accepted)."""
    if text is None:
        return None
    by_cli = {cls.CLI_NAME: key for key, cls in EXTENSIONS.items()}
    ids = [by_cli.get(t.strip(), t.strip()) for t in text.split(",")]
    if len(ids) != 2 or len(set(ids)) != 2 or not set(ids) <= set(EXTENSIONS):
        raise CliError(
            f"--separate: give two different extension ids of {list(EXTENSIONS)}, "
            f"got {text!r}."
        )
    if targets:
        raise CliError("--targets: a test that separates two causes has no targets.")
    return ids


def _design_and_write(known, tests, request: DesignRequest, lab: Lab, targets) -> int:
    """Design from `known` (a fit, a posterior or a diagnosis) within `lab`, print
    the summary and write `--out`; the exit status."""
    with refused("cannot design the test"):
        method = TestDesign(TestBudget(**dataclasses.asdict(lab)), steps=request.steps)
        cable = tests[0].cable()
        if isinstance(known, Diagnosis):
            designed = design_discriminating_test(known, method, cable=cable)
            simulated = designed.separation
        else:
            designed = design_test(known, method, cable=cable, targets=targets)
            simulated = designed.sd_after
    print(designed.summary())
    if not np.all(np.isfinite(simulated)):
        raise CliError("the designed test did not simulate.", status=1)
    out = request.out
    say_replacing([out], "--out")
    with write_errors("--out", out):
        designed.to_json(out)
    print(f"wrote {out} (run it with: jaxcable simulate {out} --params ...)")
    return 0
