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
    Simulation,
    simulate_rate_test,
)
from .._io import TestData, read_protocol, resolve_control, write_csv
from .._results import RESULTS
from .common import CliError, require_folder_of
from .data import Reading, data_options, pushing_error, read_data
from .limits import with_strain_from_load
from .models import ModelChoice, params_metadata, resolve_model
from .outputs import refuse_inputs, say_replacing, writing


# A failed simulation is reported with its status, naming where it failed.
_NO_THROW = Simulation(throw=False)
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


@dataclasses.dataclass(frozen=True)
class SimulateRequest:
    """What `jaxcable simulate` was asked, as the values its flags give.

    **Fields:**

    - `input`: the protocol (`.json`) or history (`.csv`) file.
    - `out`: `--out`.
    - `model`: `--model`, `--params` and `--test`.
    - `reading`: how to read a history ([`data_options`][]).
    - `drive`: `--drive` of a history.
    """

    input: str
    out: str
    model: ModelChoice
    reading: Reading
    drive: str = "auto"


def _write(out: str, data: TestData) -> None:
    """Write `data` to `out` (`--out`) atomically, saying so when it replaces a
    file."""
    say_replacing([out], "--out")
    with writing("--out", out) as tmp:
        write_csv(tmp, data)


def _history_drive(request: SimulateRequest) -> tuple[TestData, AbstractTestDrive]:
    """The history file, read for its drive, and the drive: `--drive`, else the
    file's `control` line, else the channel it has (detected when it has both)."""
    data = read_data(request.input, request.reading, require_force=False)
    has_force = bool(np.all(np.isfinite(data.force)))
    if request.drive != "auto" or data.control is not None:
        drive = resolve_control(data, request.drive).drive
    elif data.elongation is None or not has_force:
        drive = FORCE_DRIVEN if data.elongation is None else ELONGATION_DRIVEN
    else:
        drive = resolve_control(data, "auto").drive
    if drive == FORCE_DRIVEN and not has_force:
        # The reader's own located error for the missing force column.
        read_data(request.input, request.reading)
    if drive.imposed_of(data) is None:
        raise CliError(
            f"{request.input}: an {drive.name}-driven history needs an "
            f"{_COLUMN[drive.imposed]} column."
        )
    return data, drive


def _simulate_history(request: SimulateRequest) -> int:
    data, drive = _history_drive(request)
    if drive == FORCE_DRIVEN:
        _check_force(data, data.cable())
    name, model = resolve_model(request.model, per_test_hint=_PER_TEST)
    # A breaking load without a breaking strain: the strain the model reaches there
    # (the limit of this run, not written to the output).
    (limited,) = with_strain_from_load([data], [model])
    cable = limited.cable()
    # The measured channel as read, as `fit` drives its model: a PARAMS.json
    # re-simulates the file it was fitted to exactly as the fit saw it.
    traj = drive.simulate(
        model, cable, data.time, drive.imposed_of(data), method=_NO_THROW
    )
    _check_success(
        traj, name, lambda i: str(request.input) if i is None else data.locate(i)
    )
    metadata = dict(data.metadata)
    # Record the cable the simulation assumed where the file left it to defaults.
    metadata.setdefault("diameter_mm", float(cable.diameter) * 1e3)
    metadata.setdefault("rate_mm_per_min", float(cable.speed) * 1e3 * 60)
    metadata["model"] = name
    metadata["control"] = drive.name
    if request.model.params:
        metadata["model_params"] = params_metadata(model)
    simulated = {drive.scored: np.asarray(drive.scored_of(traj))}
    out = dataclasses.replace(data, **simulated, metadata=metadata)
    _write(request.out, out)
    print(
        f"wrote {request.out} ({data.num_samples} samples, {_COLUMN[drive.scored]} "
        f"simulated by model '{name}', {drive.name} drive)"
    )
    return 0


# The data options a protocol refuses (its file gives the cable), by their key
# in `read_test`'s metadata.
_HISTORY_ONLY = (
    ("length_mm", "--length-mm"),
    ("diameter_mm", "--diameter-mm"),
    ("rate_mm_per_min", "--rate-mm-per-min"),
)


def _history_only(reading: Reading) -> list[str]:
    """The data options given that read a history, not a protocol, in the order of
    the help."""
    given = ["--columns"] if reading.columns is not None else []
    if reading.options.skip_rows is not None:
        given.append("--skip-rows")
    given += [
        flag for key, flag in _HISTORY_ONLY if reading.metadata.get(key) is not None
    ]
    if not reading.options.detect_slack:
        given.append("--no-slack")
    return given


def _simulate_protocol(request: SimulateRequest) -> int:
    given = _history_only(request.reading)
    if given:
        raise CliError(
            f"{given[0]}: reads a HISTORY.csv; a protocol file gives its cable itself."
        )
    path = request.input
    spec = read_protocol(path)
    breaking_strain = request.reading.metadata.get("breaking_strain")
    if breaking_strain is not None:
        cable = eqx.tree_at(
            lambda c: c.breaking_strain, spec.cable, float(breaking_strain)
        )
        spec = spec._replace(cable=cable)
    name, model = resolve_model(request.model, per_test_hint=_PER_TEST)
    traj = simulate_rate_test(model, spec.cable, spec.protocol, method=_NO_THROW)

    def where(i):
        segment = spec.segment_of(i) if i is not None else None
        return path if segment is None else f"{path}, segments[{segment}]"

    _check_success(traj, name, where)
    _check_times(np.asarray(traj.time), where)
    given = {}
    if breaking_strain is not None:
        given["breaking_strain"] = float(breaking_strain)
    metadata = {
        **spec.metadata,
        **given,
        "protocol": pathlib.Path(path).name,
        "model": name,
        # A fit of this file drives it by its force history, as it was made.
        "control": FORCE_DRIVEN.name,
    }
    if request.model.params:
        metadata["model_params"] = params_metadata(model)
    data = TestData(
        time=np.asarray(traj.time),
        force=np.asarray(traj.force),
        elongation=np.asarray(traj.elongation),
        metadata=metadata,
    )
    _write(request.out, data)
    duration = float(data.time[-1])
    print(
        f"wrote {request.out} ({data.num_samples} samples over {duration:.6g} s, "
        f"model '{name}')"
    )
    return 0


def simulate_command(args) -> int:
    """Run `jaxcable simulate` with the parsed command line `args`; the exit status."""
    request = SimulateRequest(
        input=args.input,
        out=args.out,
        model=ModelChoice(args.model, args.params, args.test),
        reading=data_options(args),
        drive=args.drive,
    )
    return simulate_file(request)


def simulate_file(request: SimulateRequest) -> int:
    """`jaxcable simulate` as `request` asks: the protocol or history simulated and
    written to `out`; the exit status."""
    require_folder_of(request.out, "--out")
    inputs = [("PROTOCOL.json|HISTORY.csv", request.input)]
    if request.model.params:
        inputs.append(("--params", request.model.params))
    refuse_inputs([("--out", request.out)], inputs)
    if request.input.lower().endswith(".json"):
        return _simulate_protocol(request)
    return _simulate_history(request)
