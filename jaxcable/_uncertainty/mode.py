"""The posterior's mode and its Laplace covariance, where the chains start: the
least-squares optimum is the mode only when every test has the same noise, and a
chain that starts elsewhere spends its warm-up travelling (the metric then learns the
journey, not the posterior's shape)."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from .nuts import logdensity_of


class _Whitened(eqx.Module):
    """-log density at u = center + chol z (the Laplace approximation whitened, so
    that BFGS starts with the right scales)."""

    density: eqx.Module
    center: jax.Array
    chol: jax.Array

    def __call__(self, z, args=None):
        return -logdensity_of(self.density)(self.center + self.chol @ z)


@eqx.filter_jit
def _minimise(loss: _Whitened, max_steps: int):
    solver = optx.BFGS(rtol=1e-9, atol=1e-9)
    sol = optx.minimise(
        loss,
        solver,
        jnp.zeros_like(loss.center),
        max_steps=max_steps,
        throw=False,
    )
    return sol.value, loss(sol.value), loss(jnp.zeros_like(loss.center))


@eqx.filter_jit
def _hessian(loss: _Whitened, z, h):
    """Central differences of the gradient (the density's gradient is forward-mode
    inside a custom VJP, which a second derivative cannot go through)."""
    grad = jax.grad(loss)
    eye = jnp.eye(z.shape[0])
    rows = jax.vmap(lambda e: (grad(z + h * e) - grad(z - h * e)) / (2 * h))(eye)
    return 0.5 * (rows + rows.T)


def posterior_mode(density: eqx.Module, u_hat, cov, max_steps: int = 200):
    """The mode of `density` from `u_hat` and the covariance there.

    **Arguments:**

    - `density`: the log posterior, a Module called with u.
    - `u_hat`: the start (the least-squares optimum), `(p,)`.
    - `cov`: the Laplace covariance at `u_hat`, `(p, p)`.
    - `max_steps`: BFGS steps.

    **Returns:**

    `(u, cov)`: the mode and the inverse of the Hessian of -log density there; the
    start and `cov` unchanged when BFGS did not improve the density or the Hessian
    is not positive definite.
    """
    chol = np.linalg.cholesky(cov)
    loss = _Whitened(density, jnp.asarray(u_hat), jnp.asarray(chol))
    z, value, start = (np.asarray(v) for v in _minimise(loss, max_steps))
    if not (np.isfinite(value) and value <= start and np.all(np.isfinite(z))):
        return np.asarray(u_hat), cov
    hess = np.asarray(_hessian(loss, jnp.asarray(z), 1e-3))
    w, v = np.linalg.eigh(hess)
    if not (np.all(np.isfinite(w)) and np.all(w > 0)):
        return np.asarray(u_hat) + chol @ z, cov
    cov_z = (v / w) @ v.T
    return np.asarray(u_hat) + chol @ z, chol @ cov_z @ chol.T
