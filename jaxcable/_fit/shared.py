"""One compiled fit kernel for many subsets of one model's parameters.

A fit's kernel is compiled for its model's structure and the layout of its fitted
parameters; fitting another subset of parameters, or another model, compiles again
(several seconds each for the integrated model). A diagnosis fits a base model and
seven candidate extensions of it: here they are all one model, every extension
nested around the base at the null value of its effect (which reproduces the base
exactly), and a fit is which of its parameters are free. The layout holds every
parameter any of the fits frees; the solver's vector v has a fixed length `size` (the
most any fit frees), each coordinate setting one entry of u (`ResidualProblem.select`);
the other entries keep their values (`ResidualProblem.free`). The Jacobian is carried for the
`size` coordinates only, so a fit of few parameters does not pay for the union.
"""

from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import PRNGKeyArray

from .._models import AbstractCableModel
from .._problem import LeastSquares
from .data import as_test_list, pad_tests
from .fit import fit_result, least_squares_solver, run_kernel, with_moved_start
from .parameters import Layout, declared_parameters, field_at
from .problem import (
    ResidualProblem,
    _checked_model,
    _start,
    build_problem,
    make_problem,
    require_enough_samples,
)
from .result import FitResult
from .solver import KernelMethod


def shared_layout(
    model: AbstractCableModel,
    tests,
    names: Sequence[str],
    *,
    drive="auto",
    covariate: str | None = None,
) -> Layout:
    """The layout of `names`, every one of them fittable, for `fit_subset`.

    **Arguments:**

    - `model`: the model, with start values of every name that fix each one's
        transform (a log scale for a positive start, as [`jaxcable.fit`][] chooses):
        give each name the value a fit that frees it starts from.
    - `tests`, `drive`, `covariate`: the fields of a [`jaxcable.Problem`][].
    - `names`: the parameters any of the fits frees (shared ones only).

    **Returns:**

    The `Layout` (hashable: the static part of the kernel).
    """
    problem, _ = make_problem(
        model, as_test_list(tests), tuple(names), None, None, drive, covariate
    )
    return problem.layout


def fit_subset(
    model: AbstractCableModel,
    tests,
    layout: Layout,
    free: Sequence[str],
    *,
    size: int,
    max_steps: int = 256,
    multistart: int = 1,
    spread: float = 0.5,
    key: PRNGKeyArray | None = None,
    throw: bool = True,
    drive="auto",
    covariate: str | None = None,
    solver=None,
) -> FitResult:
    """[`jaxcable.fit`][] of the parameters `free` of `model`, through the kernel of
    `layout`: every call with the same model structure, layout, `size`, settings and
    data shapes runs one compiled program.

    **Arguments:**

    - `model`: the model and its start values (the structure `layout` was made for;
        the parameters not in `free` keep their values, inf included).
    - `tests`, `max_steps`, `multistart`, `spread`, `key`, `throw`, `drive`,
        `covariate`, `solver`: the fields of a [`jaxcable.Problem`][] and a
        [`jaxcable.LeastSquares`][], and `throw` as in [`jaxcable.fit`][].
    - `layout`: from `shared_layout`.
    - `free`: the parameters to fit, a subset of `layout.names`.
    - `size`: the length of the solver's vector, >= len(free): the same for every
        call that is to share the kernel.

    **Returns:**

    A [`jaxcable.FitResult`][] of the `free` parameters (in layout order); its model
    is `model` with them fitted.

    **Raises:**

    `ValueError` naming the argument: a name of `free` not in the layout or repeated,
    `size` too small, a log-scaled start not positive, `model` without the layout's
    parameters or failing its domain check, fewer fitted samples than parameters.
    """
    solver = least_squares_solver(
        LeastSquares(solver, max_steps, multistart, spread, key)
    )
    kernel = KernelMethod(solver, max_steps, "fwd", multistart, spread)
    test_list = as_test_list(tests)
    free = tuple(free)
    data = pad_tests(test_list, drive=drive, covariate=covariate)
    order = _checked_subset(model, layout, free, size, data)

    def attempt(model):
        # Checked, then run: a start that fails on a test is moved (as `fit`).
        problem, v0 = _subset_problem(model, layout, free, order, size, data, test_list)
        out = run_kernel(problem, v0, key, kernel, test_list)
        return problem, out

    (problem, out), note = with_moved_start(model, test_list, drive, attempt)
    k = len(order)
    # The fitted coordinates' block: the padding ones carry zero columns.
    out = eqx.tree_at(
        lambda o: (o.gram, o.natural_jacobian, o.natural),
        out,
        (
            np.asarray(out.gram)[:k, :k],
            np.asarray(out.natural_jacobian)[order][:, :k],
            np.asarray(out.natural)[order],
        ),
    )
    labels = tuple(layout.names[i] for i in order)
    units = tuple(layout.units[i] for i in order)
    return fit_result(
        out, problem, test_list, labels, units, (), throw, start_note=note
    )


def _checked_subset(
    model: AbstractCableModel, layout: Layout, free: tuple, size, data
) -> list[int]:
    """The positions in `layout` of the names `free`, after checking `fit_subset`'s
    arguments against each other.

    **Raises:**

    `ValueError` naming the argument, as `fit_subset` says.
    """
    unknown = [n for n in free if n not in layout.names]
    if unknown or len(set(free)) != len(free):
        raise ValueError(
            f"`free` must name distinct parameters of the layout {layout.names}, got "
            f"{free}."
        )
    if not (isinstance(size, int) and size >= len(free)):
        raise ValueError(f"`size` must be an int >= {len(free)}, got {size!r}.")
    if any(layout.per_test):
        raise ValueError("`layout`: a shared layout holds shared parameters only.")
    if data.num_tests != layout.num_tests:
        raise ValueError(
            f"`tests`: {data.num_tests} tests for a layout of {layout.num_tests}."
        )
    missing = [n for n in layout.names if n not in declared_parameters(model)]
    if missing:
        raise ValueError(
            f"`model`: a {type(model).__name__} has no parameters {missing} of the "
            "layout; give the model the layout was made for."
        )
    return [i for i, name in enumerate(layout.names) if name in free]


def _subset_problem(
    model: AbstractCableModel,
    layout: Layout,
    free: tuple,
    order: list[int],
    size: int,
    data,
    test_list: list,
) -> tuple[ResidualProblem, jax.Array]:
    """The problem of `fit_subset` from the start `model` (checked: a
    `StartError` when it fails on a test) and the solver's start vector v."""
    _checked_model(model, data, test_list)
    params, static = eqx.partition(model, eqx.is_inexact_array)
    # Strongly typed leaves: a start value given as a Python float is weakly typed,
    # and another weak type would be another program.
    params = jax.tree.map(lambda x: jnp.asarray(x, x.dtype), params)
    p = layout.size
    for i in order:
        name, value = layout.names[i], float(field_at(model, layout.names[i]))
        if layout.transforms[i] == "log" and not value > 0:
            raise ValueError(
                f"`model.{name}` = {value} is fitted on a log scale and must start "
                "positive."
            )
    scales, fixed = _start(model, layout, only=free)
    mask = np.isin(np.arange(p), order)
    require_enough_samples(data, len(order))
    dtype = jnp.result_type(float)
    select = np.array(order + [p] * (size - len(order)), np.int32)
    v0 = np.concatenate([fixed[order], np.zeros(size - len(order))])
    problem = build_problem(
        layout,
        params,
        static,
        scales,
        data,
        select=jnp.asarray(select),
        fixed=jnp.asarray(fixed, dtype),
        free=jnp.asarray(mask),
    )
    return problem, jnp.asarray(v0, dtype)
