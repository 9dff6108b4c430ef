"""Measured tests, checked, padded to one length and stacked for one vmapped kernel."""

import dataclasses
import os
import pathlib
from typing import cast

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float
from numpy.typing import DTypeLike

from .. import _checks
from .._cable import ZERO_CELSIUS, Cable
from .._drive import ELONGATION_DRIVEN, FORCE_DRIVEN, AbstractTestDrive, DriveSpec
from .._io import ControlDetection, TestData, force_noise, resolve_control


class PaddedTests(eqx.Module):
    """Several tests padded to one length and stacked, for one vmapped kernel.

    Build with [`jaxcable.pad_tests`][]. Padding samples repeat a test's last sample
    and are masked out of both the simulation and the residual.

    **Fields:**

    - `time`: sample times, s, shape `(tests, samples)`.
    - `force`: force, N.
    - `elongation`: measured elongation, m.
    - `simulate`: False at padding samples (they leave the model's state unchanged).
    - `weight`: 1.0 where the sample enters the residual, 0.0 at padding and at
        samples the test's own mask excludes (e.g. slack).
    - `temperature`: temperature at each sample, K (the test's temperature record,
        else its `Cable.temperature`).
    - `covariate`: the recorded covariate column at each sample, in that column's
        unit (0 where `pad_tests` was given no `covariate`); the fit sets
        `Cable.covariate` from it per sample.
    - `cable`: a batched [`jaxcable.Cable`][], one per test.
    - `drive`: each test's drive, [`jaxcable.FORCE_DRIVEN`][] (its force history
        drives the model, the elongation is scored) or
        [`jaxcable.ELONGATION_DRIVEN`][] (the elongation drives, the solved force is
        scored).
    - `scale`: each test's residual unit: 1 when every test is scored in the same
        channel (residuals in m, or N); in a fit mixing both, the noise standard
        deviation of the test's scored channel (m or N), so that residuals are
        dimensionless and each test weighs by its own noise.
    """

    time: Float[Array, "tests samples"]
    force: Float[Array, "tests samples"]
    elongation: Float[Array, "tests samples"]
    simulate: Bool[Array, "tests samples"]
    weight: Float[Array, "tests samples"]
    temperature: Float[Array, "tests samples"]
    covariate: Float[Array, "tests samples"]
    cable: Cable
    drive: tuple[AbstractTestDrive, ...] = eqx.field(static=True)
    scale: Float[Array, " tests"]

    @property
    def num_tests(self) -> int:
        return int(self.time.shape[0])

    @property
    def by_force(self) -> np.ndarray:
        """Indices of the force-driven tests."""
        return np.array([i for i, d in enumerate(self.drive) if d == FORCE_DRIVEN], int)

    @property
    def by_elongation(self) -> np.ndarray:
        """Indices of the elongation-driven tests."""
        return np.array([i for i, d in enumerate(self.drive) if d != FORCE_DRIVEN], int)

    @property
    def measured(self) -> Float[ArrayLike, "tests samples"]:
        """The scored channel of each test (elongation m, or force N), 0 where its
        weight is 0: computed by NumPy on the host unless traced (each eager JAX
        operation loads a compiled program of its own)."""
        arrays = (self.force, self.elongation, self.weight)
        xp = np if _checks.is_concrete(*arrays) else jnp
        force, elongation, weight = (xp.asarray(x) for x in arrays)
        scored_force = np.array([d.scores_force for d in self.drive])[:, None]
        return xp.where(scored_force, force, elongation) * weight

    @property
    def units(self) -> tuple[str, ...]:
        """The residual unit of each test: `"m"`, `"N"` or `"1"` (mixed fits)."""
        if len(set(self.drive)) > 1:
            return ("1",) * len(self.drive)
        return tuple(d.unit for d in self.drive)


def test_id(test, index: int) -> str:
    """A test's name for reports and errors: its `metadata['id']`, else its file's
    name, else `test INDEX`."""
    metadata = getattr(test, "metadata", None) or {}
    if "id" in metadata:
        return str(metadata["id"])
    source = getattr(test, "source", None)
    return pathlib.Path(source).name if source else f"test {index}"


def as_test_list(tests) -> list:
    """`tests` (one test or a sequence of them) as a non-empty list.

    **Raises:**

    `ValueError` naming `tests` for None, a path or file name, something not
    iterable, or an empty sequence.
    """
    if tests is None:
        raise ValueError("`tests` must be a TestData or a sequence of them, got None.")
    if isinstance(tests, (str, bytes, os.PathLike)):
        raise ValueError(
            f"`tests` must be TestData objects (read files with jaxcable.read_csv), "
            f"got {type(tests).__name__} {tests!r}."
        )
    if isinstance(tests, TestData):
        tests = [tests]
    try:
        tests = list(tests)
    except TypeError:
        raise ValueError(
            "`tests` must be a TestData or a sequence of them, got "
            f"{type(tests).__name__}."
        ) from None
    if not tests:
        raise ValueError("`tests` is empty: give at least one TestData to fit.")
    return tests


@dataclasses.dataclass(frozen=True)
class _Row:
    """One checked test, host-side (NumPy), before padding."""

    time: np.ndarray
    force: np.ndarray
    elongation: np.ndarray  # 0 where `mask` is False
    mask: np.ndarray  # True where the sample is fitted
    temperature: np.ndarray  # K
    covariate: np.ndarray  # the unit of the covariate column (0 without one)
    cable: Cable
    drive: AbstractTestDrive


def _required_fields(test, where: str) -> None:
    for field in ("time", "force", "elongation"):
        if getattr(test, field, None) is None:
            raise ValueError(
                f"`{where}` has no `{field}`; a fit needs time, force and the "
                "measured elongation."
            )
    if not callable(getattr(test, "cable", None)):
        raise ValueError(f"`{where}` has no `cable()` (length, diameter, speed).")


def _mask(test, where: str, shape: tuple[int, ...]) -> np.ndarray:
    mask = getattr(test, "mask", None)
    if mask is None:
        return np.ones(shape, bool)
    mask = np.asarray(mask, bool)
    if mask.shape != shape:
        raise ValueError(f"`{where}.mask` has shape {mask.shape}, the test {shape}.")
    if not mask.any():
        raise ValueError(f"`{where}.mask` excludes every sample.")
    return mask


def _temperature(test, where: str, time: np.ndarray, cable: Cable) -> np.ndarray:
    """The test's temperature record in K, else its cable's temperature throughout."""
    temperature = getattr(test, "temperature", None)
    if temperature is None:
        return np.full(time.shape, float(cable.temperature))
    temperature = np.asarray(temperature, float) + ZERO_CELSIUS
    _checks.require_same_shape(
        **{f"{where}.time": time, f"{where}.temperature": temperature}
    )
    _checks.require_finite(f"{where}.temperature", temperature)
    _checks.require_positive(f"{where}.temperature (K)", temperature)
    return temperature


def _covariate(test, where: str, time: np.ndarray, name: str | None) -> np.ndarray:
    """The test's covariate column `name` (its unit), else 0 throughout."""
    if name is None:
        return np.zeros(time.shape)
    extra = getattr(test, "extra", None) or {}
    if name not in extra:
        raise ValueError(
            f"`{where}` has no column {name!r} (the `covariate`); its extra columns "
            f"are {sorted(extra)}."
        )
    values = np.asarray(extra[name], float)
    _checks.require_same_shape(
        **{f"{where}.time": time, f"{where}.extra[{name!r}]": values}
    )
    _checks.require_finite(f"{where}.extra[{name!r}]", values)
    return values


def _checked_row(
    test, index: int, drive: AbstractTestDrive, covariate: str | None = None
) -> _Row:
    """Test `index` checked (errors name `tests[index]` and the field); an
    elongation-driven test needs its elongation at every sample."""
    where = f"tests[{index}] ({test_id(test, index)})"
    _required_fields(test, where)
    time = np.asarray(test.time, float)
    force = np.asarray(test.force, float)
    elongation = np.asarray(test.elongation, float)
    _checks.require_same_shape(
        **{f"{where}.time": time, f"{where}.force": force},
        **{f"{where}.elongation": elongation},
    )
    if time.ndim != 1 or time.shape[0] < 2:
        raise ValueError(
            f"`{where}.time` must be 1-d with at least 2 samples, got shape "
            f"{time.shape}."
        )
    mask = _mask(test, where, time.shape)
    _checks.require_finite(f"{where}.time", time)
    _checks.require_finite(f"{where}.force", force)
    by_elongation = drive == ELONGATION_DRIVEN
    driven = elongation if by_elongation else elongation[mask]
    _checks.require_finite(f"{where}.elongation", driven)
    _checks.require_increasing(f"{where}.time", time)
    _checks.require_positive(f"{where}.force", force, allow_zero=True)
    cable = test.cable()
    _checks.require_below(f"{where}.force", force, cable.breaking_load, "breaking load")
    return _Row(
        time=time,
        force=force,
        elongation=elongation if by_elongation else np.where(mask, elongation, 0.0),
        mask=mask,
        temperature=_temperature(test, where, time, cable),
        covariate=_covariate(test, where, time, covariate),
        cable=cable,
        drive=drive,
    )


def resolve_drives(tests, drive: DriveSpec = None) -> list[ControlDetection]:
    """The drive of every test, and why ([`jaxcable.ControlDetection`][]).

    **Arguments:**

    - `tests`: one test or a sequence of tests.
    - `drive`: `"auto"` or `None` (each test's `metadata['control']`, else detected
        from its data by [`jaxcable.detect_control`][]), a drive
        ([`jaxcable.FORCE_DRIVEN`][], [`jaxcable.ELONGATION_DRIVEN`][]) or its name
        (`"force"`, `"elongation"`), or a sequence of these, one per test.

    **Returns:**

    One [`jaxcable.ControlDetection`][] per test; its `drive` is the drive value.

    **Raises:**

    `ValueError` naming `drive`: an unknown name, or a sequence of another length.
    """
    tests = as_test_list(tests)
    if drive is None or isinstance(drive, (str, AbstractTestDrive)):
        drives = [drive] * len(tests)
    else:
        drives = list(drive)
        if len(drives) != len(tests):
            raise ValueError(
                f"`drive` names {len(drives)} drives for {len(tests)} tests; give "
                "one name, or one per test."
            )
    return [resolve_control(t, d) for t, d in zip(tests, drives)]


def _scales(rows: list[_Row]) -> np.ndarray:
    """Each test's residual unit (see `PaddedTests.scale`)."""
    # equinox Modules hash (frozen); pyright takes them for unhashable.
    if len({r.drive for r in rows}) == 1:  # pyright: ignore[reportUnhashable]
        return np.ones(len(rows))
    out = []
    for r in rows:
        scored = r.drive.scored_of(r)[r.mask]
        peak = float(np.max(np.abs(scored)))
        # Quantised or noise-free records have no measurable noise: 1e-4 of the
        # peak stands in, as a resolution.
        out.append(max(force_noise(scored), 1e-4 * peak, 1e-300))
    return np.array(out)


def pad_tests(
    tests,
    *,
    drive=None,
    multiple: int = 16,
    covariate: str | None = None,
    on_device: bool = True,
) -> PaddedTests:
    """Check, pad and stack tests for [`jaxcable.residuals`][] and the fit kernel.

    Each test needs `time` (s), `force` (N), `elongation` (m) and `.cable()` (a
    [`jaxcable.TestData`][] has them). A test may carry a per-sample boolean `mask`
    attribute, True where the sample is fitted (False: a slack stretch or any sample
    not to fit); masked samples still drive the model (their force is real) but do
    not enter the residual.

    **Arguments:**

    - `tests`: one test or a sequence of tests.
    - `drive`: which channel drives each test; see [`jaxcable.fit`][] (default: each
        test's `metadata['control']`, else detected from its data).
    - `multiple`: the padded length is rounded up to a multiple of this, so that data
        sets of similar size reuse one compiled kernel.
    - `covariate`: the name of an extra column of every test (`test.extra[name]`,
        in its own unit) read into `PaddedTests.covariate`, the per-sample
        `Cable.covariate` of the fit; None (default): 0 throughout.
    - `on_device`: the arrays transferred to JAX's device (default), or left as
        NumPy arrays (for many specimens stacked and transferred together).

    **Returns:**

    A [`jaxcable.PaddedTests`][].

    **Raises:**

    `ValueError` naming `tests[i]` and the field: no elongation, fewer than two
    samples, non-finite values, time not strictly increasing, negative force or
    force above the breaking load, a mask of the wrong shape or masking every sample,
    no `covariate` column or a non-finite one.
    """
    tests = as_test_list(tests)
    drives = [d.drive for d in resolve_drives(tests, drive)]
    rows = [
        _checked_row(t, i, d, covariate) for i, (t, d) in enumerate(zip(tests, drives))
    ]
    longest = max(r.time.shape[0] for r in rows)
    length = -(-longest // multiple) * multiple

    def padded(arrays, fill=None) -> np.ndarray:
        """The arrays padded with `fill` (default: each one's last sample), stacked."""
        return np.stack(
            [
                np.concatenate(
                    [
                        x,
                        np.full(
                            length - x.shape[0],
                            x[-1] if fill is None else fill,
                            x.dtype,
                        ),
                    ]
                )
                for x in arrays
            ]
        )

    dtype = jnp.result_type(float)

    def put(x, dtype: DTypeLike = dtype):
        # Converted by NumPy, then transferred: `jnp.asarray` of a NumPy array runs
        # a small compiled program per shape and dtype, `device_put` only copies.
        x = np.asarray(x, dtype)
        # NumPy arrays stand in for the device's until `fit_each` stacks and
        # transfers them.
        return jax.device_put(x) if on_device else cast(jax.Array, x)

    # One transfer per field (not per test): host overhead counts in a small fit.
    cable = jax.tree_util.tree_map(
        lambda *xs: put(np.stack([np.asarray(x) for x in xs])),
        *(r.cable for r in rows),
    )
    return PaddedTests(
        time=put(padded([r.time for r in rows])),
        force=put(padded([r.force for r in rows])),
        elongation=put(padded([r.elongation for r in rows], 0.0)),
        # A padding sample neither drives the model nor enters the residual.
        simulate=put(padded([np.ones_like(r.mask) for r in rows], False), bool),
        weight=put(padded([r.mask for r in rows], False)),
        temperature=put(padded([r.temperature for r in rows])),
        covariate=put(padded([r.covariate for r in rows])),
        cable=cable,
        drive=tuple(drives),
        scale=put(_scales(rows)),
    )
