"""The argparse tree of the `jaxcable` command line: its commands and their options
(the validators of numeric options in `numbers.py`)."""

import argparse
import importlib.metadata

from .._models import (
    BY_CLI_NAME,
    COVARIATE_EXTENSIONS,
    DEFAULT_CLI_MODEL,
    EXTENSIONS,
    PARK_IDENTIFIABLE,
)
from .cache import cache_command
from .common import PROG, CliError, add_choice
from .data import add_data_options as _add_data_options
from .demo import demo_command
from .design import add_design_command as _design
from .diagnose import diagnose_command
from .fit import add_out_options, fit_command
from .numbers import (
    MAX_SAMPLES_PER_RAMP as MAX_SAMPLES_PER_RAMP,
    positive_float as _positive_float,
    positive_int as _positive_int,
    samples_per_ramp as _samples_per_ramp,
    seed as _seed,
)
from .simulate import simulate_command


class _Parser(argparse.ArgumentParser):
    # argparse prints the usage and an error on two lines; we promise one line.
    def error(self, message):
        raise CliError(f"{message} (see '{self.prog} --help')")


def _version() -> str:
    try:
        return importlib.metadata.version("jaxcable")
    except importlib.metadata.PackageNotFoundError:  # pragma: no cover
        return "unknown"


def _add_model_options(parser, params_help: str) -> None:
    parser.add_argument(
        "--model",
        choices=list(BY_CLI_NAME),
        default=None,
        help=f"the cable model (default: the model of a --params file written by "
        f"'jaxcable fit', else {DEFAULT_CLI_MODEL}, Park et al.)",
    )
    parser.add_argument("--params", metavar="PARAMS.json", help=params_help)


def _add_report_data_and_fit(parser, report: str, title: str, what: str, rest: str):
    """`--report DIR` (`report`: what it holds), the data options, and the group
    `title` with `--fit NAMES`: the `what` to fit (`rest`: what becomes of the
    others); the group."""
    parser.add_argument("--report", metavar="DIR", help=report)
    _add_data_options(parser)
    group = parser.add_argument_group(title)
    group.add_argument(
        "--fit",
        metavar="NAMES",
        help=f"comma-separated {what} to fit (default: for the integrated model "
        f"{','.join(PARK_IDENTIFIABLE)}; else all){rest}",
    )
    return group


def _add_drive_option(parser, what: str) -> None:
    add_choice(
        parser,
        "--drive",
        ("auto", "force", "elongation"),
        f"which measured channel drives the model {what}: force (force "
        "control: creep, load cycles; the elongation is scored), elongation "
        "(displacement control: relaxation, constant crosshead rate; the force is "
        "solved and scored), or auto (default: the file's '# control:' line, else "
        "detected from which channel is held and ramped; printed per file)",
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
        type=_seed,
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


_ABOUT = {
    "simulate": dict(
        help="simulate a rate-driven protocol (JSON) or a force history (CSV)",
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
            "HISTORY.csv: a time-stamped force history, read as 'jaxcable fit' reads "
            "its files\n(a canonical CSV file: '# length_mm: ...' metadata, then "
            "time_s,force_N[,...]; or a raw\nexport, with the data options); the "
            "same file is written with elongation_mm filled in\n(other columns and "
            "metadata kept). With --drive elongation (or a '# control: elongation'"
            "\nline, or no force_N column) it is an elongation history "
            "(time_s,elongation_mm) and\nforce_N is filled in, solved sample by "
            "sample. The cable is taken from the metadata:\nlength_mm (required), "
            "diameter_mm (default 3), rate_mm_per_min (default 3), and its\n"
            "breaking_strain and breaking_load_N (see --breaking-strain)."
        ),
    ),
    "fit": dict(
        help="fit a model to measured tests",
        description=(
            "Fit a cable model to one or many measured tests at once by least squares "
            "(Levenberg-Marquardt, multi-start; see jaxcable.fit): a force-controlled "
            "test is driven by its force and scored on elongation, a "
            "displacement-controlled one driven by its elongation and scored on "
            "force (--drive). "
            "Material parameters are shared by all tests. Files are read with "
            "jaxcable.read_test: canonical CSV files or raw tensile-tester exports "
            "(other separators and encodings, preamble and unit rows, quoted "
            "numbers); slack stretches are detected, masked and not fitted. Writes "
            "the fitted parameters as PARAMS.json (use it with 'jaxcable simulate "
            "--params') and prints the RMSE of every test (mm or N, and % of its peak), the parameters with standard errors and correlations, and "
            "warnings naming parameters the data cannot identify."
        ),
    ),
    "diagnose": dict(
        help="find what the model gets wrong and name the physical cause",
        description=(
            "Fit the base model (default: the integrated model) to the measured "
            "tests with the last part of every test held out, analyse its residuals "
            "for structure (time under load, force, loading vs unloading, cycle, "
            "rest time, length, rate, temperature and every extra column with its "
            "rate, autocorrelation), fit every "
            f"candidate extension ({', '.join(EXTENSIONS)}), score each on the "
            "held-out data and by BIC, "
            "and give a verdict: named (the significant candidate of largest "
            "held-out gain that explains the residual), none (nothing to explain) "
            "or unexplained. Reads files like 'jaxcable fit'. See jaxcable.diagnose."
        ),
    ),
    "demo": dict(
        help="simulate Park et al.'s tests and fit the bundled data set",
        description=(
            "1. Simulate Park et al.'s test protocol with the default IntegratedModel "
            "(Dyneema SK78, 3 mm, 300 mm long): one 0-100 N cycle at 3 and 50 mm/min "
            "(rate effect) and 10 cycles to 100 and 150 N at 3 mm/min; write PNG "
            "plots (rate_effect.png, cycles10.png) and the simulated histories as "
            "canonical CSV files. 2. Fit the IntegratedModel to the bundled data set "
            "(jaxcable/data/*.csv, synthetic: Park's protocol at two lengths, two "
            f"rates and two force levels). By default {len(PARK_IDENTIFIABLE)} of its 12 "
            f"parameters are fitted ({', '.join(PARK_IDENTIFIABLE)}), the others kept at "
            "their defaults, so that the demo takes about a minute; write the fit "
            "report (params.json, fit_loops.png, fit_residuals.png, summary.md, "
            "rmse.csv). Prints the headline numbers."
        ),
    ),
    "cache": dict(
        help="show or clear the compilation cache",
        description=(
            "Every command keeps the XLA programs it compiles on disk, so that the "
            "next run with the same shapes starts in a fraction of the time. The "
            "cache is per user (JAXCABLE_CACHE_DIR, else $XDG_CACHE_HOME/jaxcable/jax, "
            "else ~/.cache/jaxcable/jax); JAXCABLE_NO_CACHE=1 turns it off. Prints its "
            "directory and size."
        ),
    ),
}


def _command(commands, name: str, run, raw=False, data=False, params=None):
    """The subparser of the command `name` (its help and description from
    `_ABOUT`; `raw`: its description keeps its line breaks), run by `run`; with
    `data`, the measured tests as arguments; with `params` (the help of
    `--params`), the model options."""
    kwargs = {"formatter_class": argparse.RawDescriptionHelpFormatter} if raw else {}
    parser = commands.add_parser(name, **_ABOUT[name], **kwargs)
    parser.set_defaults(run=run)
    if data:
        parser.add_argument(
            "data", nargs="+", metavar="DATA.csv", help="the measured tests"
        )
    if params is not None:
        _add_model_options(parser, params)
    return parser


def build_parser() -> argparse.ArgumentParser:
    """The parser of the `jaxcable` command line; each command sets `run`, the
    function that runs it with the parsed arguments and returns the exit status."""
    parser = _Parser(
        prog=PROG,
        description="Differentiable creep models of polymer (Dyneema) cables.",
    )
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    commands = parser.add_subparsers(
        dest="command", metavar="COMMAND", required=True, parser_class=_Parser
    )
    for add in (_simulate, _fit, _diagnose, _demo, _cache):
        add(commands)
    _design(commands, _add_model_options, _add_data_options, _add_drive_option)
    return parser


def _simulate(commands) -> None:
    """`jaxcable simulate`: a protocol or a history simulated."""
    sim = _command(commands, "simulate", simulate_command, raw=True)
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
    _add_drive_option(sim, "of a HISTORY.csv (elongation: force_N is filled in)")
    _add_data_options(sim)


def _fit(commands) -> None:
    """`jaxcable fit`: a model fitted to measured tests."""
    fit = _command(
        commands,
        "fit",
        fit_command,
        data=True,
        params="start values: a PARAMS.json written by 'jaxcable fit', or a JSON object of "
        "parameter name -> value (SI units) replacing the model's defaults; fixed "
        "parameters keep these values",
    )
    add_out_options(fit)
    what = _add_report_data_and_fit(
        fit,
        "write plots (fit_loops.png: measured vs model force-elongation, one "
        "panel per test; fit_residuals.png: residuals vs time) and tables "
        "(summary.md, rmse.csv) to this folder",
        "what to fit",
        "parameters",
        "; the others keep their start values",
    )
    what.add_argument(
        "--per-test",
        metavar="NAMES",
        help="comma-separated parameters fitted with one value per test",
    )
    _add_drive_option(fit, "of each test")
    _add_solver_options(fit, starts=4)


def _diagnose(commands) -> None:
    """`jaxcable diagnose`: what the model gets wrong, and its cause."""
    diag = _command(
        commands,
        "diagnose",
        diagnose_command,
        data=True,
        params="start values of the base model: a PARAMS.json written by 'jaxcable fit', or "
        "a JSON object of parameter name -> value (SI units)",
    )
    diag.add_argument(
        "--json",
        action="store_true",
        help="print one JSON object on stdout (named_cause, causes, rounds, "
        "verdict, candidates with explained_pct, structure, unit, "
        "base_heldout_rmse, extended_heldout_rmse, ... in unit: mm, N or noise; "
        "the *_mm fields in mm when every test is force-driven); the log goes to "
        "stderr",
    )
    diag.add_argument(
        "--out",
        metavar="EXTENDED.json",
        help="write the extended model the diagnosis names (the base with every "
        "named cause), fitted, as a PARAMS.json for 'jaxcable simulate --params', "
        "'jaxcable fit --params' and the controller; the fitted base model when no "
        "cause is named",
    )
    how = _add_report_data_and_fit(
        diag,
        "write diagnosis.json, summary.md and plots before/after "
        "(residuals.png, candidates.png, structure.png, rounds.png) to this folder",
        "how to diagnose",
        "base parameters",
        "",
    )
    _add_search_options(how)
    _add_drive_option(diag, "of each test (fixed for every fold and candidate)")
    _add_solver_options(diag, starts=1)


def _add_search_options(how) -> None:
    """How `jaxcable diagnose` looks for a cause: `--candidates`, the held-out data
    (`--split`, `--folds`, `--holdout`), `--max-rounds` and `--family`."""
    how.add_argument(
        "--candidates",
        metavar="IDS",
        help=f"comma-separated extension ids to try (default: the {len(EXTENSIONS)} "
        f"of the catalogue, and {', '.join(COVARIATE_EXTENSIONS)} for each extra "
        "column every test records)",
    )
    add_choice(
        how,
        "--split",
        ("time", "tests"),
        "held-out data: 'time', the last --holdout of every test (default); "
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
    how.add_argument(
        "--max-rounds",
        type=_positive_int,
        default=3,
        metavar="N",
        help="look for at most N causes, one per round, each round with the causes "
        "named before in the model (default: 3; 1 stops after the first cause)",
    )
    add_choice(
        how,
        "--family",
        ("auto", "always", "never"),
        "fit the other base models (integrated, five-element, burgers, "
        "bouc-wen, findley) on the same split and go on with the one the data want: "
        "auto (default) when the base is far from the data (held-out RMSE >= 10 x "
        "the noise, residual systematic), always, or never",
    )


def _demo(commands) -> None:
    """`jaxcable demo`: Park et al.'s tests simulated, the bundled data fitted."""
    demo = _command(commands, "demo", demo_command)
    demo.add_argument(
        "--out",
        metavar="DIR",
        default="demo_out",
        help="output folder (default: demo_out)",
    )
    demo.add_argument(
        "--samples-per-ramp",
        type=_samples_per_ramp,
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
        help=f"comma-separated parameters to fit (default: {','.join(PARK_IDENTIFIABLE)})",
    )
    demo.add_argument(
        "--no-diagnose",
        action="store_true",
        help="skip step 3, the diagnosis of the fitted data (about a minute)",
    )
    _add_solver_options(demo, starts=2)


def _cache(commands) -> None:
    """`jaxcable cache`: the compilation cache shown or cleared."""
    cache = _command(commands, "cache", cache_command)
    cache.add_argument(
        "--clear", action="store_true", help="delete the cache directory"
    )
