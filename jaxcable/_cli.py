"""The `jaxcable` command line: `jaxcable simulate` and `jaxcable demo`.

Errors in the user's input (files, arguments) exit with status 2 and one line on
stderr saying what is wrong and where; a simulation that fails exits with status 1.
"""

import argparse
import dataclasses
import importlib.metadata
import json
import os
import pathlib
import sys
from collections.abc import Sequence
from typing import NamedTuple

import jax
import numpy as np

from ._cable import Cable
from ._io import TestData, read_csv, write_csv


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


# ----------------------------------------------------------------------------------
# Models and parameters


def _model_class(name: str) -> type:
    import jaxcable

    from ._abstract import AbstractCableModel

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


def _read_params(path: str, cls: type, name: str) -> dict:
    try:
        text = pathlib.Path(path).read_text(encoding="utf-8")
    except OSError as e:
        raise _CliError(f"{path}: cannot read parameters: {e.strerror}.") from None
    try:
        params = json.loads(text)
    except json.JSONDecodeError as e:
        raise _CliError(
            f"{path}, line {e.lineno}, column {e.colno}: invalid JSON: {e.msg}."
        ) from None
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


def _simulate(args) -> int:
    import jaxcable

    cls = _model_class(args.model)
    params = _read_params(args.params, cls, args.model) if args.params else {}
    data = read_csv(args.history)
    cable = data.cable()
    _check_force(data, cable)
    model = _build_model(cls, args.model, params, args.params)
    traj = jaxcable.simulate_force_history(
        model, cable, data.time, data.force, throw=False
    )
    if traj.result != jaxcable.RESULTS.successful:
        strain = np.asarray(traj.strain)
        bad = np.flatnonzero(~np.isfinite(strain))
        where = data.locate(int(bad[0])) if bad.size else str(args.history)
        raise _CliError(
            f"{where}: model '{args.model}' failed: {jaxcable.RESULTS[traj.result]}",
            status=1,
        )
    metadata = dict(data.metadata)
    # Record the cable the simulation assumed where the file left it to defaults.
    metadata.setdefault("diameter_mm", float(cable.diameter) * 1e3)
    metadata.setdefault("rate_mm_per_min", float(cable.speed) * 1e3 * 60)
    metadata["model"] = args.model
    if args.params:
        metadata["model_params"] = json.dumps(params, separators=(",", ":"))
    out = dataclasses.replace(
        data, elongation=np.asarray(traj.elongation), metadata=metadata
    )
    write_csv(args.out, out)
    print(f"wrote {args.out} ({data.num_samples} samples, model '{args.model}')")
    return 0


# ----------------------------------------------------------------------------------
# demo


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


def _demo(args) -> int:
    import jaxcable

    if args.samples_per_ramp < 2:
        raise _CliError(
            f"--samples-per-ramp must be at least 2, got {args.samples_per_ramp}."
        )
    out = pathlib.Path(args.out)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise _CliError(f"{out}: cannot create the output folder: {e.strerror}.")
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
        "Park et al.'s tests simulated with jaxcable.IntegratedModel() (Dyneema SK78, "
        f"{_DEMO_DIAMETER_MM:g} mm, {_DEMO_LENGTH_MM:g} mm long, "
        f"{args.samples_per_ramp} samples per ramp):"
    )
    print(f"  {'case':<20} {'peak [mm]':>10} {'residual after 1st unloading [mm]':>34}")
    for r in results:
        if r.error:
            print(f"  {r.case.name:<20} FAILED: {_one_line(r.error)}")
        else:
            peak = float(np.max(r.elongation))
            print(f"  {r.case.name:<20} {peak:>10.3f} {r.residual:>34.3f}")
    print(f"Wrote {len(written)} files to {out}{os.sep}: ", end="")
    print(", ".join(p.name for p in written))
    failed = [r.case.name for r in results if r.error]
    if failed:
        raise _CliError(
            f"{len(failed)} of {len(results)} demo cases failed ({', '.join(failed)}); "
            "see the summary above.",
            status=1,
        )
    return 0


# ----------------------------------------------------------------------------------
# Entry point


def _version() -> str:
    try:
        return importlib.metadata.version("jaxcable")
    except importlib.metadata.PackageNotFoundError:  # pragma: no cover
        return "unknown"


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
        help="simulate the elongation of a time-stamped force history",
        description=(
            "Read a force history in the canonical CSV format ('# length_mm: ...' "
            "metadata, then columns time_s,force_N[,...]), simulate it with a cable "
            "model and write the same file with elongation_mm filled in (an existing "
            "elongation column is replaced; other columns and metadata are kept). "
            "The cable is taken from the metadata: length_mm (required), diameter_mm "
            "(default 3) and rate_mm_per_min (default 3)."
        ),
    )
    sim.add_argument("history", metavar="HISTORY.csv", help="the force history")
    sim.add_argument(
        "--model",
        choices=list(_MODELS),
        default="integrated",
        help="the cable model (default: integrated, Park et al.)",
    )
    sim.add_argument(
        "--params",
        metavar="PARAMS.json",
        help="JSON object of model parameter name -> value (SI units) replacing the "
        "model's defaults",
    )
    sim.add_argument(
        "--out", metavar="OUT.csv", required=True, help="the file to write"
    )
    sim.set_defaults(run=_simulate)

    demo = commands.add_parser(
        "demo",
        help="simulate Park et al.'s tests and plot them",
        description=(
            "Simulate Park et al.'s test protocol with the default IntegratedModel "
            "(Dyneema SK78, 3 mm, 300 mm long): one 0-100 N cycle at 3 and 50 mm/min "
            "(rate effect) and 10 cycles to 100 and 150 N at 3 mm/min. Writes PNG "
            "plots and the simulated histories as canonical CSV files, and prints the "
            "peak and residual elongations."
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
        help="force samples per loading or unloading ramp (default: 1000, Park's "
        "2000 per cycle)",
    )
    demo.set_defaults(run=_demo)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the `jaxcable` command line.

    **Arguments:**

    - `argv`: the arguments after the program name (default: `sys.argv[1:]`).

    **Returns:**

    The exit status: 0 on success, 2 for bad input (one line on stderr naming the
    file, line and column), 1 when a simulation fails.
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
