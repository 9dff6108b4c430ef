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

from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int, PyTree

from ... import _checks
from ..._arrays import field_array
from ..._cable import Cable
from ..._results import RESULTS
from ..base import (
    AbstractCableModel,
    AbstractExtension,
    StrainParts,
    add_parts,
    covariate_of,
    state_zero,
)
from .temperature import advance_shifted, check_shifted


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
    start, starts at the base's. Swelling with moisture (alpha > 0) or thermal
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

    EXTENSION_ID: ClassVar[str] = "covariate_strain"
    EFFECT_FIELDS: ClassVar[tuple[str, ...]] = ("alpha",)
    SIZE_FIELD: ClassVar[str] = "alpha"
    SIZE_UNIT: ClassVar[str] = "1/[c]"
    SIZE_NULL: ClassVar[float] = 0.0
    FIT_INFO: ClassVar[dict[str, tuple]] = {"alpha": ("linear", "1/[c]")}

    base: AbstractCableModel
    alpha: Float[Array, ""] = eqx.field(converter=field_array, default=0.0)

    def __check_init__(self):
        _checks.check_parameters(
            "CovariateStrain",
            self,
            ("alpha",),
            positive=False,
            reason="(1/[c])",
            qualified=False,
        )

    @classmethod
    def wrap(cls, base: AbstractCableModel) -> "CovariateStrain":
        """`base` with a fit's start value `alpha = 1e-5` per unit."""
        return cls(base, alpha=1e-5)

    def init(self, cable: Cable) -> CovariateStrainState:
        zero = state_zero(cable, self.alpha)
        return CovariateStrainState(self.base.init(cable), jnp.array(False), zero)

    def check(self, cable: Cable) -> RESULTS:
        ok = _checks.parameters_ok(self, ("alpha",), positive=False)
        return _checks.domain_result(ok, self.base.check(cable))

    def advance(
        self,
        state: CovariateStrainState,
        cable: Cable,
        dt: Float[Array, ""],
        force: Float[Array, ""],
        direction: Int[Array, ""],
    ) -> tuple[CovariateStrainState, StrainParts]:
        base_state, parts = self.base.advance(state.base, cable, dt, force, direction)
        c = covariate_of(cable, state.first)
        first = jnp.where(state.started, state.first, c)
        strain = self.alpha * (c - first)
        new = CovariateStrainState(base_state, jnp.array(True), first)
        return new, add_parts(parts, instantaneous=strain)


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

    EXTENSION_ID: ClassVar[str] = "mechano_sorptive"
    EFFECT_FIELDS: ClassVar[tuple[str, ...]] = ("m",)
    SIZE_FIELD: ClassVar[str] = "m"
    SIZE_UNIT: ClassVar[str] = "1/(Pa [c])"
    SIZE_NULL: ClassVar[float] = 0.0
    FIT_INFO: ClassVar[dict[str, tuple]] = {"m": ("linear", "1/(Pa [c])")}

    base: AbstractCableModel
    m: Float[Array, ""] = eqx.field(converter=field_array, default=0.0)

    def __check_init__(self):
        _checks.check_parameters(
            "MechanoSorptive",
            self,
            ("m",),
            positive=False,
            reason="(1/(Pa [c]))",
            qualified=False,
        )

    @classmethod
    def wrap(cls, base: AbstractCableModel) -> "MechanoSorptive":
        """`base` with a fit's start value `m = 1e-12` 1/(Pa [c])."""
        return cls(base, m=1e-12)

    def init(self, cable: Cable) -> MechanoSorptiveState:
        zero = state_zero(cable, self.m)
        return MechanoSorptiveState(
            self.base.init(cable), jnp.array(False), zero, zero, zero
        )

    def check(self, cable: Cable) -> RESULTS:
        ok = _checks.parameters_ok(self, ("m",), positive=False)
        return _checks.domain_result(ok, self.base.check(cable))

    def advance(
        self,
        state: MechanoSorptiveState,
        cable: Cable,
        dt: Float[Array, ""],
        force: Float[Array, ""],
        direction: Int[Array, ""],
    ) -> tuple[MechanoSorptiveState, StrainParts]:
        base_state, parts = self.base.advance(state.base, cable, dt, force, direction)
        c = covariate_of(cable, state.covariate)
        # The first sample has no previous covariate: no change then.
        previous = jnp.where(state.started, state.covariate, c)
        sigma = 0.5 * (state.force + force) / cable.area
        strain = state.strain + self.m * sigma * jnp.abs(c - previous)
        new = MechanoSorptiveState(base_state, jnp.array(True), force, c, strain)
        return new, add_parts(parts, creep=strain)


class CovariateShift(AbstractExtension[PyTree]):
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
    - `c_ref`: the covariate at which a = 1, [c] (e.g. the mean of the records).

    `wrap(base)` starts a fit at `k = 1e-3` per unit, `c_ref = 0`.
    """

    EXTENSION_ID: ClassVar[str] = "covariate_shift"
    EFFECT_FIELDS: ClassVar[tuple[str, ...]] = ("k",)
    SIZE_FIELD: ClassVar[str] = "k"
    SIZE_UNIT: ClassVar[str] = "1/[c]"
    SIZE_NULL: ClassVar[float] = 0.0
    FIT_INFO: ClassVar[dict[str, tuple]] = {"k": ("linear", "1/[c]")}

    base: AbstractCableModel
    k: Float[Array, ""] = eqx.field(converter=field_array, default=0.0)
    c_ref: Float[Array, ""] = eqx.field(converter=field_array, default=0.0)

    def __check_init__(self):
        _checks.check_parameters(
            "CovariateShift",
            self,
            ("k", "c_ref"),
            positive=False,
            reason="([c])",
            qualified=False,
        )

    @classmethod
    def wrap(cls, base: AbstractCableModel) -> "CovariateShift":
        """`base` with a fit's start value `k = 1e-3` per unit."""
        return cls(base, k=1e-3)

    def log_shift(self, cable: Cable) -> Float[Array, ""]:
        """log10 a at the covariate of `cable`."""
        return -self.k * (covariate_of(cable, self.k) - self.c_ref)

    def init(self, cable: Cable) -> PyTree:
        return self.base.init(cable)

    def check(self, cable: Cable) -> RESULTS:
        log_a = self.log_shift(cable)
        ok = _checks.all_ok(
            _checks.parameters_ok(self, ("k", "c_ref"), positive=False),
            jnp.all(jnp.isfinite(log_a)),
        )
        return check_shifted(self.base, cable, ok, log_a)

    def advance(
        self,
        state: PyTree,
        cable: Cable,
        dt: Float[Array, ""],
        force: Float[Array, ""],
        direction: Int[Array, ""],
    ) -> tuple[PyTree, StrainParts]:
        log_a = self.log_shift(cable)
        return advance_shifted(self.base, state, cable, dt, force, direction, log_a)
