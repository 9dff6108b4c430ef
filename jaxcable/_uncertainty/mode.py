"""The posterior's mode and its Laplace covariance, where the chains start: the
least-squares optimum is the mode only when every test has the same noise, and a
chain that starts elsewhere spends its warm-up travelling (the metric then learns the
journey, not the posterior's shape)."""

from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .nuts import logdensity_of


class _Whitened(eqx.Module):
    """-log density at u = center + chol z (the Laplace approximation whitened, so
    that Newton starts with the right scales)."""

    density: Callable[[jax.Array], jax.Array]  # a Module called with u
    center: jax.Array
    chol: jax.Array

    def __call__(self, z, args=None):
        return -logdensity_of(self.density)(self.center + self.chol @ z)


@eqx.filter_jit
def _value_and_grad(loss: _Whitened, z):
    return jax.value_and_grad(loss)(z)


def _hessian(loss: _Whitened, z: np.ndarray, h: float = 1e-3) -> np.ndarray:
    """Central differences of the gradient (the density's gradient is forward-mode
    inside a custom VJP, which a second derivative cannot go through), with the one
    compiled gradient."""
    rows = []
    for e in np.eye(z.shape[0]):
        up = np.asarray(_value_and_grad(loss, jnp.asarray(z + h * e))[1])
        down = np.asarray(_value_and_grad(loss, jnp.asarray(z - h * e))[1])
        rows.append((up - down) / (2 * h))
    hess = np.array(rows)
    return 0.5 * (hess + hess.T)


def _newton(loss: _Whitened, max_steps: int):
    """Newton's method with a backtracking line search on the whitened loss, from
    z = 0; the last point, its loss and the loss at 0 (NaN-safe: a step to a
    non-finite loss is halved)."""
    z = np.zeros(loss.center.shape[0])
    value, grad = (np.asarray(v) for v in _value_and_grad(loss, jnp.asarray(z)))
    start = float(value)
    for _ in range(max_steps):
        hess = _hessian(loss, z)
        w, v = np.linalg.eigh(hess)
        if not np.all(np.isfinite(w)):
            break
        # Where the loss is not convex, the step follows |curvature| (floored).
        w = np.maximum(np.abs(w), 1e-6 * max(np.max(np.abs(w)), 1e-300))
        step = -(v / w) @ v.T @ grad
        slope = float(grad @ step)
        if -slope < 1e-10:
            break
        t = 1.0
        while t > 1e-6:
            trial = z + t * step
            new, new_grad = (
                np.asarray(x) for x in _value_and_grad(loss, jnp.asarray(trial))
            )
            if np.isfinite(new) and new <= value + 1e-4 * t * slope:
                break
            t *= 0.5
        else:
            break
        z, value, grad = trial, new, new_grad
    return z, float(value), start


def posterior_mode(
    density: Callable[[jax.Array], jax.Array], u_hat, cov, max_steps: int = 20
):
    """The mode of `density` from `u_hat` and the covariance there.

    **Arguments:**

    - `density`: the log posterior, a Module called with u.
    - `u_hat`: the start (the least-squares optimum), `(p,)`.
    - `cov`: the Laplace covariance at `u_hat`, `(p, p)`.
    - `max_steps`: Newton steps (each 2p + 1 gradients: the Hessian by central
        differences, whitened by `cov`).

    **Returns:**

    `(u, cov)`: the mode and the inverse of the Hessian of -log density there; the
    start and `cov` unchanged when Newton did not improve the density or the
    Hessian is not positive definite.
    """
    chol = np.linalg.cholesky(cov)
    loss = _Whitened(density, jnp.asarray(u_hat), jnp.asarray(chol))
    z, value, start = _newton(loss, max_steps)
    if not (np.isfinite(value) and value <= start and np.all(np.isfinite(z))):
        return np.asarray(u_hat), cov
    hess = _hessian(loss, z)
    w, v = np.linalg.eigh(hess)
    if not (np.all(np.isfinite(w)) and np.all(w > 0)):
        return np.asarray(u_hat) + chol @ z, cov
    cov_z = (v / w) @ v.T
    return np.asarray(u_hat) + chol @ z, chol @ cov_z @ chol.T
