"""The fit's least-squares problem: the residuals of a model on padded tests, as a
function of the model's parameters and of the unconstrained vector u.
"""

import dataclasses
from collections.abc import Mapping, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int, PyTree

from .. import _checks
from .._cable import Cable
from .._drive import (
    ROBUST,
    CableState,
    ElongationDrive,
    ElongationSample,
    Solve,
    default_solver,
    init_state,
    step,
)
from .._models import AbstractCableModel, ParameterInfo, identifiable
from .._results import RESULTS
from .blocks import blocked_scan
from .data import PaddedTests, pad_tests, test_id
from .parameters import (
    Layout,
    bound_of,
    declared_parameters,
    field_at,
    to_natural,
    to_unconstrained,
)


_DOMAIN_MESSAGE = (
    "a modulus, viscosity or time is not positive, or a constraint of the model "
    "fails for this cable (e.g. Park's t_r2 = lambda1 (L0/v)^2 - lambda2 <= 0)."
)


class StartError(ValueError):
    """The start values fail on a test: outside their domain for its cable, or a
    simulation that is not finite or goes beyond break. [`jaxcable.fit`][] moves
    such a start ([`jaxcable.scaled_start`][]) rather than refusing it.

    **Attributes:**

    - `index`: the first test it fails on.
    - `reason`: why, in words.
    """

    def __init__(self, message: str, index: int, reason: str):
        super().__init__(message)
        self.index = index
        self.reason = reason


def _at_sample(cable, temperature, covariate):
    """The cable at one sample: its recorded temperature (K) and covariate."""
    return eqx.tree_at(
        lambda c: (c.temperature, c.covariate),
        cable,
        (temperature, covariate),
        is_leaf=lambda x: x is None,
    )


def _elongation_history(
    model, cable, time, force, mask, temperature, covariate
) -> tuple[Float[Array, " samples"], RESULTS]:
    """The elongation (m) of [`jaxcable.simulate_force_history`][] and its status.

    The same scan of [`jaxcable.step`][] (the first sample applied from the unloaded
    cable at `time[0]`, masked samples leaving the state unchanged), keeping only the
    elongation: inside the solver's loop, XLA on CPU copies a scan's stacked outputs
    at every step, and a full `Trajectory` (every state field, times the Jacobian's
    tangents) made each Jacobian many times slower than this. The cable's temperature
    is the sample's (K), for temperature-dependent models, and so is its covariate
    (for covariate-dependent ones). The forces are used as
    measured (no deadband), so the fit's model is the one every other entry point
    simulates.
    """

    def body(carry: CableState, x):
        t, f, m, temp, cov = x
        here = _at_sample(cable, temp, cov)
        new, _ = step(model, here, carry, t, f)
        new = jax.tree_util.tree_map(lambda a, b: jnp.where(m, a, b), new, carry)
        return new, new.strain

    final, strain = blocked_scan(
        body,
        init_state(model, cable, time[0]),
        (time, force, mask, temperature, covariate),
        off=(2,),
    )
    return strain * cable.length, final.result


def _force_history(
    model, cable, time, elongation, mask, temperature, covariate
) -> tuple[Float[Array, " samples"], RESULTS]:
    """The force (N) of [`jaxcable.simulate_elongation_history`][] and its status:
    the same drive step (a Newton solve per sample) in a scan that keeps only the
    force, for the reason `_elongation_history` gives."""
    drive = ElongationDrive(
        ElongationSample(time, elongation, mask),
        default_solver(jnp.result_type(time)),
    )

    def body(carry: CableState, x):
        t, e, m, temp, cov = x
        here = _at_sample(cable, temp, cov)
        new, _, _ = drive.step(
            model, here, carry, ElongationSample(t, e, m), Solve(ROBUST)
        )
        return new, new.force

    final, force = jax.lax.scan(
        body,
        init_state(model, cable, time[0]),
        (time, elongation, mask, temperature, covariate),
    )
    return force, final.result


def residuals(
    params: PyTree,
    static: PyTree,
    tests: PaddedTests,
) -> Float[Array, "tests samples"]:
    """Model minus measured value of every test: the fit's residual.

    A pure, jittable function of `params` (differentiate it with `jax.jacfwd`,
    `jax.grad` of a loss, ...). A force-driven test's model is driven by its
    time-stamped force history ([`jaxcable.simulate_force_history`][]) and its
    elongation is scored (m); an elongation-driven test's by its elongation history
    ([`jaxcable.simulate_elongation_history`][]) and its force is scored (N). Each
    test's residual is divided by its `tests.scale` (1 unless the tests mix both
    drives). The tests of each drive run in one `vmap`.

    **Arguments:**

    - `params`, `static`: a model split by `eqx.partition(model, eqx.is_inexact_array)`
        (natural SI values). A leaf of shape `(tests,)` is a per-test parameter (test
        i uses entry i); a scalar leaf is shared by all tests.
    - `tests`: a [`jaxcable.PaddedTests`][] from [`jaxcable.pad_tests`][].

    **Returns:**

    The residuals (m, N, or dimensionless: `tests.units`), shape `(tests, samples)`:
    0 at padding and masked samples, NaN
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

    def kernel(history):
        def run(p, cable, time, driving, simulate, weight, measured, temp, cov):
            model = eqx.combine(p, static)
            value, result = history(model, cable, time, driving, simulate, temp, cov)
            r = jnp.where(weight > 0, value - measured, 0.0)
            return jnp.where(result == RESULTS.successful, r, jnp.nan)

        return jax.vmap(run, in_axes=(in_axes, 0, 0, 0, 0, 0, 0, 0, 0))

    def group(index, history, driving, scored):
        # Static indices: each drive's tests are gathered and run in their own vmap.
        everyone = index.size == tests.num_tests

        def take(x):
            return x if everyone else x[index]

        p = jax.tree_util.tree_map(
            lambda x, a: x if a is None else take(x), params, in_axes
        )
        r = kernel(history)(
            p,
            jax.tree_util.tree_map(take, tests.cable),
            take(tests.time),
            take(driving),
            take(tests.simulate),
            take(tests.weight),
            take(scored),
            take(tests.temperature),
            take(tests.covariate),
        )
        return r / take(tests.scale)[:, None]

    by_force, by_elongation = tests.by_force, tests.by_elongation
    if not by_elongation.size:
        return group(by_force, _elongation_history, tests.force, tests.elongation)
    if not by_force.size:
        return group(by_elongation, _force_history, tests.elongation, tests.force)
    out = jnp.zeros(tests.time.shape, tests.time.dtype)
    out = out.at[by_force].set(
        group(by_force, _elongation_history, tests.force, tests.elongation)
    )
    return out.at[by_elongation].set(
        group(by_elongation, _force_history, tests.elongation, tests.force)
    )


class ResidualProblem(eqx.Module):
    """Everything the fit kernel needs: the layout of u, the fixed values, the data.

    **Fields:**

    - `layout`: which parameters u holds, and how.
    - `static`: the non-array part of the model.
    - `base`: the inexact-array fields of the start model (the fixed values).
    - `scales`: the scale s of each name's `"linear"` transform (1 where unused).
    - `data`: the padded tests.
    - `select`, `fixed`, `free`: for a problem that solves a subset of the layout
        (`jaxcable._fit.shared`, one compiled kernel for every subset): the entry of
        u set by each coordinate of the solver's vector v (index `p`, one past the
        end, for a padding coordinate that sets nothing), the u of the other
        entries, and whether each entry of u is solved; an unsolved parameter keeps
        its value in `base`. None (the default): v is u, every entry solved.
    """

    layout: Layout = eqx.field(static=True)
    static: PyTree = eqx.field(static=True)
    base: PyTree
    scales: Float[Array, " names"]
    data: PaddedTests
    select: Int[Array, " q"] | None = None
    fixed: Float[Array, " p"] | None = None
    free: Bool[Array, " p"] | None = None

    def full(self, v: Float[Array, " q"]) -> Float[Array, " p"]:
        """u from the solver's vector v (v itself unless a subset is solved)."""
        if self.select is None:
            return v
        assert self.fixed is not None  # set together with `select`
        slots = jnp.concatenate([self.fixed, jnp.zeros((1,), self.fixed.dtype)])
        return slots.at[self.select].set(v)[:-1]

    def reduce(self, x: Array) -> Array:
        """The solver coordinates' entries of a vector laid out as u (0 at padding)."""
        if self.select is None:
            return x
        return jnp.concatenate([x, jnp.zeros((1,), x.dtype)])[self.select]

    def natural(self, v: Float[Array, " q"]) -> dict[str, Array]:
        """{name: natural value} of the fitted parameters (unsolved ones: as in
        `base`)."""
        split = self.layout.split(self.full(v))
        free = None if self.free is None else self.layout.split(self.free)
        out = {}
        # Bounded transforms read their bound, so they come after the others.
        order = sorted(
            range(len(self.layout.names)),
            key=lambda i: bound_of(self.layout.transforms[i]) is not None,
        )
        for i in order:
            name, transform = self.layout.names[i], self.layout.transforms[i]
            other = bound_of(transform)
            bound = None
            if other is not None:
                bound = out[other] if other in out else field_at(self.base, other)
            value = to_natural(transform, split[name], self.scales[i], bound)
            if free is not None:
                # A select, not arithmetic: an unsolved value may be inf (E_k), and
                # its u a placeholder whose tangent must not reach the model.
                value = jnp.where(free[name], value, field_at(self.base, name))
            out[name] = value
        return out

    def natural_flat(self, u: Float[Array, " p"]) -> Float[Array, " p"]:
        """The natural values of u, laid out as u."""
        return self.layout.join(self.natural(u))

    def params(self, u: Float[Array, " p"]) -> PyTree:
        """The model's inexact-array fields with the fitted ones set from u."""
        values = self.natural(u)
        names = self.layout.names
        return eqx.tree_at(
            lambda m: [field_at(m, n) for n in names],
            self.base,
            [values[n] for n in names],
        )

    def residuals(self, u: Float[Array, " p"]) -> Float[Array, "tests samples"]:
        """[`jaxcable.residuals`][] at u (m, N or dimensionless: `data.units`)."""
        return residuals(self.params(u), self.static, self.data)

    def ssr(self, u: Float[Array, " p"]) -> Float[Array, ""]:
        """The sum of squared residuals at u, m^2."""
        return jnp.sum(self.residuals(u) ** 2)


def build_problem(
    layout: Layout, base: PyTree, static: PyTree, scales, data: PaddedTests, **subset
) -> ResidualProblem:
    """A `ResidualProblem` of the model split into `base` (its inexact-array fields) and
    `static`, with the scales of the linear transforms `scales` (converted to the
    default float dtype); `subset`: `select`, `fixed` and `free` for a problem that
    solves a subset of the layout."""
    return ResidualProblem(
        layout=layout,
        static=static,
        base=base,
        scales=jnp.asarray(scales, jnp.result_type(float)),
        data=data,
        **subset,
    )


def require_enough_samples(data: PaddedTests, num_params: int) -> int:
    """The number of fitted samples of `data`, after checking that it exceeds the
    number of fitted parameters.

    **Raises:**

    `ValueError` naming `tests` otherwise.
    """
    n = int(np.asarray(data.weight).sum())
    if n <= num_params:
        raise ValueError(
            f"`tests` have {n} fitted samples for {num_params} parameters; a "
            "least-squares fit needs more samples than parameters."
        )
    return n


@eqx.filter_jit
def _check_model(model: AbstractCableModel, cables: Cable) -> Bool[Array, " tests"]:
    return jax.vmap(lambda c: model.check(c) == RESULTS.successful)(cables)


def _checked_model(model, data: PaddedTests, tests) -> dict:
    """The declared parameters of `model`, after checking that they are scalars (start
    values) valid for every test."""
    declared = declared_parameters(model)
    for name in declared:
        shape = jnp.shape(field_at(model, name))
        if shape != ():
            raise ValueError(
                f"`model.{name}` has shape {shape}; fit a model with scalar "
                "parameters (the start values), not a batch."
            )
    # The parameter-domain check is cheap; a model that fails it would fail every
    # simulation of the fit, so it is reported before anything else compiles.
    for i in np.flatnonzero(~np.asarray(_check_model(model, data.cable))):
        raise StartError(
            f"`model`: its parameters are outside their domain for tests[{i}] "
            f"({test_id(tests[i], int(i))}): {_DOMAIN_MESSAGE}",
            int(i),
            _DOMAIN_MESSAGE.rstrip("."),
        )
    return declared


def _names(model, available: list[str], arg: str, value) -> tuple[str, ...]:
    """The parameter names given as argument `arg` (None: none), checked."""
    if value is None:
        return ()
    if isinstance(value, str):
        value = [value]
    return _checks.require_names(
        arg, value, available, type(model).__name__, "parameters"
    )


def _infos(model, declared: dict, transforms) -> dict[str, ParameterInfo]:
    """The registry's fit info of every parameter it describes, with `transforms`
    applied."""
    available = list(declared)
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
        old = table.get(name, ParameterInfo(transform, ""))
        table[name] = dataclasses.replace(old, transform=transform)
    return table


def _fitted_info(model, name: str, table: dict, per: tuple[str, ...]) -> ParameterInfo:
    """How fitted parameter `name` is fitted: the table's info, else log scale for a
    positive start and linear otherwise; checked against its start value."""
    value = float(field_at(model, name))
    info = table.get(name) or ParameterInfo("log" if value > 0 else "linear", "")
    if info.transform == "log" and not value > 0:
        raise ValueError(
            f"`model.{name}` = {value} is fitted on a log scale and must start "
            "positive; give it a positive start value, fix it, or pass "
            f"transforms={{{name!r}: 'linear'}}."
        )
    other = bound_of(info.transform)
    if other is not None and other in per and name not in per:
        raise ValueError(
            f"`per_test` names {other!r} but not {name!r}, which is bounded by "
            f"it; fit both per test or neither."
        )
    return info


def _start(
    model, layout: Layout, only: Sequence[str] | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """The scales of the `"linear"` transforms and the unconstrained start u (of the
    names in `only`, when given: the others get scale 1 and u = 0, a placeholder)."""
    scales = np.ones(len(layout.names))
    start = []
    for i, (name, transform, size) in enumerate(
        zip(layout.names, layout.transforms, layout.sizes)
    ):
        if only is not None and name not in only:
            start += [0.0] * size
            continue
        value = float(field_at(model, name))
        scales[i] = abs(value) if value != 0 else 1.0
        other = bound_of(transform)
        bound = None if other is None else float(field_at(model, other))
        start += [to_unconstrained(transform, value, scales[i], bound)] * size
    return scales, np.array(start)


def make_problem(
    model: AbstractCableModel,
    tests: list,
    fit: Sequence[str] | None,
    per_test: Sequence[str] | None,
    transforms: Mapping[str, str] | None,
    drive=None,
    covariate: str | None = None,
) -> tuple[ResidualProblem, Float[Array, " p"]]:
    """The least-squares problem of [`jaxcable.fit`][] and [`jaxcable.make_loss`][].

    **Arguments:**

    - `model`, `fit`, `per_test`, `transforms`, `drive`, `covariate`: as in
        [`jaxcable.fit`][].
    - `tests`: a list of tests (see `as_test_list`).

    **Returns:**

    `(problem, u_start)`: the `ResidualProblem` and the unconstrained start values.

    **Raises:**

    `ValueError` naming the argument that is not valid.
    """
    if not isinstance(model, AbstractCableModel):
        raise ValueError(
            "`model` must be a jaxcable model (an AbstractCableModel instance such as "
            f"jaxcable.IntegratedModel()), got {type(model).__name__}."
        )
    data = pad_tests(tests, drive=drive, covariate=covariate)
    declared = _checked_model(model, data, tests)
    available = list(declared)
    per = _names(model, available, "per_test", per_test)
    # By default the registry's identifiable set where it declares one, else all.
    default = [n for n in (identifiable(model) or available) if n in available]
    chosen = default if fit is None else _names(model, available, "fit", fit)
    if fit is not None and not chosen and not per:
        raise ValueError("`fit` is empty: name at least one parameter to fit.")
    names = tuple(n for n in available if n in chosen or n in per)
    table = _infos(model, declared, transforms)
    infos = [_fitted_info(model, name, table, per) for name in names]
    layout = Layout(
        names=names,
        per_test=tuple(n in per for n in names),
        transforms=tuple(i.transform for i in infos),
        stiffness=tuple(i.stiffness for i in infos),
        units=tuple(i.unit for i in infos),
        num_tests=data.num_tests,
    )
    scales, start = _start(model, layout)
    base, static = eqx.partition(model, eqx.is_inexact_array)
    problem = build_problem(layout, base, static, scales, data)
    return problem, jnp.asarray(start, jnp.result_type(float))
