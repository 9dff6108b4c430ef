"""The state of the online estimator ([`jaxcable.cdpr.EstimatorState`][]) and the check
of its intervals against known values ([`jaxcable.cdpr.interval_covers`][])."""

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .._drive import ControllerState
from .._results import RESULTS
from .horizon import Anchor, Track, Window


# The two-sided 95 % quantile of a normal distribution.
_Z95 = 1.959963984540054


class EstimatorState(eqx.Module):
    """The state of an [`jaxcable.cdpr.OnlineEstimator`][] (n cables, p parameters
    each, all SI).

    **Fields:**

    - `log_parameters`: the estimates' logs, `(n, p)` (ln of Pa, s, ...).
    - `covariance`: their joint covariance, `(n p, n p)` (cable-major).
    - `track`: the cables' model at the estimates: `track.model` their states
        ([`jaxcable.states.ControllerState`][], one parameter set per cable),
        `track.sensitivity` d `model.packed` / d `log_parameters` (one tangent per
        parameter, arrays `(p, n, k_i)`: cable i's state in its own parameters),
        `track.strain` and `track.strain_sensitivity` the last sample's predicted
        strains `(n,)` and their derivatives `(p, n)`, against which the next fix
        is compared.
    - `window`, `anchor`: the moving horizon of the re-linearisation (the last
        samples, and the model and the parameters' information at its start:
        `jaxcable.cdpr.horizon`); `solution`: its last solution's logs `(n, p)`,
        where the next one starts; `reduced_chi2`: its fixes' reduced chi-square
        (about 1 when the model and `fix_noise` are right; above, an effect the
        model lacks, and intervals too narrow by about its square root).
    - `nominal`: the nominal model's states (the fallback's).
    - `position`: the last fix, or the start, m, `(3,)`.
    - `time`: the last sample's time, s. `fix_time`: the last valid fix's, s.
    - `forces`: the last sample's forces, N, `(n,)`; `force_time`: when each last
        changed, s.
    - `nis`: the last fix's normalised innovation squared (chi-square with 3
        degrees of freedom when the filter is consistent).
    - `rejected`: fixes in a row beyond the gate.
    - `result`: a [`jaxcable.RESULTS`][] (`successful`, `signal_lost` or
        `estimator_diverged`).
    - `origin`: the start's time, s (a load cell's estimated drift is zero there).
    - `additive` (static): which columns are not logs (a load cell's drift, N/h).
    """

    log_parameters: Float[Array, "n p"]
    covariance: Float[Array, "np np"]
    track: Track
    window: Window
    anchor: Anchor
    solution: Float[Array, "n p"]
    reduced_chi2: Float[Array, ""]
    nominal: ControllerState
    position: Float[Array, " 3"]
    time: Float[Array, ""]
    fix_time: Float[Array, ""]
    forces: Float[Array, " n"]
    force_time: Float[Array, " n"]
    nis: Float[Array, ""]
    rejected: Float[Array, ""]
    result: RESULTS
    origin: Float[Array, ""]
    additive: tuple[bool, ...] = eqx.field(static=True, default=())

    @property
    def std(self) -> Float[Array, "n p"]:
        """Standard deviations of the log-parameters (relative uncertainty)."""
        n, p = self.log_parameters.shape
        return jnp.sqrt(jnp.diagonal(self.covariance)).reshape(n, p)

    @property
    def parameters(self) -> Float[Array, "n p"]:
        """The estimates (the medians of their log-normal marginals; a load cell's
        drift as it is, N/h), SI."""
        return self._natural(self.log_parameters)

    def _natural(self, x):
        additive = jnp.asarray(self.additive or (False,) * x.shape[-1])
        return jnp.where(additive, x, jnp.exp(x))

    def interval(self, z: float = _Z95) -> tuple[Float[Array, "n p"], ...]:
        """Each estimate's interval exp(log estimate -/+ z std) (default 95 %).

        **Arguments:**

        - `z`: the normal quantile (1.96: 95 %).

        **Returns:**

        `(low, high)`, SI, each `(n, p)`.
        """
        s = z * self.std
        return (
            self._natural(self.log_parameters - s),
            self._natural(self.log_parameters + s),
        )

    @property
    def diverged(self) -> Array:
        """Whether the estimator has diverged (boolean)."""
        return self.result == RESULTS.estimator_diverged


def interval_covers(
    state: EstimatorState, truth: Float[ArrayLike, "n p"], z: float = _Z95
) -> Array:
    """Whether each estimate's interval (default 95 %) holds the true value.

    **Arguments:**

    - `state`: an [`jaxcable.cdpr.EstimatorState`][].
    - `truth`: the true parameters, SI, `(n, p)`.
    - `z`: the normal quantile.

    **Returns:**

    A boolean array `(n, p)`.
    """
    low, high = state.interval(z)
    truth = jnp.asarray(truth)
    return (truth >= low) & (truth <= high)
