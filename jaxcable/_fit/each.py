"""Many specimens fitted at once, each its own parameter set: `jaxcable.fit_each`.

Every specimen is the least-squares problem [`jaxcable.fit`][] would solve for its
tests alone; the specimens' padded tests are stacked and the fit's kernel (the
data-derived start, the multi-start Levenberg-Marquardt, the Jacobian at the optimum)
is vmapped over them, so that one compiled program solves them all.
"""

import dataclasses
import warnings
from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np
from jaxtyping import PRNGKeyArray

from .._models import AbstractCableModel
from .._problem import LeastSquares, Problem
from .._progress import AbstractProgressMeter, NoProgressMeter, check_progress_meter
from .._results import RESULTS
from .data import pad_tests
from .fit import fit_result, least_squares_solver
from .problem import ResidualProblem, make_problem, require_enough_samples
from .queue import each_kernel
from .result import FitResult, concrete_result
from .solver import KernelMethod
from .specimens import (
    Group,
    failed_result,
    group_problem,
    grouped,
    lane,
    start_failure,
)
from .statistics import IdentifiabilityWarning


def _problem_list(problems) -> list[Problem]:
    """`problems` as a non-empty list of `Problem`s that share everything but their
    tests and drives.

    **Raises:**

    `ValueError` naming `problems` (or `problems[k]`) otherwise.
    """
    if isinstance(problems, Problem) or not isinstance(problems, Sequence):
        raise ValueError(
            "`problems` must be a sequence with one jaxcable.Problem per specimen, "
            f"got {type(problems).__name__}."
        )
    if not problems:
        raise ValueError("`problems` is empty: give at least one problem to fit.")
    out = list(problems)
    first = out[0]
    for k, problem in enumerate(out):
        if not isinstance(problem, Problem):
            raise ValueError(
                f"`problems[{k}]` must be a jaxcable.Problem, got "
                f"{type(problem).__name__}."
            )
        for name in ("fit", "per_test", "transforms", "covariate"):
            if getattr(problem, name) != getattr(first, name):
                raise ValueError(
                    f"`problems[{k}].{name}` is {getattr(problem, name)!r} but "
                    f"`problems[0].{name}` {getattr(first, name)!r}: the problems "
                    "of one fit_each share it."
                )
        if problem.model is not first.model and not eqx.tree_equal(
            problem.model, first.model
        ):
            raise ValueError(
                f"`problems[{k}].model` differs from `problems[0].model`: the "
                "problems of one fit_each share one start model (its structure and "
                "its values); fit problems of other starts with jaxcable.fit."
            )
    return out


def _checked_key(key) -> PRNGKeyArray | np.ndarray:
    """`key`, or `jax.random.key(0)` for None."""
    if key is None:
        return jr.key(0)
    typed = isinstance(key, jax.Array) and jnp.issubdtype(
        key.dtype, jax.dtypes.prng_key
    )
    raw = isinstance(key, (jax.Array, np.ndarray)) and (
        key.dtype == np.uint32 and key.shape == (2,)
    )
    if not (typed and key.shape == () or raw):
        raise TypeError(
            f"`key` must be one jax.random key (jax.random.key(seed)), got {key!r}."
        )
    return key


@eqx.filter_jit
def _domain(model: AbstractCableModel, cables) -> RESULTS:
    """`model.check` of every test's cable, shape (specimens, tests)."""
    return jax.vmap(jax.vmap(model.check))(cables)


def _solve_group(
    model: AbstractCableModel,
    group: Group,
    checks: RESULTS,
    template: ResidualProblem,
    settings: tuple,
    per: tuple[str, ...],
) -> list[FitResult]:
    """The `FitResult` of every specimen of `group` (`checks`: the model's domain
    check of each of their tests; `settings`: the kernel's `key` and
    `KernelMethod`)."""
    problem, u_user = group_problem(model, template, group)
    layout = problem.layout
    key, method = settings
    out = each_kernel(problem, group.data, u_user, key, method)
    host = jax.device_get(out)
    bad_domain = np.asarray(checks._value) != int(RESULTS.successful._value)
    units = tuple(u for u, s in zip(layout.units, layout.sizes) for _ in range(s))
    results = []
    for j, tests in enumerate(group.tests):
        here = eqx.tree_at(lambda p: p.data, problem, lane(group.host, j))
        if bad_domain[j].any():
            i = int(np.flatnonzero(bad_domain[j])[0])
            member = concrete_result(lane(lane(checks, j), i))
        elif not host.start_ok[j].all():
            member = start_failure(model, tests, group.host.drive, host.start_ok[j])
        else:
            # Moved back in one call: the fitted model's leaves are device arrays,
            # as `jaxcable.fit`'s.
            out_j = lane(host, j)
            out_j = eqx.tree_at(lambda o: o.params, out_j, jax.device_put(out_j.params))
            results.append(
                fit_result(out_j, here, tests, layout.labels, units, per, False)
            )
            continue
        results.append(
            failed_result(model, here, tests, per, method.num_starts, member)
        )
    return results


def _template(groups: list[Group], checks: list, drives: list) -> tuple[list, object]:
    """(tests, drive) of the first specimen whose cables all pass the model's
    domain check: `make_problem` of it gives every group's layout.

    **Raises:**

    `ValueError` naming `problems` when there is none.
    """
    ok = int(RESULTS.successful._value)
    for group, check in zip(groups, checks):
        for j, k in enumerate(group.indices):
            if (np.asarray(check._value)[j] == ok).all():
                return group.tests[j], drives[k]
    raise ValueError(
        "`problems`: the start model's parameters are outside their domain for a "
        "cable of every specimen (e.g. Park's t_r2 = lambda1 (L0/v)^2 - lambda2 "
        "<= 0); give start values valid for the specimens' cables."
    )


def fit_each(
    problems: Sequence[Problem],
    method: LeastSquares = LeastSquares(),
    *,
    progress_meter: AbstractProgressMeter | None = None,
) -> list[FitResult]:
    """Fit one parameter set per specimen, all specimens in one compiled solve.

    Each specimen's [`jaxcable.Problem`][] is the problem [`jaxcable.fit`][] solves:
    the same residuals, data-derived start, multi-start Levenberg-Marquardt and
    standard errors, from the same start model. The
    specimens' padded tests are padded further to one length (padding samples
    neither drive the model nor enter the residual) and stacked, and the fit's
    kernel is vmapped over them: one compiled program solves every specimen, each
    with its own steps (the loop runs until the last specimen has converged). Each
    specimen's parameters equal those of `jaxcable.fit(problem, method)`, up to
    rounding. Specimens whose tests differ in number or in
    drive are solved by one program per such group.

    A specimen that fails does not stop the others: its `FitResult` has NaN values
    and its [`jaxcable.RESULTS`][] member in `result`: the member of the model's
    domain check when the start parameters are outside their domain for one of its
    cables (e.g. `parameter_out_of_domain`), the simulation's member when the start
    does not simulate on one of its tests (where `jaxcable.fit` raises), else the
    solver's result as with `jaxcable.fit(problem, method, throw=False)` (e.g.
    `nonlinear_max_steps_reached`, `every_start_failed`). Identifiability warnings
    are kept in each result's `warnings`, and one
    [`jaxcable.IdentifiabilityWarning`][] names the specimens that have any.

    **Arguments:**

    - `problems`: a sequence with one [`jaxcable.Problem`][] per specimen: its
        tests and drives its own, the rest (the start model, its structure and its
        values; `fit`, `per_test`, `transforms`, `covariate`) shared by all.
    - `method`: the [`jaxcable.LeastSquares`][] of every specimen (its `key` the
        same for every specimen).
    - `progress_meter`: how progress is shown ([`jaxcable.NoProgressMeter`][], the
        default, says nothing).

    **Returns:**

    A list of [`jaxcable.FitResult`][], one per specimen, in order.

    **Raises:**

    `ValueError` naming the argument: `problems` not a sequence of problems that
    share their model and fields, or a specimen's tests malformed or with fewer
    fitted samples than parameters (`problems[k]`, with the test and field); the
    model or a field as `jaxcable.fit` refuses them, or the model outside its
    domain for every specimen; `progress_meter` not a progress meter. `TypeError`
    naming `method` when it is not a `LeastSquares`, or `key` when `method.key` is
    not one random key.
    """
    if not isinstance(method, LeastSquares):
        raise TypeError(
            f"`method` must be a jaxcable.LeastSquares, got {type(method).__name__}."
        )
    solver = least_squares_solver(method)
    meter = check_progress_meter(progress_meter, NoProgressMeter())
    key = _checked_key(method.key)
    problem_list = _problem_list(problems)
    first = problem_list[0]
    model, covariate = first.model, first.covariate
    specimen_list = [list(p.tests) for p in problem_list]
    drives = [p.drive for p in problem_list]
    datas = []
    with meter.bar("checking the specimens", len(specimen_list)) as bar:
        for k, (tests, d) in enumerate(zip(specimen_list, drives)):
            try:
                datas.append(
                    pad_tests(tests, drive=d, covariate=covariate, on_device=False)
                )
            except ValueError as e:
                raise ValueError(f"`problems[{k}]`: {e}") from None
            bar.advance()
    groups = grouped(specimen_list, datas)
    checks = [jax.device_get(_domain(model, g.data.cable)) for g in groups]
    template = _template(groups, checks, drives)
    problem, _ = make_problem(
        model,
        template[0],
        first.fit,
        first.per_test,
        first.transform_map,
        template[1],
        covariate,
    )
    for k, data in enumerate(datas):
        size = dataclasses.replace(problem.layout, num_tests=data.num_tests).size
        try:
            require_enough_samples(data, size)
        except ValueError as e:
            raise ValueError(f"`problems[{k}]`: {e}") from None
    layout = problem.layout
    per = tuple(n for n, q in zip(layout.names, layout.per_test) if q)
    # Every specimen has more fitted samples than parameters: forward mode, as
    # `jaxcable.fit` chooses.
    kernel = KernelMethod(
        solver, method.max_steps, "fwd", method.multistart, method.spread
    )
    settings = (key, kernel)
    results: list = [None] * len(specimen_list)
    label = f"fitting {len(specimen_list)} specimens"
    with meter.bar(label), warnings.catch_warnings():
        warnings.simplefilter("ignore", IdentifiabilityWarning)
        for group, check in zip(groups, checks):
            fitted = _solve_group(model, group, check, problem, settings, per)
            for k, r in zip(group.indices, fitted):
                results[k] = r
    _warn_flagged(results)
    return results


def _warn_flagged(results: list[FitResult]) -> None:
    """One [`jaxcable.IdentifiabilityWarning`][] naming the specimens whose results
    have identifiability warnings, if any."""
    flagged = [k for k, r in enumerate(results) if r.warnings]
    if flagged:
        shown = ", ".join(str(k) for k in flagged[:10])
        more = f" and {len(flagged) - 10} more" if len(flagged) > 10 else ""
        warnings.warn(
            f"{len(flagged)} of {len(results)} specimens have identifiability "
            f"warnings (specimens {shown}{more}); see each FitResult.warnings.",
            IdentifiabilityWarning,
            stacklevel=3,
        )
