"""The measured tests of `jaxcable fit`, `jaxcable diagnose` and `jaxcable demo`: read
with the data options, thinned, and described in one line per file."""

import csv
import dataclasses
import pathlib
import sys
import warnings
from collections.abc import Callable, Sequence

import numpy as np

from .._io import MetadataConflictWarning, TestData, read_test
from .._progress import AbstractProgressMeter
from .common import PROG, CliError, one_line


# The csv module's limit on one cell (its default, 128 KiB): a longer cell is no
# measurement, and is reported as such.
_FIELD_LIMIT = csv.field_size_limit()


def read_located(read: Callable[..., TestData], path, **options) -> TestData:
    """`read(path, **options)`, with the errors the readers do not locate (the csv
    module's, a number too large for a float) reported naming `path`; the readers'
    own `ValueError`s already name the file, line and column. A given option that
    replaces a file's value ([`jaxcable.MetadataConflictWarning`][]) is printed as
    one warning line on stderr."""
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", MetadataConflictWarning)
            data = read(path, **options)
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


def data_options(args) -> dict:
    """`read_test` keyword arguments from the data options of the command line."""
    return dict(
        columns=args.columns,
        skip_rows=args.skip_rows,
        length_mm=args.length_mm,
        diameter_mm=args.diameter_mm,
        rate_mm_per_min=args.rate_mm_per_min,
        detect_slack=not args.no_slack,
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
        mask=data.mask[index],
        force_raw=take(data.force_raw),
    )


def read_tests(
    paths: Sequence, options: dict, every: int, meter: AbstractProgressMeter
) -> list[TestData]:
    """Measured tests, read with `read_test` (canonical or raw exports).

    **Arguments:**

    - `paths`: the files.
    - `options`: `read_test` keyword arguments ([`data_options`][]).
    - `every`: keep every `every`-th sample (the first and last kept).
    - `meter`: the progress meter.

    **Returns:**

    The tests, each with its elongation and a cable; fails naming the file otherwise.
    """
    tests = []
    with meter.bar("reading", len(paths)) as bar:
        for path in paths:
            data = read_located(read_test, path, **options)
            if data.elongation is None:
                raise CliError(
                    f"{path}: no elongation column; a fit needs the measured "
                    "elongation (a column elongation_mm, or name it with --columns)."
                )
            data.cable()  # raises, naming the file, when length_mm is missing
            tests.append(_thin(data, every))
            bar.advance(note=pathlib.Path(path).name)
    return tests


def describe_tests(
    tests: Sequence[TestData], every: int, drives: Sequence | None = None
) -> list[str]:
    """One line per test: its name, samples, what was masked as slack, and (with
    `drives`, a `ControlDetection` per test) its drive and why; then its notes
    (`TestData.notes`), one indented line each."""
    lines = []
    for i, t in enumerate(tests):
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
        if drives is not None:
            text += f"; drive: {drives[i].reason}"
        lines.append(text)
        # How an instrument export was read: the columns it has that are not read.
        lines.extend(f"    {note}" for note in getattr(t, "notes", ()))
    return lines
