"""The measured tests of every command (`fit`, `diagnose`, `design`, `simulate
HISTORY.csv`, `demo`): read by one path with the data options, their force cleaned
of a load cell's noise about zero, thinned, and described in one line per file."""

import csv
import dataclasses
import pathlib
import sys
import warnings
from collections.abc import Callable, Mapping, Sequence

import numpy as np

from .._fit import resolve_drives
from .._io import (
    MetadataConflictWarning,
    ReadOptions,
    TestData,
    mask_slack,
    pushing_samples,
    read_test,
)
from .._progress import AbstractProgressMeter
from .common import PROG, CliError, add_choice, one_line, refused
from .limits import limits_note
from .numbers import (
    breaking_strain as _breaking_strain,
    non_negative_int as _non_negative_int,
    positive_float as _positive_float,
)


# The csv module's limit on one cell (its default, 128 KiB): a longer cell is no
# measurement, and is reported as such.
_FIELD_LIMIT = csv.field_size_limit()


def read_located(read: Callable[..., TestData], path, *args, **kwargs) -> TestData:
    """`read(path, *args, **kwargs)`, with the errors the readers do not locate (the csv
    module's, a number too large for a float) reported naming `path`; the readers'
    own `ValueError`s already name the file, line and column. A given option that
    replaces a file's value ([`jaxcable.MetadataConflictWarning`][]) is printed as
    one warning line on stderr."""
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", MetadataConflictWarning)
            data = read(path, *args, **kwargs)
    except csv.Error as e:
        message = str(e)
        if "field larger than field limit" in message:
            message = (
                f"a cell is longer than {_FIELD_LIMIT // 1024} KiB (an unclosed quote?)"
            )
        raise CliError(f"{path}: cannot read the file: {message}.") from None
    except OverflowError as e:
        raise CliError(f"{path}: a number is too large: {e}.") from None
    for warning in caught:
        if issubclass(warning.category, MetadataConflictWarning):
            # A given option replaced a file's value: one line, as errors are.
            print(f"{PROG}: warning: {one_line(warning.message)}", file=sys.stderr)
        else:
            warnings.warn_explicit(
                warning.message, warning.category, warning.filename, warning.lineno
            )
    return data


def add_data_options(parser) -> None:
    """The options that say how to read the data files: the same for every command
    that reads them (`fit`, `diagnose`, `design`, `simulate HISTORY.csv`)."""
    raw = parser.add_argument_group(
        "reading data files (every command reads them alike)"
    )
    _add_layout_options(raw)
    _add_cable_options(raw)
    parser.add_argument_group("the material's limits").add_argument(
        "--breaking-strain",
        type=_breaking_strain,
        metavar="X",
        help="breaking strain (elongation / length at break; 'inf' for a material "
        "that does not break): a simulation beyond it fails (replaces the files' "
        "'# breaking_strain:'). Default: the files' value; with only a "
        "'# breaking_load_N:', none before a fit and, after one, the fitted model's "
        "strain at that load in a ramp at the crosshead speed; else none",
    )


def _add_layout_options(raw) -> None:
    """How a file is laid out and what its load cell reads: `--columns`,
    `--frequency-hz`, `--force-sign`, `--no-tare`, `--skip-rows`."""
    raw.add_argument(
        "--columns",
        metavar="NAMES",
        help="the files' columns in order with their units, e.g. "
        "time_s,elongation_mm,force_N (also time_ms, time_min, time_h, force_kN, "
        "elongation_m, temperature_C; '-' for a column to ignore), or some of them "
        "by their header names, e.g. Load=force_kN,Cycles=cycles (the others not "
        "read); also stress_MPa, stress_kPa, stress_Pa (force = stress x the area "
        "of --diameter-mm), strain, strain_percent (elongation = strain x "
        "--length-mm), stretch_ratio (elongation = (ratio - 1) x "
        "--length-mm), cycles (a cycle count: time = N / --frequency-hz, each burst "
        "of samples at one count read as its mean); default: from the header",
    )
    raw.add_argument(
        "--frequency-hz",
        type=_positive_float,
        metavar="F",
        help="the test frequency, Hz, of files whose time is a cycle count "
        "('cycles' in --columns)",
    )
    add_choice(
        raw,
        "--force-sign",
        ("auto", "+1", "-1"),
        "the sign of the files' force: +1 as written, -1 flipped, auto "
        "(default) flipped where the load cell reads tension as negative (the force "
        "mostly negative and growing in magnitude as the elongation grows; a "
        "compression test, force and elongation both negative, is read as written)",
    )
    raw.add_argument(
        "--no-tare",
        action="store_true",
        help="keep a load cell's offset at rest (by default, the force of the first "
        "samples, before the elongation moves, is removed where it is clearly an "
        "offset: a reading below zero at rest, or one the test loads above and "
        "unloads below without ever reading zero; a preload is kept)",
    )
    raw.add_argument(
        "--skip-rows",
        type=_non_negative_int,
        metavar="N",
        help="lines before the first data row (default: detected)",
    )


def _add_cable_options(raw) -> None:
    """The cable's facts that replace the files' (`--length-mm`, `--diameter-mm`,
    `--rate-mm-per-min`) and `--no-slack`."""
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
        "masked and not fitted; a fast recovery at zero force can look like one). "
        "Either way a force reading below zero within the load cell's noise is read "
        "as 0 N: the tolerance is max(0.5%% of the peak force, 3 x the noise of the "
        "file's own force, from its second differences), at most 5%% of the peak; "
        "a reading below it is refused, naming file, line and column, where the "
        "force drives the model (and masked where the elongation does)",
    )


@dataclasses.dataclass(frozen=True)
class Reading:
    """How a command reads its data files: the arguments of `read_test` after the
    path, from the data options of the command line.

    **Fields:**

    - `columns`: `--columns`, or None (from the header).
    - `metadata`: the facts the options give or replace (`length_mm`,
        `diameter_mm`, `rate_mm_per_min`, `breaking_strain`; None: not given).
    - `options`: the reader's options; `detect_slack` says whether slack
        stretches are looked for (see [`read_data`][]).
    """

    columns: str | None = None
    metadata: Mapping[str, float | None] = dataclasses.field(default_factory=dict)
    options: ReadOptions = ReadOptions()


def data_options(args) -> Reading:
    """How to read the data files, from the data options of the parsed command line
    `args` (the flags of [`add_data_options`][])."""
    return Reading(
        columns=args.columns,
        metadata={
            "length_mm": args.length_mm,
            "diameter_mm": args.diameter_mm,
            "rate_mm_per_min": args.rate_mm_per_min,
            "breaking_strain": args.breaking_strain,
        },
        options=ReadOptions(
            skip_rows=args.skip_rows,
            detect_slack=not args.no_slack,
            force_sign=args.force_sign,
            tare=not args.no_tare,
            frequency_hz=args.frequency_hz,
        ),
    )


@dataclasses.dataclass(frozen=True)
class DataFiles:
    """The measured tests a command was asked to read, and how.

    **Fields:**

    - `paths`: the data files, as given.
    - `reading`: how to read them ([`data_options`][]).
    - `every`: keep every `every`-th sample (`--every`; the first and last kept).
    - `drive`: `--drive`: `"auto"`, `"force"` or `"elongation"`.
    """

    paths: tuple[str, ...]
    reading: Reading = Reading()
    every: int = 1
    drive: str = "auto"


def read_data(path, reading: Reading, *, require_force: bool = True) -> TestData:
    """One data file as every command reads it: `read_test` with the data options,
    then its force cleaned by `mask_slack` whatever `--no-slack` says (which only
    stops the search for slack stretches): a reading within the load cell's noise
    below zero is 0 N, the tolerance being the slack threshold, max(0.5 % of the
    peak force, 3 x the force noise estimated from the file's own second
    differences), at most 5 % of the peak. Before that, a load cell that reads
    tension as negative is read with its sign flipped, and an offset at rest is
    removed, where the file shows them (`force_sign="auto"`, `tare=True` unless the
    options say otherwise; each said in the test's notes). A file without a force
    column (with `require_force=False`, an elongation history) is read as
    written."""
    options = dataclasses.replace(
        reading.options, detect_slack=False, require_force=require_force
    )
    data = read_located(
        read_test, path, reading.columns, metadata=reading.metadata, options=options
    )
    if np.all(np.isfinite(data.force)):
        data = mask_slack(data, stretches=reading.options.detect_slack)
    return data


def pushing_error(data: TestData) -> str | None:
    """The message for the first force reading below zero by more than the load
    cell's noise (`jaxcable._io`'s `pushing_samples`), naming file, line and column;
    None when there is none. Only an error where the force drives the model."""
    pushing = pushing_samples(data)
    if not pushing.size:
        return None
    i = int(pushing[0])
    measured = data.force if data.force_raw is None else data.force_raw
    report = data.slack_report
    tolerance = (
        ""
        if report is None
        else f" (readings down to -{report.threshold:.3g} N, the load cell's noise "
        "about zero, are read as 0 N)"
    )
    return (
        f"{data.locate(i, data.column_name('force'))}: force {measured[i]:g} N is "
        f"negative beyond the noise{tolerance}; a cable cannot push, and this "
        "test's force drives the model."
    )


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
        mask=np.asarray(data.mask)[index],
        force_raw=take(data.force_raw),
    )


def read_measured(
    paths: Sequence, reading: Reading, every: int, meter: AbstractProgressMeter
) -> list[tuple[TestData, str | None]]:
    """Measured tests, read by [`read_data`][] (canonical or raw exports), each
    with its [`pushing_error`][] found before thinning (the caller refuses it
    where the test is force-driven).

    **Arguments:**

    - `paths`: the files.
    - `reading`: how to read them ([`data_options`][]).
    - `every`: keep every `every`-th sample (the first and last kept).
    - `meter`: the progress meter.

    **Returns:**

    `(test, error or None)` per file, each test with its elongation and a cable;
    fails naming the file otherwise.
    """
    tests = []
    with meter.bar("reading", len(paths)) as bar:
        for path in paths:
            data = read_data(path, reading)
            if data.elongation is None:
                raise CliError(
                    f"{path}: no elongation column; a fit needs the measured "
                    "elongation (a column elongation_mm, or name it with --columns)."
                )
            data.cable()  # raises, naming the file, when length_mm is missing
            tests.append((_thin(data, every), pushing_error(data)))
            bar.advance(note=pathlib.Path(path).name)
    return tests


def read_tests(
    paths: Sequence, reading: Reading, every: int, meter: AbstractProgressMeter
) -> list[TestData]:
    """The tests of [`read_measured`][], without their force checks."""
    return [test for test, _ in read_measured(paths, reading, every, meter)]


def describe_tests(
    tests: Sequence[TestData], every: int, drives: Sequence | None = None
) -> list[str]:
    """One line per test: its name, samples, what was masked as slack, and (with
    `drives`, a `ControlDetection` per test) its drive and why; then its notes
    (`TestData.notes`), one indented line each."""
    lines = []
    for i, t in enumerate(tests):
        name = pathlib.Path(t.source).name if t.source else t.metadata.get("id", "")
        masked = int(np.sum(~np.asarray(t.mask)))
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
        if drives is not None:
            text += f"; drive: {drives[i].reason}"
        lines.append(text)
        # How an instrument export was read: the columns it has that are not read.
        lines.extend(f"    {note}" for note in getattr(t, "notes", ()))
    return lines


def input_files(data: DataFiles, params: str | None) -> list[tuple[str, str]]:
    """(what, path) of the files a fit or diagnosis reads: its data and `--params`
    (`params`, when given)."""
    inputs = [("DATA.csv", str(path)) for path in data.paths]
    if params:
        inputs.append(("--params", params))
    return inputs


def test_drives(tests, drive: str):
    """Each test's drive with its reason (`--drive`, the file's `control` line, or
    detected from the data)."""
    with refused("--drive"):
        return resolve_drives(tests, drive)


def read_described(data: DataFiles, meter: AbstractProgressMeter, log=None):
    """(tests, drives with their reasons) of the data files, read as every command
    reads them, after printing one line per file (and what limits the material) on
    `log` (default stdout); fails naming file, line and column where a
    force-driven test's force is negative beyond its noise."""
    measured = read_measured(data.paths, data.reading, data.every, meter)
    tests = [test for test, _ in measured]
    drives = test_drives(tests, data.drive)
    for (_, error), drive in zip(measured, drives):
        if error is not None and drive.control == "force":
            raise CliError(error)
    print(f"read {len(tests)} file(s):", file=log)
    print("\n".join(describe_tests(tests, data.every, drives)), file=log)
    note = limits_note(tests)
    if note:
        print(note, file=log)
    return tests, drives
