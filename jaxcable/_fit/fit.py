"""Least-squares fit of any cable model to one or many measured tests (issue 3, item 2).

The model is driven by each test's time-stamped force history
([`jaxcable.simulate_force_history`][]); the residual is model minus measured
elongation, m. Tests of different lengths are padded to one shape and vmapped, so one
compiled kernel serves them all; the parameters are fitted on an unconstrained
reparameterisation (log for positive parameters) by optimistix's Levenberg-Marquardt
with Jacobians through the scan; standard errors and correlations come from the
Jacobian at the optimum.
"""

import dataclasses
import importlib.metadata
import json
import math
import os
import pathlib
import warnings
from collections.abc import Callable, Mapping, Sequence
from typing import Any, Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.random as jr
import lineax as lx
import numpy as np
import optimistix as optx
from jaxtyping import Array, Bool, Float, PRNGKeyArray, PyTree

from .. import _checks
from .._cable import ZERO_CELSIUS, Cable
from .._drive import CableState, init_state, step
from .._io import TestData
from .._models import (
    EXTENSIONS,
    AbstractCableModel,
    BoucWenModel,
    BurgersModel,
    FiveElementModel,
    HookeModel,
    IntegratedModel,
)
from .._results import RESULTS


class IdentifiabilityWarning(UserWarning):
    """Issued by [`jaxcable.fit`][] for parameters the data cannot identify."""


# ----------------------------------------------------------------------------------
# Parameters: reparameterisation, units, stiffness scaling.
#
# Each fitted parameter x is a function of one unconstrained number u:
#
# - "log":        x = exp(u)              (x > 0: moduli, viscosities, times, ...)
# - "log1":       x = 1 + exp(u)          (x > 1: the Bouc-Wen exponent n >= 1)
# - "linear":     x = s u, s = |x_start|  (signed or possibly zero: Park's lambda2)
# - "tanh:OTHER": x = OTHER tanh(u)       (|x| < OTHER: Bouc-Wen |gamma| <= beta)
#
# `stiffness` is the power k with which the parameter is multiplied by c**k when the
# data-derived initial guess scales the model's stiffness by c (moduli and viscosities
# k = 1, compliances k = -1, the rest 0): for the linear models this divides every
# strain by exactly c.


@dataclasses.dataclass(frozen=True)
class _Info:
    transform: str
    unit: str
    stiffness: float = 0.0


_MODULUS = _Info("log", "Pa", 1.0)
_VISCOSITY = _Info("log", "Pa s", 1.0)

_PARAMETERS: dict[type, dict[str, _Info]] = {
    IntegratedModel: {
        "E1c": _MODULUS,
        "beta": _Info("log", "-"),
        "gamma": _Info("log", "-"),
        "E1r": _MODULUS,
        "E2c": _MODULUS,
        "t_c": _Info("log", "s"),
        "eta0": _VISCOSITY,
        "E2r": _MODULUS,
        "t_r1": _Info("log", "s"),
        "E3r": _MODULUS,
        "lambda1": _Info("log", "1/s"),
        # t_r2 = lambda1 (L0/v)^2 - lambda2 (Park Eq. 8): lambda2 may take either sign.
        "lambda2": _Info("linear", "s"),
    },
    FiveElementModel: {
        **{n: _MODULUS for n in ("E_L1", "E_L2", "E_L3", "E_UL1", "E_UL2", "E_UL3")},
        **{n: _VISCOSITY for n in ("eta_L2", "eta_L3", "eta_UL2", "eta_UL3")},
    },
    BurgersModel: {
        "E1": _MODULUS,
        "eta0": _VISCOSITY,
        "E2": _MODULUS,
        "eta2": _VISCOSITY,
    },
    HookeModel: {"E": _MODULUS},
    BoucWenModel: {
        "E": _MODULUS,
        "sigma_y": _Info("log", "Pa"),
        # eps = sigma / E + z_y (...): E -> c E with z_y -> z_y / c divides eps by c.
        "z_y": _Info("log", "-", -1.0),
        "A": _Info("log", "-"),
        "beta": _Info("log", "-"),
        # The model requires |gamma| <= beta (a dissipative loop).
        "gamma": _Info("tanh:beta", "-"),
        "n": _Info("log1", "-"),
    },
}

# Models `FitResult.from_json` can rebuild, by class name (extensions included).
_MODEL_CLASSES = {cls.__name__: cls for cls in (*_PARAMETERS, *EXTENSIONS.values())}


def _info(owner: AbstractCableModel, field: str, prefix: str) -> _Info | None:
    """How a parameter of `owner` is fitted: the table above, else the model class's
    `FIT_INFO` ({field: (transform, unit[, stiffness])}, as extensions declare it)."""
    info = _PARAMETERS.get(type(owner), {}).get(field)
    if info is None:
        declared = getattr(type(owner), "FIT_INFO", {}).get(field)
        if declared is None:
            return None
        info = _Info(*declared)
    if info.transform.startswith("tanh:"):
        # The bound is a sibling parameter: name it by its full path.
        info = dataclasses.replace(
            info, transform="tanh:" + prefix + info.transform[5:]
        )
    return info


def _parameters(model: AbstractCableModel, prefix: str = "") -> dict[str, _Info | None]:
    """{path: fit info} of every inexact-array field of `model`, in field order,
    descending into wrapped models: a wrapper's own fields are named as they are, its
    base's as `base.NAME` (`base.base.NAME`, ... for deeper nesting)."""
    out = {}
    for f in dataclasses.fields(model):
        value = getattr(model, f.name)
        if eqx.is_inexact_array(value):
            out[prefix + f.name] = _info(model, f.name, prefix)
        elif isinstance(value, AbstractCableModel):
            out.update(_parameters(value, prefix + f.name + "."))
    return out


def _get(obj, path: str):
    """`obj.a.b` for the path "a.b"."""
    for part in path.split("."):
        obj = getattr(obj, part)
    return obj


_DOMAIN_MESSAGE = (
    "a modulus, viscosity or time is not positive, or a constraint of the model "
    "fails for this cable (e.g. Park's t_r2 = lambda1 (L0/v)^2 - lambda2 <= 0)."
)

# A start exactly on the bound of "log1" / "tanh" (e.g. the Bouc-Wen default n = 1) is
# moved inside by this much, so that its unconstrained value is finite.
_BOUND_NUDGE = 1e-2


@dataclasses.dataclass(frozen=True)
class _Layout:
    """Which parameters are fitted and how (hashable: the static part of the kernel).

    The unconstrained vector u holds the shared parameters, one entry each, then the
    per-test parameters, `num_tests` entries each, in the order of `names`.
    """

    names: tuple[str, ...]
    per_test: tuple[bool, ...]
    transforms: tuple[str, ...]
    stiffness: tuple[float, ...]
    units: tuple[str, ...]
    num_tests: int

    @property
    def sizes(self) -> tuple[int, ...]:
        return tuple(self.num_tests if p else 1 for p in self.per_test)

    @property
    def size(self) -> int:
        return sum(self.sizes)

    @property
    def labels(self) -> tuple[str, ...]:
        out = []
        for name, p in zip(self.names, self.per_test):
            out.extend([f"{name}[{i}]" for i in range(self.num_tests)] if p else [name])
        return tuple(out)

    def split(self, u: Float[Array, " p"]) -> dict[str, Array]:
        """Flat u -> {name: scalar (shared) or (num_tests,) array (per test)}."""
        out = {}
        start = 0
        for name, p, size in zip(self.names, self.per_test, self.sizes):
            out[name] = u[start : start + size] if p else u[start]
            start += size
        return out

    def join(self, values: Mapping[str, Any]) -> Float[Array, " p"]:
        """{name: value} -> flat u (the inverse of `split`)."""
        parts = [
            jnp.broadcast_to(jnp.asarray(values[n]), (s,))
            if p
            else jnp.reshape(jnp.asarray(values[n]), (1,))
            for n, p, s in zip(self.names, self.per_test, self.sizes)
        ]
        return jnp.concatenate(parts)


def _to_natural(transform: str, u, scale, bound):
    if transform == "log":
        return jnp.exp(u)
    if transform == "log1":
        return 1.0 + jnp.exp(u)
    if transform == "linear":
        return scale * u
    return bound * jnp.tanh(u)  # "tanh:OTHER"


def _to_unconstrained(transform: str, x, scale, bound) -> float:
    if transform == "log":
        return math.log(x)
    if transform == "log1":
        return math.log(max(x - 1.0, _BOUND_NUDGE))
    if transform == "linear":
        return x / scale
    ratio = min(max(x / bound, -1 + _BOUND_NUDGE), 1 - _BOUND_NUDGE)
    return math.atanh(ratio)


# ----------------------------------------------------------------------------------
# Tests, padded and stacked.


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
    - `cable`: a batched [`jaxcable.Cable`][], one per test.
    """

    time: Float[Array, "tests samples"]
    force: Float[Array, "tests samples"]
    elongation: Float[Array, "tests samples"]
    simulate: Bool[Array, "tests samples"]
    weight: Float[Array, "tests samples"]
    temperature: Float[Array, "tests samples"]
    cable: Cable

    @property
    def num_tests(self) -> int:
        return int(self.time.shape[0])


def test_id(test, index: int) -> str:
    metadata = getattr(test, "metadata", None) or {}
    if "id" in metadata:
        return str(metadata["id"])
    source = getattr(test, "source", None)
    return pathlib.Path(source).name if source else f"test {index}"


def as_test_list(tests) -> list:
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


def pad_tests(tests, *, multiple: int = 16) -> PaddedTests:
    """Check, pad and stack tests for [`jaxcable.residuals`][] and the fit kernel.

    Each test needs `time` (s), `force` (N), `elongation` (m) and `.cable()` (a
    [`jaxcable.TestData`][] has them). A test may carry a per-sample boolean `mask`
    attribute, True where the sample is fitted (False: a slack stretch or any sample
    not to fit); masked samples still drive the model (their force is real) but do
    not enter the residual.

    **Arguments:**

    - `tests`: one test or a sequence of tests.
    - `multiple`: the padded length is rounded up to a multiple of this, so that data
        sets of similar size reuse one compiled kernel.

    **Returns:**

    A [`jaxcable.PaddedTests`][].

    **Raises:**

    `ValueError` naming `tests[i]` and the field: no elongation, fewer than two
    samples, non-finite values, time not strictly increasing, negative force or
    force above the breaking load, a mask of the wrong shape or masking every sample.
    """
    tests = as_test_list(tests)
    dtype = jnp.result_type(float)
    rows = []
    cables = []
    for i, test in enumerate(tests):
        where = f"tests[{i}] ({test_id(test, i)})"
        for field in ("time", "force", "elongation"):
            if getattr(test, field, None) is None:
                raise ValueError(
                    f"`{where}` has no `{field}`; a fit needs time, force and the "
                    "measured elongation."
                )
        if not callable(getattr(test, "cable", None)):
            raise ValueError(f"`{where}` has no `cable()` (length, diameter, speed).")
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
        mask = getattr(test, "mask", None)
        if mask is None:
            mask = np.ones(time.shape, bool)
        else:
            mask = np.asarray(mask, bool)
            if mask.shape != time.shape:
                raise ValueError(
                    f"`{where}.mask` has shape {mask.shape}, the test {time.shape}."
                )
            if not mask.any():
                raise ValueError(f"`{where}.mask` excludes every sample.")
        _checks.require_finite(f"{where}.time", time)
        _checks.require_finite(f"{where}.force", force)
        _checks.require_finite(f"{where}.elongation", elongation[mask])
        _checks.require_increasing(f"{where}.time", time)
        _checks.require_positive(f"{where}.force", force, allow_zero=True)
        cable = test.cable()
        _checks.require_below(
            f"{where}.force", force, cable.breaking_load, "breaking load"
        )
        temperature = getattr(test, "temperature", None)
        if temperature is None:
            temperature = np.full(time.shape, float(cable.temperature))
        else:
            temperature = np.asarray(temperature, float) + ZERO_CELSIUS
            _checks.require_same_shape(
                **{f"{where}.time": time, f"{where}.temperature": temperature}
            )
            _checks.require_finite(f"{where}.temperature", temperature)
            _checks.require_positive(f"{where}.temperature (K)", temperature)
        rows.append((time, force, np.where(mask, elongation, 0.0), mask, temperature))
        cables.append(cable)
    longest = max(r[0].shape[0] for r in rows)
    length = -(-longest // multiple) * multiple

    def pad(x, value=None):
        fill = x[-1] if value is None else value
        return np.concatenate([x, np.full(length - x.shape[0], fill, x.dtype)])

    time = np.stack([pad(r[0]) for r in rows])
    force = np.stack([pad(r[1]) for r in rows])
    elongation = np.stack([pad(r[2], 0.0) for r in rows])
    simulate = np.stack([pad(np.ones_like(r[3]), False) for r in rows])
    weight = np.stack([pad(r[3], False) for r in rows]).astype(float)
    temperature = np.stack([pad(r[4]) for r in rows])
    # One transfer per field (not per test): host overhead counts in a fit of ~50 ms.
    cable = jax.tree_util.tree_map(
        lambda *xs: jnp.asarray(np.stack([np.asarray(x) for x in xs]), dtype), *cables
    )
    return PaddedTests(
        time=jnp.asarray(time, dtype),
        force=jnp.asarray(force, dtype),
        elongation=jnp.asarray(elongation, dtype),
        simulate=jnp.asarray(simulate),
        weight=jnp.asarray(weight, dtype),
        temperature=jnp.asarray(temperature, dtype),
        cable=cable,
    )


# ----------------------------------------------------------------------------------
# Residuals.


def _elongation_history(
    model, cable, time, force, mask, temperature
) -> tuple[Float[Array, " samples"], RESULTS]:
    """The elongation (m) of [`jaxcable.simulate_force_history`][] and its status.

    The same scan of [`jaxcable.step`][] (the first sample applied from the unloaded
    cable at `time[0]`, masked samples leaving the state unchanged), keeping only the
    elongation: inside the solver's loop, XLA on CPU copies a scan's stacked outputs
    at every step, and a full `Trajectory` (every state field, times the Jacobian's
    tangents) made each Jacobian about 20x slower than this. The cable's temperature
    is the sample's (K), for temperature-dependent models. The forces are used as
    measured (no deadband), so the fit's model is the one every other entry point
    simulates.
    """

    def body(carry: CableState, x):
        t, f, m, temp = x
        here = eqx.tree_at(lambda c: c.temperature, cable, temp)
        new, _ = step(model, here, carry, t, f)
        new = jax.tree_util.tree_map(lambda a, b: jnp.where(m, a, b), new, carry)
        return new, new.strain

    final, strain = jax.lax.scan(
        body, init_state(model, cable, time[0]), (time, force, mask, temperature)
    )
    return strain * cable.length, final.result


def residuals(
    params: PyTree,
    static: PyTree,
    tests: PaddedTests,
) -> Float[Array, "tests samples"]:
    """Model minus measured elongation of every test, m: the fit's residual.

    A pure, jittable function of `params` (differentiate it with `jax.jacfwd`,
    `jax.grad` of a loss, ...). Each test's model is driven by its time-stamped force
    history ([`jaxcable.simulate_force_history`][]); the tests run in one `vmap`.

    **Arguments:**

    - `params`, `static`: a model split by `eqx.partition(model, eqx.is_inexact_array)`
        (natural SI values). A leaf of shape `(tests,)` is a per-test parameter (test
        i uses entry i); a scalar leaf is shared by all tests.
    - `tests`: a [`jaxcable.PaddedTests`][] from [`jaxcable.pad_tests`][].

    **Returns:**

    The residuals, m, shape `(tests, samples)`: 0 at padding and masked samples, NaN
    for every sample of a test whose simulation failed (a parameter outside its
    domain, a non-finite strain; `Trajectory.result`), so that a least-squares solver
    rejects such a step.
    """
    if not isinstance(tests, PaddedTests):
        raise ValueError(
            "`tests` must be a jaxcable.PaddedTests (use jaxcable.pad_tests), got "
            f"{type(tests).__name__}."
        )
    in_axes = jax.tree_util.tree_map(lambda x: 0 if jnp.ndim(x) == 1 else None, params)

    def one(p, cable, time, force, simulate, weight, measured, temperature):
        model = eqx.combine(p, static)
        elongation, result = _elongation_history(
            model, cable, time, force, simulate, temperature
        )
        r = jnp.where(weight > 0, elongation - measured, 0.0)
        return jnp.where(result == RESULTS.successful, r, jnp.nan)

    return jax.vmap(one, in_axes=(in_axes, 0, 0, 0, 0, 0, 0, 0))(
        params,
        tests.cable,
        tests.time,
        tests.force,
        tests.simulate,
        tests.weight,
        tests.elongation,
        tests.temperature,
    )


class _Problem(eqx.Module):
    """Everything the fit kernel needs: the layout of u, the fixed values, the data."""

    layout: _Layout = eqx.field(static=True)
    static: PyTree = eqx.field(static=True)
    base: PyTree  # the inexact-array fields of the start model (fixed values)
    scales: Float[Array, " names"]  # the s of "linear" parameters, per name
    data: PaddedTests

    def natural(self, u: Float[Array, " p"]) -> dict[str, Array]:
        """{name: natural value} of the fitted parameters."""
        split = self.layout.split(u)
        out = {}
        # Bounded transforms read their bound, so they come after the others.
        order = sorted(
            range(len(self.layout.names)),
            key=lambda i: self.layout.transforms[i].startswith("tanh:"),
        )
        for i in order:
            name, transform = self.layout.names[i], self.layout.transforms[i]
            bound = None
            if transform.startswith("tanh:"):
                other = transform.split(":", 1)[1]
                bound = out[other] if other in out else _get(self.base, other)
            out[name] = _to_natural(transform, split[name], self.scales[i], bound)
        return out

    def natural_flat(self, u: Float[Array, " p"]) -> Float[Array, " p"]:
        return self.layout.join(self.natural(u))

    def params(self, u: Float[Array, " p"]) -> PyTree:
        values = self.natural(u)
        names = self.layout.names
        return eqx.tree_at(
            lambda m: [_get(m, n) for n in names],
            self.base,
            [values[n] for n in names],
        )

    def residuals(self, u: Float[Array, " p"]) -> Float[Array, "tests samples"]:
        return residuals(self.params(u), self.static, self.data)

    def ssr(self, u: Float[Array, " p"]) -> Float[Array, ""]:
        return jnp.sum(self.residuals(u) ** 2)


@eqx.filter_jit
def _check_model(model: AbstractCableModel, cables: Cable) -> Bool[Array, " tests"]:
    return jax.vmap(lambda c: model.check(c) == RESULTS.successful)(cables)


def _layout_and_problem(model, tests, fit, per_test, transforms):
    """Validate the arguments of `fit` / `make_loss`; return (problem, u_start)."""
    if not isinstance(model, AbstractCableModel):
        raise ValueError(
            "`model` must be a jaxcable model (an AbstractCableModel instance such as "
            f"jaxcable.IntegratedModel()), got {type(model).__name__}."
        )
    data = pad_tests(tests)
    base, static = eqx.partition(model, eqx.is_inexact_array)
    declared = _parameters(model)
    available = list(declared)
    for name in available:
        shape = jnp.shape(_get(model, name))
        if shape != ():
            raise ValueError(
                f"`model.{name}` has shape {shape}; fit a model with scalar "
                "parameters (the start values), not a batch."
            )
    # The parameter-domain check is cheap; a model that fails it would fail every
    # simulation of the fit, so it is reported before anything else compiles.
    for i in np.flatnonzero(~np.asarray(_check_model(model, data.cable))):
        raise ValueError(
            f"`model`: its parameters are outside their domain for tests[{i}] "
            f"({test_id(tests[i], i)}): {_DOMAIN_MESSAGE}"
        )

    def names_of(arg, value) -> tuple[str, ...]:
        if value is None:
            return ()
        if isinstance(value, str):
            value = [value]
        value = tuple(value)
        unknown = [n for n in value if n not in available]
        if unknown:
            raise ValueError(
                f"`{arg}` names {unknown}, which are not parameters of "
                f"{type(model).__name__}; its parameters are {available}."
            )
        if len(set(value)) != len(value):
            raise ValueError(f"`{arg}` repeats a name: {list(value)}.")
        return value

    per = names_of("per_test", per_test)
    chosen = names_of("fit", fit) if fit is not None else tuple(available)
    if fit is not None and not chosen and not per:
        raise ValueError("`fit` is empty: name at least one parameter to fit.")
    names = tuple(n for n in available if n in chosen or n in per)

    table = {k: v for k, v in declared.items() if v is not None}
    for name, transform in (transforms or {}).items():
        if name not in available:
            raise ValueError(
                f"`transforms` names {name!r}, not a parameter of "
                f"{type(model).__name__} ({available})."
            )
        if transform not in ("log", "linear"):
            raise ValueError(
                f"`transforms[{name!r}]` must be 'log' or 'linear', got {transform!r}."
            )
        old = table.get(name, _Info(transform, ""))
        table[name] = dataclasses.replace(old, transform=transform)
    infos = []
    for name in names:
        value = float(_get(model, name))
        info = table.get(name) or _Info("log" if value > 0 else "linear", "")
        if info.transform == "log" and not value > 0:
            raise ValueError(
                f"`model.{name}` = {value} is fitted on a log scale and must start "
                "positive; give it a positive start value, fix it, or pass "
                f"transforms={{{name!r}: 'linear'}}."
            )
        if info.transform.startswith("tanh:"):
            other = info.transform.split(":", 1)[1]
            if other in per and name not in per:
                raise ValueError(
                    f"`per_test` names {other!r} but not {name!r}, which is bounded by "
                    f"it; fit both per test or neither."
                )
        infos.append(info)
    layout = _Layout(
        names=names,
        per_test=tuple(n in per for n in names),
        transforms=tuple(i.transform for i in infos),
        stiffness=tuple(i.stiffness for i in infos),
        units=tuple(i.unit for i in infos),
        num_tests=data.num_tests,
    )
    dtype = jnp.result_type(float)
    scales = np.ones(len(names))
    start = []
    for i, (name, transform, size) in enumerate(
        zip(names, layout.transforms, layout.sizes)
    ):
        value = float(_get(model, name))
        scales[i] = abs(value) if value != 0 else 1.0
        bound = None
        if transform.startswith("tanh:"):
            bound = float(_get(model, transform.split(":", 1)[1]))
        start += [_to_unconstrained(transform, value, scales[i], bound)] * size
    problem = _Problem(
        layout=layout,
        static=static,
        base=base,
        scales=jnp.asarray(scales, dtype),
        data=data,
    )
    return problem, jnp.asarray(np.array(start), dtype)


def make_loss(
    model: AbstractCableModel,
    tests,
    *,
    fit: Sequence[str] | None = None,
    per_test: Sequence[str] | None = None,
    transforms: Mapping[str, str] | None = None,
) -> tuple[
    Callable[[dict[str, Array]], Float[Array, ""]],
    dict[str, Array],
    Callable[[dict[str, Array]], AbstractCableModel],
]:
    """The fit's loss as a pure function of unconstrained parameters, for your own
    optimiser (optax, ...).

    The same problem as [`jaxcable.fit`][] solves: the sum of squared residuals
    (model minus measured elongation, m^2, masked samples excluded) over all tests,
    as a function of a dict of unconstrained parameters (log of the positive ones;
    see [`jaxcable.fit`][] for each model's reparameterisation).

    ```python
    loss, params, to_model = jc.make_loss(jc.BurgersModel(), tests)  # log-parameters
    opt = optax.adam(1e-2); state = opt.init(params)
    step = jax.jit(lambda p, s: opt.update(jax.grad(loss)(p), s))
    for _ in range(2000):
        updates, state = step(params, state); params = optax.apply_updates(params, updates)
    fitted = to_model(params)
    ```

    ([`jaxcable.fit`][]'s Levenberg-Marquardt on the same problem typically needs
    10-20 steps, and reports standard errors.)

    **Arguments:**

    - `model`, `tests`, `fit`, `per_test`, `transforms`: as in [`jaxcable.fit`][].

    **Returns:**

    `(loss, params, to_model)`: `loss(params)`, the sum of squared residuals, m^2
    (jittable, differentiable; NaN where a simulation fails); `params`, the start, a
    dict {name: unconstrained value}, a scalar for shared and a `(tests,)` array for
    per-test parameters; `to_model(params)`, the model with those values (per-test
    fields as `(tests,)` arrays).
    """
    problem, u0 = _layout_and_problem(
        model, as_test_list(tests), fit, per_test, transforms
    )
    layout = problem.layout

    def loss(params: dict[str, Array]) -> Float[Array, ""]:
        return problem.ssr(layout.join(params))

    def to_model(params: dict[str, Array]) -> AbstractCableModel:
        return eqx.combine(problem.params(layout.join(params)), problem.static)

    return loss, layout.split(u0), to_model


# ----------------------------------------------------------------------------------
# The fit kernel: stiffness scan, multi-start Levenberg-Marquardt, Jacobian.


class _KernelOut(eqx.Module):
    starts: Float[Array, "starts p"]
    values: Float[Array, "starts p"]
    results: optx.RESULTS
    best_result: optx.RESULTS
    converged: Bool[Array, " starts"]
    steps: Float[Array, " starts"]
    ssr: Float[Array, " starts"]
    best: Float[Array, ""]
    residuals: Float[Array, "tests samples"]
    gram: Float[Array, "p p"]
    natural: Float[Array, " p"]
    params: PyTree
    natural_jacobian: Float[Array, "p p"]
    start_ok: Bool[Array, " tests"]


def _residuals_and_jacobian(
    problem: _Problem, u: Float[Array, " p"], jac: Literal["fwd", "bwd"]
) -> tuple[Float[Array, " residuals"], Float[Array, "residuals p"]]:
    """The flat residuals (m) and their Jacobian in u, in one differentiated scan:
    forward mode carries the p tangents through the scan together, reverse mode one
    cotangent per residual."""

    def flat(u):
        r = jnp.ravel(problem.residuals(u))
        return r, r

    jacobian, r = (jax.jacfwd if jac == "fwd" else jax.jacrev)(flat, has_aux=True)(u)
    return r, jacobian


def _scaled_residual_fn(problem: _Problem, jac: Literal["fwd", "bwd"], scale):
    """fn(u, args) for optimistix: residuals / scale, whose JVP is a product with the
    Jacobian computed with them.

    Optimistix linearises fn and then materialises, transposes and applies the
    linearisation. Through the scan each of those would be its own copy of the scan in
    the compiled program; with this rule they are products with one dense (n, p)
    matrix, and the scan is differentiated once per step.
    """

    @jax.custom_jvp
    def scaled(u):
        return jnp.ravel(problem.residuals(u)) / scale

    @scaled.defjvp
    def _(primals, tangents):
        (u,), (du,) = primals, tangents
        r, jacobian = _residuals_and_jacobian(problem, u, jac)
        return r / scale, (jacobian @ du) / scale

    return lambda u, args: scaled(u)


class _LevenbergMarquardt(optx.AbstractGaussNewton):
    """Levenberg-Marquardt: optimistix's damped Newton descent in a classical trust
    region, with the textbook cut-offs (Nocedal & Wright, Algorithm 4.1: shrink the
    step by 4 below a ratio of actual to predicted reduction of 1/4, grow it above
    3/4; here by 5). `optx.LevenbergMarquardt`'s constants (grow by 3.5 only above
    0.99) took about twice the steps on the recovery tests' fits, where parameter
    correlations keep the ratio below 0.99 while the damping is still too strong.

    The damped step is solved by Cholesky on the normal equations (J^T J + lambda I,
    p x p) rather than by QR of the tall (n + p, p) matrix: LAPACK's QR of a tall
    matrix, through a multi-threaded OpenBLAS on a busy 2-core machine, took 10-60 ms
    per step (its threads spin), several Jacobians' worth.
    Squaring the condition number is harmless here: lambda > 0 bounds it, the
    parameters are log-scaled, and the fit runs in float64 (a float32 fit of a
    poorly identified problem may fail the solve; `throw=False` then reports it)."""

    rtol: float
    atol: float
    norm: Callable = optx.max_norm
    descent: optx.DampedNewtonDescent = optx.DampedNewtonDescent(
        linear_solver=lx.Normal(lx.Cholesky())
    )
    search: optx.ClassicalTrustRegion = optx.ClassicalTrustRegion(
        high_cutoff=0.75, low_cutoff=0.25, high_constant=5.0, low_constant=0.25
    )
    verbose: Callable = lambda **kwargs: None


# The solver's residuals are r / sqrt(_DAMPING * sum(e_measured^2)). A modulus that
# carries all the elongation has |dr / dlog E|^2 ~ sum(e^2), the largest curvature
# scale of the problem, so Levenberg-Marquardt's initial damping (lambda = 1 in the
# solver's units) is _DAMPING times it: nearly a Gauss-Newton step, which the trust
# region shortens where the model is not yet linear (Marquardt's lambda_0 = tau max
# diag(J^T J), with a small tau for a start believed close; 1e-4 took the fewest
# steps over the recovery tests' models).
_DAMPING = 1e-4
# Secant iterations of the data-derived start.
_SECANT_ITERATIONS = 4
# The data-derived stiffness factor stays within [1 / _SECANT_RANGE, _SECANT_RANGE].
_SECANT_RANGE = 30.0


@eqx.filter_jit
def _fit_kernel(
    problem: _Problem,
    u_user: Float[Array, " p"],
    key: PRNGKeyArray,
    solver: optx.AbstractGaussNewton,
    max_steps: int,
    jac: Literal["fwd", "bwd"],
    num_starts: int,
    spread: float,
) -> _KernelOut:
    layout = problem.layout
    dtype = u_user.dtype

    # Data-derived start: multiply every stiffness-like fitted parameter by c**k
    # (for the linear models this divides every strain by exactly c). The best c in
    # the least-squares sense follows from a secant (closed-form) fit: the multiplier
    # g = <e_model, e_measured> / <e_model, e_model> of the model's elongation is
    # 1 / c for a linear model, and a few such updates converge for the nonlinear
    # ones. Each iterate's loss is evaluated and the best kept, so the start never
    # gets worse than the user's. The first iterate (c = 1) is the user's start,
    # checked for validity on every test.
    power = jnp.concatenate(
        [jnp.full((s,), k) for s, k in zip(layout.sizes, layout.stiffness)]
    ).astype(dtype)
    data = problem.data
    measured = data.elongation * data.weight
    iterations = _SECANT_ITERATIONS if any(k != 0 for k in layout.stiffness) else 1
    limit = math.log(_SECANT_RANGE)

    def secant(carry, _):
        log_c, best_log_c, best_loss = carry
        r = problem.residuals(u_user + power * log_c)
        loss = jnp.sum(r**2)
        better = jnp.isfinite(loss) & (loss < best_loss)
        best_log_c = jnp.where(better, log_c, best_log_c)
        best_loss = jnp.where(better, loss, best_loss)
        model = (r + data.elongation) * data.weight
        g = jnp.sum(model * measured) / jnp.sum(model**2)
        ok = jnp.isfinite(g) & (g > 0)
        step = jnp.where(ok, -jnp.log(jnp.where(ok, g, 1.0)), 0.0)
        log_c = jnp.clip(log_c + step, -limit, limit)
        return (log_c, best_log_c, best_loss), jnp.all(jnp.isfinite(r), axis=1)

    zero = jnp.zeros((), dtype)
    init = (zero, zero, jnp.asarray(jnp.inf, dtype))
    (_, log_c, _), finite = jax.lax.scan(secant, init, None, length=iterations)
    start_ok = finite[0]
    u_start = u_user + power * log_c

    # Multi-start: the data-derived start plus perturbed copies.
    noise = spread * jr.normal(key, (num_starts - 1, layout.size), dtype)
    starts = jnp.concatenate([u_start[None], u_start[None] + noise])
    scale = jnp.sqrt(_DAMPING * jnp.sum(measured**2))
    fn = _scaled_residual_fn(problem, jac, scale)

    def solve(u0):
        sol = optx.least_squares(fn, solver, u0, max_steps=max_steps, throw=False)
        # A Gauss-Newton-type solver's state holds the residuals and the linearised
        # residual function at the returned (last accepted) point; with the rule of
        # `_scaled_residual_fn` its matrix is the Jacobian, with no further scan.
        f_info = sol.state.f_info
        r = f_info.residual * scale
        jacobian = f_info.jac.as_matrix() * scale
        return sol.value, sol.result, sol.stats["num_steps"], r, jacobian

    # One start after the other: a vmapped solve compiles about twice as slowly, and
    # on a CPU the few starts gain little from batching.
    values, results, steps, r, jacobian = jax.lax.map(solve, starts)
    ssr = jnp.sum(r**2, axis=1)
    ssr = jnp.where(jnp.isfinite(ssr), ssr, jnp.inf)
    converged = (results == optx.RESULTS.successful) & jnp.isfinite(ssr)
    # The best converged start; if none converged, the best finite one.
    best = jnp.where(
        jnp.any(converged),
        jnp.argmin(jnp.where(converged, ssr, jnp.inf)),
        jnp.argmin(ssr),
    )
    u_best = values[best]
    return _KernelOut(
        starts=starts,
        values=values,
        results=results,
        best_result=jax.tree_util.tree_map(lambda x: x[best], results),
        converged=converged,
        steps=steps,
        ssr=ssr,
        best=best,
        residuals=jnp.reshape(r[best], problem.data.time.shape),
        gram=jacobian[best].T @ jacobian[best],
        natural=problem.natural_flat(u_best),
        params=problem.params(u_best),
        natural_jacobian=jax.jacfwd(problem.natural_flat)(u_best),
        start_ok=start_ok,
    )


# ----------------------------------------------------------------------------------
# The result.

# Identifiability thresholds (see `fit`).
_MAX_RELATIVE_ERROR = 1.0
_MAX_CORRELATION = 0.99
_MIN_SINGULAR_RATIO = 1e-6
# Relative rounding level of the eigenvalues of J^T J (float64).
_ROUNDING = 1e-13


def _model_document(model: AbstractCableModel) -> dict[str, Any]:
    """{"model": class name, "parameters", "static"[, "base": the wrapped model's]}."""
    parameters = {}
    static = {}
    document: dict[str, Any] = {"model": type(model).__name__}
    for field in dataclasses.fields(model):
        value = getattr(model, field.name)
        if eqx.is_inexact_array(value):
            v = np.asarray(value, float)
            parameters[field.name] = float(v) if v.ndim == 0 else [float(x) for x in v]
        elif isinstance(value, AbstractCableModel):
            document[field.name] = _model_document(value)
        elif isinstance(value, (bool, int, float, str)):
            static[field.name] = value
    return {**document, "parameters": parameters, "static": static}


def _model_from_document(doc: Mapping[str, Any]) -> AbstractCableModel:
    """The inverse of `_model_document` (the class names are checked by the caller)."""
    fields: dict[str, Any] = {
        k: np.asarray(v, float) for k, v in doc["parameters"].items()
    }
    if "base" in doc:
        fields["base"] = _model_from_document(doc["base"])
    return _MODEL_CLASSES[doc["model"]](**fields, **doc.get("static", {}))


def _json_number(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def _from_json_number(x) -> float:
    return math.nan if x is None else float(x)


@dataclasses.dataclass(frozen=True, eq=False)
class FitResult:
    """The outcome of [`jaxcable.fit`][]: fitted model(s), errors and uncertainty.

    **Fields:**

    - `model`: the fitted model. Shared parameters hold their fitted value; a
        per-test parameter holds a `(tests,)` array (a batch for `jax.vmap`).
    - `models`: one model per test, each with its own per-test values.
    - `names`: labels of the fitted parameters; a per-test parameter `p` appears as
        `p[0]`, `p[1]`, ... (test order).
    - `units`: unit of each fitted parameter (SI; `-` dimensionless).
    - `values`: fitted values, SI.
    - `stderr`: standard errors, SI: sqrt of the diagonal of `covariance` (inf for
        a parameter the residuals do not depend on; huge, not inf, for one in a
        direction the data do not determine, whose eigenvalue of J^T J is raised to
        1e-13 of the largest).
    - `covariance`: sigma^2 (J^T J)^-1 in the unconstrained parameters u, with
        sigma^2 = SSR / (n - p) (n fitted samples, p parameters) and J the Jacobian
        of the residuals (m) at the optimum, carried to the natural parameters by the
        delta method, G C G^T with G = dx/du.
    - `correlation`: `covariance` normalised by `stderr`.
    - `singular_values`: of J (in u), largest first.
    - `loss`: sum of squared residuals at the optimum, SSR, m^2.
    - `rmse_mm`: RMS residual of each test over its fitted samples, mm.
    - `rmse_percent`: `rmse_mm` as a percentage of the test's largest |measured
        elongation| (Park et al. report errors as RMSE in mm and as this percentage
        of the peak elongation).
    - `test_ids`: each test's `metadata['id']`, file name or `test i`.
    - `num_samples`: fitted (unmasked) samples per test.
    - `warnings`: the identifiability warnings (also issued with `warnings.warn`).
    - `converged`: whether the chosen start's solver run succeeded.
    - `message`: the solver's message when it did not ("" otherwise).
    - `num_steps`: solver steps of the chosen start.
    - `start_losses`: SSR reached from each start (m^2; inf where it failed).
    - `per_test`: the names fitted per test.
    """

    model: AbstractCableModel
    models: tuple[AbstractCableModel, ...]
    names: tuple[str, ...]
    units: tuple[str, ...]
    values: np.ndarray
    stderr: np.ndarray
    covariance: np.ndarray
    correlation: np.ndarray
    singular_values: np.ndarray
    loss: float
    rmse_mm: np.ndarray
    rmse_percent: np.ndarray
    test_ids: tuple[str, ...]
    num_samples: np.ndarray
    warnings: tuple[str, ...]
    converged: bool
    message: str
    num_steps: int
    start_losses: np.ndarray
    per_test: tuple[str, ...] = ()

    @property
    def params(self) -> dict[str, float]:
        """{label: fitted value, SI}."""
        return {n: float(v) for n, v in zip(self.names, self.values)}

    @property
    def relative_error(self) -> np.ndarray:
        """stderr / |value| of each fitted parameter (inf for a zero value)."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(self.values != 0, self.stderr / np.abs(self.values), np.inf)

    def summary(self) -> str:
        """A text report: the fit, the per-test errors, the parameter table with
        standard errors, the correlation matrix and the warnings.

        **Returns:**

        The report as a multi-line string.
        """
        n = int(np.sum(self.num_samples))
        lines = [
            f"jaxcable fit: {type(self.model).__name__}, {len(self.test_ids)} test(s), "
            f"{n} samples, {len(self.names)} parameters",
            f"SSR {self.loss:.6g} m^2; "
            + (
                f"converged in {self.num_steps} steps"
                if self.converged
                else f"NOT converged ({self.message})"
            )
            + f"; best of {len(self.start_losses)} start(s)",
            "",
            f"{'test':<24} {'samples':>8} {'RMSE mm':>10} {'RMSE %':>8}",
        ]
        for tid, k, mm, pct in zip(
            self.test_ids, self.num_samples, self.rmse_mm, self.rmse_percent
        ):
            lines.append(f"{tid[:24]:<24} {int(k):>8} {mm:>10.4f} {pct:>8.2f}")
        lines += [
            "",
            f"{'parameter':<12} {'value':>12} {'std err':>10} {'rel %':>8}  unit",
        ]
        for name, v, s, r, u in zip(
            self.names, self.values, self.stderr, self.relative_error, self.units
        ):
            lines.append(f"{name:<12} {v:>12.5g} {s:>10.3g} {100 * r:>8.3g}  {u}")
        if len(self.names) > 1:
            lines += ["", "correlation:"]
            width = max(7, max(len(x) for x in self.names) + 1)
            lines.append(" " * width + "".join(f"{x[:7]:>8}" for x in self.names))
            for name, row in zip(self.names, self.correlation):
                lines.append(f"{name:<{width}}" + "".join(f"{c:>8.3f}" for c in row))
        if self.warnings:
            lines += ["", "warnings:"] + [f"  - {w}" for w in self.warnings]
        return "\n".join(lines)

    def to_json(self, path: str | os.PathLike | None = None) -> str:
        """The fit as PARAMS.json: every model parameter by name (SI) plus metadata.

        `parameters` holds every array field of the model (fitted and fixed), a list
        per test for per-test parameters; `static` the model's non-array settings;
        `fitted`, `stderr` and `correlation` the fitted parameters' statistics; `tests`
        each test's id, samples and RMSE. Non-finite numbers are written as null.

        **Arguments:**

        - `path`: optional file to write.

        **Returns:**

        The JSON text.
        """
        document = {
            "format": "jaxcable-params",
            "format_version": 1,
            "jaxcable_version": importlib.metadata.version("jaxcable"),
            **_model_document(self.model),
            "units": "SI (N, m, s, Pa, Pa s)",
            "per_test": list(self.per_test),
            "fitted": [
                {
                    "name": n,
                    "value": float(v),
                    "stderr": _json_number(float(s)),
                    "unit": u,
                }
                for n, v, s, u in zip(self.names, self.values, self.stderr, self.units)
            ],
            "correlation": [
                [_json_number(float(c)) for c in row] for row in self.correlation
            ],
            "covariance": [
                [_json_number(float(c)) for c in row] for row in self.covariance
            ],
            "singular_values": [_json_number(float(s)) for s in self.singular_values],
            "tests": [
                {
                    "id": tid,
                    "samples": int(k),
                    "rmse_mm": float(mm),
                    "rmse_percent": float(pct),
                }
                for tid, k, mm, pct in zip(
                    self.test_ids, self.num_samples, self.rmse_mm, self.rmse_percent
                )
            ],
            "loss_m2": float(self.loss),
            "converged": bool(self.converged),
            "message": self.message,
            "num_steps": int(self.num_steps),
            "start_losses": [_json_number(float(x)) for x in self.start_losses],
            "warnings": list(self.warnings),
        }
        text = json.dumps(document, indent=2)
        if path is not None:
            pathlib.Path(path).write_text(text + "\n", encoding="utf-8")
        return text

    @classmethod
    def from_json(cls, source: str | os.PathLike) -> "FitResult":
        """Read a PARAMS.json written by [`jaxcable.FitResult.to_json`][].

        **Arguments:**

        - `source`: a path, or the JSON text itself (a string starting with `{`).

        **Returns:**

        A [`jaxcable.FitResult`][]; `result.model` is the fitted model, ready to
        simulate.

        **Raises:**

        `ValueError` naming `source` for text that is not such a file, or a model
        class jaxcable does not know.
        """
        if isinstance(source, str) and source.lstrip().startswith("{"):
            text, where = source, "<json text>"
        else:
            where = str(source)
            try:
                text = pathlib.Path(source).read_text(encoding="utf-8")
            except OSError as e:
                raise ValueError(f"`source` {where}: cannot read ({e}).") from None
        try:
            doc = json.loads(text)
        except json.JSONDecodeError as e:
            raise ValueError(f"`source` {where}: not JSON ({e}).") from None
        if not isinstance(doc, dict) or doc.get("format") != "jaxcable-params":
            raise ValueError(
                f"`source` {where}: not a jaxcable PARAMS.json (no "
                "'format': 'jaxcable-params')."
            )
        sub = doc
        while isinstance(sub, dict):
            if sub.get("model") not in _MODEL_CLASSES:
                raise ValueError(
                    f"`source` {where}: unknown model {sub.get('model')!r}; known: "
                    f"{sorted(_MODEL_CLASSES)}."
                )
            sub = sub.get("base")
        try:
            model = _model_from_document(doc)
            fitted = doc["fitted"]
            tests = doc["tests"]
            num_tests = len(tests)
            models = tuple(
                jax.tree_util.tree_map(
                    lambda x, i=i: x[i] if jnp.ndim(x) == 1 else x, model
                )
                for i in range(num_tests)
            )

            def matrix(key):
                return np.array(
                    [[_from_json_number(c) for c in row] for row in doc[key]],
                    dtype=float,
                ).reshape(len(fitted), len(fitted))

            return cls(
                model=model,
                models=models,
                names=tuple(p["name"] for p in fitted),
                units=tuple(p.get("unit", "") for p in fitted),
                values=np.array([p["value"] for p in fitted], float),
                stderr=np.array([_from_json_number(p["stderr"]) for p in fitted]),
                covariance=matrix("covariance"),
                correlation=matrix("correlation"),
                singular_values=np.array(
                    [_from_json_number(s) for s in doc.get("singular_values", [])]
                ),
                loss=float(doc["loss_m2"]),
                rmse_mm=np.array([t["rmse_mm"] for t in tests], float),
                rmse_percent=np.array([t["rmse_percent"] for t in tests], float),
                test_ids=tuple(t["id"] for t in tests),
                num_samples=np.array([t["samples"] for t in tests], int),
                warnings=tuple(doc.get("warnings", [])),
                converged=bool(doc["converged"]),
                message=doc.get("message", ""),
                num_steps=int(doc["num_steps"]),
                start_losses=np.array(
                    [_from_json_number(x) for x in doc.get("start_losses", [])]
                ),
                per_test=tuple(doc.get("per_test", [])),
            )
        except (KeyError, TypeError, ValueError) as e:
            raise ValueError(
                f"`source` {where}: malformed PARAMS.json ({e})."
            ) from None


def _identifiability(labels, values, stderr, correlation, s, vt) -> list[str]:
    """The warnings of the three rules documented in `fit`."""
    out = []
    for i, name in enumerate(labels):
        rel = stderr[i] / abs(values[i]) if values[i] != 0 else math.inf
        if not rel <= _MAX_RELATIVE_ERROR:
            out.append(
                f"{name}: relative standard error {100 * rel:.3g} % > "
                f"{100 * _MAX_RELATIVE_ERROR:g} %; the data do not determine it."
            )
    p = len(labels)
    for i in range(p):
        for j in range(i + 1, p):
            c = correlation[i, j]
            if abs(c) > _MAX_CORRELATION:
                out.append(
                    f"{labels[i]} and {labels[j]}: correlation {c:+.4f} (|r| > "
                    f"{_MAX_CORRELATION}); the data determine only a combination."
                )
    if s.size and s[0] > 0:
        for k in np.flatnonzero(s < _MIN_SINGULAR_RATIO * s[0]):
            weights = np.abs(vt[k])
            involved = [labels[i] for i in np.flatnonzero(weights > 0.3)]
            out.append(
                f"{', '.join(involved)}: near-zero singular value of the Jacobian "
                f"({s[k] / s[0]:.2g} of the largest); the residuals do not change "
                "along this combination."
            )
    return out


def _statistics(out: _KernelOut, ssr: float, n: int, p: int, labels):
    """Host-side (float64) covariance, standard errors, correlation and
    identifiability warnings at the chosen optimum (see `fit`).

    Works on the p x p matrix J^T J, formed in the kernel, not on the tall J: LAPACK
    on a tall matrix through a multi-threaded OpenBLAS took ~0.1 s on a busy 2-core
    machine (its threads spin), more than the whole fit. The covariance is inverted
    after scaling J's columns to unit norm; the singular values of J for the third
    rule are the square roots of J^T J's eigenvalues (resolved down to ~1e-8 of the
    largest in float64, well below the rule's 1e-6).

    **Returns:**

    `(values, covariance, correlation, stderr, singular_values, warnings)`.
    """
    gram = np.asarray(out.gram, float)
    g = np.asarray(out.natural_jacobian, float)
    values = np.asarray(out.natural, float)
    sigma2 = ssr / (n - p)
    norms = np.sqrt(np.clip(np.diag(gram), 0.0, None))
    d = np.where(norms > 0, norms, 1.0)
    w, v = np.linalg.eigh(gram / np.outer(d, d))
    # Eigenvalues below rounding level are raised to it: a direction the data do not
    # determine then shows as a huge variance and a correlation of +-1 between the
    # parameters that share it, which names them (a pseudo-inverse would drop it).
    w = np.maximum(w, _ROUNDING * max(w[-1], 0.0))
    cov_u = sigma2 * ((v / np.where(w > 0, w, np.inf)) @ v.T) / np.outer(d, d)
    cov = g @ cov_u @ g.T
    stderr = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    # A parameter the residuals do not depend on at all has an unbounded variance.
    singular = norms == 0
    stderr = np.where(singular, np.inf, stderr)
    with np.errstate(divide="ignore", invalid="ignore"):
        corr = cov / np.outer(stderr, stderr)
    # No correlation is defined for a parameter of unbounded variance.
    corr = np.where(np.isfinite(corr), corr, np.nan)
    corr[singular, :] = np.nan
    corr[:, singular] = np.nan
    np.fill_diagonal(corr, 1.0)
    # Singular values of J (largest first) and its right singular vectors (rows).
    w_raw, v_raw = np.linalg.eigh(gram)
    s = np.sqrt(np.clip(w_raw[::-1], 0.0, None))
    vt = v_raw[:, ::-1].T
    messages = _identifiability(labels, values, stderr, corr, s, vt)
    return values, cov, corr, stderr, s, messages


# ----------------------------------------------------------------------------------
# fit


def fit(
    model: AbstractCableModel,
    tests,
    *,
    fit: Sequence[str] | None = None,
    per_test: Sequence[str] | None = None,
    transforms: Mapping[str, str] | None = None,
    solver: optx.AbstractGaussNewton | None = None,
    max_steps: int = 256,
    multistart: int = 4,
    spread: float = 0.5,
    key: PRNGKeyArray | None = None,
    throw: bool = True,
) -> FitResult:
    """Fit a model's parameters to one or many tests by least squares on elongation.

    Each test's model is driven by its time-stamped force history
    ([`jaxcable.simulate_force_history`][]); the residual is the model's minus the
    measured elongation, m, over the samples each test's mask keeps (all by default).
    Material parameters are shared by all tests (different lengths, rates, forces);
    parameters named in `per_test` take one value per test. The tests are padded to
    one length and run in one `vmap`, so one compiled kernel serves them all.

    **Method.** Levenberg-Marquardt (optimistix's damped Newton descent in a trust
    region) on unconstrained parameters u. The Jacobian of the residuals is taken
    through the whole scan, by forward mode: the p parameter tangents are carried
    through one scan together, about 1.5-2.5 forward simulations' cost for 6-16
    parameters. (The mode is chosen by size, tangents p against cotangents n; since a
    least-squares fit needs more samples than parameters, reverse mode, one cotangent
    per residual and 3-6x slower on the benchmark, is never chosen.) The residuals are divided by sqrt(1e-4 sum(e_measured^2))
    inside the solver, which leaves the optimum unchanged and sets the initial
    damping to 1e-4 of the problem's largest curvature (nearly a Gauss-Newton step).
    Reparameterisation x = f(u):

    | model | parameter | x = f(u) |
    | --- | --- | --- |
    | all | positive parameters (moduli Pa, viscosities Pa s, times s, Park's beta and gamma, ...) | exp(u) |
    | `IntegratedModel` | `lambda2` (Park Eq. 8, either sign) | s u, s = abs(start) |
    | `BoucWenModel` | `gamma` (abs(gamma) <= beta) | beta tanh(u) |
    | `BoucWenModel` | `n` (n >= 1) | 1 + exp(u) |
    | other models | a parameter starting > 0 / <= 0 | exp(u) / s u |

    (`transforms` overrides with `'log'` or `'linear'`.) Constraints the
    reparameterisation does not enforce (Park's t_r2 > 0 and E1c A above the breaking
    load, the Bouc-Wen monotonicity bound) make the simulation fail; its residuals are
    then NaN and the solver rejects the step. A start on the bound of `1 + exp(u)` or
    `beta tanh(u)` (e.g. the Bouc-Wen default n = 1) is moved 1 % inside.

    **Initial guess.** From the start `model`, every stiffness-like fitted parameter
    (moduli and viscosities times c; the Bouc-Wen compliance `z_y` divided by c) is
    scaled by one factor c found in closed form: the least-squares multiplier
    g = <e_model, e_measured> / <e_model, e_model> of the model's elongation gives
    c <- c / g, exact in one step for the linear models (their strains scale as
    1 / c) and iterated 4 times for the others, keeping the iterate of least loss
    (never worse than the given start); c stays within [1/30, 30]. Then
    `multistart - 1` further starts perturb u by normal noise of standard deviation
    `spread` (0.5: about +-50 % on a log parameter), drawn from `key`; the starts are
    solved one after the other in the same compiled kernel and the converged one of
    least loss is kept.

    **Uncertainty and identifiability.** With J the Jacobian of the residuals (m) in
    u at the optimum, n fitted samples and p parameters, the covariance of u is
    sigma^2 (J^T J)^-1, sigma^2 = SSR / (n - p), carried to the natural parameters by
    the delta method (G C G^T, G = dx/du). A parameter is reported (in
    `FitResult.warnings`, and by `warnings.warn` with an
    [`jaxcable.IdentifiabilityWarning`][]) when

    1. its relative standard error exceeds 100 %, or
    2. its correlation with another fitted parameter exceeds 0.99 in absolute value
        (both are named), or
    3. it weighs more than 0.3 in a right singular vector of J whose singular value
        is below 1e-6 of the largest (J nearly rank-deficient: the residuals do not
        change along that combination).

    A parameter the data do not determine usually also keeps the solver from
    converging (it drifts along a flat valley): with `throw=True` the `RuntimeError`
    then carries these warnings; `throw=False` returns the result to inspect.

    **Arguments:**

    - `model`: any [`jaxcable.AbstractCableModel`][] with scalar parameters; it gives
        the start values of the fitted parameters and the values of the others.
    - `tests`: a [`jaxcable.TestData`][] or a sequence of them, with elongation and
        `length_mm` metadata; an optional boolean `mask` attribute (True = fit the
        sample) excludes samples, e.g. slack, from the residual.
    - `fit`: names of the parameters to fit; default all inexact array fields.
    - `per_test`: names of parameters fitted with one value per test (fitted whether
        or not they are in `fit`).
    - `transforms`: optional {name: `'log'` | `'linear'`} overriding the table above.
    - `solver`: an optimistix Gauss-Newton-type least-squares solver
        (`optx.LevenbergMarquardt`, `optx.GaussNewton`, `optx.Dogleg`, ...); default
        Levenberg-Marquardt with rtol = atol = 1e-6 and textbook trust-region
        constants.
    - `max_steps`: solver steps per start.
    - `multistart`: number of starts (>= 1).
    - `spread`: standard deviation of the start perturbations in u.
    - `key`: a `jax.random` key for the perturbations; default `jax.random.key(0)`, so
        that a fit is reproducible unless asked otherwise.
    - `throw`: raise `RuntimeError` when no start converged (default), with the
        solver's message and the identifiability warnings; with `False` return the
        best start with `converged=False` and the solver's `message`.

    **Returns:**

    A [`jaxcable.FitResult`][].

    **Raises:**

    `ValueError` naming the argument: `model` not a model, batched, or failing on a
    test at its start values; `tests` empty or malformed (see
    [`jaxcable.pad_tests`][]); an unknown or repeated name in `fit`, `per_test` or
    `transforms`; fewer fitted samples than parameters; a bad `multistart`,
    `max_steps`, `spread` or `solver`.
    """
    if not isinstance(multistart, int) or multistart < 1:
        raise ValueError(f"`multistart` must be an int >= 1, got {multistart!r}.")
    if not isinstance(max_steps, int) or max_steps < 1:
        raise ValueError(f"`max_steps` must be an int >= 1, got {max_steps!r}.")
    if not (isinstance(spread, (int, float)) and spread >= 0 and math.isfinite(spread)):
        raise ValueError(f"`spread` must be a finite number >= 0, got {spread!r}.")
    if solver is None:
        solver = _LevenbergMarquardt(rtol=1e-6, atol=1e-6)
    elif not isinstance(solver, optx.AbstractGaussNewton):
        raise ValueError(
            "`solver` must be an optimistix Gauss-Newton-type least-squares solver "
            "(optx.LevenbergMarquardt, optx.GaussNewton, optx.Dogleg, ...), got "
            f"{type(solver).__name__}."
        )
    test_list = as_test_list(tests)
    problem, u_user = _layout_and_problem(model, test_list, fit, per_test, transforms)
    layout = problem.layout
    weight = np.asarray(problem.data.weight)
    num_samples = weight.sum(axis=1).astype(int)
    n, p = int(num_samples.sum()), layout.size
    if n <= p:
        raise ValueError(
            f"`tests` have {n} fitted samples for {p} parameters; a least-squares fit "
            "needs more samples than parameters."
        )
    if key is None:
        key = jr.key(0)
    jac = "fwd" if p <= n else "bwd"
    out = _fit_kernel(problem, u_user, key, solver, max_steps, jac, multistart, spread)

    bad = np.flatnonzero(~np.asarray(out.start_ok))
    if bad.size:
        i = int(bad[0])
        raise ValueError(
            f"`model`: the start parameters fail on tests[{i}] "
            f"({test_id(test_list[i], i)}): the simulation is not finite or a "
            "parameter is outside its domain for this cable (e.g. Park's t_r2 = "
            "lambda1 (L0/v)^2 - lambda2 <= 0); give start values valid for every test."
        )
    best = int(out.best)
    converged = bool(out.converged[best])
    message = "" if converged else str(optx.RESULTS[out.best_result])
    ssr = float(out.ssr[best])
    labels = layout.labels
    if not math.isfinite(ssr):
        message = f"every start failed ({message or 'non-finite residuals'})"
        if throw:
            raise RuntimeError(
                f"jaxcable.fit: {message}. Try other start values or fewer fitted "
                "parameters."
            )
        nan = np.full((p, p), np.nan)
        stats = (
            np.full(p, np.nan),
            nan,
            nan,
            np.full(p, np.nan),
            np.full(p, np.nan),
            [],
        )
    else:
        stats = _statistics(out, ssr, n, p, labels)
    values, cov, corr, stderr, singular_values, messages = stats
    if not converged and throw:
        diagnosis = "; ".join(messages) or "no parameter flagged as unidentifiable"
        raise RuntimeError(
            f"jaxcable.fit: no start converged ({message}); best SSR {ssr:.3g} m^2. "
            f"Identifiability at the best start: {diagnosis}. Try more `max_steps`, "
            "other start values, fewer fitted parameters, or throw=False to inspect "
            "the result."
        )
    for text in messages:
        warnings.warn(text, IdentifiabilityWarning, stacklevel=2)

    r = np.asarray(out.residuals, float)
    rmse = np.sqrt((r**2).sum(axis=1) / num_samples)
    measured = np.asarray(problem.data.elongation, float)
    peak = np.max(np.abs(measured) * weight, axis=1)
    # Sliced on the host and moved back in one call: eager per-leaf indexing cost
    # more than the whole solve of a small fit.
    host = jax.device_get(out.params)
    fitted_model = eqx.combine(out.params, problem.static)
    per_test_params = [
        jax.tree_util.tree_map(lambda x, i=i: x[i] if np.ndim(x) == 1 else x, host)
        for i in range(layout.num_tests)
    ]
    models = tuple(
        eqx.combine(p, problem.static) for p in jax.device_put(per_test_params)
    )
    units = tuple(u for u, size in zip(layout.units, layout.sizes) for _ in range(size))
    return FitResult(
        model=fitted_model,
        models=models,
        names=labels,
        units=units,
        values=values,
        stderr=stderr,
        covariance=cov,
        correlation=corr,
        singular_values=singular_values,
        loss=ssr,
        rmse_mm=1e3 * rmse,
        rmse_percent=100 * rmse / np.where(peak > 0, peak, np.nan),
        test_ids=tuple(test_id(t, i) for i, t in enumerate(test_list)),
        num_samples=num_samples,
        warnings=tuple(messages),
        converged=converged,
        message=message,
        num_steps=int(out.steps[best]),
        start_losses=np.asarray(out.ssr, float),
        per_test=tuple(n for n, q in zip(layout.names, layout.per_test) if q),
    )
