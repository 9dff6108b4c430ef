"""`jaxcable demo`: Park et al.'s tests simulated, a fit of the bundled data set, and
the diagnosis of what that fit gets wrong.

The demo's two plots (simulated force vs elongation and elongation vs time, several
cases overlaid) are its own: the report's plots show measured tests against a fit.
"""

import contextlib
import dataclasses
import importlib.resources
import os
import pathlib
import sys
from typing import NamedTuple

import numpy as np

from .._cable import Cable
from .._diagnose import CandidateSearch
from .._drive import Protocol, Simulation, simulate_rate_test
from .._io import TestData, write_csv
from .._models import PARK_IDENTIFIABLE, IntegratedModel
from .._problem import LeastSquares, Problem
from .._report import (
    DIAGNOSIS_REPORT_FILES,
    FIT_REPORT_FILES,
    save_png,
    write_diagnosis_report,
    write_report,
)
from .._results import RESULTS
from .common import CliError, least_squares, make_folder, one_line, progress_meter
from .data import Reading, read_tests
from .diagnose import run_diagnosis
from .fit import fit_failure, run_fit
from .models import names_option, parameter_names
from .outputs import refuse_inputs, say_replacing, write_errors, writing


class _Case(NamedTuple):
    name: str
    label: str
    group: str
    force_max: float  # N
    cycles: int
    rate: float  # mm/min


_LENGTH_MM = 300.0
_DIAMETER_MM = 3.0
# Park et al. Section 4: the rate effect (Fig. 3) and 10-cycle tests (Fig. 4).
_CASES = (
    _Case("rate_3mm_per_min", "3 mm/min", "rate", 100.0, 1, 3.0),
    _Case("rate_50mm_per_min", "50 mm/min", "rate", 100.0, 1, 50.0),
    _Case("cycles10_100N", "100 N", "cycles", 100.0, 10, 3.0),
    _Case("cycles10_150N", "150 N", "cycles", 150.0, 10, 3.0),
)
_PLOTS = {
    "rate": (
        "rate_effect.png",
        "Rate effect: 300 mm, 0-100 N, one cycle (Park Fig. 3)",
    ),
    "cycles": (
        "cycles10.png",
        "10 cycles at 3 mm/min, 300 mm (Park Fig. 4)",
    ),
}


class _Simulated(NamedTuple):
    case: _Case
    time: np.ndarray  # s
    force: np.ndarray  # N
    elongation: np.ndarray  # mm
    residual: float  # mm, at the end of the first unloading
    error: str  # "" when successful


@dataclasses.dataclass(frozen=True)
class DemoRequest:
    """What `jaxcable demo` was asked, as the values its flags give.

    **Fields:**

    - `out`: the output folder.
    - `samples_per_ramp`: of the simulated tests.
    - `data`: the folder of CSV files to fit, or None for the bundled data set.
    - `fit`: `--fit` as given (None: Park's identifiable parameters).
    - `method`: the least-squares method of the fit (the diagnosis's: one start).
    - `every`: fit every `every`-th sample.
    - `diagnose`: whether step 3, the diagnosis, runs.
    - `quiet`: `--quiet`.
    """

    out: str
    samples_per_ramp: int
    data: str | None
    fit: str | None
    method: LeastSquares
    every: int = 1
    diagnose: bool = True
    quiet: bool = False


def _simulate_case(
    model, case: _Case, samples_per_ramp: int, samples: int
) -> _Simulated:
    cable = Cable(
        length=_LENGTH_MM * 1e-3,
        diameter=_DIAMETER_MM * 1e-3,
        speed=case.rate * 1e-3 / 60,
    )
    # Padded to a common length so that all cases share one compilation.
    protocol = Protocol.cycles(
        case.force_max, case.cycles, samples_per_ramp=samples_per_ramp
    ).pad(samples)
    traj = simulate_rate_test(model, cable, protocol, method=Simulation(throw=False))
    error = ""
    if traj.result != RESULTS.successful:
        error = RESULTS[traj.result]
    valid = np.asarray(traj.mask)
    elongation = np.asarray(traj.elongation)[valid] * 1e3
    # Sample 0 is the unloaded start; the first unloading ends 2 ramps later.
    residual = float(elongation[2 * samples_per_ramp])
    return _Simulated(
        case,
        np.asarray(traj.time)[valid],
        np.asarray(traj.force)[valid],
        elongation,
        residual,
        error,
    )


def _plot(path: pathlib.Path, title: str, results: list[_Simulated]) -> None:
    """Force vs elongation and elongation vs time of `results`, side by side."""
    # The object-oriented API, not pyplot: no global backend or figure state, and
    # Figure.savefig renders PNG with Agg.
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10, 4), layout="constrained")
    ax_f, ax_t = fig.subplots(1, 2)
    for r in results:
        if r.error:
            # Keep a failed case visible in the legend rather than silently absent.
            ax_f.plot([], [], " ", label=f"{r.case.label}: failed")
            continue
        ax_f.plot(r.elongation, r.force, label=r.case.label)
        ax_t.plot(r.time / 60, r.elongation, label=r.case.label)
    ax_f.set_xlabel("elongation [mm]")
    ax_f.set_ylabel("force [N]")
    ax_f.set_title("force vs elongation")
    ax_t.set_xlabel("time [min]")
    ax_t.set_ylabel("elongation [mm]")
    ax_t.set_title("elongation vs time")
    for ax in (ax_f, ax_t):
        ax.grid(alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend()
    fig.suptitle(title)
    save_png(fig, path, dpi=100)


def _bundled_files() -> list:
    """The bundled data set's CSV files (`jaxcable/data/*.csv`), sorted by name."""
    folder = importlib.resources.files("jaxcable").joinpath("data")
    if not folder.is_dir():
        return []
    return sorted(
        (p for p in folder.iterdir() if p.name.endswith(".csv")), key=lambda p: p.name
    )


def _data(data: str | None) -> tuple[list, str]:
    """(files, description) of the data set the demo fits: the folder `data`
    (`--data`), else the bundled one; fails when it is empty."""
    if data is not None:
        folder = pathlib.Path(data)
        if not folder.is_dir():
            raise CliError(f"--data {data}: not a folder.")
        files = sorted(folder.glob("*.csv"))
        if not files:
            raise CliError(f"--data {data}: no *.csv files in this folder.")
        return files, str(folder)
    files = _bundled_files()
    if not files:
        raise CliError(
            "the bundled data set is missing: jaxcable/data/ has no *.csv files. In a "
            "source checkout, make it with 'python scripts/make_bundled_data.py', or "
            "pass --data DIR (a folder of canonical CSV files).",
            status=1,
        )
    return files, "the bundled data set (jaxcable/data/, synthetic)"


def _simulate(spr: int, out: pathlib.Path) -> tuple[list, list[pathlib.Path]]:
    """Step 1: Park's tests simulated with `spr` samples per ramp, written as CSV
    files and two plots."""
    model = IntegratedModel()
    samples = 1 + 2 * spr * max(c.cycles for c in _CASES)
    results = [_simulate_case(model, c, spr, samples) for c in _CASES]

    written = []
    for r in results:
        if r.error:
            continue
        data = TestData(
            time=r.time,
            force=r.force,
            elongation=r.elongation * 1e-3,
            metadata={
                "id": r.case.name,
                "material": "Dyneema SK78",
                "length_mm": _LENGTH_MM,
                "diameter_mm": _DIAMETER_MM,
                "rate_mm_per_min": r.case.rate,
                "protocol": f"{r.case.cycles} x 0-{r.case.force_max:g} N",
                "model": "integrated (default parameters), simulated by jaxcable demo",
                "control": "force",
            },
        )
        path = out / f"{r.case.name}.csv"
        with writing("--out", path) as tmp:
            write_csv(tmp, data)
        written.append(path)
    for group, (filename, title) in _PLOTS.items():
        path = out / filename
        _plot(path, title, [r for r in results if r.case.group == group])
        written.append(path)

    print(
        "1. Park et al.'s tests simulated with jaxcable.IntegratedModel() (Dyneema "
        f"SK78, {_DIAMETER_MM:g} mm, {_LENGTH_MM:g} mm long, "
        f"{spr} samples per ramp):"
    )
    print(f"  {'case':<20} {'peak [mm]':>10} {'residual after 1st unloading [mm]':>34}")
    for r in results:
        if r.error:
            print(f"  {r.case.name:<20} FAILED: {one_line(r.error)}")
        else:
            peak = float(np.max(r.elongation))
            print(f"  {r.case.name:<20} {peak:>10.3f} {r.residual:>34.3f}")
    return results, written


def _print_fit(request, result, num_tests: int, source: str, notes: list[str]) -> None:
    """The headline numbers of step 2: RMSE per test, parameters, warnings."""
    n = int(np.sum(result.num_samples))
    print()
    print(
        f"2. jaxcable.IntegratedModel fitted to {source}: {num_tests} tests, {n} "
        f"samples, multi-start x{request.method.multistart}"
        + (f", 1 sample in {request.every}" if request.every > 1 else "")
        + "."
    )
    for note in notes[1:]:
        print(f"  Note: {note}.")
    print(
        f"  RMSE per test {np.min(result.rmse_mm):.3g}-{np.max(result.rmse_mm):.3g} "
        f"mm ({np.min(result.rmse_percent):.3g}-{np.max(result.rmse_percent):.3g} % "
        "of the peak elongation); "
        + (
            f"converged in {result.num_steps} steps."
            if result.converged
            else f"NOT converged ({result.message})."
        )
    )
    print(f"  {'test':<30} {'RMSE [mm]':>10} {'RMSE [%]':>9}")
    for tid, mm, pct in zip(result.test_ids, result.rmse_mm, result.rmse_percent):
        print(f"  {tid[:30]:<30} {mm:>10.4f} {pct:>9.2f}")
    print(f"  {'parameter':<10} {'value':>12} {'± std err':>11}  unit")
    for p, v, s, u in zip(result.names, result.values, result.stderr, result.units):
        print(f"  {p:<10} {v:>12.5g} {s:>11.3g}  {u}")
    if result.warnings:
        print("  Identifiability warnings:")
        for w in result.warnings:
            print(f"    - {w}")
    if source.startswith("the bundled"):
        print(
            "  The data are synthetic: the model's defaults plus noise and one "
            "physical effect the model lacks (scripts/make_bundled_data.py), so the "
            "fit is imperfect by design: the residuals show what is missing."
        )


def _fit(request: DemoRequest, files: list, source: str, meter):
    """Step 2: the integrated model fitted to the data set, with its report."""
    model = IntegratedModel()
    # By default the identifiable Park parameters; the others keep their defaults:
    # with all fourteen free the fit does not converge within the demo's time.
    names = (
        names_option(request.fit, "--fit", model, "integrated")
        if request.fit
        else list(PARK_IDENTIFIABLE)
    )
    with contextlib.ExitStack() as stack:
        # The bundled files may live in a zip: made real files while they are read.
        paths = [
            stack.enter_context(importlib.resources.as_file(f))
            if not isinstance(f, pathlib.Path)
            else f
            for f in files
        ]
        tests = read_tests(paths, Reading(), request.every, meter)
    problem = Problem(model, tests, fit=names or None)
    result = run_fit(problem, "integrated", request.method, meter)
    failure = fit_failure(result)
    if failure is not None and not np.isfinite(result.loss):
        raise failure
    all_names = parameter_names(model)
    fixed = [n for n in all_names if n not in names]
    notes = [f"data: {source}, {len(tests)} tests"]
    if fixed:
        notes.append(
            f"fitted {len(names)} of {len(all_names)} parameters; "
            f"{', '.join(fixed)} kept at the defaults of IntegratedModel() "
            "(with all fourteen free the fit does not converge within the demo's time)"
        )
    if request.every > 1:
        notes.append(f"1 sample in {request.every} fitted (--every)")
    out = pathlib.Path(request.out)
    params = out / "params.json"  # one of `_outputs`
    result.to_json(params)
    written = write_report(
        out,
        result,
        tests,
        title="jaxcable demo: IntegratedModel fitted to the bundled data set",
        notes=notes,
        progress_meter=meter,
    )
    _print_fit(request, result, len(tests), source, notes)
    return failure, [params, *written], tests


def _diagnose(request: DemoRequest, tests, meter):
    """Step 3: `jaxcable diagnose` on the same tests, report in `out/diagnosis/`."""
    print()
    print(
        "3. What the fit gets wrong: jaxcable diagnose (every candidate extension "
        "fitted, scored on the last 30 % of every test, held out)."
    )
    problem = Problem(
        IntegratedModel(),
        tests,
        fit=tuple(request.fit.split(",")) if request.fit else None,
    )
    search = CandidateSearch(
        least_squares=dataclasses.replace(request.method, multistart=1)
    )
    diagnosis = run_diagnosis(problem, "integrated", search, meter)
    print()
    print(diagnosis.summary())
    folder = pathlib.Path(request.out) / "diagnosis"
    written = write_diagnosis_report(folder, diagnosis, tests)
    print(f"  wrote the diagnosis report to {folder}{os.sep}")
    return written


def _outputs(out: pathlib.Path, diagnose: bool) -> list[pathlib.Path]:
    """Every file the demo writes to the folder `out`."""
    names = [f"{c.name}.csv" for c in _CASES]
    names += [filename for filename, _ in _PLOTS.values()]
    names += ["params.json", *FIT_REPORT_FILES]
    if diagnose:
        names += [f"diagnosis/{name}" for name in DIAGNOSIS_REPORT_FILES]
    return [out / name for name in names]


def demo_command(args) -> int:
    """Run `jaxcable demo` with the parsed command line `args`; the exit status."""
    request = DemoRequest(
        out=args.out,
        samples_per_ramp=args.samples_per_ramp,
        data=args.data,
        fit=args.fit,
        method=least_squares(args),
        every=args.every,
        diagnose=not args.no_diagnose,
        quiet=args.quiet,
    )
    return run_demo(request)


def run_demo(request: DemoRequest) -> int:
    """`jaxcable demo` as `request` asks; the exit status."""
    # Bars on a terminal; the diagnosis's news on stdout with the rest of the demo.
    meter = progress_meter(request.quiet, sys.stdout)
    # Checked first: no data, no demo (and no half-written output folder).
    files, source = _data(request.data)
    out = pathlib.Path(request.out)
    outputs = _outputs(out, diagnose=request.diagnose)
    refuse_inputs(
        [("--out", path) for path in outputs],
        [("--data", f) for f in files if isinstance(f, pathlib.Path)],
    )
    make_folder(out, "--out")
    say_replacing(outputs, "--out")
    with write_errors("--out", out):
        results, written = _simulate(request.samples_per_ramp, out)
        failure, fit_written, tests = _fit(request, files, source, meter)
        written += fit_written
        if request.diagnose:
            written += _diagnose(request, tests, meter)
    print()
    print(f"Wrote {len(written)} files to {out}{os.sep}: ", end="")
    print(", ".join(p.name for p in written))
    failed = [r.case.name for r in results if r.error]
    if failed:
        raise CliError(
            f"{len(failed)} of {len(results)} simulated demo cases failed "
            f"({', '.join(failed)}); see the summary above.",
            status=1,
        )
    if failure is not None:
        raise failure
    return 0
