"""The robot: Piao et al.'s CNU high-payload suspended cable robot as their Section 2.1
describes it (a 4 m x 4 m x 4 m frame, eight pulleys near the corners of the top
frame, 6 mm Dyneema cables, LIROS D-Pro, payloads up to 65 kg), with a point-mass
end-effector: its geometry ([`jaxcable.cdpr.Robot`][]), the tensions that hold the
end-effector ([`jaxcable.cdpr.tension_distribution`][]) and the forward kinematics of
stretched cables ([`jaxcable.cdpr.forward_kinematics`][]). Pure JAX, differentiable."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._arrays import field_array
from .._cable import DEFAULT_BREAKING_STRAIN, Cable
from .._drive import GRAVITY
from .._models import IntegratedModel


# Piao Section 2.1: LIROS D-Pro 01505-0600, 6 mm. Its breaking load is not printed; it
# is taken as Park's rated load of the 3 mm SK78 cable (2000 N, Park Section 2.1)
# scaled with the cross-section (x4): the same rated stress. The manufacturer's
# breaking load of such a rope is higher, so this is conservative for the input checks.
DIAMETER = 6e-3
BREAKING_LOAD = 8000.0
# The strain rate that sets Park's long-term retardation time t_r2 (Eq. 8): that of
# Park's fastest test, 50 mm/min on 300 mm (t_r2 ~ 8 min with the default set).
# A cable's `speed` is its length times this rate.
STRAIN_RATE = (50e-3 / 60) / 0.3
# The nominal model of these cables: the controller's model, and the median of the
# "real" cables' parameters (`real_cables`).
NOMINAL = IntegratedModel()


def _default_pulleys() -> np.ndarray:
    # Two pulleys per top corner of the 4 m cube (frame centred on x = y = 0, floor
    # at z = 0), 0.3 m apart along the two edges that meet there.
    rows = []
    for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
        rows.append((sx * 1.95, sy * 1.65, 4.0))
        rows.append((sx * 1.65, sy * 1.95, 4.0))
    return np.array(rows)


class Robot(eqx.Module):
    """A suspended cable robot with a point-mass end-effector.

    **Fields (SI):**

    - `pulleys`: exit points of the cables at the pulleys, m, shape `(n, 3)` (default:
        8 pulleys near the corners of the top of a 4 m cube, z up, floor at 0).
    - `routing`: unstretched cable length from each winch drum to its pulley, m
        (default 4 m: winches at the foot of the columns). It is loaded like the rest,
        so a cable's free length is routing + the pulley-to-end-effector distance
        (6.9-9.0 m over `pick_and_place`; Piao tested 5.4-8.4 m).
    - `platform_mass`: mass of the end-effector without payload, kg.
    - `min_tension`: the least tension of every cable, N (taut cables).
    - `diameter`, `breaking_load`: of every cable, m and N (6 mm Dyneema).
    - `breaking_strain`: of every cable, dimensionless (elongation / L0 at break):
        Piao's rope's is not printed, so that of the 3 mm Dyneema cable,
        `jaxcable.DEFAULT_BREAKING_STRAIN` (a strain, unlike a load, does not
        scale with the cross-section).
    - `strain_rate`: 1/s, sets each cable's `speed` = length * strain_rate.
    """

    pulleys: Float[Array, "n 3"] = eqx.field(
        converter=field_array, default_factory=_default_pulleys
    )
    routing: Float[Array, ""] = eqx.field(converter=field_array, default=4.0)
    platform_mass: Float[Array, ""] = eqx.field(converter=field_array, default=20.0)
    min_tension: Float[Array, ""] = eqx.field(converter=field_array, default=10.0)
    diameter: Float[Array, ""] = eqx.field(converter=field_array, default=DIAMETER)
    breaking_load: Float[Array, ""] = eqx.field(
        converter=field_array, default=BREAKING_LOAD
    )
    breaking_strain: Float[Array, ""] = eqx.field(
        converter=field_array, default=DEFAULT_BREAKING_STRAIN
    )
    strain_rate: Float[Array, ""] = eqx.field(
        converter=field_array, default=STRAIN_RATE
    )

    def __check_init__(self):
        shape = jnp.shape(self.pulleys)
        if len(shape) != 2 or shape[1] != 3 or shape[0] < 4:
            raise ValueError(
                f"Robot `pulleys` must have shape (n, 3) with n >= 4, got {shape}."
            )

    @property
    def num_cables(self) -> int:
        return int(jnp.shape(self.pulleys)[0])

    def geometric_lengths(self, position: Float[Array, " 3"]) -> Float[Array, " n"]:
        """Inverse kinematics: pulley-to-end-effector distances, m."""
        return jnp.linalg.norm(self.pulleys - position, axis=-1)

    def free_lengths(self, position: Float[Array, " 3"]) -> Float[Array, " n"]:
        """Loaded cable lengths, winch to end-effector (routing + geometric), m."""
        return self.routing + self.geometric_lengths(position)

    def directions(self, position: Float[Array, " 3"]) -> Float[Array, "3 n"]:
        """The structure matrix: unit vectors from the end-effector to the pulleys."""
        d = self.pulleys - position
        return (d / jnp.linalg.norm(d, axis=-1, keepdims=True)).T

    def cables(self, lengths: Float[Array, " n"]) -> Cable:
        """The [`jaxcable.Cable`][] set of these free lengths (m)."""
        return Cable(
            length=lengths,
            diameter=self.diameter,
            speed=lengths * self.strain_rate,
            breaking_load=self.breaking_load,
            breaking_strain=self.breaking_strain,
        )


def _solve3(m: Float[Array, "3 3"], b: Float[Array, " 3"]) -> Float[Array, " 3"]:
    """The solution of m x = b for a 3 x 3 matrix, by its adjugate (Cramer's rule).

    The matrices solved here (A A^T with a ridge, J^T J of eight well-spread cables)
    are symmetric and well conditioned, where the closed form is as accurate as an LU
    factorisation, and it is plain arithmetic instead of a LAPACK call with its
    pivoting and differentiation rules in every step of the robot's scan (the cost
    of the closed loop's loss and gradient: benchmarks/README.md)."""
    # The columns of the adjugate's transpose: cross products of m's rows.
    r0, r1, r2 = m[0], m[1], m[2]
    c0, c1, c2 = jnp.cross(r1, r2), jnp.cross(r2, r0), jnp.cross(r0, r1)
    det = jnp.dot(r0, c0)
    return (c0 * b[0] + c1 * b[1] + c2 * b[2]) / det


def tension_distribution(
    robot: Robot,
    position: Float[ArrayLike, " 3"],
    mass: Float[ArrayLike, ""],
    *,
    iterations: int = 12,
) -> Float[Array, " n"]:
    r"""Cable tensions that hold a point mass at `position`: the minimum-norm
    distribution above the minimum tension.

    Solves min ||t||^2 / 2 subject to A t = m g e_z and t >= t_min (A: the
    structure matrix `robot.directions`, quasi-static). Its KKT conditions give
    t = max(t_min, A^T lambda) with A max(t_min, A^T lambda) = m g e_z, three
    piecewise-linear equations in lambda, solved by a semismooth Newton method
    (`iterations` steps from the unconstrained minimum-norm solution; exact once the
    set of cables at t_min stops changing, usually after 1-3 steps). Differentiable
    (`jax.grad` through the unrolled steps). For a suspended robot the problem is
    feasible only while t_min * sum(A_z) < m g: keep `robot.min_tension` well below
    the weight per cable.

    **Arguments:**

    - `robot`: the [`jaxcable.cdpr.Robot`][].
    - `position`: end-effector position, m.
    - `mass`: total suspended mass (platform + payload), kg.
    - `iterations`: Newton steps (static).

    **Returns:**

    The tensions, N, shape `(n,)`; NaN where no distribution balances the load
    (infeasible pose), so that [`jaxcable.controller_step`][] raises on it.
    """
    A = robot.directions(jnp.asarray(position))
    dtype = A.dtype
    w = jnp.zeros(3, dtype).at[2].set(jnp.asarray(mass, dtype) * GRAVITY)
    t_min = robot.min_tension
    AAt = A @ A.T
    lam = _solve3(AAt, w)
    # A small ridge keeps the Newton matrix invertible while fewer than three cables
    # are above t_min (that step then moves lambda towards the feasible set).
    ridge = 1e-9 * jnp.trace(AAt) * jnp.eye(3, dtype=dtype)

    def newton(_, lam):
        s = A.T @ lam
        active = (s > t_min).astype(dtype)
        residual = A @ jnp.maximum(t_min, s) - w
        J = (A * active) @ A.T + ridge
        return lam - _solve3(J, residual)

    # A fixed trip count: a scan, so reverse-mode differentiable (and compact to
    # compile inside the robot's scan).
    lam = jax.lax.fori_loop(0, iterations, newton, lam)
    t = jnp.maximum(t_min, A.T @ lam)
    # Infeasible (the pose is outside the workspace for this mass and t_min) or not
    # converged: NaN, which the creep models flag as a non-physical force.
    balanced = jnp.linalg.norm(A @ t - w) <= 1e-6 * jnp.linalg.norm(w)
    return jnp.where(balanced, t, jnp.nan)


def forward_kinematics(
    robot: Robot,
    lengths: Float[ArrayLike, " n"],
    guess: Float[ArrayLike, " 3"],
    *,
    iterations: int = 6,
) -> Float[Array, " 3"]:
    """Least-squares forward kinematics: the point whose distances to the pulleys best
    fit the stretched pulley-to-end-effector `lengths` (m).

    min_x sum_i (|p_i - x| - l_i)^2 by Gauss-Newton, `iterations` steps from `guess`
    (quadratic convergence from the previous sample's position; unrolled, so
    `jax.grad` applies). With 8 cables for 3 coordinates the lengths are redundant:
    where they disagree (cables stretched unequally) this is the unweighted
    least-squares compromise, not a stiffness-weighted equilibrium.
    """
    lengths = jnp.asarray(lengths)
    x = jnp.asarray(guess, lengths.dtype)

    def gauss_newton(_, x):
        d = robot.pulleys - x
        dist = jnp.linalg.norm(d, axis=-1)
        r = dist - lengths
        J = -d / dist[:, None]
        return x - _solve3(J.T @ J, J.T @ r)

    return jax.lax.fori_loop(0, iterations, gauss_newton, x)
