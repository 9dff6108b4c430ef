"""Bayesian posterior of a model's fitted parameters: `jaxcable.sample_posterior`."""

import math
import time
import warnings
from collections.abc import Mapping, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, PRNGKeyArray

from .._fit import (
    FitResult,
    IdentifiabilityWarning,
    as_test_list,
    field_at,
    fit as least_squares,
    make_problem,
)
from .._io import force_noise
from .._models import AbstractCableModel
from .._progress import AbstractProgressMeter, NoProgressMeter
from .diagnostics import bulk_ess, split_rhat
from .mode import posterior_mode
from .nuts import run_chains
from .priors import (
    PRIOR_SCALE,
    bound_of,
    log_prior,
    prior_precision,
    to_unconstrained,
)
from .result import Posterior


NOISE_MODELS = ("fitted", "robust")


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


def _to_u(problem, values: np.ndarray, model) -> np.ndarray:
    """The unconstrained vector of natural `values` (laid out as the problem's u),
    with the problem's scales (those of the user's start) and each tanh bound read
    from `values` or `model`."""
    layout = problem.layout
    by_name = dict(zip(layout.names, values))
    out = []
    for i, (name, transform) in enumerate(zip(layout.names, layout.transforms)):
        other = bound_of(transform)
        bound = None
        if other is not None:
            bound = by_name.get(other, float(field_at(model, other)))
        out.append(
            to_unconstrained(
                transform, float(values[i]), float(problem.scales[i]), bound
            )
        )
    return np.array(out)


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


def _laplace(fit_result: FitResult, problem, u_hat, prior_scale) -> np.ndarray:
    """The covariance of u of the least-squares fit (the delta method undone), with
    the prior's curvature added to its precision: the sampler's first metric."""
    layout = problem.layout
    values = np.asarray(fit_result.values, float)
    by_name = dict(zip(layout.names, values))
    g = []
    for i, (name, transform) in enumerate(zip(layout.names, layout.transforms)):
        other = bound_of(transform)
        bound = None
        if other is not None:
            bound = by_name.get(other, float(field_at(fit_result.model, other)))
        g.append(
            _natural_derivative(
                transform, by_name[name], float(problem.scales[i]), bound
            )
        )
    g = np.array(g)
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

    problem: eqx.Module
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


def sample_posterior(
    model: AbstractCableModel,
    tests,
    *,
    fit: Sequence[str] | None = None,
    drive="auto",
    transforms: Mapping[str, str] | None = None,
    covariate: str | None = None,
    noise: str = "fitted",
    num_samples: int = 500,
    num_chains: int = 4,
    num_warmup: int = 500,
    key: PRNGKeyArray | None = None,
    start: FitResult | None = None,
    prior_scale: float = PRIOR_SCALE,
    max_doublings: int = 8,
    progress_meter: AbstractProgressMeter = NoProgressMeter(),
) -> Posterior:
    """Sample the Bayesian posterior of a model's fitted parameters by NUTS.

    The likelihood is the fit's ([`jaxcable.fit`][]): every test is simulated by its
    drive, its residual is the model minus the measured scored channel, and the
    residuals of test i are independent normal with standard deviation sigma_i.

    **Noise model** (`noise`): `"fitted"` (default) treats each test's sigma_i as
    unknown, with the scale-invariant prior 1 / sigma_i, and integrates it out
    exactly: test i contributes SSR_i^(-n_i / 2) (n_i fitted samples), so each test
    weighs by its own residual level, whatever the scored channel. `"robust"` fixes
    sigma_i at the robust estimate of the scored channel's noise from second
    differences (as the fit's noise units for mixed drives), which trusts the model
    to reach the noise.

    **Priors**, from each parameter's declared domain, on the unconstrained scale u
    the fit solves on: a positive parameter (log scale) is log-normal with median
    the start value in `model` and log standard deviation `prior_scale` (default
    ln 10), likewise x - 1 for a parameter > 1 and x / |start| for a linear one; a
    parameter bounded by another (|x| < bound, tanh scale) is uniform on its
    interval. The start values are the prior's centre, not the fit's optimum, so the
    data are not used twice.

    **Sampler.** BlackJAX's NUTS kernel (multinomial, iterative), the chains vmapped
    in one compiled program (laid out over the devices when there are several: see
    `jaxcable.monte_carlo`); the gradient of the log density is taken through the
    simulation in forward mode. The chains start at the posterior's mode (Newton on
    the log density from the least-squares fit, whose Laplace covariance in u, the
    prior's curvature added, whitens it) and at draws of the Laplace approximation
    there (the inverse Hessian at the mode), which is also the first dense metric; the warm-up adapts the step size by dual
    averaging (target acceptance 0.8), re-estimates the dense metric from the
    chains' draws half-way, and adapts the step size again. R-hat and the effective
    sample size per parameter are the rank-normalised split R-hat and bulk ESS of
    Vehtari et al. (2021).

    **Arguments:**

    - `model`: the model and the start values (the prior's centre) of the fitted
        parameters; the others are fixed at its values.
    - `tests`, `fit`, `drive`, `transforms`, `covariate`: as in [`jaxcable.fit`][]
        (parameters fitted per test are not sampled).
    - `noise`: `"fitted"` or `"robust"` (see above).
    - `num_samples`: draws kept per chain.
    - `num_chains`: chains (>= 2 for R-hat).
    - `num_warmup`: warm-up steps per chain (rounded up to a multiple of 25).
    - `key`: a `jax.random` key; default `jax.random.key(0)`.
    - `start`: a least-squares [`jaxcable.FitResult`][] of the same model, tests and
        `fit` to start from; default: `jaxcable.fit` is run here.
    - `prior_scale`: the prior standard deviation on the unconstrained scale (> 0).
    - `max_doublings`: the largest NUTS tree depth (trajectories of at most
        2^depth - 1 steps).
    - `progress_meter`: how to show progress (a [`jaxcable.TextProgressMeter`][]
        draws a bar of the chains' chunks of 25 steps); default none.

    **Returns:**

    A [`jaxcable.Posterior`][]: the draws, their summary, R-hat and ESS, and
    conversions to ArviZ and to [`jaxcable.CorrelatedParameters`][].

    **Raises:**

    `ValueError` naming the argument: as [`jaxcable.fit`][] for the model and tests;
    a bad `noise`, count, `prior_scale`, or a `start` whose parameters differ.
    """
    if noise not in NOISE_MODELS:
        raise ValueError(f"`noise` must be one of {NOISE_MODELS}, got {noise!r}.")
    for name, value, low in (
        ("num_samples", num_samples, 4),
        ("num_chains", num_chains, 1),
        ("num_warmup", num_warmup, 1),
        ("max_doublings", max_doublings, 1),
    ):
        if not isinstance(value, int) or isinstance(value, bool) or value < low:
            raise ValueError(f"`{name}` must be an int >= {low}, got {value!r}.")
    if not (isinstance(prior_scale, (int, float)) and 0 < prior_scale < math.inf):
        raise ValueError(
            f"`prior_scale` must be a finite number > 0, got {prior_scale!r}."
        )
    if key is None:
        key = jax.random.key(0)
    began = time.perf_counter()
    test_list = as_test_list(tests)
    problem, center = make_problem(
        model, test_list, fit, None, transforms, drive, covariate
    )
    layout = problem.layout
    if start is None:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", IdentifiabilityWarning)
            start = least_squares(
                model,
                test_list,
                fit=fit,
                transforms=transforms,
                drive=drive,
                covariate=covariate,
                throw=False,
            )
    if not isinstance(start, FitResult) or tuple(start.names) != layout.labels:
        got = start.names if isinstance(start, FitResult) else type(start).__name__
        raise ValueError(
            f"`start` must be a FitResult of the parameters {list(layout.labels)}, "
            f"got {got}."
        )
    values = np.asarray(start.values, float)
    if not np.all(np.isfinite(values)):
        raise ValueError(
            "`start`: the least-squares fit failed (non-finite values); give start "
            "values from which `jaxcable.fit` converges."
        )
    u_hat = _to_u(problem, values, start.model)
    sigma = jnp.asarray(_robust_noise(problem.data))
    density = LogPosterior(
        problem, sigma, jnp.asarray(center), noise, float(prior_scale)
    )
    cov = _laplace(start, problem, u_hat, float(prior_scale))
    u_hat, cov = posterior_mode(density, u_hat, cov)
    key_start, key_run = jax.random.split(key)
    z = np.asarray(jax.random.normal(key_start, (num_chains, len(u_hat))))
    # The first chain starts at the mode, the others at draws of the Laplace
    # approximation there (one outside the model's domain is moved to the mode).
    positions = u_hat + z @ np.linalg.cholesky(cov).T
    positions[0] = u_hat
    run = run_chains(
        density,
        jnp.asarray(positions),
        cov,
        key_run,
        num_warmup,
        num_samples,
        max_doublings=max_doublings,
        progress_meter=progress_meter,
    )
    draws_u = run["draws"]
    flat = draws_u.reshape(-1, draws_u.shape[-1])
    natural = np.asarray(_to_natural(problem, jnp.asarray(flat))).reshape(draws_u.shape)
    p = natural.shape[-1]
    rhat = np.array([split_rhat(draws_u[:, :, k]) for k in range(p)])
    ess = np.array([bulk_ess(draws_u[:, :, k]) for k in range(p)])
    return Posterior(
        model=start.model,
        names=layout.labels,
        units=tuple(start.units),
        samples=natural,
        unconstrained=draws_u,
        transforms=layout.transforms,
        rhat=rhat,
        ess=ess,
        divergences=int(run["divergent"]),
        acceptance=run["acceptance"],
        step_size=run["step_size"],
        mean_steps=run["mean_steps"],
        noise=noise,
        noise_sd=None if noise == "fitted" else np.asarray(sigma),
        fit=start,
        seconds=time.perf_counter() - began,
    )
