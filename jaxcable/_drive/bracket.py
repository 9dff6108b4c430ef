"""The bracket that `newton.root_scalar` keeps of a sample's root, from the points
its solve has evaluated: what its bisection fallback narrows and what its verdict
of no root rests on."""

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float


class Bracket(eqx.Module):
    """A bracket of the wanted root, from the points a solve has evaluated.

    With s = `slope_sign`, the wanted root has fn * s < 0 to its left (not yet
    reached) and fn * s > 0 to its right (past it). `left` is the largest y seen on
    the left side, `right` the smallest y seen past the root and above `left`; while
    `left < right` the interval holds a crossing of fn in the wanted direction
    (fn continuous). A crossing in the other direction (a root where fn has the other
    slope, e.g. where creep overtakes the crosshead after the force was passed) is
    never bracketed. Without `slope_sign`, any sign change is a bracket.
    """

    left: Float[Array, ""]
    right: Float[Array, ""]
    has_left: Bool[Array, ""]
    has_right: Bool[Array, ""]
    slope_sign: Float[Array, ""] | None

    @staticmethod
    def empty(y, slope_sign):
        no = jnp.zeros_like(y, dtype=bool)
        return Bracket(y, y, no, no, slope_sign)

    def see(self, y, r):
        if self.slope_sign is None:
            is_left, is_right = r < 0, r > 0
            left = jnp.where(is_left, y, self.left)
            right = jnp.where(is_right, y, self.right)
            return Bracket(
                left, right, self.has_left | is_left, self.has_right | is_right, None
            )
        q = r * self.slope_sign
        is_left = (q < 0) & (~self.has_left | (y > self.left))
        left = jnp.where(is_left, y, self.left)
        has_left = self.has_left | is_left
        # A `right` at or below the new `left` no longer brackets anything.
        has_right = self.has_right & (~has_left | (self.right > left))
        is_right = (q > 0) & (~has_left | (y > left)) & (~has_right | (y < self.right))
        right = jnp.where(is_right, y, self.right)
        return Bracket(left, right, has_left, has_right | is_right, self.slope_sign)

    @property
    def found(self):
        return self.has_left & self.has_right

    def midpoint(self):
        return 0.5 * (self.left + self.right)
