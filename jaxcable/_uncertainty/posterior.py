"""Bayesian posterior of a model's fitted parameters: `jaxcable.sample_posterior`."""

import time
import warnings
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array

from .._fit import (
    FitResult,
    IdentifiabilityWarning,
    field_at,
    fit as least_squares,
    make_problem,
)
from .._io import force_noise
from .._problem import LeastSquares, Problem
from .._progress import AbstractProgressMeter, NoProgressMeter, check_progress_meter
from .diagnostics import bulk_ess, split_rhat
from .methods import NUTS
from .mode import posterior_mode
from .nuts import run_chains
from .priors import bound_of, log_prior, prior_precision, to_unconstrained
from .result import Posterior


def _natural_derivative(transform: str, x: float, scale: float, bound: float):
    """dx/du of one parameter at its natural value x (see `jaxcable.fit`'s
    reparameterisations)."""
    if transform == "log":
        return x
    if transform == "log1":
        return x - 1.0
    if transform == "linear":
        return scale
    return (bound**2 - x**2) / bound  # tanh: x = bound tanh(u)


def _bounds(layout, values: np.ndarray, model) -> list:
    """Each parameter's tanh bound (None for another transform), read from the
    natural `values` (laid out as the problem's u) where the bound is fitted, else
    from `model`."""
    by_name = dict(zip(layout.names, values))
    out = []
    for transform in layout.transforms:
        other = bound_of(transform)
        if other is None:
            out.append(None)
        else:
            out.append(by_name.get(other, float(field_at(model, other))))
    return out


def _to_u(lsq, values: np.ndarray, model) -> np.ndarray:
    """The unconstrained vector of natural `values` (laid out as the least-squares
    problem's u), with its scales (those of the user's start)."""
    bounds = _bounds(lsq.layout, values, model)
    return np.array(
        [
            to_unconstrained(t, float(x), float(scale), bound)
            for t, x, scale, bound in zip(
                lsq.layout.transforms, values, lsq.scales, bounds
            )
        ]
    )


def _robust_noise(data) -> np.ndarray:
    """Each test's noise standard deviation in its residual unit: the robust estimate
    from second differences of the scored channel, over the fitted samples."""
    measured = np.asarray(data.measured, float)
    weight = np.asarray(data.weight) > 0
    scale = np.asarray(data.scale, float)
    out = []
    for i in range(data.num_tests):
        scored = measured[i][weight[i]]
        peak = float(np.max(np.abs(scored))) if scored.size else 1.0
        # As the fit's noise units: a noise-free record gets 1e-4 of its peak.
        out.append(max(force_noise(scored), 1e-4 * peak, 1e-300) / scale[i])
    return np.array(out)


def _laplace(fit_result: FitResult, lsq, prior_scale) -> np.ndarray:
    """The covariance of u of the least-squares fit (the delta method undone), with
    the prior's curvature added to its precision: the sampler's first metric."""
    layout = lsq.layout
    values = np.asarray(fit_result.values, float)
    bounds = _bounds(layout, values, fit_result.model)
    g = np.array(
        [
            _natural_derivative(t, float(x), float(scale), bound)
            for t, x, scale, bound in zip(layout.transforms, values, lsq.scales, bounds)
        ]
    )
    cov = np.asarray(fit_result.covariance, float) / np.outer(g, g)
    if not np.all(np.isfinite(cov)):
        cov = np.diag(np.full(len(g), prior_scale**2))
    w, v = np.linalg.eigh(0.5 * (cov + cov.T))
    w = np.clip(w, 1e-12 * max(w.max(), 1e-300), None)
    precision = (v / w) @ v.T + np.diag(
        np.asarray(prior_precision(layout.transforms, prior_scale))
    )
    w, v = np.linalg.eigh(precision)
    return (v / w) @ v.T


@eqx.filter_jit
def _to_natural(problem, u):
    return jax.vmap(problem.natural_flat)(u)


class LogPosterior(eqx.Module):
    """The log posterior density of u (up to a constant), a callable Module whose
    data are arrays (so that one compiled sampler serves every data set of the same
    shapes).

    **Fields:**

    - `problem`: the fit's least-squares problem.
    - `sigma`: each test's noise standard deviation in its residual unit (used by
        the `"robust"` noise model).
    - `center`: the prior's centre on the unconstrained scale.
    - `noise`: `"fitted"` or `"robust"`.
    - `prior_scale`: the prior's standard deviation on the unconstrained scale.
    """

    # The fit package's ResidualProblem (its `data`, `layout`, `residuals`).
    problem: Any
    sigma: Array
    center: Array
    noise: str = eqx.field(static=True)
    prior_scale: float = eqx.field(static=True)

    def __call__(self, u):
        weight = self.problem.data.weight
        counts = jnp.sum(weight > 0, axis=1).astype(self.center.dtype)
        r = self.problem.residuals(u)
        ssr = jnp.sum(r**2, axis=1)
        if self.noise == "fitted":
            # Each test's noise sigma_i integrated out under the scale-invariant
            # prior 1 / sigma_i: the marginal likelihood is SSR_i^(-n_i / 2).
            loglik = -0.5 * jnp.sum(counts * jnp.log(ssr + 1e-300))
        else:
            loglik = -0.5 * jnp.sum(ssr / self.sigma**2)
        transforms = self.problem.layout.transforms
        return loglik + log_prior(transforms, self.center, self.prior_scale, u)


def _start_fit(problem: Problem, start: FitResult | None, labels) -> FitResult:
    """`start`, or the least-squares fit of `problem` (default method) run here;
    checked against the sampled parameters `labels`."""
    if start is None:
        # What the data do not identify shows in the posterior itself.
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", IdentifiabilityWarning)
            start = least_squares(problem, LeastSquares(), throw=False)
    if not isinstance(start, FitResult) or tuple(start.names) != labels:
        got = start.names if isinstance(start, FitResult) else type(start).__name__
        raise ValueError(
            f"`start` must be a FitResult of the parameters {list(labels)}, got {got}."
        )
    if not np.all(np.isfinite(np.asarray(start.values, float))):
        raise ValueError(
            "`start`: the least-squares fit failed (non-finite values); give start "
            "values from which `jaxcable.fit` converges."
        )
    return start


def _chain_starts(density, lsq, start: FitResult, method: NUTS, key) -> tuple:
    """`(positions, metric)`: the chains' first positions in u (the first at the
    posterior's mode, the others at draws of its Laplace approximation) and the
    first metric (that approximation's covariance)."""
    u_hat = _to_u(lsq, np.asarray(start.values, float), start.model)
    cov = _laplace(start, lsq, float(method.prior_scale))
    u_hat, cov = posterior_mode(density, u_hat, cov)
    z = np.asarray(jax.random.normal(key, (method.num_chains, len(u_hat))))
    # The first chain starts at the mode; a draw outside the model's domain is moved
    # there by run_chains.
    positions = u_hat + z @ np.linalg.cholesky(cov).T
    positions[0] = u_hat
    return positions, cov


def _checked(problem, method, progress_meter) -> AbstractProgressMeter:
    if not isinstance(problem, Problem):
        raise TypeError(
            f"`problem` must be a jaxcable.Problem, got {type(problem).__name__}."
        )
    if problem.per_test:
        raise ValueError(
            "`problem.per_test`: parameters fitted per test are not sampled "
            f"({list(problem.per_test)}); sample a problem without them."
        )
    if not isinstance(method, NUTS):
        raise TypeError(f"`method` must be a jaxcable.NUTS, got {method!r}.")
    return check_progress_meter(progress_meter, NoProgressMeter())


def sample_posterior(
    problem: Problem,
    method: NUTS = NUTS(),
    *,
    start: FitResult | None = None,
    progress_meter: AbstractProgressMeter | None = None,
) -> Posterior:
    """Sample the Bayesian posterior of a model's fitted parameters by NUTS.

    The likelihood is the fit's ([`jaxcable.fit`][]): every test is simulated by its
    drive, its residual is the model minus the measured scored channel, and the
    residuals of test i are independent normal with standard deviation sigma_i.

    **Noise model** (`method.noise`): `"fitted"` (default) treats each test's sigma_i
    as unknown, with the scale-invariant prior 1 / sigma_i, and integrates it out
    exactly: test i contributes SSR_i^(-n_i / 2) (n_i fitted samples), so each test
    weighs by its own residual level, whatever the scored channel. `"robust"` fixes
    sigma_i at the robust estimate of the scored channel's noise from second
    differences (as the fit's noise units for mixed drives), which trusts the model
    to reach the noise.

    **Priors**, from each parameter's declared domain, on the unconstrained scale u
    the fit solves on: a positive parameter (log scale) is log-normal with median
    the start value in `problem.model` and log standard deviation
    `method.prior_scale` (default ln 10), likewise x - 1 for a parameter > 1 and
    x / |start| for a linear one; a parameter bounded by another (|x| < bound, tanh
    scale) is uniform on its interval. The start values are the prior's centre, not
    the fit's optimum, so the data are not used twice.

    **Sampler.** BlackJAX's NUTS kernel (multinomial, iterative), the chains vmapped
    in one compiled program (laid out over the devices when there are several: see
    `jaxcable.monte_carlo`); the gradient of the log density is taken through the
    simulation in forward mode. The chains start at the posterior's mode (Newton on
    the log density from the least-squares fit, whose Laplace covariance in u, the
    prior's curvature added, whitens it) and at draws of the Laplace approximation
    there (the inverse Hessian at the mode), which is also the first dense metric;
    the warm-up adapts the step size by dual averaging (target acceptance 0.8),
    re-estimates the dense metric from the chains' draws half-way, and adapts the
    step size again. R-hat and the effective sample size per parameter are the
    rank-normalised split R-hat and bulk ESS of Vehtari et al. (2021).

    **Arguments:**

    - `problem`: a [`jaxcable.Problem`][]: its model holds the start values (the
        prior's centre) of the fitted parameters and fixes the others; its tests,
        `fit`, `transforms`, `drive` and `covariate` are read as
        [`jaxcable.fit`][] reads them. Its `per_test` must be empty (parameters
        fitted per test are not sampled).
    - `method`: a [`jaxcable.NUTS`][]: the noise model, the prior's width and the
        sampler's settings (draws, chains, warm-up, tree depth, key).
    - `start`: a least-squares [`jaxcable.FitResult`][] of the same problem to start
        from; default: [`jaxcable.fit`][] is run here ([`jaxcable.LeastSquares`][]'s
        defaults).
    - `progress_meter`: how to show progress (a [`jaxcable.TextProgressMeter`][]
        draws a bar of the chains' chunks of 25 steps); default none.

    **Returns:**

    A [`jaxcable.Posterior`][]: the draws, their summary, R-hat and ESS, and
    conversions to ArviZ and to [`jaxcable.CorrelatedParameters`][].

    **Raises:**

    `TypeError` naming `problem` or `method` of another type; `ValueError` naming
    the argument: as [`jaxcable.fit`][] for the model and tests, `problem.per_test`
    not empty, a `start` whose parameters differ or whose fit failed.
    """
    meter = _checked(problem, method, progress_meter)
    key = jax.random.key(0) if method.key is None else method.key
    began = time.perf_counter()
    lsq, center = make_problem(
        problem.model,
        list(problem.tests),
        problem.fit,
        None,
        problem.transform_map,
        problem.drive,
        problem.covariate,
    )
    layout = lsq.layout
    start = _start_fit(problem, start, layout.labels)
    sigma = jnp.asarray(_robust_noise(lsq.data))
    density = LogPosterior(
        lsq, sigma, jnp.asarray(center), method.noise, float(method.prior_scale)
    )
    key_start, key_run = jax.random.split(key)
    positions, cov = _chain_starts(density, lsq, start, method, key_start)
    run = run_chains(density, jnp.asarray(positions), cov, key_run, method, meter)
    draws_u = run["draws"]
    flat = draws_u.reshape(-1, draws_u.shape[-1])
    natural = np.asarray(_to_natural(lsq, jnp.asarray(flat))).reshape(draws_u.shape)
    p = natural.shape[-1]
    return Posterior(
        model=start.model,
        names=layout.labels,
        units=tuple(start.units),
        samples=natural,
        unconstrained=draws_u,
        transforms=layout.transforms,
        rhat=np.array([split_rhat(draws_u[:, :, k]) for k in range(p)]),
        ess=np.array([bulk_ess(draws_u[:, :, k]) for k in range(p)]),
        divergences=int(run["divergent"]),
        acceptance=run["acceptance"],
        step_size=run["step_size"],
        mean_steps=run["mean_steps"],
        noise=method.noise,
        noise_sd=None if method.noise == "fitted" else np.asarray(sigma),
        fit=start,
        seconds=time.perf_counter() - began,
    )
