"""`jaxcable simulate`: a rate-driven protocol (JSON) or a force history (CSV) simulated
by a model, written as a canonical CSV file."""

import dataclasses
import pathlib
from collections.abc import Callable

import equinox as eqx
import numpy as np

from .._cable import Cable
from .._drive import (
    ELONGATION_DRIVEN,
    FORCE_DRIVEN,
    AbstractTestDrive,
    simulate_rate_test,
)
from .._io import TestData, read_protocol, resolve_control, write_csv
from .._results import RESULTS
from .common import CliError, require_folder_of
from .data import data_options, pushing_error, read_data
from .limits import with_strain_from_load
from .models import params_metadata, resolve_model
from .outputs import refuse_inputs, say_replacing, writing


_PER_TEST = "choose the test to simulate with --test ID (or its index)."
# The column a channel is written as.
_COLUMN = {"force": "force_N", "elongation": "elongation_mm"}


def _check_force(data: TestData, cable: Cable) -> None:
    """Fail naming file, line and column unless the force, which drives the model,
    is a cable's: not negative beyond the load cell's noise (readings within it
    were read as 0 N), not above the breaking load."""
    # The simulation checks these too, but only knows sample indices, not file lines.
    error = pushing_error(data)
    if error is not None:
        raise CliError(error)
    force = data.force
    limit = float(cable.breaking_load)
    above = np.flatnonzero(force > limit)
    if above.size:
        i = int(above[0])
        raise CliError(
            f"{data.locate(i, data.column_name('force'))}: force {force[i]:g} N "
            f"exceeds the cable's breaking load ({limit:g} N)."
        )


def _check_success(traj, name: str, where: Callable[[int | None], str]) -> None:
    """Fail with status 1 unless the simulation succeeded; `where(i)` says where the
    first non-finite sample `i` (None if there is none) is in the input."""
    if traj.result == RESULTS.successful:
        return
    bad = np.flatnonzero(~np.isfinite(np.asarray(traj.strain)))
    i = int(bad[0]) if bad.size else None
    raise CliError(
        f"{where(i)}: model '{name}' failed: {RESULTS[traj.result]}", status=1
    )


def _check_times(time: np.ndarray, where: Callable[[int], str]) -> None:
    """Fail unless the solved times are finite and increase, as the CSV reader
    requires: a run never writes a file its own reader rejects."""
    bad = np.flatnonzero(~np.isfinite(time[1:]) | ~(np.diff(time) > 0))
    if bad.size:
        i = int(bad[0]) + 1
        raise CliError(
            f"{where(i)}: the solved time of sample {i} ({time[i]:g} s) does not "
            f"increase on the one before ({time[i - 1]:g} s); the samples are too "
            "close together for this model and cable."
        )


def _write(args, data: TestData) -> None:
    """Write `data` to `--out` atomically, saying so when it replaces a file."""
    say_replacing([args.out], "--out")
    with writing("--out", args.out) as tmp:
        write_csv(tmp, data)


def _history_drive(args) -> tuple[TestData, AbstractTestDrive]:
    """The history file, read for its drive, and the drive: `--drive`, else the
    file's `control` line, else the channel it has (detected when it has both)."""
    options = data_options(args)
    data = read_data(args.input, options, require_force=False)
    has_force = bool(np.all(np.isfinite(data.force)))
    if args.drive != "auto" or data.control is not None:
        drive = resolve_control(data, args.drive).drive
    elif data.elongation is None or not has_force:
        drive = FORCE_DRIVEN if data.elongation is None else ELONGATION_DRIVEN
    else:
        drive = resolve_control(data, "auto").drive
    if drive == FORCE_DRIVEN and not has_force:
        # The reader's own located error for the missing force column.
        read_data(args.input, options)
    if drive.imposed_of(data) is None:
        raise CliError(
            f"{args.input}: an {drive.name}-driven history needs an "
            f"{_COLUMN[drive.imposed]} column."
        )
    return data, drive


def _simulate_history(args) -> int:
    data, drive = _history_drive(args)
    if drive == FORCE_DRIVEN:
        _check_force(data, data.cable())
    name, model = resolve_model(args, per_test_hint=_PER_TEST)
    # A breaking load without a breaking strain: the strain the model reaches there
    # (the limit of this run, not written to the output).
    (limited,) = with_strain_from_load([data], [model])
    cable = limited.cable()
    # The measured channel as read, as `fit` drives its model: a PARAMS.json
    # re-simulates the file it was fitted to exactly as the fit saw it.
    traj = drive.simulate(model, cable, data.time, drive.imposed_of(data), throw=False)
    _check_success(
        traj, name, lambda i: str(args.input) if i is None else data.locate(i)
    )
    metadata = dict(data.metadata)
    # Record the cable the simulation assumed where the file left it to defaults.
    metadata.setdefault("diameter_mm", float(cable.diameter) * 1e3)
    metadata.setdefault("rate_mm_per_min", float(cable.speed) * 1e3 * 60)
    metadata["model"] = name
    metadata["control"] = drive.name
    if args.params:
        metadata["model_params"] = params_metadata(model)
    simulated = {drive.scored: np.asarray(drive.scored_of(traj))}
    out = dataclasses.replace(data, **simulated, metadata=metadata)
    _write(args, out)
    print(
        f"wrote {args.out} ({data.num_samples} samples, {_COLUMN[drive.scored]} "
        f"simulated by model '{name}', {drive.name} drive)"
    )
    return 0


def _simulate_protocol(args) -> int:
    given = [
        option
        for option, value in (
            ("--columns", args.columns),
            ("--skip-rows", args.skip_rows),
            ("--length-mm", args.length_mm),
            ("--diameter-mm", args.diameter_mm),
            ("--rate-mm-per-min", args.rate_mm_per_min),
            ("--no-slack", args.no_slack or None),
        )
        if value is not None
    ]
    if given:
        raise CliError(
            f"{given[0]}: reads a HISTORY.csv; a protocol file gives its cable itself."
        )
    spec = read_protocol(args.input)
    if args.breaking_strain is not None:
        cable = eqx.tree_at(
            lambda c: c.breaking_strain, spec.cable, float(args.breaking_strain)
        )
        spec = spec._replace(cable=cable)
    name, model = resolve_model(args, per_test_hint=_PER_TEST)
    traj = simulate_rate_test(model, spec.cable, spec.protocol, throw=False)

    def where(i):
        segment = spec.segment_of(i) if i is not None else None
        return args.input if segment is None else f"{args.input}, segments[{segment}]"

    _check_success(traj, name, where)
    _check_times(np.asarray(traj.time), where)
    given = {}
    if args.breaking_strain is not None:
        given["breaking_strain"] = float(args.breaking_strain)
    metadata = {
        **spec.metadata,
        **given,
        "protocol": pathlib.Path(args.input).name,
        "model": name,
        # A fit of this file drives it by its force history, as it was made.
        "control": FORCE_DRIVEN.name,
    }
    if args.params:
        metadata["model_params"] = params_metadata(model)
    data = TestData(
        time=np.asarray(traj.time),
        force=np.asarray(traj.force),
        elongation=np.asarray(traj.elongation),
        metadata=metadata,
    )
    _write(args, data)
    duration = float(data.time[-1])
    print(
        f"wrote {args.out} ({data.num_samples} samples over {duration:.6g} s, "
        f"model '{name}')"
    )
    return 0


def simulate_command(args) -> int:
    """Run `jaxcable simulate` with the parsed command line `args`; the exit status."""
    require_folder_of(args.out, "--out")
    inputs = [("PROTOCOL.json|HISTORY.csv", args.input)]
    if args.params:
        inputs.append(("--params", args.params))
    refuse_inputs([("--out", args.out)], inputs)
    if args.input.lower().endswith(".json"):
        return _simulate_protocol(args)
    return _simulate_history(args)
