"""The protocol file of `jaxcable simulate`: a rate-driven test described in JSON.

```json
{
  "id": "sk78-300mm-100N",
  "material": "Dyneema SK78",
  "length_mm": 300,
  "diameter_mm": 3,
  "rate_mm_per_min": 3,
  "segments": [
    {"cycles": 10, "force_max_N": 100, "samples_per_ramp": 200},
    {"rest_h": 24},
    {"ramp_to_N": 50, "samples": 100},
    {"hold_s": 60, "force_N": 50},
    {"ramp_to_N": 0, "samples": 100}
  ]
}
```

Top-level keys: `length_mm` (required, the free length, mm), `diameter_mm` (default
3 mm), `rate_mm_per_min` (the crosshead speed of every ramp, default 3 mm/min),
`segments` (required, a non-empty list) and the optional strings `id`, `material`,
`description` (copied to the output's metadata). The cable's breaking load is the
3 mm rope's 2000 N scaled with the cross-section ([`jaxcable.default_breaking_load`][])
and it has no breaking strain (`inf`) unless the caller gives one. The test starts
unloaded (0 N) at t = 0 and runs the segments in order; each segment is named by
exactly one of these keys:

| segment | keys (units; default) | what it does |
| --- | --- | --- |
| cycles | `cycles` (count), `force_max_N` (N), `force_min_N` (N; 0), `samples_per_ramp` (200), `peak_hold_s` (s; 0) | `cycles` ramps from the current force up to `force_max_N` and back down to `force_min_N` |
| ramp | `ramp_to_N` (N), `samples` (100) | one ramp from the current force to `ramp_to_N` |
| hold | `hold_s` (s), `force_N` (N; the current force), `samples` (10) | holds the current force (creep); `force_N`, if given, must equal it |
| rest | `rest_h` (h) or `rest_s` (s), `samples` (24) | a rest at 0 N (recovery); the force must be 0 when it starts |

Ramps run at the crosshead speed; the time of each ramp sample is solved by the model
([`jaxcable.simulate_rate_test`][]). Unknown keys are errors (a misspelt key would
otherwise be silently ignored).

Every number must be physical, so that a run never succeeds on a cable no test could
hold: the length within 1 mm to 10 km, the diameter 0.01 mm to 1 m, the speed 1e-6
to 1e7 mm/min, every duration at most 1e10 s (about 300 years) and at least 1 µs a
sample, every force at most the cable's breaking load and a stress of 10 GPa (above
any polymer fibre's strength), every ramp at least 1 µN a sample. A protocol has at
most 100,000 cycles a segment and 1,000,000 samples in all (a larger one would take
hours and gigabytes to solve).
"""

import json
import math
import os
from typing import Any, NamedTuple

import numpy as np

from .._cable import DEFAULT_DIAMETER_MM, DEFAULT_RATE_MM_PER_MIN, Cable
from .._checks import is_number
from .._drive import Protocol
from .json_file import read_json


_TOP_LEVEL = (
    "length_mm",
    "diameter_mm",
    "rate_mm_per_min",
    "segments",
    "id",
    "material",
    "description",
)
_STRINGS = ("id", "material", "description")

# Segment kind -> (the key that names it, its other keys). `rest` is named by either
# `rest_h` or `rest_s`.
_SEGMENTS = {
    "cycles": ("force_max_N", "force_min_N", "samples_per_ramp", "peak_hold_s"),
    "ramp_to_N": ("samples",),
    "hold_s": ("force_N", "samples"),
    "rest_h": ("samples",),
    "rest_s": ("samples",),
}
_DEFAULT_SAMPLES_PER_RAMP = 200
_DEFAULT_RAMP_SAMPLES = 100
_DEFAULT_HOLD_SAMPLES = 10
_DEFAULT_REST_SAMPLES = 24
# Physical ranges of the cable (the docstring says why): key -> (low, high, unit).
_CABLE_RANGES = {
    "length_mm": (1.0, 1e7, "mm"),
    "diameter_mm": (0.01, 1e3, "mm"),
    "rate_mm_per_min": (1e-6, 1e7, "mm/min"),
}
_MAX_DURATION_S = 1e10
_MIN_STEP_S = 1e-6  # the shortest sample of a hold or rest
_MIN_FORCE_STEP_N = 1e-6  # the smallest force step of a ramp
_MAX_STRESS_PA = 1e10
# Resource limits: the rate solve is sequential, about 10^4-10^5 samples a second.
MAX_SAMPLES = 1_000_000
MAX_CYCLES = 100_000
# A hold's `force_N` equals the current force when it is within this (relative).
_SAME_FORCE = 1e-9


class ProtocolFile(NamedTuple):
    """A protocol file, parsed.

    - `protocol`: the [`jaxcable.Protocol`][] (its first sample is 0 N at t = 0).
    - `cable`: the [`jaxcable.Cable`][] (SI) it is run on.
    - `metadata`: `length_mm`, `diameter_mm`, `rate_mm_per_min` and the file's
        strings, for the output file's `# key: value` block.
    - `segment_starts`: the index of each segment's first sample (sample 0 is the
        unloaded start), for error messages.
    """

    protocol: Protocol
    cable: Cable
    metadata: dict[str, float | str]
    segment_starts: tuple[int, ...]

    def segment_of(self, sample: int) -> int | None:
        """The index of the segment sample `sample` belongs to (None: the start)."""
        starts = np.asarray(self.segment_starts)
        k = int(np.searchsorted(starts, sample, side="right")) - 1
        return None if k < 0 else k


def _repeat(protocol: Protocol, times: int) -> Protocol:
    """`protocol` run `times` times in a row."""
    return Protocol(
        **{
            name: np.tile(np.asarray(getattr(protocol, name)), times)
            for name in ("force", "direction", "duration", "mask")
        }
    )


def _show(value: Any) -> str:
    """`value` as JSON, cut short: the error's one line stays readable."""
    text = json.dumps(value)
    return text if len(text) <= 40 else f"{text[:30]}... ({len(text)} characters)"


class _Reader:
    """Typed access to one JSON object, with errors naming the file and key path."""

    def __init__(self, path: str, where: str, obj: dict):
        self.path = path
        self.where = where
        self.obj = obj

    def _name(self, key: str) -> str:
        return f"{self.where}.{key}" if self.where else key

    def error(self, key: str | None, message: str) -> ValueError:
        name = self.where if key is None else self._name(key)
        return ValueError(f"{self.path}, {name}: {message}" if name else message)

    def number(self, key: str, unit: str, default=None, *, allow_zero=False) -> float:
        """The finite number at `key` (> 0, or >= 0 with `allow_zero`); `default`
        when absent, or an error naming the missing key when `default` is None."""
        if key not in self.obj:
            if default is None:
                where = f"{self.path}, {self.where}" if self.where else self.path
                raise ValueError(f"{where}: missing key '{key}' ({unit}).")
            return float(default)
        value = self.obj[key]
        if not is_number(value) or not math.isfinite(value):
            raise self.error(key, f"{_show(value)} is not a finite number ({unit}).")
        if not (value > 0 or (allow_zero and value == 0)):
            bound = ">= 0" if allow_zero else "> 0"
            raise self.error(key, f"{value:g} {unit} must be {bound}.")
        return float(value)

    def within(self, key: str, value: float, low: float, high: float, unit: str):
        """`value` (of `key`), refused unless `low <= value <= high`."""
        if not low <= value <= high:
            raise self.error(
                key, f"{value:g} {unit} is outside {low:g}-{high:g} {unit}."
            )
        return value

    def duration(self, key: str, seconds: float, samples: int) -> float:
        """`seconds` (of `key`), refused beyond the duration limits."""
        if seconds > _MAX_DURATION_S:
            raise self.error(
                key, f"{seconds:g} s is longer than {_MAX_DURATION_S:g} s."
            )
        if seconds / samples < _MIN_STEP_S:
            raise self.error(
                key,
                f"{seconds:g} s in {samples} samples is less than {_MIN_STEP_S:g} s "
                "a sample (time stamps must increase).",
            )
        return seconds

    def count(self, key: str, default: int) -> int:
        if key not in self.obj:
            return default
        value = self.obj[key]
        if not (is_number(value) and float(value).is_integer() and value >= 1):
            raise self.error(key, f"{_show(value)} is not an integer >= 1.")
        if value > MAX_SAMPLES:
            raise self.error(key, f"{value:g} is more than {MAX_SAMPLES:,}.")
        return int(value)


class _Builder:
    """The protocol as its segments are read: the samples so far, the force the last
    segment ends at, and the limits of the cable it runs on."""

    def __init__(self, cable: Cable, diameter_mm: float):
        self.breaking = float(cable.breaking_load)
        self.strongest = _MAX_STRESS_PA * float(cable.area)
        self.diameter_mm = diameter_mm
        self.parts = [Protocol.start()]
        self.starts: list[int] = []
        self.num_samples = 1
        self.force = 0.0  # the force the previous segment ends at, N

    def force_value(self, reader: _Reader, key: str, default=None) -> float:
        if default is not None and key not in reader.obj:
            return default
        value = reader.number(key, "N", allow_zero=True)
        if value > self.breaking:
            raise reader.error(
                key,
                f"{value:g} N exceeds the cable's breaking load ({self.breaking:g} N).",
            )
        if value > self.strongest:
            raise reader.error(
                key,
                f"{value:g} N on a {self.diameter_mm:g} mm cable is a stress above "
                f"{_MAX_STRESS_PA / 1e9:g} GPa (no polymer fibre holds it).",
            )
        return value

    @staticmethod
    def ramp_samples(reader: _Reader, key: str, start: float, end: float, n: int):
        if abs(end - start) / n < _MIN_FORCE_STEP_N:
            raise reader.error(
                key,
                f"{start:g} to {end:g} N in {n} samples is less than "
                f"{_MIN_FORCE_STEP_N:g} N a sample (time stamps must increase).",
            )
        return n

    def room(self, reader: _Reader, key: str, wanted: int) -> None:
        # Checked before the segment is built: a huge one would not fit in memory.
        if self.num_samples + wanted > MAX_SAMPLES:
            raise reader.error(
                key,
                f"the protocol would have {self.num_samples + wanted:,} samples, "
                f"more than {MAX_SAMPLES:,}; split it into several files.",
            )

    def add(self, segment_parts: list[Protocol]) -> None:
        self.starts.append(self.num_samples)
        self.num_samples += sum(p.num_samples for p in segment_parts)
        self.parts.extend(segment_parts)

    def cycles(self, r: _Reader) -> list[Protocol]:
        cycles = r.count("cycles", 1)
        if cycles > MAX_CYCLES:
            raise r.error("cycles", f"{cycles:,} is more than {MAX_CYCLES:,}.")
        high = self.force_value(r, "force_max_N")
        low = self.force_value(r, "force_min_N", 0.0)
        spr = r.count("samples_per_ramp", _DEFAULT_SAMPLES_PER_RAMP)
        hold = r.number("peak_hold_s", "s", 0.0, allow_zero=True)
        if hold > 0:
            r.duration("peak_hold_s", hold, 1)
        force = self.force
        if not high > force:
            raise r.error(
                "force_max_N",
                f"{high:g} N must exceed the force the previous segment ends "
                f"at ({force:g} N).",
            )
        if not low < high:
            raise r.error(
                "force_min_N", f"{low:g} N must be below force_max_N ({high:g} N)."
            )
        self.ramp_samples(r, "force_max_N", force, high, spr)
        self.ramp_samples(r, "force_min_N", low, high, spr)
        self.room(r, "cycles", cycles * (2 * spr + (hold > 0)))
        peak = [Protocol.hold(high, hold, 1)] if hold > 0 else []
        down = Protocol.ramp(high, low, spr)
        segment_parts = [Protocol.ramp(force, high, spr), *peak, down]
        if cycles > 1:
            # Every cycle after the first is the same: one, tiled.
            later = Protocol.concatenate(Protocol.ramp(low, high, spr), *peak, down)
            segment_parts.append(_repeat(later, cycles - 1))
        self.force = low
        return segment_parts

    def ramp(self, r: _Reader) -> list[Protocol]:
        target = self.force_value(r, "ramp_to_N")
        samples = r.count("samples", _DEFAULT_RAMP_SAMPLES)
        force = self.force
        if target == force:
            raise r.error(
                "ramp_to_N",
                f"the previous segment already ends at {force:g} N; a ramp "
                "needs another force.",
            )
        self.ramp_samples(r, "ramp_to_N", force, target, samples)
        self.room(r, "samples", samples)
        self.force = target
        return [Protocol.ramp(force, target, samples)]

    def hold(self, r: _Reader) -> list[Protocol]:
        force = self.force
        duration = r.number("hold_s", "s")
        held = self.force_value(r, "force_N", force)
        samples = r.count("samples", _DEFAULT_HOLD_SAMPLES)
        r.duration("hold_s", duration, samples)
        self.room(r, "samples", samples)
        if abs(held - force) > _SAME_FORCE * max(1.0, abs(force)):
            raise r.error(
                "force_N",
                f"{held:g} N differs from the force the previous segment ends "
                f'at ({force:g} N); add {{"ramp_to_N": {held:g}}} before the '
                "hold.",
            )
        return [Protocol.hold(force, duration, samples)]

    def rest(self, r: _Reader, kind: str) -> list[Protocol]:
        duration = r.number(kind, "h" if kind == "rest_h" else "s")
        if kind == "rest_h":
            duration *= 3600.0
        samples = r.count("samples", _DEFAULT_REST_SAMPLES)
        r.duration(kind, duration, samples)
        self.room(r, "samples", samples)
        if self.force != 0.0:
            raise r.error(
                kind,
                f"a rest is at 0 N but the previous segment ends at {self.force:g} "
                'N; add {"ramp_to_N": 0} before it.',
            )
        return [Protocol.rest(duration, samples)]


def _segment_kind(path: str, where: str, segment) -> str:
    """The kind of `segment` (the key of `_SEGMENTS` naming it), its keys checked."""
    if not isinstance(segment, dict):
        raise ValueError(
            f"{path}, {where}: a segment is a JSON object such as "
            f'{{"ramp_to_N": 50}}, got {_show(segment)}.'
        )
    kinds = [k for k in _SEGMENTS if k in segment]
    if len(kinds) != 1:
        found = f"has {', '.join(kinds)}" if kinds else "has none"
        raise ValueError(
            f"{path}, {where}: a segment has exactly one of "
            f"{', '.join(_SEGMENTS)}; this one {found}."
        )
    kind = kinds[0]
    for key in segment:
        if key != kind and key not in _SEGMENTS[kind]:
            raise ValueError(
                f"{path}, {where}.{key}: unknown key for a '{kind}' segment "
                f"(it takes {', '.join((kind, *_SEGMENTS[kind]))})."
            )
    return kind


def _top_level(
    path: str, doc
) -> tuple[_Reader, tuple[float, float, float], dict[str, float | str]]:
    """The reader of the file's top-level object, the cable's length, diameter (mm)
    and crosshead speed (mm/min), checked against their ranges, and the metadata
    (those and the strings)."""
    if not isinstance(doc, dict):
        raise ValueError(
            f"{path}: a protocol file is a JSON object with length_mm and segments, "
            f"got a {type(doc).__name__}."
        )
    for key in doc:
        if key not in _TOP_LEVEL:
            raise ValueError(
                f"{path}, {key}: unknown key (a protocol file has "
                f"{', '.join(_TOP_LEVEL)})."
            )
    top = _Reader(path, "", doc)
    length, diameter, rate = (
        top.within(key, top.number(key, unit, default), low, high, unit)
        for (key, (low, high, unit)), default in zip(
            _CABLE_RANGES.items(),
            (None, DEFAULT_DIAMETER_MM, DEFAULT_RATE_MM_PER_MIN),
        )
    )
    metadata: dict[str, float | str] = {}
    for key in _STRINGS:
        if key in doc:
            if not isinstance(doc[key], str):
                raise top.error(key, f"{_show(doc[key])} is not a string.")
            metadata[key] = doc[key]
    metadata.update(length_mm=length, diameter_mm=diameter, rate_mm_per_min=rate)
    return top, (length, diameter, rate), metadata


def read_protocol(path: str | os.PathLike) -> ProtocolFile:
    """Read a rate-driven protocol file (the JSON schema of this module's docstring).

    **Arguments:**

    - `path`: the `.json` file.

    **Returns:**

    A `ProtocolFile`: the [`jaxcable.Protocol`][], the [`jaxcable.Cable`][] and the
    metadata for the output file.

    **Raises:**

    `ValueError` naming the file and the key (e.g. `segments[2].force_max_N`) of the
    first problem: invalid JSON (with its line and column), a missing or unknown key,
    a value that is not a positive number or count, a segment that does not follow on
    from the force the previous one ends at, or a force above the cable's breaking
    load; naming the file when it cannot be read or is not UTF-8 text.
    """
    path = str(path)
    doc = read_json(path, "a protocol file")
    top, (length, diameter, rate), metadata = _top_level(path, doc)
    # A protocol names no material: no strain limit unless the caller gives one
    # (`jaxcable simulate --breaking-strain`), as for a data file without one.
    cable = Cable.from_mm(
        length_mm=length,
        diameter_mm=diameter,
        rate_mm_per_min=rate,
        breaking_strain=math.inf,
    )
    if "segments" not in doc:
        raise ValueError(
            f"{path}: missing key 'segments' (a list such as "
            '[{"cycles": 10, "force_max_N": 100}, {"rest_h": 24}]).'
        )
    segments = doc["segments"]
    if not isinstance(segments, list) or not segments:
        raise top.error("segments", "must be a non-empty list of segment objects.")
    builder = _Builder(cable, diameter)
    for i, segment in enumerate(segments):
        where = f"segments[{i}]"
        kind = _segment_kind(path, where, segment)
        r = _Reader(path, where, segment)
        if kind == "cycles":
            builder.add(builder.cycles(r))
        elif kind == "ramp_to_N":
            builder.add(builder.ramp(r))
        elif kind == "hold_s":
            builder.add(builder.hold(r))
        else:  # rest_h / rest_s
            builder.add(builder.rest(r, kind))
    return ProtocolFile(
        protocol=Protocol.concatenate(*builder.parts),
        cable=cable,
        metadata=metadata,
        segment_starts=tuple(builder.starts),
    )
