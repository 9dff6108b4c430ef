"""Distributions of one scalar model parameter: the abstract interface and the normal,
log-normal and uniform distributions the Monte-Carlo draws parameters from."""

import abc

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, PRNGKeyArray

from .. import _checks
from .._arrays import field_array


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
    # A traced field (a distribution built under `jit` or `vmap`) is not checked.
    if not _checks.is_concrete(value):
        return
    if np.shape(value) != ():
        raise ValueError(
            f"{cls} `{name}` must be a scalar, got shape {np.shape(value)}."
        )
    _checks.require_finite(f"{cls}.{name}", value)


def float_dtype(*xs):
    """The floating-point dtype of draws from the values `xs` (at least the default
    float: float64 under `jax_enable_x64`, else float32)."""
    return jnp.result_type(float, *xs)


class Normal(AbstractDistribution):
    """A normal distribution N(mean, std**2).

    **Arguments:**

    - `mean`: the mean, in the parameter's unit.
    - `std`: the standard deviation (>= 0), same unit.
    """

    mean: Float[Array, ""] = eqx.field(converter=field_array)
    std: Float[Array, ""] = eqx.field(converter=field_array)

    def __check_init__(self):
        _require_scalar("Normal", "mean", self.mean)
        _require_scalar("Normal", "std", self.std)
        if _checks.is_concrete(self.std):
            _checks.require_positive("Normal.std", self.std, allow_zero=True)

    def sample(self, key: PRNGKeyArray, shape: tuple[int, ...] = ()) -> Array:
        dtype = float_dtype(self.mean, self.std)
        return self.mean + self.std * jax.random.normal(key, shape, dtype)


class LogNormal(AbstractDistribution):
    """A log-normal distribution: log(x) ~ N(log(median), sigma**2); x > 0.

    The natural choice for moduli, viscosities and time constants: a fit's relative
    standard error s gives sigma ~ s for s << 1.

    **Arguments:**

    - `median`: the median exp(E[log x]) (> 0), in the parameter's unit.
    - `sigma`: the standard deviation of log(x) (>= 0), dimensionless.
    """

    median: Float[Array, ""] = eqx.field(converter=field_array)
    sigma: Float[Array, ""] = eqx.field(converter=field_array)

    def __check_init__(self):
        _require_scalar("LogNormal", "median", self.median)
        _require_scalar("LogNormal", "sigma", self.sigma)
        if _checks.is_concrete(self.median, self.sigma):
            _checks.require_positive("LogNormal.median", self.median)
            _checks.require_positive("LogNormal.sigma", self.sigma, allow_zero=True)

    def sample(self, key: PRNGKeyArray, shape: tuple[int, ...] = ()) -> Array:
        dtype = float_dtype(self.median, self.sigma)
        return self.median * jnp.exp(self.sigma * jax.random.normal(key, shape, dtype))


class Uniform(AbstractDistribution):
    """A uniform distribution on [low, high).

    **Arguments:**

    - `low`, `high`: the bounds (low < high), in the parameter's unit.
    """

    low: Float[Array, ""] = eqx.field(converter=field_array)
    high: Float[Array, ""] = eqx.field(converter=field_array)

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
        dtype = float_dtype(self.low, self.high)
        u = jax.random.uniform(key, shape, dtype)
        return self.low + (self.high - self.low) * u
