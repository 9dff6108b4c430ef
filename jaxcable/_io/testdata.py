"""The measured test: [`jaxcable.TestData`][] (time-stamped force and elongation with the
file's metadata), where its samples came from, and [`jaxcable.mask_slack`][], which
masks the samples a slack cable gives."""

import dataclasses
import math

import numpy as np

from .._cable import (
    DEFAULT_DIAMETER_MM,
    Cable,
    default_breaking_load,
    speed_from_mm_per_min,
)
from .._checks import require_number
from .slack import SlackReport, detect_slack
from .units import COLUMNS, QUANTITIES, written_name


# The canonical column name of each quantity, for messages about a TestData not
# read from a file.
_WRITTEN = {quantity: written_name(quantity) for quantity in QUANTITIES}


# The metadata keys that describe the cable, named as the arguments of
# `Cable.from_mm`.
_CABLE_KEYS = (
    "length_mm",
    "diameter_mm",
    "rate_mm_per_min",
    "temperature_C",
    "breaking_load_N",
    "breaking_strain",
)


def where(path, line=None, column=None, position=None) -> str:
    """The location prefix of every error message: file, 1-based line, column (its
    1-based position in the row when known, and its name)."""
    parts = [str(path)]
    if line is not None:
        parts.append(f"line {line}")
    if column is not None:
        number = "" if position is None else f"{position} "
        parts.append(f"column {number}'{column}'")
    return ", ".join(parts)


@dataclasses.dataclass(frozen=True, eq=False)
class TestData:
    """One measured or simulated cable test: a time-stamped force (and elongation)
    history with its metadata, as read from or written to the canonical CSV file.

    **Fields:**

    - `time`: sample times, s.
    - `force`: cable force, N.
    - `elongation`: elongation, m, or `None` when the file has no elongation column.
    - `temperature`: temperature at each sample, °C, or `None`.
    - `extra`: any other columns, by their name in the file, values as in the file
        (not converted); carried through on write.
    - `metadata`: the `# key: value` block. `length_mm`, `diameter_mm`,
        `rate_mm_per_min`, `temperature_C`, `breaking_load_N` and `breaking_strain`
        (elongation / L0 at break, dimensionless) are floats in the units their
        names say, checked when read; `control` is the channel the test
        imposed, `"force"` or `"elongation"` (see [`jaxcable.fit`][]'s `drive`;
        displacement, extension, position... are read as `"elongation"`); every
        other key (`material`, `id`, ...) is a string.
    - `source`: the file the data were read from (for error messages), or `None`.
    - `lines`: the 1-based line number of each sample in `source`, or `None`.
    - `mask`: per sample, True where it is to be fitted, False where it is not (a
        slack stretch, see [`jaxcable.mask_slack`][]). All True unless set. It weights
        residuals only: the whole history, masked samples included, still drives a
        simulation (with `force` there, which is never negative).
    - `force_raw`: the force as measured, N, where `force` differs from it (negative
        readings clipped to 0 by [`jaxcable.mask_slack`][]); `None` when `force` is
        the measured force.
    - `slack_report`: what [`jaxcable.mask_slack`][] found (a
        [`jaxcable.SlackReport`][]), or `None` when it has not run (e.g.
        [`jaxcable.read_csv`][]).
    - `notes`: one line each about how the file was read that is no error (the
        columns of an instrument export that are not read).
    - `column_names`: per quantity (`"time"`, `"force"`, ...), the name of its
        column in `source` (`"Load"` of an Instron export), for error messages;
        empty when not read from a file.
    """

    # pytest would otherwise try to collect this class wherever it is imported.
    __test__ = False

    time: np.ndarray
    force: np.ndarray
    elongation: np.ndarray | None = None
    temperature: np.ndarray | None = None
    extra: dict[str, np.ndarray] = dataclasses.field(default_factory=dict)
    metadata: dict[str, float | str] = dataclasses.field(default_factory=dict)
    source: str | None = None
    lines: np.ndarray | None = None
    mask: np.ndarray | None = None
    force_raw: np.ndarray | None = None
    slack_report: SlackReport | None = None
    notes: tuple[str, ...] = ()
    column_names: dict[str, str] = dataclasses.field(default_factory=dict)

    def __post_init__(self):
        arrays = {"time": self.time, "force": self.force}
        for name in ("elongation", "temperature", "force_raw"):
            if getattr(self, name) is not None:
                arrays[name] = getattr(self, name)
        for name, value in self.extra.items():
            arrays[f"extra[{name!r}]"] = value
        converted = {}
        for name, value in arrays.items():
            v = np.asarray(value, dtype=float)
            if v.ndim != 1:
                raise ValueError(
                    f"TestData `{name}` must be 1-dimensional, got shape {v.shape}."
                )
            converted[name] = v
        lengths = {name: v.shape[0] for name, v in converted.items()}
        if len(set(lengths.values())) != 1:
            raise ValueError(f"TestData columns differ in length: {lengths}.")
        if lengths["time"] == 0:
            raise ValueError("TestData needs at least one sample.")
        for name in (*QUANTITIES, "force_raw"):
            if name in converted:
                object.__setattr__(self, name, converted[name])
        if self.mask is None:
            mask = np.ones(lengths["time"], dtype=bool)
        else:
            mask = np.asarray(self.mask, dtype=bool)
            if mask.shape != (lengths["time"],):
                raise ValueError(
                    f"TestData `mask` must have shape ({lengths['time']},) like "
                    f"`time`, got {mask.shape}."
                )
        object.__setattr__(self, "mask", mask)
        canonical = set(COLUMNS)
        extra = {}
        for name in self.extra:
            if name in canonical:
                raise ValueError(
                    f"TestData extra column '{name}' is a canonical column; set the "
                    f"`{COLUMNS[name].quantity}` field instead."
                )
            extra[name] = converted[f"extra[{name!r}]"]
        object.__setattr__(self, "extra", extra)
        object.__setattr__(self, "metadata", dict(self.metadata))
        object.__setattr__(self, "notes", tuple(str(n) for n in self.notes))
        object.__setattr__(self, "column_names", dict(self.column_names))
        if self.lines is not None:
            object.__setattr__(self, "lines", np.asarray(self.lines, dtype=int))

    @property
    def control(self) -> str | None:
        """The channel the test imposed, from `metadata['control']`: `"force"`,
        `"elongation"`, or `None` when the metadata do not say (then
        [`jaxcable.detect_control`][] tells from the data)."""
        value = self.metadata.get("control")
        return None if value is None else str(value)

    @property
    def num_samples(self) -> int:
        """The number of samples (rows)."""
        return int(self.time.shape[0])

    def cable(self) -> Cable:
        """The [`jaxcable.Cable`][] described by the metadata, in SI.

        `length_mm` is required; `diameter_mm` defaults to 3 mm and `rate_mm_per_min`
        (the crosshead speed) to 3 mm/min, Park's Dyneema SK78 test. The temperature
        is the metadata's `temperature_C`, else the mean of the temperature column,
        else the `Cable` default (20 °C).

        A material's limits come from its data. The breaking strain is
        `breaking_strain` when given (`inf`: a material that does not break), else
        none (`inf`): the `Cable` default is a Dyneema rope's, which must not stop
        another material's simulation; a file with only a breaking load gets its
        strain from a fitted model (the command line does so after a fit). The
        breaking load is `breaking_load_N` when given, else the 3 mm rope's 2000 N
        scaled with the cross-section ([`jaxcable.default_breaking_load`][]), and
        never below the largest force the test measured (the cable carried it).

        **Returns:**

        A [`jaxcable.Cable`][] with `length` and `diameter` in m and `speed` in m/s.
        """
        if "length_mm" not in self.metadata:
            raise ValueError(
                f"{where(self.source or '<TestData>')}: metadata has no 'length_mm' "
                "(the free length of the cable, mm)."
            )
        mm = {}
        for key in _CABLE_KEYS:
            if key in self.metadata:
                try:
                    mm[key] = float(self.metadata[key])
                except (TypeError, ValueError):
                    raise ValueError(
                        f"{where(self.source or '<TestData>')}, metadata '{key}': "
                        f"{self.metadata[key]!r} is not a number."
                    ) from None
        if "temperature_C" not in mm and self.temperature is not None:
            mm["temperature_C"] = float(np.mean(self.temperature))
        mm.setdefault("breaking_strain", math.inf)
        if "breaking_load_N" not in mm:
            scaled = default_breaking_load(mm.get("diameter_mm", DEFAULT_DIAMETER_MM))
            mm["breaking_load_N"] = max(scaled, self.peak_force())
        return Cable.from_mm(**mm)

    def peak_force(self) -> float:
        """The largest force the test measured, N (`force_raw` where set; 0 when
        there is no finite positive force, e.g. an elongation history)."""
        measured = self.force if self.force_raw is None else self.force_raw
        finite = measured[np.isfinite(measured)]
        return max(float(np.max(finite)), 0.0) if finite.size else 0.0

    def column_name(self, quantity: str) -> str:
        """The name of `quantity`'s column in the file (`"Load"`), else its
        canonical name (`"force_N"`), for error messages."""
        return self.column_names.get(quantity, _WRITTEN.get(quantity, quantity))

    def locate(self, index: int, column: str | None = None) -> str:
        """Where sample `index` came from: `file, line N, column 'name'` (for errors)."""
        if self.lines is None:
            place = where(self.source or "<TestData>", column=column)
            return f"{place}, sample {index}"
        return where(self.source, int(self.lines[index]), column)


def mask_slack(
    data: TestData, *, threshold_N: float | None = None, stretches: bool = True
) -> TestData:
    """Detect the slack stretches of a test, mask them and clip negative forces.

    A slack stretch is a run of samples with the force below a threshold while the
    crosshead keeps moving (the elongation changes at the test's speed and by at
    least 2 % of the test's range). The threshold is `max(0.5 % of the peak force,
    3 x the force noise)`, capped at 5 % of the peak; the noise is the robust
    standard deviation of the force's second differences. Samples in slack
    stretches, and any sample with the force below minus the threshold, are masked
    (`mask` False): they are not fitted. Every negative force is set to 0 in `force`
    (the kernels reject negative forces, and a slack cable carries none); the
    measured force is kept in `force_raw`. The full rule and its constants are in
    the docstring of the slack-detection module (`jaxcable._io.slack`).

    **Arguments:**

    - `data`: a [`jaxcable.TestData`][]; detection reads `force_raw` when set (so it
        can be re-run) and the crosshead speed from `rate_mm_per_min` when the
        metadata has it (else it is estimated from the elongation).
    - `threshold_N`: the force threshold, N, or `None` for the rule above.
    - `stretches`: whether to look for slack stretches; without, only the readings
        below minus the threshold are masked and the negative forces clipped (the
        command line's `--no-slack`: every command still sees the same force).

    **Returns:**

    A new [`jaxcable.TestData`][] with `mask`, `force`, `force_raw` and
    `slack_report` (a [`jaxcable.SlackReport`][]) set; any previous mask is replaced.
    """
    if not isinstance(data, TestData):
        raise TypeError(
            f"`data` must be a jaxcable.TestData, got {type(data).__name__}."
        )
    if threshold_N is not None:
        require_number("threshold_N", threshold_N, 0)
    measured = data.force if data.force_raw is None else data.force_raw
    rate = data.metadata.get("rate_mm_per_min")
    speed = None if rate is None else speed_from_mm_per_min(float(rate))
    if not isinstance(stretches, bool | np.bool_):
        raise TypeError(f"`stretches` must be True or False, got {stretches!r}.")
    mask, force, report = detect_slack(
        data.time,
        measured,
        data.elongation if stretches else None,
        speed=speed,
        threshold=threshold_N,
        lines=data.lines,
    )
    return dataclasses.replace(
        data,
        force=force,
        force_raw=measured if report.clipped else None,
        mask=mask,
        slack_report=report,
    )


def pushing_samples(data: TestData) -> np.ndarray:
    """The samples whose measured force is below minus the noise tolerance, outside
    the slack stretches: readings that a load cell's noise about zero does not
    explain (a cable cannot push). The tolerance is the slack threshold of
    [`jaxcable.mask_slack`][] (`data.slack_report.threshold`, from the file's own
    force noise); without a slack report, every negative force.

    **Arguments:**

    - `data`: a [`jaxcable.TestData`][].

    **Returns:**

    The sample indices, in order (an integer array, empty when there is none).
    """
    measured = data.force if data.force_raw is None else data.force_raw
    report = data.slack_report
    if report is None:
        return np.flatnonzero(measured < 0)
    below = measured < -report.threshold
    for stretch in report.stretches:
        below[stretch.start : stretch.stop] = False
    return np.flatnonzero(below)
