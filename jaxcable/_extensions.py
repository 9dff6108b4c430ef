"""Model extensions: physical effects a base model lacks, each a wrapper around any
[`jaxcable.AbstractCableModel`][] (wrap, don't subclass), composable by nesting.

Each has a stable id (`EXTENSION_ID`) used by the diagnosis workflow."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int, PyTree

from ._abstract import AbstractCableModel, StrainParts
from ._cable import Cable
from ._results import RESULTS


class TerminationCompliance(AbstractCableModel[PyTree]):
    r"""A length-independent series compliance: splices, knots, grips and pulleys.

    A termination adds the same extra millimetres at a given force whatever the
    cable's length, so its strain contribution scales as 1 / L0 — which is how it is
    told apart from the cable's own (strain-proportional) compliance when tests of
    several lengths are fitted together:

    delta(F) = `compliance` * F  (m),   eps_extra = delta(F) / L0,

    added to the instantaneous strain of the wrapped model.

    **Fields:**

    - `base`: the wrapped model.
    - `compliance`: series compliance of the terminations, m/N (>= 0).
    """

    EXTENSION_ID = "termination_compliance"

    base: AbstractCableModel
    compliance: Float[Array, ""] = eqx.field(converter=jnp.asarray, default=0.0)

    def __check_init__(self):
        if not isinstance(self.compliance, jax.core.Tracer):
            c = np.asarray(self.compliance)
            if not np.all(np.isfinite(c)) or np.any(c < 0):
                raise ValueError(
                    "TerminationCompliance `compliance` must be finite and >= 0 "
                    f"(m/N), got {c}."
                )

    def init(self, cable: Cable) -> PyTree:
        return self.base.init(cable)

    def check(self, cable: Cable) -> RESULTS:
        ok = jnp.isfinite(self.compliance) & (self.compliance >= 0)
        return RESULTS.where(
            ok, self.base.check(cable), RESULTS.parameter_out_of_domain
        )

    def advance(
        self,
        state: PyTree,
        cable: Cable,
        dt: Float[Array, ""],
        force: Float[Array, ""],
        direction: Int[Array, ""],
    ) -> tuple[PyTree, StrainParts]:
        state, parts = self.base.advance(state, cable, dt, force, direction)
        extra = self.compliance * force / cable.length
        parts = eqx.tree_at(
            lambda p: p.instantaneous, parts, parts.instantaneous + extra
        )
        return state, parts
