"""Parameter samplers: one model per PRNG key, drawn from independent per-parameter
distributions or from a fit's mean and covariance (a multivariate normal)."""

import abc
import dataclasses
import zlib
from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float, PRNGKeyArray

from .. import _checks
from .._models import AbstractCableModel
from .distributions import AbstractDistribution, float_dtype


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
    """Raise `ValueError` unless `names` are distinct scalar float parameters of
    `model`; return the model's scalar float fields, by name."""
    fields = _scalar_fields(model)
    _checks.require_names(
        argname, names, sorted(fields), type(model).__name__, "scalar float parameters"
    )
    return fields


def _replace(model, names, values):
    """`model` with the parameters `names` set to `values`."""
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
        `{"E3r": jc.LogNormal(8e8, 0.1), "t_e": jc.Uniform(3.0, 6.0)}`
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
            .astype(float_dtype(fields[n]))
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
        dtype = float_dtype(*fields.values())
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
            values.append(v.astype(float_dtype(mean)))
        return _replace(self.model, self.names, values)
