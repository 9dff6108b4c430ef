"""The `jaxcable` command line: `jaxcable simulate`, `jaxcable fit` and `jaxcable demo`.

Errors in the user's input (files, arguments) exit with status 2 and one line on
stderr saying what is wrong and where; a simulation or fit that fails exits with
status 1.
"""

import argparse
import contextlib
import dataclasses
import importlib.metadata
import importlib.resources
import json
import os
import pathlib
import sys
import warnings
from collections.abc import Sequence
from typing import NamedTuple

import equinox as eqx
import jax
import numpy as np

from .._cable import Cable
from .._io import TestData, read_csv, read_test, write_csv


_PROG = "jaxcable"

# Model name on the command line -> class name on the `jaxcable` package. Resolved at
# run time, so that a model added to the package needs only a line here.
_MODELS = {
    "integrated": "IntegratedModel",
    "five-element": "FiveElementModel",
    "hooke": "HookeModel",
    "burgers": "BurgersModel",
    "bouc-wen": "BoucWenModel",
}
_DEFAULT_MODEL = "integrated"


class _CliError(Exception):
    """An error to report as one line on stderr, with an exit status."""

    def __init__(self, message: str, status: int = 2):
        super().__init__(message)
        self.status = status


class _Parser(argparse.ArgumentParser):
    # argparse prints the usage and an error on two lines; we promise one line.
    def error(self, message):
        raise _CliError(f"{message} (see '{self.prog} --help')")


def _one_line(message) -> str:
    return " ".join(str(message).split())


def _show_progress(args) -> bool:
    # Carriage-return bars only on a terminal: logs and pipes get none.
    return not getattr(args, "quiet", False) and sys.stderr.isatty()


# ----------------------------------------------------------------------------------
# Models and parameters


def _model_class(name: str) -> type:
    import jaxcable

    from .._models import AbstractCableModel

    attribute = _MODELS[name]
    cls = getattr(jaxcable, attribute, None)
    if cls is None:
        raise _CliError(
            f"model '{name}' needs jaxcable.{attribute}, which this version of "
            f"jaxcable ({_version()}) does not have."
        )
    if not (isinstance(cls, type) and issubclass(cls, AbstractCableModel)):
        raise _CliError(f"jaxcable.{attribute} is not a cable model.")
    return cls


def _model_name(model) -> str | None:
    """The command-line name of a model instance's class, or None."""
    names = {attribute: name for name, attribute in _MODELS.items()}
    return names.get(type(model).__name__)


def _parameter_names(model) -> list[str]:
    """The model's fittable parameters: its inexact-array fields."""
    return [
        f.name
        for f in dataclasses.fields(model)
        if eqx.is_inexact_array(getattr(model, f.name))
    ]


def _read_json(path: str, what: str):
    try:
        text = pathlib.Path(path).read_text(encoding="utf-8")
    except OSError as e:
        raise _CliError(f"{path}: cannot read {what}: {e.strerror}.") from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as e:
        raise _CliError(
            f"{path}, line {e.lineno}, column {e.colno}: invalid JSON: {e.msg}."
        ) from None


def _check_plain_params(path: str, params, cls: type, name: str) -> dict:
    """Validate a plain {parameter name: value (SI)} object for model `name`."""
    if not isinstance(params, dict):
        raise _CliError(
            f"{path}: expected a JSON object of parameter name -> value (SI units), "
            f"got {type(params).__name__}."
        )
    fields = {f.name: f for f in dataclasses.fields(cls)}
    for key, value in params.items():
        if key not in fields:
            raise _CliError(
                f"{path}, parameter '{key}': not a parameter of model '{name}' "
                f"(its parameters: {', '.join(fields)})."
            )
        static = fields[key].metadata.get("static", False)
        number = isinstance(value, int | float) and not isinstance(value, bool)
        if not number and not (static and isinstance(value, str | bool | int | float)):
            raise _CliError(
                f"{path}, parameter '{key}': {json.dumps(value)} is not a number "
                "(SI units)."
            )
    return params


def _build_model(cls: type, name: str, params: dict, params_path: str | None):
    where = params_path or "default parameters"
    try:
        return cls(**params)
    except (TypeError, ValueError) as e:
        raise _CliError(f"{where}: cannot build model '{name}': {e}") from None


def _select_test(path: str, result, test: str | None, purpose: str):
    """The model of one test of a fit with per-test parameters (`--test`)."""
    if not result.per_test:
        return result.model
    ids = list(result.test_ids)
    if test is None:
        raise _CliError(
            f"{path}: parameters {', '.join(result.per_test)} were fitted per test "
            f"({', '.join(ids)}); {purpose}"
        )
    if test in ids:
        return result.models[ids.index(test)]
    if test.isdigit() and int(test) < len(ids):
        return result.models[int(test)]
    raise _CliError(
        f"--test {test}: not a test of {path} (its tests: "
        f"{', '.join(f'{i} {t}' for i, t in enumerate(ids))})."
    )


def _resolve_model(args, *, per_test_hint: str) -> tuple[str, object]:
    """(name, model) from `--model` and `--params`.

    `--params` is either a plain {name: value} object of SI values replacing the
    model's defaults, or a PARAMS.json written by `jaxcable fit`
    (`FitResult.to_json`), whose model it names; `--model`, when given, must agree.
    """
    from .._fit import FitResult

    requested = args.model
    if not args.params:
        name = requested or _DEFAULT_MODEL
        return name, _build_model(_model_class(name), name, {}, None)
    path = args.params
    doc = _read_json(path, "parameters")
    if isinstance(doc, dict) and doc.get("format") == "jaxcable-params":
        result = FitResult.from_json(path)  # ValueError -> exit 2, naming the file
        name = _model_name(result.model)
        if name is None:
            raise _CliError(
                f"{path}: model {type(result.model).__name__} has no command-line "
                f"name (known: {', '.join(_MODELS)})."
            )
        if requested is not None and requested != name:
            raise _CliError(
                f"{path}: holds a fit of model '{name}', not '{requested}' "
                f"(--model); drop --model or pass --model {name}."
            )
        model = _select_test(path, result, getattr(args, "test", None), per_test_hint)
        return name, model
    name = requested or _DEFAULT_MODEL
    cls = _model_class(name)
    params = _check_plain_params(path, doc, cls, name)
    return name, _build_model(cls, name, params, path)


def _params_metadata(model) -> str:
    """The model's parameters as compact JSON (SI), for an output file's metadata."""
    values = {}
    for name in _parameter_names(model):
        v = np.asarray(getattr(model, name), float)
        values[name] = float(v) if v.ndim == 0 else v.tolist()
    return json.dumps(values, separators=(",", ":"))


# ----------------------------------------------------------------------------------
# simulate


def _check_force(data: TestData, cable: Cable) -> None:
    # The simulation checks these too, but only knows sample indices, not file lines.
    force = data.force
    limit = float(cable.breaking_load)
    negative = np.flatnonzero(force < 0)
    if negative.size:
        i = int(negative[0])
        raise _CliError(
            f"{data.locate(i, 'force_N')}: force {force[i]:g} N is negative (a cable "
            "cannot push)."
        )
    above = np.flatnonzero(force > limit)
    if above.size:
        i = int(above[0])
        raise _CliError(
            f"{data.locate(i, 'force_N')}: force {force[i]:g} N exceeds the cable's "
            f"breaking load ({limit:g} N)."
        )


def _first_bad_sample(traj) -> int | None:
    bad = np.flatnonzero(~np.isfinite(np.asarray(traj.strain)))
    return int(bad[0]) if bad.size else None


def _simulate(args) -> int:
    if args.input.lower().endswith(".json"):
        return _simulate_protocol(args)
    return _simulate_history(args)


def _simulate_history(args) -> int:
    import jaxcable

    data = read_csv(args.input)
    cable = data.cable()
    _check_force(data, cable)
    name, model = _resolve_model(args, per_test_hint=_SIMULATE_PER_TEST)
    # The forces as read, as `fit` drives its model: a PARAMS.json re-simulates the
    # file it was fitted to exactly as the fit saw it.
    traj = jaxcable.simulate_force_history(
        model, cable, data.time, data.force, throw=False
    )
    if traj.result != jaxcable.RESULTS.successful:
        i = _first_bad_sample(traj)
        where = data.locate(i) if i is not None else str(args.input)
        raise _CliError(
            f"{where}: model '{name}' failed: {jaxcable.RESULTS[traj.result]}",
            status=1,
        )
    metadata = dict(data.metadata)
    # Record the cable the simulation assumed where the file left it to defaults.
    metadata.setdefault("diameter_mm", float(cable.diameter) * 1e3)
    metadata.setdefault("rate_mm_per_min", float(cable.speed) * 1e3 * 60)
    metadata["model"] = name
    if args.params:
        metadata["model_params"] = _params_metadata(model)
    out = dataclasses.replace(
        data, elongation=np.asarray(traj.elongation), metadata=metadata
    )
    write_csv(args.out, out)
    print(f"wrote {args.out} ({data.num_samples} samples, model '{name}')")
    return 0


def _simulate_protocol(args) -> int:
    import jaxcable

    from .._io import read_protocol

    spec = read_protocol(args.input)
    name, model = _resolve_model(args, per_test_hint=_SIMULATE_PER_TEST)
    traj = jaxcable.simulate_rate_test(model, spec.cable, spec.protocol, throw=False)
    if traj.result != jaxcable.RESULTS.successful:
        i = _first_bad_sample(traj)
        segment = spec.segment_of(i) if i is not None else None
        where = args.input if segment is None else f"{args.input}, segments[{segment}]"
        raise _CliError(
            f"{where}: model '{name}' failed: {jaxcable.RESULTS[traj.result]}",
            status=1,
        )
    metadata = {
        **spec.metadata,
        "protocol": pathlib.Path(args.input).name,
        "model": name,
    }
    if args.params:
        metadata["model_params"] = _params_metadata(model)
    data = TestData(
        time=np.asarray(traj.time),
        force=np.asarray(traj.force),
        elongation=np.asarray(traj.elongation),
        metadata=metadata,
    )
    write_csv(args.out, data)
    duration = float(data.time[-1])
    print(
        f"wrote {args.out} ({data.num_samples} samples over {duration:.6g} s, "
        f"model '{name}')"
    )
    return 0


_SIMULATE_PER_TEST = "choose the test to simulate with --test ID (or its index)."


# ----------------------------------------------------------------------------------
# fit


def _names_option(value: str | None, option: str, model, name: str) -> list[str]:
    """Parse a comma-separated `--fit` / `--per-test` list of parameter names."""
    if value is None:
        return []
    names = [n.strip() for n in value.split(",")]
    available = _parameter_names(model)
    for n in names:
        if not n:
            raise _CliError(f"{option} {value!r}: an empty name.")
        if n not in available:
            raise _CliError(
                f"{option}: '{n}' is not a parameter of model '{name}' (its "
                f"parameters: {', '.join(available)})."
            )
    if len(set(names)) != len(names):
        raise _CliError(f"{option} {value!r}: a name is repeated.")
    return names


def _thin(data: TestData, every: int) -> TestData:
    """Every `every`-th sample of `data` (the first and last kept)."""
    if every <= 1:
        return data
    index = np.arange(0, data.num_samples, every)
    if index[-1] != data.num_samples - 1:
        index = np.append(index, data.num_samples - 1)

    def take(x):
        return None if x is None else np.asarray(x)[index]

    return dataclasses.replace(
        data,
        time=data.time[index],
        force=data.force[index],
        elongation=take(data.elongation),
        temperature=take(data.temperature),
        extra={k: v[index] for k, v in data.extra.items()},
        lines=take(data.lines),
        mask=data.mask[index],
        force_raw=take(data.force_raw),
    )


def _read_tests(
    paths: Sequence, options: dict, every: int, progress: bool
) -> list[TestData]:
    """Read measured tests with `read_test` (canonical or raw), with elongation,
    thinned to every `every`-th sample."""
    from .._report import Progress

    tests = []
    with Progress("reading", len(paths), enabled=progress) as bar:
        for path in paths:
            data = read_test(path, **options)
            if data.elongation is None:
                raise _CliError(
                    f"{path}: no elongation column; a fit needs the measured "
                    "elongation (a column elongation_mm, or name it with --columns)."
                )
            data.cable()  # raises, naming the file, when length_mm is missing
            tests.append(_thin(data, every))
            bar.advance(note=pathlib.Path(path).name)
    return tests


def _data_options(args) -> dict:
    """`read_test` keyword arguments from the data options (`_add_data_options`)."""
    return dict(
        columns=args.columns,
        skip_rows=args.skip_rows,
        length_mm=args.length_mm,
        diameter_mm=args.diameter_mm,
        rate_mm_per_min=args.rate_mm_per_min,
        detect_slack=not args.no_slack,
    )


def _describe_tests(tests: Sequence[TestData], every: int) -> list[str]:
    lines = []
    for t in tests:
        name = pathlib.Path(t.source).name if t.source else t.metadata.get("id", "")
        masked = int(np.sum(~t.mask))
        text = f"  {name}: {t.num_samples} samples"
        if every > 1:
            text += f" (1 in {every} kept)"
        if masked:
            text += f", {masked} masked"
        report = t.slack_report
        if report is not None and report.stretches:
            where = ", ".join(
                f"lines {s.lines[0]}-{s.lines[1]}"
                if s.lines is not None
                else f"samples {s.start}-{s.stop - 1}"
                for s in report.stretches
            )
            text += f" (slack: {where})"
        lines.append(text)
    return lines


def _run_fit(model, name: str, tests, *, fit, per_test, args, progress: bool):
    """`jaxcable.fit` with the command line's options; identifiability warnings are
    returned in the result (and printed with the summary), not issued."""
    import jaxcable

    from .._report import Progress

    n = sum(int(np.sum(t.mask)) for t in tests)
    label = f"fitting {name} to {len(tests)} test(s), {n} samples"
    with Progress(label, enabled=progress), warnings.catch_warnings():
        warnings.simplefilter("ignore", jaxcable.IdentifiabilityWarning)
        try:
            return jaxcable.fit(
                model,
                tests,
                fit=fit or None,
                per_test=per_test or None,
                multistart=args.starts,
                max_steps=args.max_steps,
                key=jax.random.key(args.seed),
                throw=False,
            )
        except ValueError as e:
            raise _CliError(f"cannot fit model '{name}': {e}") from None


def _require_folder_of(path: str, option: str) -> None:
    parent = pathlib.Path(path).resolve().parent
    if not parent.is_dir():
        raise _CliError(f"{option} {path}: folder {parent} does not exist.")


def _make_folder(path: pathlib.Path, option: str) -> None:
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise _CliError(
            f"{option} {path}: cannot create the folder: {e.strerror}."
        ) from None


def _fit_failure(result) -> _CliError | None:
    if not np.isfinite(result.loss):
        return _CliError(
            f"the fit failed from every start ({result.message}); try other start "
            "values (--params) or fewer parameters (--fit).",
            status=1,
        )
    if not result.converged:
        return _CliError(
            f"the fit did not converge ({result.message}); the best start was "
            "written for inspection. Try more --max-steps, other start values "
            "(--params) or fewer parameters (--fit).",
            status=1,
        )
    return None


def _fit(args) -> int:
    from .._report import write_report

    progress = _show_progress(args)
    name, model = _resolve_model(
        args,
        per_test_hint="use a plain {name: value} file of start values with --params.",
    )
    fit_names = _names_option(args.fit, "--fit", model, name)
    per_test = _names_option(args.per_test, "--per-test", model, name)
    _require_folder_of(args.out, "--out")
    tests = _read_tests(args.data, _data_options(args), args.every, progress)
    print(f"read {len(tests)} file(s):")
    print("\n".join(_describe_tests(tests, args.every)))
    result = _run_fit(
        model,
        name,
        tests,
        fit=fit_names,
        per_test=per_test,
        args=args,
        progress=progress,
    )
    failure = _fit_failure(result)
    print()
    print(result.summary())
    print()
    if failure is not None and not np.isfinite(result.loss):
        raise failure
    result.to_json(args.out)
    print(f"wrote {args.out}")
    if args.report:
        out = pathlib.Path(args.report)
        _make_folder(out, "--report")
        notes = [f"files: {', '.join(str(p) for p in args.data)}"]
        if args.no_slack:
            notes.append("slack detection off (--no-slack)")
        if args.every > 1:
            notes.append(f"1 sample in {args.every} fitted (--every)")
        written = write_report(
            out,
            result,
            tests,
            title=f"jaxcable fit: model '{name}'",
            notes=notes,
            progress=progress,
        )
        print(
            f"wrote the report to {out}{os.sep}: {', '.join(p.name for p in written)}"
        )
    if failure is not None:
        raise failure
    return 0


# ----------------------------------------------------------------------------------
# diagnose: what the model gets wrong, the named cause, the gain on held-out data


def _run_diagnosis(model, name, tests, *, args, progress, log):
    """`jaxcable.diagnose` with the command line's options."""
    from .._diagnose import diagnose
    from .._report import Progress

    bar = Progress("diagnosing", enabled=progress)
    with bar:
        try:
            return diagnose(
                tests,
                model,
                fit_names=args.fit.split(",") if args.fit else None,
                candidates=args.candidates.split(",") if args.candidates else None,
                split=args.split,
                holdout=args.holdout,
                folds=args.folds,
                multistart=args.starts,
                max_steps=args.max_steps,
                key=jax.random.key(args.seed),
                progress=lambda message: print(message, file=log, flush=True),
            )
        except ValueError as e:
            raise _CliError(f"cannot diagnose with model '{name}': {e}") from None


def _diagnose(args) -> int:
    from .._report import write_diagnosis_report

    progress = _show_progress(args)
    # With --json, stdout carries the one JSON object; everything else goes to stderr.
    log = sys.stderr if args.json else sys.stdout
    name, model = _resolve_model(
        args, per_test_hint="diagnose fits shared parameters; give start values."
    )
    if args.report:
        _require_folder_of(args.report, "--report")
    tests = _read_tests(args.data, _data_options(args), args.every, progress)
    print(f"read {len(tests)} file(s):", file=log)
    print("\n".join(_describe_tests(tests, args.every)), file=log)
    diagnosis = _run_diagnosis(
        model, name, tests, args=args, progress=progress, log=log
    )
    if args.json:
        print(diagnosis.to_json())
    else:
        print(file=log)
        print(diagnosis.summary(), file=log)
    if args.report:
        out = pathlib.Path(args.report)
        _make_folder(out, "--report")
        written = write_diagnosis_report(out, diagnosis, tests)
        print(
            f"wrote the report to {out}{os.sep}: {', '.join(p.name for p in written)}",
            file=log,
        )
    return 0


# ----------------------------------------------------------------------------------
# demo: Park's tests simulated, and a fit of the bundled data set


class _DemoCase(NamedTuple):
    name: str
    label: str
    group: str
    force_max: float  # N
    cycles: int
    rate: float  # mm/min


_DEMO_LENGTH_MM = 300.0
_DEMO_DIAMETER_MM = 3.0
# Park et al. Section 4: the rate effect (Fig. 3) and 10-cycle tests (Fig. 4).
_DEMO_CASES = (
    _DemoCase("rate_3mm_per_min", "3 mm/min", "rate", 100.0, 1, 3.0),
    _DemoCase("rate_50mm_per_min", "50 mm/min", "rate", 100.0, 1, 50.0),
    _DemoCase("cycles10_100N", "100 N", "cycles", 100.0, 10, 3.0),
    _DemoCase("cycles10_150N", "150 N", "cycles", 150.0, 10, 3.0),
)
_DEMO_PLOTS = {
    "rate": (
        "rate_effect.png",
        "Rate effect: 300 mm, 0-100 N, one cycle (Park Fig. 3)",
    ),
    "cycles": (
        "cycles10.png",
        "10 cycles at 3 mm/min, 300 mm (Park Fig. 4)",
    ),
}
# The parameters the demo fits to the bundled data. The other four keep their
# defaults: with all twelve free the fit does not converge within the demo's time
# (hardening beta, gamma and the long-term retardation law lambda1, lambda2 are nearly
# degenerate on these tests: correlations > 0.999, a near-zero singular value).
_DEMO_FIT = ("E1c", "E1r", "E2c", "t_c", "eta0", "E2r", "t_r1", "E3r")
_DEMO_STARTS = 2


class _DemoResult(NamedTuple):
    case: _DemoCase
    time: np.ndarray  # s
    force: np.ndarray  # N
    elongation: np.ndarray  # mm
    residual: float  # mm, at the end of the first unloading
    error: str  # "" when successful


def _run_demo_case(
    model, case: _DemoCase, samples_per_ramp: int, samples: int
) -> _DemoResult:
    import jaxcable

    cable = Cable(
        length=_DEMO_LENGTH_MM * 1e-3,
        diameter=_DEMO_DIAMETER_MM * 1e-3,
        speed=case.rate * 1e-3 / 60,
    )
    # Padded to a common length so that all cases share one compilation.
    protocol = jaxcable.Protocol.cycles(
        case.force_max, case.cycles, samples_per_ramp=samples_per_ramp
    ).pad(samples)
    traj = jaxcable.simulate_rate_test(model, cable, protocol, throw=False)
    error = ""
    if traj.result != jaxcable.RESULTS.successful:
        error = jaxcable.RESULTS[traj.result]
    valid = np.asarray(traj.mask)
    elongation = np.asarray(traj.elongation)[valid] * 1e3
    # Sample 0 is the unloaded start; the first unloading ends 2 ramps later.
    residual = float(elongation[2 * samples_per_ramp])
    return _DemoResult(
        case,
        np.asarray(traj.time)[valid],
        np.asarray(traj.force)[valid],
        elongation,
        residual,
        error,
    )


def _demo_plot(path: pathlib.Path, title: str, results: list[_DemoResult]) -> None:
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
    fig.savefig(path, dpi=100)


def _bundled_files() -> list:
    """The bundled data set's CSV files (`jaxcable/data/*.csv`), sorted by name."""
    folder = importlib.resources.files("jaxcable").joinpath("data")
    if not folder.is_dir():
        return []
    return sorted(
        (p for p in folder.iterdir() if p.name.endswith(".csv")), key=lambda p: p.name
    )


def _demo_data(args) -> tuple[list, str]:
    """(files, description) of the data set the demo fits; fails when it is empty."""
    if args.data is not None:
        folder = pathlib.Path(args.data)
        if not folder.is_dir():
            raise _CliError(f"--data {args.data}: not a folder.")
        files = sorted(folder.glob("*.csv"))
        if not files:
            raise _CliError(f"--data {args.data}: no *.csv files in this folder.")
        return files, str(folder)
    files = _bundled_files()
    if not files:
        raise _CliError(
            "the bundled data set is missing: jaxcable/data/ has no *.csv files. In a "
            "source checkout, make it with 'python scripts/make_bundled_data.py', or "
            "pass --data DIR (a folder of canonical CSV files).",
            status=1,
        )
    return files, "the bundled data set (jaxcable/data/, synthetic)"


def _demo_simulate(args, out: pathlib.Path) -> tuple[list, list[pathlib.Path]]:
    import jaxcable

    model = jaxcable.IntegratedModel()
    spr = args.samples_per_ramp
    samples = 1 + 2 * spr * max(c.cycles for c in _DEMO_CASES)
    results = [_run_demo_case(model, c, spr, samples) for c in _DEMO_CASES]

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
                "length_mm": _DEMO_LENGTH_MM,
                "diameter_mm": _DEMO_DIAMETER_MM,
                "rate_mm_per_min": r.case.rate,
                "protocol": f"{r.case.cycles} x 0-{r.case.force_max:g} N",
                "model": "integrated (default parameters), simulated by jaxcable demo",
            },
        )
        path = out / f"{r.case.name}.csv"
        write_csv(path, data)
        written.append(path)
    for group, (filename, title) in _DEMO_PLOTS.items():
        path = out / filename
        _demo_plot(path, title, [r for r in results if r.case.group == group])
        written.append(path)

    print(
        "1. Park et al.'s tests simulated with jaxcable.IntegratedModel() (Dyneema "
        f"SK78, {_DEMO_DIAMETER_MM:g} mm, {_DEMO_LENGTH_MM:g} mm long, "
        f"{args.samples_per_ramp} samples per ramp):"
    )
    print(f"  {'case':<20} {'peak [mm]':>10} {'residual after 1st unloading [mm]':>34}")
    for r in results:
        if r.error:
            print(f"  {r.case.name:<20} FAILED: {_one_line(r.error)}")
        else:
            peak = float(np.max(r.elongation))
            print(f"  {r.case.name:<20} {peak:>10.3f} {r.residual:>34.3f}")
    return results, written


def _demo_fit(args, out: pathlib.Path, files: list, source: str, progress: bool):
    import jaxcable

    from .._report import write_report

    model = jaxcable.IntegratedModel()
    names = (
        _names_option(args.fit, "--fit", model, "integrated")
        if args.fit
        else list(_DEMO_FIT)
    )
    with contextlib.ExitStack() as stack:
        paths = [
            stack.enter_context(importlib.resources.as_file(f))
            if not isinstance(f, pathlib.Path)
            else f
            for f in files
        ]
        tests = _read_tests(paths, {}, args.every, progress)
    result = _run_fit(
        model,
        "integrated",
        tests,
        fit=names,
        per_test=[],
        args=args,
        progress=progress,
    )
    failure = _fit_failure(result)
    if failure is not None and not np.isfinite(result.loss):
        raise failure
    all_names = _parameter_names(model)
    fixed = [n for n in all_names if n not in names]
    notes = [f"data: {source}, {len(tests)} tests"]
    if fixed:
        notes.append(
            f"fitted {len(names)} of {len(all_names)} parameters; "
            f"{', '.join(fixed)} kept at the defaults of IntegratedModel() "
            "(with all twelve free the fit does not converge within the demo's time)"
        )
    if args.every > 1:
        notes.append(f"1 sample in {args.every} fitted (--every)")
    params = out / "params.json"
    result.to_json(params)
    written = write_report(
        out,
        result,
        tests,
        title="jaxcable demo: IntegratedModel fitted to the bundled data set",
        notes=notes,
        progress=progress,
    )
    n = int(np.sum(result.num_samples))
    print()
    print(
        f"2. jaxcable.IntegratedModel fitted to {source}: {len(tests)} tests, {n} "
        f"samples, multi-start x{args.starts}"
        + (f", 1 sample in {args.every}" if args.every > 1 else "")
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
    return failure, [params, *written], tests


def _demo_diagnose(args, out: pathlib.Path, tests, progress: bool):
    """Step 3 of the demo: `jaxcable diagnose` on the same tests, report in
    `out/diagnosis/`."""
    import jaxcable

    from .._report import write_diagnosis_report

    print()
    print(
        "3. What the fit gets wrong: jaxcable diagnose (every candidate extension "
        "fitted, scored on the last 30 % of every test, held out)."
    )
    diagnosis = _run_diagnosis(
        jaxcable.IntegratedModel(),
        "integrated",
        tests,
        args=argparse.Namespace(
            fit=args.fit,
            candidates=None,
            split="time",
            holdout=0.3,
            folds=None,
            starts=1,
            max_steps=args.max_steps,
            seed=args.seed,
        ),
        progress=progress,
        log=sys.stdout,
    )
    print()
    print(diagnosis.summary())
    folder = out / "diagnosis"
    written = write_diagnosis_report(folder, diagnosis, tests)
    print(f"  wrote the diagnosis report to {folder}{os.sep}")
    return written


def _demo(args) -> int:
    if args.samples_per_ramp < 2:
        raise _CliError(
            f"--samples-per-ramp must be at least 2, got {args.samples_per_ramp}."
        )
    progress = _show_progress(args)
    # Checked first: no data, no demo (and no half-written output folder).
    files, source = _demo_data(args)
    out = pathlib.Path(args.out)
    _make_folder(out, "--out")
    results, written = _demo_simulate(args, out)
    failure, fit_written, tests = _demo_fit(args, out, files, source, progress)
    written += fit_written
    if not args.no_diagnose:
        written += _demo_diagnose(args, out, tests, progress)
    print()
    print(f"Wrote {len(written)} files to {out}{os.sep}: ", end="")
    print(", ".join(p.name for p in written))
    failed = [r.case.name for r in results if r.error]
    if failed:
        raise _CliError(
            f"{len(failed)} of {len(results)} simulated demo cases failed "
            f"({', '.join(failed)}); see the summary above.",
            status=1,
        )
    if failure is not None:
        raise failure
    return 0


# ----------------------------------------------------------------------------------
# Entry point


def _version() -> str:
    try:
        return importlib.metadata.version("jaxcable")
    except importlib.metadata.PackageNotFoundError:  # pragma: no cover
        return "unknown"


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"{text} must be at least 1")
    return value


def _non_negative_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"{text} must be at least 0")
    return value


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not (np.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"{text} must be a positive number")
    return value


def _add_model_options(parser, params_help: str) -> None:
    parser.add_argument(
        "--model",
        choices=list(_MODELS),
        default=None,
        help=f"the cable model (default: the model of a --params file written by "
        f"'jaxcable fit', else {_DEFAULT_MODEL}, Park et al.)",
    )
    parser.add_argument("--params", metavar="PARAMS.json", help=params_help)


def _add_data_options(parser) -> None:
    """The options that say how to read the data files (`fit`, `diagnose`)."""
    raw = parser.add_argument_group("reading raw exports")
    raw.add_argument(
        "--columns",
        metavar="NAMES",
        help="the files' columns in order with their units, e.g. "
        "time_s,elongation_mm,force_N (also time_ms, time_min, time_h, force_kN, "
        "elongation_m, temperature_C; '-' for a column to ignore); default: from "
        "the header",
    )
    raw.add_argument(
        "--skip-rows",
        type=_non_negative_int,
        metavar="N",
        help="lines before the first data row (default: detected)",
    )
    raw.add_argument(
        "--length-mm",
        type=_positive_float,
        metavar="X",
        help="free length of the cable, mm (replaces the files' length_mm)",
    )
    raw.add_argument(
        "--diameter-mm",
        type=_positive_float,
        metavar="X",
        help="diameter, mm (replaces the files' diameter_mm; default 3)",
    )
    raw.add_argument(
        "--rate-mm-per-min",
        type=_positive_float,
        metavar="X",
        help="crosshead speed, mm/min (replaces the files' rate_mm_per_min; default 3)",
    )
    raw.add_argument(
        "--no-slack",
        action="store_true",
        help="do not detect slack stretches (by default, stretches where the force "
        "is about zero while the elongation moves at the crosshead's speed are "
        "masked and not fitted; a fast recovery at zero force can look like one)",
    )


def _add_solver_options(parser, starts: int) -> None:
    parser.add_argument(
        "--starts",
        type=_positive_int,
        default=starts,
        metavar="N",
        help=f"number of starts of the multi-start fit (default: {starts})",
    )
    parser.add_argument(
        "--seed",
        type=int,
        default=0,
        metavar="N",
        help="seed of the random start perturbations (default: 0)",
    )
    parser.add_argument(
        "--max-steps",
        type=_positive_int,
        default=256,
        metavar="N",
        help="Levenberg-Marquardt steps per start (default: 256)",
    )
    parser.add_argument(
        "--every",
        type=_positive_int,
        default=1,
        metavar="K",
        help="fit every K-th sample only, to thin dense exports (default: 1, all)",
    )
    parser.add_argument(
        "--quiet",
        action="store_true",
        help="no progress bar (it is shown only when stderr is a terminal)",
    )


def _parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog=_PROG,
        description="Differentiable creep models of polymer (Dyneema) cables.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    commands = parser.add_subparsers(
        dest="command", metavar="COMMAND", required=True, parser_class=_Parser
    )

    sim = commands.add_parser(
        "simulate",
        help="simulate a rate-driven protocol (JSON) or a force history (CSV)",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description=(
            "Simulate a cable model and write the result in the canonical CSV "
            "format\n(time_s,force_N,elongation_mm with '# key: value' metadata).\n\n"
            "PROTOCOL.json: a rate-driven test as a tensile tester runs it; the time "
            "of each\nforce sample is solved by the model. Example:\n"
            '  {"length_mm": 300, "diameter_mm": 3, "rate_mm_per_min": 3,\n'
            '   "segments": [{"cycles": 10, "force_max_N": 100, "samples_per_ramp": '
            "200},\n"
            '                {"rest_h": 24},\n'
            '                {"ramp_to_N": 50, "samples": 100},\n'
            '                {"hold_s": 60, "force_N": 50}]}\n'
            "Segments: cycles (force_max_N, force_min_N=0, samples_per_ramp=200, "
            "peak_hold_s=0),\nramp_to_N (samples=100), hold_s (force_N = the current "
            "force, samples=10),\nrest_h or rest_s (at 0 N, samples=24). diameter_mm "
            "and rate_mm_per_min default to 3;\nid, material and description are "
            "copied to the output.\n\n"
            "HISTORY.csv: a time-stamped force history in the canonical CSV format "
            "('# length_mm: ...'\nmetadata, then time_s,force_N[,...]); the same file "
            "is written with elongation_mm filled\nin (other columns and metadata "
            "kept). The cable is taken from the metadata:\nlength_mm (required), "
            "diameter_mm (default 3) and rate_mm_per_min (default 3)."
        ),
    )
    sim.add_argument(
        "input",
        metavar="PROTOCOL.json|HISTORY.csv",
        help="a protocol (.json) or a force history (.csv)",
    )
    _add_model_options(
        sim,
        "model parameters: a PARAMS.json written by 'jaxcable fit', or a JSON object "
        "of parameter name -> value (SI units) replacing the model's defaults "
        "(default: the model's documented defaults, Dyneema SK78 3 mm for "
        "integrated)",
    )
    sim.add_argument(
        "--test",
        metavar="ID",
        help="with a PARAMS.json fitted with per-test parameters: the test (id or "
        "index) whose values to use",
    )
    sim.add_argument(
        "--out", metavar="OUT.csv", required=True, help="the file to write"
    )
    sim.set_defaults(run=_simulate)

    fit = commands.add_parser(
        "fit",
        help="fit a model to measured tests",
        description=(
            "Fit a cable model to one or many measured tests at once by least squares "
            "on elongation (Levenberg-Marquardt, multi-start; see jaxcable.fit). "
            "Material parameters are shared by all tests. Files are read with "
            "jaxcable.read_test: canonical CSV files or raw tensile-tester exports "
            "(other separators and encodings, preamble and unit rows, quoted "
            "numbers); slack stretches are detected, masked and not fitted. Writes "
            "the fitted parameters as PARAMS.json (use it with 'jaxcable simulate "
            "--params') and prints the RMSE of every test (mm and % of its peak "
            "elongation), the parameters with standard errors and correlations, and "
            "warnings naming parameters the data cannot identify."
        ),
    )
    fit.add_argument("data", nargs="+", metavar="DATA.csv", help="the measured tests")
    _add_model_options(
        fit,
        "start values: a PARAMS.json written by 'jaxcable fit', or a JSON object of "
        "parameter name -> value (SI units) replacing the model's defaults; fixed "
        "parameters keep these values",
    )
    fit.add_argument(
        "--out", metavar="PARAMS.json", required=True, help="the file to write"
    )
    fit.add_argument(
        "--report",
        metavar="DIR",
        help="write plots (fit_loops.png: measured vs model force-elongation, one "
        "panel per test; fit_residuals.png: residuals vs time) and tables "
        "(summary.md, rmse.csv) to this folder",
    )
    _add_data_options(fit)
    what = fit.add_argument_group("what to fit")
    what.add_argument(
        "--fit",
        metavar="NAMES",
        help="comma-separated parameters to fit (default: all); the others keep "
        "their start values",
    )
    what.add_argument(
        "--per-test",
        metavar="NAMES",
        help="comma-separated parameters fitted with one value per test",
    )
    _add_solver_options(fit, starts=4)
    fit.set_defaults(run=_fit)

    diag = commands.add_parser(
        "diagnose",
        help="find what the model gets wrong and name the physical cause",
        description=(
            "Fit the base model (default: the integrated model) to the measured "
            "tests with the last part of every test held out, analyse its residuals "
            "for structure (time under load, force, loading vs unloading, cycle, "
            "rest time, length, rate, temperature, autocorrelation), fit every "
            "candidate extension (hereditary, second_retardation, "
            "stress_nonlinear_creep, temperature, termination_compliance, "
            "bedding_in, sensor_drift), score each on the held-out data and by BIC, "
            "and name the cause: the significant candidate of largest held-out gain, "
            "or none. Reads files like 'jaxcable fit'. See jaxcable.diagnose."
        ),
    )
    diag.add_argument("data", nargs="+", metavar="DATA.csv", help="the measured tests")
    _add_model_options(
        diag,
        "start values of the base model: a PARAMS.json written by 'jaxcable fit', or "
        "a JSON object of parameter name -> value (SI units)",
    )
    diag.add_argument(
        "--json",
        action="store_true",
        help="print one JSON object on stdout (named_cause, candidates, "
        "base_heldout_rmse_mm, extended_heldout_rmse_mm, ...); the log goes to stderr",
    )
    diag.add_argument(
        "--report",
        metavar="DIR",
        help="write diagnosis.json, summary.md and plots before/after "
        "(residuals.png, candidates.png, structure.png) to this folder",
    )
    _add_data_options(diag)
    how = diag.add_argument_group("how to diagnose")
    how.add_argument(
        "--fit",
        metavar="NAMES",
        help="comma-separated base parameters to fit (default: for the integrated "
        "model E1c,E1r,E2c,t_c,eta0,E2r,t_r1,E3r; else all)",
    )
    how.add_argument(
        "--candidates",
        metavar="IDS",
        help="comma-separated extension ids to try (default: all seven)",
    )
    how.add_argument(
        "--split",
        choices=("time", "tests"),
        default="time",
        help="held-out data: 'time', the last --holdout of every test (default); "
        "'tests', cross-validation over whole tests (--folds; one fit per fold "
        "and candidate)",
    )
    how.add_argument(
        "--folds",
        type=_positive_int,
        default=None,
        metavar="K",
        help="folds of --split tests (default: leave-one-test-out)",
    )
    how.add_argument(
        "--holdout",
        type=_positive_float,
        default=0.3,
        metavar="X",
        help="held-out fraction of every test's samples for --split time "
        "(default: 0.3)",
    )
    _add_solver_options(diag, starts=1)
    diag.set_defaults(run=_diagnose)

    demo = commands.add_parser(
        "demo",
        help="simulate Park et al.'s tests and fit the bundled data set",
        description=(
            "1. Simulate Park et al.'s test protocol with the default IntegratedModel "
            "(Dyneema SK78, 3 mm, 300 mm long): one 0-100 N cycle at 3 and 50 mm/min "
            "(rate effect) and 10 cycles to 100 and 150 N at 3 mm/min; write PNG "
            "plots (rate_effect.png, cycles10.png) and the simulated histories as "
            "canonical CSV files. 2. Fit the IntegratedModel to the bundled data set "
            "(jaxcable/data/*.csv, synthetic: Park's protocol at two lengths, two "
            f"rates and two force levels). By default {len(_DEMO_FIT)} of its 12 "
            f"parameters are fitted ({', '.join(_DEMO_FIT)}), the others kept at "
            "their defaults, so that the demo takes about a minute; write the fit "
            "report (params.json, fit_loops.png, fit_residuals.png, summary.md, "
            "rmse.csv). Prints the headline numbers."
        ),
    )
    demo.add_argument(
        "--out",
        metavar="DIR",
        default="demo_out",
        help="output folder (default: demo_out)",
    )
    demo.add_argument(
        "--samples-per-ramp",
        type=int,
        default=1000,
        metavar="N",
        help="force samples per loading or unloading ramp of the simulated tests "
        "(default: 1000, Park's 2000 per cycle)",
    )
    demo.add_argument(
        "--data",
        metavar="DIR",
        help="fit the canonical CSV files in this folder instead of the bundled "
        "data set",
    )
    demo.add_argument(
        "--fit",
        metavar="NAMES",
        help=f"comma-separated parameters to fit (default: {','.join(_DEMO_FIT)})",
    )
    demo.add_argument(
        "--no-diagnose",
        action="store_true",
        help="skip step 3, the diagnosis of the fitted data (about a minute)",
    )
    _add_solver_options(demo, starts=_DEMO_STARTS)
    demo.set_defaults(run=_demo)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the `jaxcable` command line.

    **Arguments:**

    - `argv`: the arguments after the program name (default: `sys.argv[1:]`).

    **Returns:**

    The exit status: 0 on success, 2 for bad input (one line on stderr naming the
    file, line and column, or the option), 1 when a simulation or fit fails.
    """
    try:
        args = _parser().parse_args(argv)
        # The command line writes files, so its precision must not depend on the
        # caller's jax config: float32 Newton solves of rate-driven tests do not
        # converge at the default tolerances. Scoped; jax.config is left as it was.
        with jax.enable_x64(True):
            return args.run(args)
    except SystemExit as e:  # --help and --version
        return e.code if isinstance(e.code, int) else 0
    except _CliError as e:
        _report(e)
        return e.status
    except ValueError as e:
        _report(e)
        return 2
    except OSError as e:
        where = e.filename if e.filename is not None else "file"
        _report(f"{where}: {e.strerror or e}.")
        return 2


def _report(message) -> None:
    print(f"{_PROG}: error: {_one_line(message)}", file=sys.stderr)
