"""The prior of a posterior: one density per fitted parameter, derived from the
parameter's declared domain (the reparameterisation the fit uses for it).

Each parameter is sampled on the unconstrained scale u that `jaxcable.fit` solves on
(`x = f(u)`, declared beside the parameter by its model). The prior is placed on u:

- `"log"` (x > 0), `"log1"` (x > 1), `"linear"` (x = s u, s the |start value|):
    u ~ Normal(u_start, `scale`^2), u_start the user's start value on that scale. For
    a positive parameter this is a log-normal prior on x (on x - 1 for `"log1"`)
    with median the start value; the default `scale` ln(10) puts 95 % of the prior
    within a factor of about 90 of it, broad enough that well-measured parameters
    are set by the data, narrow enough that a parameter the data do not determine
    keeps a proper, finite posterior instead of drifting without end.
- `"tanh:OTHER"` (|x| < OTHER): uniform on the whole open interval, i.e. the density
    of u is (1 - tanh(u)^2) / 2.
"""

import math

import jax.numpy as jnp
from jaxtyping import Array, Float


PRIOR_SCALE = math.log(10.0)
"""Default standard deviation of the prior of a log-, log1- or linear-scale parameter
on its unconstrained scale (ln 10: one decade of a positive parameter)."""


def bound_of(transform: str) -> str | None:
    """The path of the parameter bounding a `"tanh:OTHER"` transform, else None."""
    return transform.split(":", 1)[1] if transform.startswith("tanh:") else None


def to_unconstrained(transform: str, x: float, scale: float, bound) -> float:
    """u = f^-1(x) of one parameter, the inverse of the fit's reparameterisation
    (`"log"`: x = e^u; `"log1"`: x = 1 + e^u; `"linear"`: x = scale u; `"tanh:OTHER"`:
    x = bound tanh(u)); a value on a bound is moved 1 % inside, as the fit does."""
    if transform == "log":
        return math.log(x)
    if transform == "log1":
        return math.log(max(x - 1.0, 1e-2))
    if transform == "linear":
        return x / scale
    return math.atanh(min(max(x / bound, -1 + 1e-2), 1 - 1e-2))


def log_prior(
    transforms: tuple[str, ...],
    center: Float[Array, " p"],
    scale: float,
    u: Float[Array, " p"],
) -> Float[Array, ""]:
    """The log prior density of the unconstrained parameters u (up to a constant).

    **Arguments:**

    - `transforms`: each entry's reparameterisation (see `jaxcable.fit`).
    - `center`: each entry's prior centre on the unconstrained scale (the start).
    - `scale`: the prior standard deviation on the unconstrained scale (> 0).
    - `u`: the unconstrained parameters.

    **Returns:**

    The log density, a scalar.
    """
    total = jnp.zeros((), u.dtype)
    for i, transform in enumerate(transforms):
        if transform.startswith("tanh:"):
            # log(1 - tanh(u)^2) = 2 log(2) - 2 log(e^u + e^-u), stable for large |u|.
            total = total - 2.0 * jnp.logaddexp(u[i], -u[i])
        else:
            total = total - 0.5 * ((u[i] - center[i]) / scale) ** 2
    return total


def prior_precision(transforms: tuple[str, ...], scale: float) -> Float[Array, " p"]:
    """The curvature of `-log_prior` at its centre, entry by entry: 1 / scale^2 for a
    normal prior, 1 for the uniform prior of a tanh-bounded parameter (its density's
    curvature at u = 0 is 2; 1 keeps the Laplace start conservative)."""
    return jnp.asarray(
        [1.0 if t.startswith("tanh:") else 1.0 / scale**2 for t in transforms]
    )
