"""Monte-Carlo of cable sets: parameter draws x cables x load histories, chunked over
the draws, sharded over devices, reduced to percentiles of elongation over time."""

import abc
import dataclasses
import functools
import sys
import time as _time
import warnings
import zlib
from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec as P
from jaxtyping import Array, ArrayLike, Bool, Float, Int, PRNGKeyArray

from .. import _checks
from .._cable import CABLE_FIELDS, Cable
from .._drive import Protocol, check_history, simulate_force_history, simulate_rate_test
from .._models import AbstractCableModel
from .._results import RESULTS


# ----------------------------------------------------------------------------------
# Distributions of one parameter.


class AbstractDistribution(eqx.Module):
    """A distribution of one scalar model parameter (in the parameter's SI unit)."""

    @abc.abstractmethod
    def sample(self, key: PRNGKeyArray, shape: tuple[int, ...] = ()) -> Array:
        """Draw independent samples.

        **Arguments:**

        - `key`: a JAX PRNG key.
        - `shape`: the shape of the samples (default one scalar).

        **Returns:**

        An array of `shape`, in the unit of the parameter.
        """


def _require_scalar(cls: str, name: str, value) -> None:
    if not _checks.is_concrete(value):
        return
    if np.shape(value) != ():
        raise ValueError(
            f"{cls} `{name}` must be a scalar, got shape {np.shape(value)}."
        )
    _checks.require_finite(f"{cls}.{name}", value)


def _float_dtype(*xs):
    return jnp.result_type(float, *xs)


class Normal(AbstractDistribution):
    """A normal distribution N(mean, std**2).

    **Arguments:**

    - `mean`: the mean, in the parameter's unit.
    - `std`: the standard deviation (>= 0), same unit.
    """

    mean: Float[Array, ""] = eqx.field(converter=jnp.asarray)
    std: Float[Array, ""] = eqx.field(converter=jnp.asarray)

    def __check_init__(self):
        _require_scalar("Normal", "mean", self.mean)
        _require_scalar("Normal", "std", self.std)
        if _checks.is_concrete(self.std):
            _checks.require_positive("Normal.std", self.std, allow_zero=True)

    def sample(self, key: PRNGKeyArray, shape: tuple[int, ...] = ()) -> Array:
        dtype = _float_dtype(self.mean, self.std)
        return self.mean + self.std * jax.random.normal(key, shape, dtype)


class LogNormal(AbstractDistribution):
    """A log-normal distribution: log(x) ~ N(log(median), sigma**2); x > 0.

    The natural choice for moduli, viscosities and time constants: a fit's relative
    standard error s gives sigma ~ s for s << 1.

    **Arguments:**

    - `median`: the median exp(E[log x]) (> 0), in the parameter's unit.
    - `sigma`: the standard deviation of log(x) (>= 0), dimensionless.
    """

    median: Float[Array, ""] = eqx.field(converter=jnp.asarray)
    sigma: Float[Array, ""] = eqx.field(converter=jnp.asarray)

    def __check_init__(self):
        _require_scalar("LogNormal", "median", self.median)
        _require_scalar("LogNormal", "sigma", self.sigma)
        if _checks.is_concrete(self.median, self.sigma):
            _checks.require_positive("LogNormal.median", self.median)
            _checks.require_positive("LogNormal.sigma", self.sigma, allow_zero=True)

    def sample(self, key: PRNGKeyArray, shape: tuple[int, ...] = ()) -> Array:
        dtype = _float_dtype(self.median, self.sigma)
        return self.median * jnp.exp(self.sigma * jax.random.normal(key, shape, dtype))


class Uniform(AbstractDistribution):
    """A uniform distribution on [low, high).

    **Arguments:**

    - `low`, `high`: the bounds (low < high), in the parameter's unit.
    """

    low: Float[Array, ""] = eqx.field(converter=jnp.asarray)
    high: Float[Array, ""] = eqx.field(converter=jnp.asarray)

    def __check_init__(self):
        _require_scalar("Uniform", "low", self.low)
        _require_scalar("Uniform", "high", self.high)
        if _checks.is_concrete(self.low, self.high) and not (
            float(self.low) < float(self.high)
        ):
            raise ValueError(
                f"Uniform needs `low` < `high`, got low={float(self.low)}, "
                f"high={float(self.high)}."
            )

    def sample(self, key: PRNGKeyArray, shape: tuple[int, ...] = ()) -> Array:
        dtype = _float_dtype(self.low, self.high)
        u = jax.random.uniform(key, shape, dtype)
        return self.low + (self.high - self.low) * u


# ----------------------------------------------------------------------------------
# Parameter sets.


def _scalar_fields(model: AbstractCableModel) -> dict[str, Array]:
    """The model's scalar floating-point array fields, by name (the drawable ones)."""
    out = {}
    for f in dataclasses.fields(model):
        value = getattr(model, f.name)
        if (
            eqx.is_array(value)
            and jnp.shape(value) == ()
            and (jnp.issubdtype(value.dtype, jnp.floating))
        ):
            out[f.name] = value
    return out


def _require_names(argname: str, model, names) -> dict[str, Array]:
    fields = _scalar_fields(model)
    for n in names:
        if not isinstance(n, str) or n not in fields:
            raise ValueError(
                f"`{argname}` names {n!r}, which is not a scalar float parameter of "
                f"{type(model).__name__}; its parameters are {sorted(fields)}."
            )
    if len(set(names)) != len(names):
        raise ValueError(f"`{argname}` repeats a parameter name: {list(names)}.")
    return fields


def _replace(model, names, values):
    return eqx.tree_at(
        lambda m: tuple(getattr(m, n) for n in names), model, tuple(values)
    )


def _name_stream(key, name: str):
    # Each parameter's random stream depends on its name only, so adding or removing a
    # distribution does not change the draws of the others.
    return jax.random.fold_in(key, zlib.crc32(name.encode()) & 0x7FFFFFFF)


class AbstractParameterSampler(eqx.Module):
    """Draws one parameter set (a model) per PRNG key; [`jaxcable.monte_carlo`][]
    calls it under `vmap` with one key per draw."""

    @abc.abstractmethod
    def draw(self, key: PRNGKeyArray) -> AbstractCableModel:
        """Draw one parameter set.

        **Arguments:**

        - `key`: a JAX PRNG key (one per draw).

        **Returns:**

        A model of the sampler's model type with the drawn parameters.
        """


class IndependentParameters(AbstractParameterSampler):
    """Independent per-parameter distributions around a model.

    Parameters without a distribution keep the model's value.

    **Arguments:**

    - `model`: any [`jaxcable.AbstractCableModel`][] (the values of the parameters
        that are not drawn).
    - `distributions`: `{parameter name: distribution}`, e.g.
        `{"E2c": jc.LogNormal(3.7e8, 0.1), "t_c": jc.Uniform(80.0, 120.0)}`
        ([`jaxcable.Normal`][], [`jaxcable.LogNormal`][], [`jaxcable.Uniform`][] or any
        [`jaxcable.AbstractDistribution`][]), in the parameters' SI units.

    A drawn value outside the parameter's domain (e.g. a negative modulus from a wide
    `Normal`) makes that draw fail with `RESULTS.parameter_out_of_domain`; the Monte-Carlo
    counts and excludes it.
    """

    model: AbstractCableModel
    distributions: dict[str, AbstractDistribution]

    def __init__(
        self,
        model: AbstractCableModel,
        distributions: dict[str, AbstractDistribution],
    ):
        if not isinstance(model, AbstractCableModel):
            raise ValueError(
                f"`model` must be a jaxcable model, got {type(model).__name__}."
            )
        if not isinstance(distributions, dict) or not distributions:
            raise ValueError(
                "`distributions` must be a non-empty dict {parameter name: "
                f"distribution}}, got {distributions!r}."
            )
        _require_names("distributions", model, list(distributions))
        for name, dist in distributions.items():
            if not isinstance(dist, AbstractDistribution):
                raise ValueError(
                    f"`distributions[{name!r}]` must be a jaxcable distribution "
                    f"(Normal, LogNormal, Uniform, ...), got {type(dist).__name__}."
                )
        self.model = model
        self.distributions = dict(sorted(distributions.items()))

    def draw(self, key: PRNGKeyArray) -> AbstractCableModel:
        names = list(self.distributions)
        fields = _scalar_fields(self.model)
        values = [
            self.distributions[n]
            .sample(_name_stream(key, n), ())
            .astype(_float_dtype(fields[n]))
            for n in names
        ]
        return _replace(self.model, names, values)


class CorrelatedParameters(AbstractParameterSampler):
    """A multivariate normal around a fitted model, from the fit's covariance.

    Parameters listed in `log_space` are drawn log-normally: z ~ N(0, S) with
    S_ij = C_ij / (s_i s_j), s_i = mean_i for a log-space parameter and 1 otherwise (the
    delta method), then p_i = mean_i exp(z_i) (log space, median mean_i, always > 0) or
    p_i = mean_i + z_i. To first order in the relative standard errors the draws have
    covariance C. Parameters not in `names` keep the model's value.

    Works with any fit that reports a mean model, parameter names and a covariance
    matrix, e.g. `CorrelatedParameters(fit.model, fit.names, fit.covariance)`; from
    standard errors and a correlation matrix use
    [`jaxcable.CorrelatedParameters.from_correlation`][].

    **Arguments:**

    - `model`: the mean (fitted) model, any [`jaxcable.AbstractCableModel`][].
    - `names`: the names of the fitted parameters, in the covariance's order.
    - `covariance`: their covariance matrix, in the parameters' SI units (symmetric,
        positive semi-definite, shape `(len(names), len(names))`).
    - `log_space`: the names drawn in log space (default: every parameter whose mean
        is > 0, which keeps moduli, viscosities and times positive); `()` for a plain
        multivariate normal.
    """

    model: AbstractCableModel
    names: tuple[str, ...] = eqx.field(static=True)
    log_space: tuple[bool, ...] = eqx.field(static=True)
    covariance: Float[Array, "p p"]
    factor: Float[Array, "p p"]

    def __init__(
        self,
        model: AbstractCableModel,
        names: Sequence[str],
        covariance: Float[ArrayLike, "p p"],
        *,
        log_space: Sequence[str] | None = None,
    ):
        if not isinstance(model, AbstractCableModel):
            raise ValueError(
                f"`model` must be a jaxcable model, got {type(model).__name__}."
            )
        if isinstance(names, str) or not isinstance(names, Sequence) or not names:
            raise ValueError(
                f"`names` must be a non-empty sequence of parameter names, got {names!r}."
            )
        names = tuple(names)
        fields = _require_names("names", model, names)
        p = len(names)
        mean = np.array([float(fields[n]) for n in names])
        if log_space is None:
            log = tuple(bool(m > 0) for m in mean)
        else:
            if isinstance(log_space, str):
                raise ValueError(
                    f"`log_space` must be a sequence of names, got the string {log_space!r}."
                )
            for n in log_space:
                if n not in names:
                    raise ValueError(
                        f"`log_space` names {n!r}, which is not in `names` {list(names)}."
                    )
                if fields[n] <= 0:
                    raise ValueError(
                        f"`log_space` names {n!r}, whose mean {float(fields[n])} is not "
                        "> 0: it cannot be drawn in log space."
                    )
            log = tuple(n in log_space for n in names)
        cov = np.asarray(covariance, dtype=float)
        if cov.shape != (p, p):
            raise ValueError(
                f"`covariance` must have shape ({p}, {p}) for {p} names, got {cov.shape}."
            )
        _checks.require_finite("covariance", cov)
        scale = np.max(np.abs(cov)) if cov.size else 0.0
        if not np.allclose(cov, cov.T, rtol=1e-8, atol=1e-12 * scale):
            raise ValueError("`covariance` must be symmetric.")
        variance = np.diag(cov)
        if np.any(variance < 0):
            raise ValueError(
                f"`covariance` has a negative variance on its diagonal: {variance}."
            )
        # Check and factor the correlation matrix, whose eigenvalues are O(1) whatever
        # the parameters' units; a zero variance leaves that parameter fixed.
        d = np.sqrt(variance)
        if np.any((cov != 0) & (d[:, None] == 0)):
            raise ValueError(
                "`covariance` must be positive semi-definite; a parameter with zero "
                "variance has a nonzero covariance."
            )
        inv = np.where(d > 0, 1.0 / np.where(d > 0, d, 1.0), 0.0)
        corr = cov * np.outer(inv, inv) + np.diag(d == 0).astype(float)
        w, v = np.linalg.eigh(0.5 * (corr + corr.T))
        if w.min() < -1e-8:
            raise ValueError(
                "`covariance` must be positive semi-definite; its correlation matrix "
                f"has the eigenvalue {w.min():g}."
            )
        # z = diag(d / s) R^(1/2) eps, with s the log-space scale (the delta method).
        s = np.where(np.asarray(log), mean, 1.0)
        factor = (d / s)[:, None] * (v * np.sqrt(np.maximum(w, 0.0)))
        dtype = _float_dtype(*fields.values())
        self.model = model
        self.names = names
        self.log_space = log
        self.covariance = jnp.asarray(cov, dtype)
        self.factor = jnp.asarray(factor, dtype)

    @classmethod
    def from_correlation(
        cls,
        model: AbstractCableModel,
        names: Sequence[str],
        std: Float[ArrayLike, " p"],
        correlation: Float[ArrayLike, "p p"],
        *,
        log_space: Sequence[str] | None = None,
    ) -> "CorrelatedParameters":
        """Build from standard errors and a correlation matrix (as a fit reports them).

        **Arguments:**

        - `model`, `names`, `log_space`: as in [`jaxcable.CorrelatedParameters`][].
        - `std`: the standard errors of the parameters, in their SI units.
        - `correlation`: their correlation matrix (ones on the diagonal).

        **Returns:**

        A [`jaxcable.CorrelatedParameters`][] with covariance std_i std_j corr_ij.
        """
        std = np.asarray(std, dtype=float)
        corr = np.asarray(correlation, dtype=float)
        if std.ndim != 1 or corr.shape != (std.size, std.size):
            raise ValueError(
                f"`std` must be 1-D and `correlation` square of the same size, got "
                f"shapes {std.shape} and {corr.shape}."
            )
        _checks.require_positive("std", std, allow_zero=True)
        return cls(model, names, np.outer(std, std) * corr, log_space=log_space)

    def draw(self, key: PRNGKeyArray) -> AbstractCableModel:
        fields = _scalar_fields(self.model)
        dtype = self.factor.dtype
        eps = jax.random.normal(key, (len(self.names),), dtype)
        z = self.factor @ eps
        values = []
        for i, n in enumerate(self.names):
            mean = fields[n]
            v = mean * jnp.exp(z[i]) if self.log_space[i] else mean + z[i]
            values.append(v.astype(_float_dtype(mean)))
        return _replace(self.model, self.names, values)


# ----------------------------------------------------------------------------------
# Loads.


class ForceHistory(eqx.Module):
    """Time-stamped force histories, one per cable (as a CDPR logs its cables).

    **Arguments:**

    - `time`: sample times, s, shape `(cables, samples)` or `(samples,)` (shared by
        all cables); strictly increasing along samples.
    - `force`: cable forces, N, shape `(cables, samples)` or `(samples,)`.
    - `mask`: optional, False marks padding samples (histories of different lengths).

    The three are broadcast to one shape.
    """

    time: Float[Array, "*cables samples"]
    force: Float[Array, "*cables samples"]
    mask: Bool[Array, "*cables samples"]

    def __init__(
        self,
        time: Float[ArrayLike, "*cables samples"],
        force: Float[ArrayLike, "*cables samples"],
        mask: Bool[ArrayLike, "*cables samples"] | None = None,
    ):
        time = jnp.asarray(time)
        force = jnp.asarray(force)
        mask = jnp.ones((), bool) if mask is None else jnp.asarray(mask, bool)
        try:
            shape = np.broadcast_shapes(time.shape, force.shape, mask.shape)
        except ValueError:
            raise ValueError(
                f"`time` {time.shape}, `force` {force.shape} and `mask` {mask.shape} "
                "must have one shape (a 1-D `time` is shared by all cables)."
            ) from None
        if len(shape) not in (1, 2) or shape[-1] == 0:
            raise ValueError(
                "`time` and `force` must have shape (samples,) or (cables, samples) "
                f"with at least one sample, got {shape}."
            )
        self.time = jnp.broadcast_to(time, shape)
        self.force = jnp.broadcast_to(force, shape)
        self.mask = jnp.broadcast_to(mask, shape)


# ----------------------------------------------------------------------------------
# The result.


class MonteCarloResult(eqx.Module):
    """Statistics of elongation over time, per cable, over the successful draws.

    **Fields:**

    - `q`: the percentile levels, in percent (as `numpy.percentile`), shape `(q,)`.
    - `time`: sample times, s, shape `(cables, samples)`: the given times of a
        [`jaxcable.ForceHistory`][]; for a rate-driven [`jaxcable.Protocol`][] (whose
        times are solved per draw) the mean solved time over the successful draws.
        Statistics are per sample index (e.g. per force sample of a protocol).
    - `percentiles`: elongation percentiles, m, shape `(q, cables, samples)`.
    - `resolution`: a bound on the absolute error of each percentile, m, same shape:
        0 with `method="exact"`; the width of the histogram bins that hold the
        order statistics with `method="histogram"`.
    - `mean`, `std`, `min`, `max`: exact elongation statistics, m, shape
        `(cables, samples)` (std with ddof=0).
    - `num_draws`: the number of draws.
    - `num_successful`: successful draws per cable, shape `(cables,)`; the statistics
        use these only.
    - `status_counts`: `{RESULTS member name: count per cable}`; they sum to
        `num_draws` for every cable. A draw that fails for one cable (e.g. a Newton
        solve that does not converge) is excluded for that cable only.
    - `method`: `"exact"` or `"histogram"`.
    - `elongation`: every draw's elongation, m, shape `(draws, cables, samples)`, with
        NaN where the draw failed; only with `method="exact"` and `keep_draws=True`,
        else None.
    """

    q: Float[Array, " q"]
    time: Float[Array, "cables samples"]
    percentiles: Float[Array, "q cables samples"]
    resolution: Float[Array, "q cables samples"]
    mean: Float[Array, "cables samples"]
    std: Float[Array, "cables samples"]
    min: Float[Array, "cables samples"]
    max: Float[Array, "cables samples"]
    num_draws: int = eqx.field(static=True)
    num_successful: Int[Array, " cables"]
    status_counts: dict[str, Int[Array, " cables"]]
    method: str = eqx.field(static=True)
    elongation: Float[Array, "draws cables samples"] | None = None

    def percentile(self, q: float) -> Float[Array, "cables samples"]:
        """The elongation percentile `q` (one of `self.q`, in percent), m.

        **Arguments:**

        - `q`: the percentile level, in percent.

        **Returns:**

        An array of shape `(cables, samples)`.
        """
        levels = np.asarray(self.q, dtype=float)
        hit = np.flatnonzero(np.isclose(levels, q, rtol=0, atol=1e-9))
        if hit.size == 0:
            raise ValueError(
                f"`q`={q} was not computed; the result holds the percentiles "
                f"{levels.tolist()}."
            )
        return self.percentiles[int(hit[0])]


# ----------------------------------------------------------------------------------
# The chunked, sharded engine.

_AXIS = "draws"
# `method="auto"` keeps every draw (exact percentiles) up to this many values.
_EXACT_LIMIT = 2**24
# Default chunk: about this many elongation values per device (bounded memory).
_CHUNK_VALUES = 2**23
# Refuse histograms above this many bytes per device.
_HISTOGRAM_LIMIT = 4 * 2**30


def _status_names() -> tuple[str, ...]:
    # equinox keeps an Enumeration's members in this mapping; it has no public list.
    return tuple(RESULTS._name_to_item)


def _simulate_one(model, cable, load):
    if isinstance(load, Protocol):
        traj = simulate_rate_test(model, cable, load, throw=False)
    else:
        traj = simulate_force_history(
            model, cable, load.time, load.force, mask=load.mask, throw=False
        )
    return traj.elongation, traj.time, traj.result


class _Accumulator(eqx.Module):
    # Per-device running statistics (leading axis: device, sharded over the mesh).
    count: Float[Array, "dev cables"]
    mean: Float[Array, "dev cables samples"]
    m2: Float[Array, "dev cables samples"]
    time_mean: Float[Array, "dev cables samples"]
    minimum: Float[Array, "dev cables samples"]
    maximum: Float[Array, "dev cables samples"]
    status: Int[Array, "dev status cables"]
    histogram: Int[Array, "dev cells"]


def _local_draws(parameters, cables, loads, key, start, num_draws, local, load_axis):
    device = jax.lax.axis_index(_AXIS)
    index = start + device * local + jnp.arange(local)
    keys = jax.vmap(lambda i: jax.random.fold_in(key, i))(index)
    models = jax.vmap(parameters.draw)(keys)

    def per_draw(model):
        return jax.vmap(
            lambda c, ld: _simulate_one(model, c, ld), in_axes=(0, load_axis)
        )(cables, loads)

    elongation, time, result = eqx.filter_vmap(per_draw)(models)
    real = index < num_draws
    valid = (result == RESULTS.successful) & real[:, None]
    status = jnp.stack(
        [
            jnp.sum(
                (result == RESULTS._name_to_item[n]) & real[:, None],
                axis=0,
                dtype=jnp.int32,
            )
            for n in _status_names()
        ]
    )
    return elongation, time, valid, status


class _Running(eqx.Module):
    # One device's running statistics inside the loop over its draws.
    count: Float[Array, " cables"]
    mean: Float[Array, "cables samples"]
    m2: Float[Array, "cables samples"]
    time_mean: Float[Array, "cables samples"]
    minimum: Float[Array, "cables samples"]
    maximum: Float[Array, "cables samples"]
    histogram: Int[Array, " cells"]


def _update(acc: _Accumulator, elongation, time, valid, status, lo, width, bins):
    """Fold one chunk of draws into the accumulator, one draw at a time.

    Welford's update (numerically stable in float32 over 10^6 draws) over the draws in
    a `fori_loop`: each step reads one contiguous (cables, samples) row. This is ~5x
    faster on CPU than reductions over the draw axis, which XLA does not fuse into one
    pass when several statistics read the same array.
    """
    dtype = acc.mean.dtype
    ncables, nsamples = elongation.shape[1:]
    cells = bins + 2
    col = jnp.arange(ncables * nsamples, dtype=jnp.int32).reshape(ncables, nsamples)
    dropped = ncables * nsamples * cells  # out of bounds: dropped by the scatter

    def body(i, r: _Running) -> _Running:
        x = elongation[i].astype(dtype)
        ok = valid[i]
        w = ok[:, None]
        count = r.count + ok.astype(dtype)
        inv = (1.0 / jnp.maximum(count, 1.0))[:, None]
        delta = x - r.mean
        mean = jnp.where(w, r.mean + delta * inv, r.mean)
        m2 = jnp.where(w, r.m2 + delta * (x - mean), r.m2)
        if time is None:
            time_mean = r.time_mean
        else:
            t = time[i].astype(dtype)
            time_mean = jnp.where(w, r.time_mean + (t - r.time_mean) * inv, r.time_mean)
        minimum = jnp.where(w, jnp.minimum(r.minimum, x), r.minimum)
        maximum = jnp.where(w, jnp.maximum(r.maximum, x), r.maximum)
        histogram = r.histogram
        if bins:
            # Bin 0 holds x < lo, bins 1..bins the equal bins of [lo, hi), and
            # bins + 1 holds x >= hi.
            b = jnp.clip(jnp.floor((x - lo) / width), -1, bins).astype(jnp.int32) + 1
            flat = jnp.where(w, col * cells + b, dropped)
            histogram = histogram.at[flat.reshape(-1)].add(1, mode="drop")
        return _Running(count, mean, m2, time_mean, minimum, maximum, histogram)

    init = _Running(
        acc.count[0],
        acc.mean[0],
        acc.m2[0],
        acc.time_mean[0],
        acc.minimum[0],
        acc.maximum[0],
        acc.histogram[0],
    )
    r = jax.lax.fori_loop(0, elongation.shape[0], body, init)
    return _Accumulator(
        count=r.count[None],
        mean=r.mean[None],
        m2=r.m2[None],
        time_mean=r.time_mean[None],
        minimum=r.minimum[None],
        maximum=r.maximum[None],
        status=(acc.status[0] + status)[None],
        histogram=r.histogram[None],
    )


@functools.lru_cache(maxsize=32)
def _compiled(mesh: Mesh, local: int, load_axis, bins: int, keep: bool, impl: str):
    """The jitted chunk function of one Monte-Carlo configuration: compiled once, then
    called once per chunk with the same shapes."""
    spec = P(_AXIS)

    @eqx.filter_jit
    def step(parameters, cables, loads, key, start, num_draws, acc, lo, width):
        dyn, static = eqx.partition((parameters, cables, loads), eqx.is_array)

        def per_device(dyn, key, start, num_draws, acc, lo, width):
            parameters, cables, loads = eqx.combine(dyn, static)
            # The key travels as raw key data (a plain global array on every host).
            key = jax.random.wrap_key_data(key, impl=impl)
            elongation, time, valid, status = _local_draws(
                parameters, cables, loads, key, start, num_draws, local, load_axis
            )
            # Only a rate-driven test has solved (per-draw) times to average.
            if not isinstance(loads, Protocol):
                time = None
            acc = _update(acc, elongation, time, valid, status, lo, width, bins)
            return (acc, elongation, valid) if keep else acc

        return jax.shard_map(
            per_device,
            mesh=mesh,
            in_specs=(P(), P(), P(), P(), spec, P(), P()),
            out_specs=(spec, spec, spec) if keep else spec,
            check_vma=False,
        )(dyn, key, start, num_draws, acc, lo, width)

    return step


def _global(x, sharding) -> Array:
    """A host NumPy array as a global jax array laid out by `sharding`: each process
    places the shards of its own devices (the same call on one or several hosts)."""
    x = np.asarray(x)
    return jax.make_array_from_callback(x.shape, sharding, lambda index: x[index])


def _to_host(x) -> np.ndarray:
    """A global array as a NumPy array on this process (all-gathered across hosts)."""
    if getattr(x, "is_fully_addressable", True):
        return np.asarray(x)
    from jax.experimental import multihost_utils

    return np.asarray(multihost_utils.process_allgather(x, tiled=True))


class _Progress:
    # A one-line text bar on stderr; the ETA leaves out the first chunk (compilation).
    def __init__(self, total: int, enabled: bool, width: int = 30):
        self.total = total
        self.enabled = enabled
        self.width = width
        self.start = _time.perf_counter()
        self.first = None

    def update(self, done: int, draws: int):
        if not self.enabled:
            return
        now = _time.perf_counter()
        if self.first is None:
            self.first = now
        bar = "#" * int(round(done / self.total * self.width))
        if done > 1:
            eta = f"{(now - self.first) / (done - 1) * (self.total - done):.1f} s"
        else:
            eta = "?"
        sys.stderr.write(
            f"\rmonte_carlo [{bar:<{self.width}}] {done}/{self.total} chunks, "
            f"{draws} draws, {now - self.start:.1f} s, ETA {eta} "
        )
        if done == self.total:
            sys.stderr.write("\n")
        sys.stderr.flush()


def _check_int(name: str, value, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ValueError(f"`{name}` must be an int, got {value!r}.")
    if value < minimum:
        raise ValueError(f"`{name}` must be >= {minimum}, got {value}.")
    return int(value)


def _check_key(key):
    if not isinstance(key, jax.Array) and not isinstance(key, np.ndarray):
        raise ValueError(
            "`key` must be a JAX PRNG key, e.g. `jax.random.key(0)`, got "
            f"{type(key).__name__}."
        )
    if jnp.issubdtype(key.dtype, jax.dtypes.prng_key):
        if key.shape != ():
            raise ValueError(
                f"`key` must be one key (shape ()), got shape {key.shape}."
            )
        return key
    if key.dtype == jnp.uint32 and key.shape == (2,):
        return jax.random.wrap_key_data(jnp.asarray(key))
    raise ValueError(
        "`key` must be a JAX PRNG key (`jax.random.key(seed)`), got an array of dtype "
        f"{key.dtype} and shape {key.shape}."
    )


def _check_cables(cables) -> Cable:
    if not isinstance(cables, Cable):
        raise ValueError(
            f"`cables` must be a jaxcable.Cable (fields of shape (cables,)), got "
            f"{type(cables).__name__}."
        )
    names = CABLE_FIELDS
    shapes = {n: jnp.shape(getattr(cables, n)) for n in names}
    if any(len(s) > 1 for s in shapes.values()):
        raise ValueError(
            f"`cables` fields must be scalars or 1-D (one value per cable), got {shapes}."
        )
    try:
        shape = np.broadcast_shapes(*shapes.values())
    except ValueError:
        raise ValueError(
            f"`cables` fields must have one length (one value per cable), got {shapes}."
        ) from None
    n = shape[0] if shape else 1
    dtype = jnp.result_type(float, cables.length)
    return Cable(
        **{
            n_: jnp.broadcast_to(jnp.asarray(getattr(cables, n_), dtype), (n,))
            for n_ in names
        }
    )


def _cable(cables: Cable, j: int) -> Cable:
    return jax.tree_util.tree_map(lambda x: x[j], cables)


def _check_loads(loads, cables: Cable):
    ncables = cables.length.shape[0]
    dtype = cables.length.dtype
    if isinstance(loads, Protocol):
        force = np.asarray(loads.force)
        if force.ndim not in (1, 2) or (force.ndim == 2 and force.shape[0] != ncables):
            raise ValueError(
                f"`loads.force` must have shape (samples,) or ({ncables}, samples) for "
                f"{ncables} cables, got {force.shape}."
            )
        limit = np.asarray(cables.breaking_load)
        over = force > (limit[:, None] if force.ndim == 2 else limit.min())
        if np.any(over):
            idx = np.argwhere(over)[0].tolist()
            raise ValueError(
                f"`loads.force` exceeds a cable's breaking load at index {idx}: "
                f"{force[tuple(idx)]:g} N."
            )
        axis = 0 if force.ndim == 2 else None
        # tree_at, not the constructor, which takes one 1-D protocol.
        loads = eqx.tree_at(
            lambda p: (p.force, p.direction, p.duration, p.mask),
            loads,
            (
                jnp.asarray(loads.force, dtype),
                jnp.asarray(loads.direction, jnp.int32),
                jnp.asarray(loads.duration, dtype),
                jnp.asarray(loads.mask, bool),
            ),
        )
        return loads, axis, force.shape[-1]
    if isinstance(loads, ForceHistory):
        t = np.asarray(loads.time)
        if t.ndim == 2 and t.shape[0] != ncables:
            raise ValueError(
                f"`loads.time` has {t.shape[0]} histories for {ncables} cables; give "
                "one per cable, or one 1-D history shared by all."
            )
        for j in range(ncables):
            if t.ndim == 2:
                tj, fj, mj = loads.time[j], loads.force[j], loads.mask[j]
            else:
                tj, fj, mj = loads.time, loads.force, loads.mask
            try:
                check_history(_cable(cables, j), tj, fj, mj, "force")
            except ValueError as e:
                raise ValueError(f"`loads` (cable {j}): {e}") from None
            if t.ndim == 1:
                break
        axis = 0 if t.ndim == 2 else None
        loads = ForceHistory(
            jnp.asarray(loads.time, dtype), jnp.asarray(loads.force, dtype), loads.mask
        )
        return loads, axis, t.shape[-1]
    raise ValueError(
        "`loads` must be a jaxcable.Protocol (rate-driven test) or a "
        f"jaxcable.ForceHistory (time-stamped forces), got {type(loads).__name__}."
    )


def _percentiles_from_histogram(hist, lo, width, minimum, maximum, count, q):
    """Percentiles (numpy's linear interpolation between order statistics) from the
    per-column histograms, with a bound on their error."""
    bins = hist.shape[-1] - 2
    cum = np.cumsum(hist, axis=-1, dtype=np.int64)  # values in bins 0..k

    def order_statistic(j):
        # The bin b holding the j-th smallest value (0-based), its edges, and an
        # estimate of the value that spreads the bin's values evenly over the bin.
        b = np.minimum(np.sum(cum <= j[..., None], axis=-1), bins + 1)
        n_b = np.take_along_axis(hist, b[..., None], axis=-1)[..., 0]
        before = np.take_along_axis(cum, b[..., None], axis=-1)[..., 0] - n_b
        left = np.where(b == 0, minimum, lo + (b - 1) * width)
        right = np.where(b == bins + 1, maximum, lo + b * width)
        left, right = np.clip(left, minimum, maximum), np.clip(right, minimum, maximum)
        frac = np.clip((j - before + 0.5) / np.maximum(n_b, 1), 0.0, 1.0)
        est = left + frac * (right - left)
        # The extremes are known exactly.
        first, last = j == 0, j == count - 1
        est = np.where(first, minimum, np.where(last, maximum, est))
        width_b = np.where(first | last, 0.0, right - left)
        return est, width_b

    values, bounds = [], []
    with np.errstate(invalid="ignore"):
        for level in q:
            rank = level / 100.0 * np.maximum(count - 1, 0)
            j0 = np.floor(rank).astype(np.int64)
            j1 = np.minimum(j0 + 1, np.maximum(count - 1, 0))
            frac = rank - j0
            e0, w0 = order_statistic(j0)
            e1, w1 = order_statistic(j1)
            values.append(e0 + frac * (e1 - e0))
            # Each estimate lies in the bin of its order statistic, so the error of
            # the interpolated value is at most the interpolated bin width.
            bounds.append((1 - frac) * w0 + frac * w1)
    return np.stack(values), np.stack(bounds)


def monte_carlo(
    parameters: AbstractParameterSampler,
    cables: Cable,
    loads: Protocol | ForceHistory,
    *,
    key: PRNGKeyArray,
    num_draws: int,
    percentiles: Sequence[float] = (1.0, 5.0, 50.0, 95.0, 99.0),
    chunk_size: int | None = None,
    method: str = "auto",
    bins: int = 1024,
    keep_draws: bool = False,
    devices: Sequence[jax.Device] | None = None,
    progress: bool = True,
) -> MonteCarloResult:
    """Monte-Carlo of a set of cables over parameter draws: percentiles of elongation
    over time.

    Each draw is one parameter set (from `parameters`), shared by all cables (the 8
    cables of a CDPR cut from one spool); every (draw, cable) pair is simulated with the
    cable's length, speed and load history, all in one jitted `vmap`. Draws run in
    chunks of `chunk_size` (one compiled function called once per chunk with the same
    shapes; the last chunk is padded with draws that are discarded), so memory is
    bounded whatever `num_draws` is. Draw i uses the key `jax.random.fold_in(key, i)`:
    results are reproducible and do not depend on `chunk_size` or on the devices.

    A (draw, cable) whose simulation fails (`RESULTS` other than `successful`, e.g. a
    Newton solve that does not converge, or a drawn parameter outside its domain) is
    counted in `status_counts` and excluded from that cable's statistics.

    **Percentiles in bounded memory.** `method="exact"` keeps every draw on the host
    (draws x cables x samples values) and calls `numpy.percentile`. `method="histogram"`
    keeps, per (cable, sample), a histogram of `bins` equal bins over the range of the
    first chunk widened by half of it on each side, plus an underflow and an overflow
    bin bounded by the exact running minimum and maximum; a percentile is interpolated
    within the bins that hold its order statistics, and `resolution` bounds its
    absolute error (the width of those bins, 2 x range(first chunk) / `bins`: ~2e-3
    of the spread with the default 1024 bins; larger only where a percentile falls in
    the under- or overflow bin, i.e. beyond 1.5 x the first chunk's range, which
    `resolution` then shows). Mean, std, min and max are exact
    in both (Welford's running update per device, merged
    across devices with Chan's formula). `"auto"` is `"exact"` up to
    2**24 stored values, else `"histogram"`.

    **Devices.** The draws of a chunk are sharded over `devices` (default
    `jax.devices()`: every visible device, on every host) with `jax.shard_map` on a
    one-axis `Mesh`; each device runs its share and keeps its own statistics, merged
    once at the end. On one device this is a no-op. On a CPU, XLA runs one scan on one
    core: `XLA_FLAGS=--xla_force_host_platform_device_count=N` (set before importing
    jax) exposes N CPU devices and spreads the draws over N cores.

    **Several hosts.** Start the same script on every host with
    `jax.distributed.initialize(coordinator_address, num_processes, process_id)` first
    (on Slurm/TPU pods it needs no arguments); `jax.devices()` then lists the devices
    of all hosts, each host runs the draws of its own devices, and every process
    receives the same full result. All processes must call `monte_carlo` with the same
    arguments (same key).

    **Arguments:**

    - `parameters`: an [`jaxcable.AbstractParameterSampler`][]:
        [`jaxcable.IndependentParameters`][] (per-parameter distributions) or
        [`jaxcable.CorrelatedParameters`][] (a fit's mean and covariance).
    - `cables`: a [`jaxcable.Cable`][] whose fields have shape `(cables,)` (or are
        scalars: one cable).
    - `loads`: a [`jaxcable.ForceHistory`][] (time-stamped forces) or a
        [`jaxcable.Protocol`][] (a rate-driven test), of shape `(samples,)` (shared) or
        `(cables, samples)` (for protocols: stack equal-length ones, see
        [`jaxcable.Protocol.pad`][], with
        `jax.tree_util.tree_map(lambda *a: jnp.stack(a), *protocols)`).
    - `key`: a JAX PRNG key (`jax.random.key(seed)`); no default, for reproducibility.
    - `num_draws`: the number of parameter draws.
    - `percentiles`: the percentile levels to compute, in percent (0-100).
    - `chunk_size`: draws per chunk (rounded up to a multiple of the number of
        devices); default about 2**23 / (cables x samples) per device.
    - `method`: `"auto"`, `"exact"` or `"histogram"` (see above).
    - `bins`: histogram bins per (cable, sample) (`method="histogram"`).
    - `keep_draws`: with `method="exact"`, return every draw in `elongation`.
    - `devices`: the devices to shard the draws over (default `jax.devices()`).
    - `progress`: print a progress bar on stderr.

    **Returns:**

    A [`jaxcable.MonteCarloResult`][] (elongations in m, times in s).
    """
    if not isinstance(parameters, AbstractParameterSampler):
        raise ValueError(
            "`parameters` must be a jaxcable parameter sampler (IndependentParameters "
            f"or CorrelatedParameters), got {type(parameters).__name__}."
        )
    key = _check_key(key)
    num_draws = _check_int("num_draws", num_draws, 1)
    q = np.asarray(percentiles, dtype=float)
    if q.ndim != 1 or q.size == 0:
        raise ValueError(
            f"`percentiles` must be a non-empty 1-D sequence, got {percentiles!r}."
        )
    _checks.require_finite("percentiles", q)
    if np.any((q < 0) | (q > 100)):
        raise ValueError(f"`percentiles` must lie in [0, 100] (percent), got {q}.")
    if method not in ("auto", "exact", "histogram"):
        raise ValueError(
            f"`method` must be 'auto', 'exact' or 'histogram', got {method!r}."
        )
    bins = _check_int("bins", bins, 2)
    if not isinstance(progress, bool):
        raise ValueError(f"`progress` must be a bool, got {progress!r}.")
    cables = _check_cables(cables)
    loads, load_axis, samples = _check_loads(loads, cables)
    ncables = cables.length.shape[0]
    dtype = cables.length.dtype

    if devices is None:
        devices = jax.devices()
    devices = list(devices)
    if not devices or not all(isinstance(d, jax.Device) for d in devices):
        raise ValueError(
            f"`devices` must be a non-empty list of jax devices, got {devices!r}."
        )
    ndev = len(devices)
    per_draw = ncables * samples
    if chunk_size is None:
        # About 2**23 values per device and chunk (32 MiB of float32 elongations).
        chunk_size = max(1, _CHUNK_VALUES // per_draw) * ndev
    chunk_size = _check_int("chunk_size", chunk_size, 1)
    chunk_size = min(chunk_size, num_draws)
    chunk = -(-chunk_size // ndev) * ndev
    local = chunk // ndev
    num_chunks = -(-num_draws // chunk)

    if method == "auto":
        method = "exact" if num_draws * per_draw <= _EXACT_LIMIT else "histogram"
    if keep_draws and method != "exact":
        raise ValueError("`keep_draws=True` needs `method='exact'`.")
    exact = method == "exact"
    hist_bins = 0 if exact else bins
    if hist_bins and per_draw * (hist_bins + 2) * 4 > _HISTOGRAM_LIMIT:
        raise ValueError(
            f"`bins`={bins} makes a histogram of {per_draw * (bins + 2) * 4 / 2**30:.1f} "
            "GiB per device for this many cables x samples; use fewer bins."
        )

    mesh = Mesh(np.asarray(devices), (_AXIS,))
    sharded = NamedSharding(mesh, P(_AXIS))
    replicated = NamedSharding(mesh, P())
    step = _compiled(mesh, local, load_axis, hist_bins, exact, jax.random.key_impl(key))

    # Every input becomes a global array replicated over the mesh (on several hosts,
    # every process passes the same values).
    dyn, static = eqx.partition((parameters, cables, loads), eqx.is_array)
    dyn = jax.tree_util.tree_map(lambda x: _global(x, replicated), dyn)
    parameters, cables, loads = eqx.combine(dyn, static)

    def zeros(shape, dt=dtype, fill=0):
        return _global(np.full((ndev, *shape), fill, dt), sharded)

    def fresh():
        return _Accumulator(
            count=zeros((ncables,)),
            mean=zeros((ncables, samples)),
            m2=zeros((ncables, samples)),
            time_mean=zeros((ncables, samples)),
            minimum=zeros((ncables, samples), fill=np.inf),
            maximum=zeros((ncables, samples), fill=-np.inf),
            status=zeros((len(_status_names()), ncables), jnp.int32),
            histogram=zeros(
                (per_draw * (hist_bins + 2) if hist_bins else 1,), jnp.int32
            ),
        )

    key_data = _global(jax.random.key_data(key), replicated)
    total = _global(np.int32(num_draws), replicated)

    def run(c, acc, lo, width):
        start = _global(np.int32(c * chunk), replicated)
        return step(parameters, cables, loads, key_data, start, total, acc, lo, width)

    def put(x):
        return _global(np.asarray(x, dtype), replicated)

    lo = np.zeros((ncables, samples), dtype)
    width = np.ones((ncables, samples), dtype)
    if hist_bins:
        # The bins are set by the range of the first chunk: it is run once more (same
        # compiled function) and only its exact minimum and maximum are kept.
        probe = run(0, fresh(), put(lo), put(width))
        lo_raw = _to_host(probe.minimum).min(axis=0).astype(float)
        hi_raw = _to_host(probe.maximum).max(axis=0).astype(float)
        empty = ~np.isfinite(lo_raw)
        lo_raw, hi_raw = np.where(empty, 0.0, lo_raw), np.where(empty, 0.0, hi_raw)
        pad = (
            0.5 * (hi_raw - lo_raw)
            + 1e-9 * np.maximum(np.abs(lo_raw), np.abs(hi_raw))
            + 1e-12
        )
        # The edges as the device sees them (in the simulation's dtype).
        lo = (lo_raw - pad).astype(dtype)
        width = ((hi_raw - lo_raw + 2 * pad) / hist_bins).astype(dtype)
    lo_dev, width_dev = put(lo), put(width)

    kept = kept_valid = None
    if exact:
        kept = np.empty((num_chunks * chunk, ncables, samples), np.dtype(dtype))
        kept_valid = np.empty((num_chunks * chunk, ncables), bool)
    acc = fresh()
    bar = _Progress(num_chunks, progress)
    for c in range(num_chunks):
        out = run(c, acc, lo_dev, width_dev)
        if exact:
            acc, elongation, valid = out
            kept[c * chunk : (c + 1) * chunk] = _to_host(elongation)
            kept_valid[c * chunk : (c + 1) * chunk] = _to_host(valid)
        else:
            acc = jax.block_until_ready(out)
        bar.update(c + 1, min((c + 1) * chunk, num_draws))

    # Merge the devices' statistics (float64 on the host).
    host = jax.tree_util.tree_map(_to_host, acc)
    count = host.count[0].astype(float)
    mean = host.mean[0].astype(float)
    m2 = host.m2[0].astype(float)
    time_mean = host.time_mean[0].astype(float)
    for d in range(1, ndev):
        cd = host.count[d].astype(float)
        merged = count + cd
        safe = np.maximum(merged, 1.0)[:, None]
        delta = host.mean[d] - mean
        time_mean = time_mean + (host.time_mean[d] - time_mean) * (cd[:, None] / safe)
        mean = mean + delta * (cd[:, None] / safe)
        m2 = m2 + host.m2[d] + delta**2 * (count * cd)[:, None] / safe
        count = merged
    minimum = host.minimum.min(axis=0).astype(float)
    maximum = host.maximum.max(axis=0).astype(float)
    status = host.status.sum(axis=0)
    n_ok = status[_status_names().index("successful")]
    none = n_ok == 0
    if np.any(none):
        warnings.warn(
            f"monte_carlo: no successful draw for cables {np.flatnonzero(none).tolist()}; "
            "their statistics are NaN (see `status_counts`).",
            stacklevel=2,
        )
    nan_if_none = lambda a: np.where(none[:, None], np.nan, a)

    if exact:
        kept, kept_valid = kept[:num_draws], kept_valid[:num_draws]
        values = np.full((q.size, ncables, samples), np.nan)
        for j in range(ncables):
            x = kept[kept_valid[:, j], j]
            if x.shape[0]:
                values[:, j] = np.percentile(x, q, axis=0)
        resolution = np.where(np.isnan(values), np.nan, 0.0)
        if keep_draws:
            kept = np.where(kept_valid[:, :, None], kept, np.nan)
    else:
        hist = host.histogram.sum(axis=0).reshape(ncables, samples, hist_bins + 2)
        cnt = np.broadcast_to(n_ok[:, None], (ncables, samples))
        values, resolution = _percentiles_from_histogram(
            hist, lo.astype(float), width.astype(float), minimum, maximum, cnt, q
        )
        values = np.where(none[None, :, None], np.nan, values)
        resolution = np.where(none[None, :, None], np.nan, resolution)

    if isinstance(loads, ForceHistory):
        time = np.broadcast_to(np.asarray(loads.time), (ncables, samples))
    else:
        time = nan_if_none(time_mean)
    std = np.sqrt(m2 / np.maximum(count, 1.0)[:, None])
    as_dtype = lambda a: jnp.asarray(np.asarray(a), dtype)
    return MonteCarloResult(
        q=as_dtype(q),
        time=as_dtype(time),
        percentiles=as_dtype(values),
        resolution=as_dtype(resolution),
        mean=as_dtype(nan_if_none(mean)),
        std=as_dtype(nan_if_none(std)),
        min=as_dtype(nan_if_none(minimum)),
        max=as_dtype(nan_if_none(maximum)),
        num_draws=num_draws,
        num_successful=jnp.asarray(n_ok),
        status_counts={
            n: jnp.asarray(status[i]) for i, n in enumerate(_status_names())
        },
        method=method,
        elongation=as_dtype(kept) if keep_draws else None,
    )
