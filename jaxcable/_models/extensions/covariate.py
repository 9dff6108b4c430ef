r"""Effects of a recorded covariate c: an extra column of a test (the lab's humidity,
a second thermocouple, a moisture content), set per sample as `Cable.covariate` by
`jaxcable.fit(..., covariate=NAME)` and the simulations. Each is an extension of any
base model, in the unit of the covariate's column ("[c]" below):

- [`CovariateStrain`][]: a strain proportional to the covariate's change since the
    test's first sample (swelling with moisture, thermal expansion read at a second
    thermocouple), eps_c = alpha (c - c_0).
- [`MechanoSorptive`][]: creep driven by the covariate's changes under stress (the
    mechano-sorptive form of wood and paper: each change of humidity lets the
    braid's strands re-seat, whatever its sign), d(eps_m)/dt = m sigma |dc/dt|.
- [`CovariateShift`][]: the base on reduced time shifted by the covariate (a
    plasticiser, e.g. water in a braid's finish), log10 a = -k (c - c_ref): k > 0
    makes every time-dependent process of the base faster as c rises.

At the null value of its parameter (alpha = 0, m = 0, k = 0) each reproduces its
base exactly; without a covariate (`Cable.covariate` None, read as 0) the first two
add nothing. They are not candidates of the diagnosis's catalogue
([`jaxcable.EXTENSIONS`][], run on data without a covariate);
[`jaxcable.COVARIATE_EXTENSIONS`][] lists them.
"""

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int, PyTree

from ..._cable import Cable
from .. import base as _base
from ..base import AbstractExtension, StrainParts
from ..fields import setting, signed_effect
from .temperature import AbstractTimeShift


class CovariateStrainState(eqx.Module):
    """Scan carry of [`jaxcable.CovariateStrain`][]: the base's state, whether a
    sample was taken (`started`) and the covariate at the first sample (`first`)."""

    base: PyTree
    started: Bool[Array, ""]
    first: Float[Array, ""]


class CovariateStrain(AbstractExtension[CovariateStrainState]):
    r"""A strain proportional to the covariate's change since the first sample,

        eps_c = alpha (c - c_0),   eps = eps_base + eps_c (instantaneous part),

    with c = `cable.covariate` at each sample (the unit of its column) and c_0 its
    value at the test's first sample, so that the measured elongation, zeroed at the
    start, starts at the base's. (c_0 is the data's own, per test: nothing of the
    base is measured against it, so unlike a shift's reference it needs no choice.) Swelling with moisture (alpha > 0) or thermal
    expansion read at a second thermocouple (alpha < 0 for UHMWPE along the fibre).
    `alpha = 0` is the base exactly.

    **Continuity.** eps_c does not depend on the force; it moves by alpha times a
    change of the covariate record.

    **Fields:**

    - `base`: the wrapped model.
    - `alpha`: the strain per unit of the covariate, 1/[c] (finite, either sign).

    `wrap(base)` starts a fit at `alpha = 1e-5` per unit (a linear transform scaled
    by that start).
    """

    CLI_NAME = "covariate-strain"
    LIBRARY_TERM = "c_rate"

    alpha: Float[Array, ""] = signed_effect("1/[c]", start=1e-5)

    def init(self, cable: Cable) -> CovariateStrainState:
        zero = _base.state_zero(cable, self.alpha)
        return CovariateStrainState(self.base.init(cable), jnp.array(False), zero)

    def advance(
        self,
        state: CovariateStrainState,
        cable: Cable,
        dt: Float[Array, ""],
        force: Float[Array, ""],
        direction: Int[Array, ""],
    ) -> tuple[CovariateStrainState, StrainParts]:
        base_state, parts = self.base.advance(state.base, cable, dt, force, direction)
        c = _base.covariate_of(cable, state.first)
        first = jnp.where(state.started, state.first, c)
        strain = self.alpha * (c - first)
        new = CovariateStrainState(base_state, jnp.array(True), first)
        return new, _base.add_parts(parts, instantaneous=strain)


class MechanoSorptiveState(eqx.Module):
    """Scan carry of [`jaxcable.MechanoSorptive`][]: the base's state, whether a
    sample was taken (`started`), the previous sample's force (N) and covariate,
    and the mechano-sorptive strain so far."""

    base: PyTree
    started: Bool[Array, ""]
    force: Float[Array, ""]
    covariate: Float[Array, ""]
    strain: Float[Array, ""]


class MechanoSorptive(AbstractExtension[MechanoSorptiveState]):
    r"""Creep driven by the covariate's changes under stress (mechano-sorptive
    creep),

        d(eps_m)/dt = m sigma |dc/dt|,   sigma = F / A,   eps = eps_base + eps_m,

    integrated over each step as m (sigma_0 + sigma_1) / 2 |c_1 - c_0| (the
    stress's mean over the step, the covariate's change). The strain is
    irreversible: it stays when the load is removed. `m = 0` is the base exactly.
    The form of [`jaxcable.DiscoveredTerm`][]'s `sigma_c_abs_rate` term, as a
    one-parameter extension.

    **Continuity.** The increment is Lipschitz in the force (m |dc| / (2 A) per
    newton of either sample); it accumulates the total variation of the covariate
    record, so noise on the covariate adds m sigma times its total variation (a
    logger that filters and rounds its reading, as a humidity logger does, adds
    none between changes).

    **Fields:**

    - `base`: the wrapped model.
    - `m`: the coefficient, 1/(Pa [c]) (finite, either sign).

    `wrap(base)` starts a fit at `m = 1e-12` 1/(Pa [c]) (about 1e-3 of strain per
    10 units of change at 100 N on a 3 mm cable).
    """

    CLI_NAME = "mechano-sorptive"
    LIBRARY_TERM = "sigma_c_abs_rate"

    m: Float[Array, ""] = signed_effect("1/(Pa [c])", start=1e-12)

    def init(self, cable: Cable) -> MechanoSorptiveState:
        zero = _base.state_zero(cable, self.m)
        return MechanoSorptiveState(
            self.base.init(cable), jnp.array(False), zero, zero, zero
        )

    def advance(
        self,
        state: MechanoSorptiveState,
        cable: Cable,
        dt: Float[Array, ""],
        force: Float[Array, ""],
        direction: Int[Array, ""],
    ) -> tuple[MechanoSorptiveState, StrainParts]:
        base_state, parts = self.base.advance(state.base, cable, dt, force, direction)
        c = _base.covariate_of(cable, state.covariate)
        # The first sample has no previous covariate: no change then.
        previous = jnp.where(state.started, state.covariate, c)
        sigma = 0.5 * (state.force + force) / cable.area
        strain = state.strain + self.m * sigma * jnp.abs(c - previous)
        new = MechanoSorptiveState(base_state, jnp.array(True), force, c, strain)
        return new, _base.add_parts(parts, creep=strain)


class CovariateShift(AbstractTimeShift):
    r"""The base on reduced time shifted by the covariate,

        dt_eff = dt / a(c),   log10 a = -k (c - c_ref),

    as [`jaxcable.TemperatureShift`][] does with the temperature: every
    time-dependent process of the base runs on reduced time, and the base gets a
    cable whose crosshead speed is v a (the same strain per reduced second);
    instantaneous strains are unchanged. k > 0: the cable creeps and recovers faster
    as c rises (a plasticiser such as water in a braid's finish). `k = 0` is the
    base exactly. The state is the base's.

    **Continuity.** a depends on the covariate, not on the force: as continuous in
    the force history as the base on reduced time.

    **Fields:**

    - `base`: the wrapped model.
    - `k`: the shift per unit of the covariate, decades per [c] (finite, either
        sign).
    - `c_ref`: the covariate at which a = 1, [c]: the base's parameters are the
        material's at c_ref. [`jaxcable.diagnose`][] takes it at the median of the
        column's records ([`jaxcable.with_data_reference`][]); 0 by default.

    `wrap(base)` starts a fit at `k = 1e-3` per unit, `c_ref = 0`.
    """

    CLI_NAME = "covariate-shift"

    k: Float[Array, ""] = signed_effect("1/[c]", start=1e-3)
    c_ref: Float[Array, ""] = setting(0.0, unit="[c]", domain="any")

    def log_shift(self, cable: Cable) -> Float[Array, ""]:
        """log10 a at the covariate of `cable`."""
        return -self.k * (_base.covariate_of(cable, self.k) - self.c_ref)

    def log_shift_at(self, cable: Cable) -> Float[Array, ""]:
        return self.log_shift(cable)

    def shift_ok(self, cable: Cable) -> Bool[Array, ""]:
        return jnp.all(jnp.isfinite(self.log_shift(cable)))
