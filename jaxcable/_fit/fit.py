"""Least-squares fit of any cable model to one or many measured tests: `jaxcable.fit`.

The model is driven by each test's time-stamped force history
([`jaxcable.simulate_force_history`][]); the residual is model minus measured
elongation, m. Tests of different lengths are padded to one shape and vmapped, so one
compiled kernel serves them all; the parameters are fitted on an unconstrained
reparameterisation (log for positive parameters) by optimistix's Levenberg-Marquardt
with Jacobians through the scan; standard errors and correlations come from the
Jacobian at the optimum.
"""

import math
import warnings

import equinox as eqx
import jax
import jax.random as jr
import numpy as np
import optimistix as optx
from jaxtyping import PRNGKeyArray

from .._drive import FORCE_DRIVEN
from .._models import MODELS, AbstractCableModel, transform_table
from .._problem import LeastSquares, Problem, StreamingLeastSquares
from .._results import RESULTS
from .data import (
    test_id,
)
from .exported import current_fit_kernel
from .parameters import test_slice
from .problem import (
    ResidualProblem,
    StartError,
    make_problem,
    require_enough_samples,
)
from .result import FitResult, concrete_result
from .solver import KernelMethod, KernelOut, LevenbergMarquardt
from .specimens import failing_start
from .start import StartMovedWarning, start_scaling
from .statistics import (
    IdentifiabilityWarning,
    Statistics,
    statistics,
)
from .stream import streaming_kernel


def least_squares_solver(method: LeastSquares) -> optx.AbstractGaussNewton:
    """The solver of `method` ([`jaxcable.LeastSquares`][], checked when it was
    made): its own, or by default Levenberg-Marquardt with rtol = atol = 1e-6."""
    if method.solver is None:
        return LevenbergMarquardt(rtol=1e-6, atol=1e-6)
    return method.solver


def _require_valid_start(out: KernelOut, tests: list, problem: ResidualProblem) -> None:
    """Raise a `StartError` if the user's start does not simulate finitely on every
    test, with the simulation's own reason (re-run for the first such test, by its
    drive)."""
    ok = np.asarray(out.start_ok)
    if ok.all():
        return
    model = eqx.combine(problem.base, problem.static)
    i, traj = failing_start(model, tests, problem.data.drive, ok)
    test, drive = tests[i], problem.data.drive[i]
    reason = str(RESULTS[traj.result]) or (
        "the simulation is not finite or a parameter is outside its domain for this "
        "cable (e.g. Park's t_r2 = lambda1 (L0/v)^2 - lambda2 <= 0)"
    )
    raise StartError(
        f"`model`: the start parameters fail on tests[{i}] ({test_id(test, i)}, "
        f"{drive}-driven): {reason.rstrip('.')}.",
        i,
        reason.rstrip("."),
    )


def with_moved_start(model, test_list: list, drive, attempt):
    """`(attempt(model), "")`; when the start fails on a test (a `StartError`),
    `(attempt(scaled), note)` with the start scaled to the data
    ([`jaxcable.scaled_start`][]) and a note saying why it was moved (also issued as
    a [`jaxcable.StartMovedWarning`][]). A scaled start that fails too raises
    `ValueError` naming `model`, with both reasons."""
    try:
        return attempt(model), ""
    except StartError as first:
        scaling = start_scaling(model, test_list, drive=drive)
        i = first.index
        note = (
            f"the start failed on tests[{i}] ({test_id(test_list[i], i)}): "
            f"{first.reason}; moved to the start scaled to the data: "
            f"{scaling.describe()}"
        )
        try:
            result = attempt(scaling.model)
        except StartError as second:
            raise ValueError(
                f"{first} The start scaled to the data ({scaling.describe()}) "
                f"fails too: {second.reason}. Check the data's breaking strain and "
                "load, or give start values valid for every test."
            ) from None
        warnings.warn(note, StartMovedWarning, stacklevel=3)
        return result, note


def run_kernel(
    problem: ResidualProblem,
    u0,
    key: PRNGKeyArray | None,
    method: KernelMethod,
    test_list: list,
) -> KernelOut:
    """The fit kernel run on `problem` from `u0` (the arguments as in `fit_kernel`;
    `key` None: `jax.random.key(0)`), after which the user's start must have
    simulated on every test of `test_list`."""
    if key is None:
        key = jr.key(0)
    # `fit_kernel`, or the command line's exported programs (`cached_fit_kernels`).
    kernel = current_fit_kernel()
    out = kernel(problem, u0, key, method)
    _require_valid_start(out, test_list, problem)
    return out


def _outcome(
    out: KernelOut, labels: tuple[str, ...], n: int, throw: bool
) -> tuple[RESULTS, float, Statistics]:
    """`(result, ssr, statistics)` of the chosen start: `RESULTS.successful`, the
    solver's result (optimistix's, promoted), or `RESULTS.every_start_failed`; with
    `throw`, a `RuntimeError` when it failed or did not converge."""
    best = int(out.best)
    # Indexed on the host: an index of a device array is a program of its own.
    converged = bool(np.asarray(out.converged)[best])
    solver_result = RESULTS.promote(out.best_result)
    message = "" if converged else str(RESULTS[solver_result])
    result = RESULTS.successful if converged else concrete_result(solver_result)
    ssr = float(np.asarray(out.ssr)[best])
    if math.isfinite(ssr):
        stats = statistics(out.gram, out.natural_jacobian, out.natural, ssr, n, labels)
    else:
        message = f"every start failed ({message or 'non-finite residuals'})"
        if throw:
            raise RuntimeError(
                f"jaxcable.fit: {message}. Try other start values or fewer fitted "
                "parameters."
            )
        result = RESULTS.every_start_failed
        stats = Statistics.undefined(len(labels))
    if not converged and throw:
        diagnosis = (
            "; ".join(stats.warnings) or "no parameter flagged as unidentifiable"
        )
        raise RuntimeError(
            f"jaxcable.fit: no start converged ({message}); best SSR {ssr:.3g}. "
            f"Identifiability at the best start: {diagnosis}. Try more `max_steps`, "
            "other start values, fewer fitted parameters, or throw=False to inspect "
            "the result."
        )
    return result, ssr, stats


def _fitted_models(
    out: KernelOut, problem: ResidualProblem
) -> tuple[AbstractCableModel, tuple[AbstractCableModel, ...]]:
    """The fitted model (per-test parameters as batches) and one model per test."""
    # Sliced on the host and moved back in one call: eager per-leaf indexing cost
    # more than the whole solve of a small fit.
    host = jax.device_get(out.params)
    per_test = [test_slice(host, i) for i in range(problem.layout.num_tests)]
    models = tuple(eqx.combine(p, problem.static) for p in jax.device_put(per_test))
    return eqx.combine(out.params, problem.static), models


def _rmse(
    out: KernelOut, problem: ResidualProblem, num_samples: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each test's RMS residual in its scored channel: elongation, mm (NaN for an
    elongation-driven test); force, N (NaN for a force-driven test); and as a
    percentage of the test's peak |measured value| in that channel."""
    data = problem.data
    r = np.asarray(out.residuals, float) * np.asarray(data.scale, float)[:, None]
    rmse = np.sqrt((r**2).sum(axis=1) / num_samples)
    measured = np.asarray(data.measured, float)
    peak = np.max(np.abs(measured), axis=1)
    by_force = np.array([d == FORCE_DRIVEN for d in data.drive])
    rmse_mm = np.where(by_force, 1e3 * rmse, np.nan)
    rmse_n = np.where(by_force, np.nan, rmse)
    return rmse_mm, rmse_n, 100 * rmse / np.where(peak > 0, peak, np.nan)


def _residual_problem(problem: Problem, start, test_list: list):
    """`make_problem` of `problem`'s fields from the start model `start`."""
    return make_problem(
        start,
        test_list,
        problem.fit,
        problem.per_test,
        problem.transform_map,
        problem.drive,
        problem.covariate,
    )


def fit(
    problem: Problem,
    method: LeastSquares | StreamingLeastSquares = LeastSquares(),
    *,
    throw: bool = True,
) -> FitResult:
    """Fit a model's parameters to one or many tests by least squares.

    ```python
    result = jc.fit(jc.Problem(jc.BurgersModel(), tests))
    result = jc.fit(problem, jc.LeastSquares(multistart=8), throw=False)
    ```

    **Drives.** A force-controlled test (creep, a load cycle) drives its model by its
    time-stamped force history ([`jaxcable.simulate_force_history`][]); its residual
    is the model's minus the measured elongation, m. A displacement-controlled test
    (stress relaxation, a constant crosshead rate) drives it by its elongation
    history ([`jaxcable.simulate_elongation_history`][], a Newton solve for the
    force at every sample); its residual is the model's minus the measured force, N.
    `problem.drive = "auto"` takes each test's `metadata['control']` (a `# control:`
    line), else detects it from the data ([`jaxcable.detect_control`][]). Tests of both
    kinds may be fitted together: each test's residuals are then divided by the
    noise standard deviation of its scored channel (robust, from second
    differences), so that every residual is dimensionless and weighs by its own
    noise. Residuals count over the samples each test's mask keeps (all by default).
    Material parameters are shared by all tests (different lengths, rates, forces);
    parameters named in `problem.per_test` take one value per test. The tests are
    padded to one length and run in one `vmap`, so one compiled kernel serves them
    all.

    **Method.** Levenberg-Marquardt (optimistix's damped Newton descent in a trust
    region) on unconstrained parameters u. The Jacobian of the residuals is taken
    through the whole scan, by forward mode: the p parameter tangents are carried
    through one scan together, a small multiple of one forward simulation's cost.
    (The mode is chosen by size, tangents p against cotangents n; since a
    least-squares fit needs more samples than parameters, reverse mode, one cotangent
    per residual, is never chosen.) The residuals are divided by
    sqrt(1e-4 sum(e_measured^2)) inside the solver, which leaves the optimum
    unchanged and sets the initial damping to 1e-4 of the problem's largest
    curvature (nearly a Gauss-Newton step).
    Reparameterisation x = f(u), as each model declares it (in parentheses: not
    fitted by default; an extension declares its own):

    {TRANSFORMS}

    (`problem.transforms` overrides with `'log'` or `'linear'`.) Constraints the
    reparameterisation does not enforce (Park's t_r2 > 0 and E1c A above the breaking
    load, the Bouc-Wen monotonicity bound) make the simulation fail; its residuals are
    then NaN and the solver rejects the step. A start on the bound of `1 + exp(u)` or
    `beta tanh(u)` (e.g. the Bouc-Wen default n = 1) is moved 1 % inside.

    **A start that fails.** A start outside its domain for a test's cable, or whose
    simulation of a test is not finite or goes beyond the cable's break, is moved,
    not refused: the fit starts instead from the start scaled to the data
    ([`jaxcable.scaled_start`][], as [`jaxcable.Problem.with_scaled_start`][]: its
    moduli scaled to the data's first loading, its times to the data's holds when
    far off), `FitResult.start_note` says why and how, and a
    [`jaxcable.StartMovedWarning`][] is issued. Only a scaled start that fails too
    raises.

    **Initial guess.** From the start `problem.model`, every stiffness-like fitted
    parameter (moduli and viscosities times c; the Bouc-Wen compliance `z_y`
    divided by c) is
    scaled by one factor c found in closed form: the least-squares multiplier
    g = <e_model, e_measured> / <e_model, e_model> of the model's elongation gives
    c <- c / g, exact in one step for the linear models (their strains scale as
    1 / c) and iterated 4 times for the others, keeping the iterate of least loss
    (never worse than the given start); c stays within [1/30, 30]. Then
    `method.multistart - 1` further starts perturb u by normal noise of standard
    deviation `method.spread` (0.5: about +-50 % on a log parameter), drawn from
    `method.key`; the starts are
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

    - `problem`: a [`jaxcable.Problem`][]: the start model, the tests, which
        parameters to fit (and which per test), their transforms, the drives and
        the covariate.
    - `method`: a [`jaxcable.LeastSquares`][]: the solver, its steps, and the
        starts (default `jaxcable.LeastSquares()`); or a
        [`jaxcable.StreamingLeastSquares`][] for a record too long to hold its
        Jacobian (memory independent of its length).
    - `throw`: raise `RuntimeError` when no start converged (default), with the
        solver's message and the identifiability warnings; with `False` return the
        best start, its `result` the solver's ([`jaxcable.RESULTS`][]: optimistix's
        members, e.g. `max_steps_reached`, or `every_start_failed`).

    **Returns:**

    A [`jaxcable.FitResult`][].

    **Raises:**

    `TypeError` naming `problem` or `method` when it is not a `Problem` or a
    `LeastSquares` (the values check their own fields when they are made).
    `ValueError` naming the field: `model` batched, or failing on a test both at its
    start values and scaled to the data (above); `tests` malformed (see
    [`jaxcable.pad_tests`][]); an unknown or repeated name in `fit`, `per_test` or
    `transforms`; fewer fitted samples than parameters.
    """
    if not isinstance(problem, Problem):
        raise TypeError(
            f"`problem` must be a jaxcable.Problem, got {type(problem).__name__}."
        )
    if isinstance(method, StreamingLeastSquares):
        return _fit_streaming(problem, method, throw)
    if not isinstance(method, LeastSquares):
        raise TypeError(
            "`method` must be a jaxcable.LeastSquares or a "
            f"jaxcable.StreamingLeastSquares, got {type(method).__name__}."
        )
    solver = least_squares_solver(method)
    test_list = list(problem.tests)

    def attempt(start):
        residual_problem, u_user = _residual_problem(problem, start, test_list)
        p = residual_problem.layout.size
        n = require_enough_samples(residual_problem.data, p)
        jac = "fwd" if p <= n else "bwd"
        kernel = KernelMethod(
            solver, method.max_steps, jac, method.multistart, method.spread
        )
        out = run_kernel(residual_problem, u_user, method.key, kernel, test_list)
        return residual_problem, out

    (residual_problem, out), note = with_moved_start(
        problem.model, test_list, problem.drive, attempt
    )
    layout = residual_problem.layout
    units = tuple(u for u, s in zip(layout.units, layout.sizes) for _ in range(s))
    per = tuple(n for n, q in zip(layout.names, layout.per_test) if q)
    return fit_result(
        out,
        residual_problem,
        test_list,
        layout.labels,
        units,
        per,
        throw,
        start_note=note,
    )


def _fit_streaming(
    problem: Problem, method: StreamingLeastSquares, throw: bool
) -> FitResult:
    """`fit` with the normal equations accumulated over each record
    (`stream.solve_streaming`): the same `FitResult`, from one start."""
    if problem.per_test:
        raise ValueError(
            "`problem.per_test`: jaxcable.StreamingLeastSquares fits shared "
            "parameters only."
        )
    test_list = list(problem.tests)

    def attempt(start):
        residual_problem, u_user = _residual_problem(problem, start, test_list)
        if residual_problem.data.by_elongation.size:
            raise ValueError(
                "`problem.tests`: jaxcable.StreamingLeastSquares fits force-driven "
                "tests (their elongation scored); some are elongation-driven."
            )
        require_enough_samples(residual_problem.data, residual_problem.layout.size)
        out = streaming_kernel(residual_problem, u_user, method)
        _require_valid_start(out, test_list, residual_problem)
        return residual_problem, out

    (residual_problem, out), note = with_moved_start(
        problem.model, test_list, problem.drive, attempt
    )
    layout = residual_problem.layout
    units = tuple(u for u, s in zip(layout.units, layout.sizes) for _ in range(s))
    return fit_result(
        out, residual_problem, test_list, layout.labels, units, (), throw, note
    )


# The table of reparameterisations is derived from the models' declarations
# (docstrings are None under `python -OO`).
if fit.__doc__:
    fit.__doc__ = fit.__doc__.replace(
        "{TRANSFORMS}",
        transform_table(e.cls for e in MODELS).replace("\n", "\n    "),
    )


def fit_result(
    out: KernelOut,
    problem: ResidualProblem,
    test_list: list,
    labels: tuple[str, ...],
    units: tuple[str, ...],
    per_test: tuple[str, ...],
    throw: bool,
    start_note: str = "",
) -> FitResult:
    """The [`jaxcable.FitResult`][] of a kernel's output (`labels`, `units`: of each
    entry of the output's `natural`; `per_test`: the names fitted per test;
    `start_note`: how the start was moved, "" when it was not); with `throw`, a
    `RuntimeError` when no start converged. Identifiability warnings are issued."""
    num_samples = np.asarray(problem.data.weight).sum(axis=1).astype(int)
    n = int(num_samples.sum())
    result, ssr, stats = _outcome(out, labels, n, throw)
    for text in stats.warnings:
        warnings.warn(text, IdentifiabilityWarning, stacklevel=3)
    fitted_model, models = _fitted_models(out, problem)
    rmse_mm, rmse_n, rmse_percent = _rmse(out, problem, num_samples)
    return FitResult(
        model=fitted_model,
        models=models,
        names=labels,
        units=units,
        values=stats.values,
        stderr=stats.stderr,
        covariance=stats.covariance,
        correlation=stats.correlation,
        singular_values=stats.singular_values,
        loss=ssr,
        rmse_mm=rmse_mm,
        rmse_percent=rmse_percent,
        rmse_N=rmse_n,
        drives=problem.data.drive,
        loss_unit={"m": "m^2", "N": "N^2", "1": "1"}[problem.data.units[0]],
        test_ids=tuple(test_id(t, i) for i, t in enumerate(test_list)),
        num_samples=num_samples,
        warnings=stats.warnings,
        result=result,
        num_steps=int(np.asarray(out.steps)[int(out.best)]),
        start_losses=np.asarray(out.ssr, float),
        per_test=per_test,
        start_note=start_note,
    )
