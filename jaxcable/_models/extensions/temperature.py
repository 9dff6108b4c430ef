r"""Thermally activated creep by time-temperature superposition: the base model on
reduced time, with the Arrhenius ([`TemperatureShift`][]) or the Williams-Landel-Ferry
([`TemperatureShiftWLF`][]) shift factor."""

import abc
import math
from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float, Int, PyTree

from ... import _checks
from ..._arrays import field_array
from ..._cable import Cable
from ..._results import RESULTS
from ..base import AbstractCableModel, AbstractExtension, StrainParts


# Gas constant, J/(mol K).
GAS_CONSTANT = 8.314462618
_LN10 = math.log(10.0)


def log_shift_arrhenius(
    temperature, activation_energy, reference_temperature
) -> Float[Array, "*shape"]:
    r"""log10 of the Arrhenius time-temperature shift factor,

        log10 a_T = E_a / (R ln 10) (1 / T - 1 / T_ref),

    with T, T_ref in K and E_a in J/mol (R = 8.314 J/(mol K)). a_T < 1 above T_ref:
    processes run faster.
    """
    return (
        activation_energy
        / (GAS_CONSTANT * _LN10)
        * (1.0 / temperature - 1.0 / reference_temperature)
    )


def log_shift_wlf(temperature, c1, c2, reference_temperature) -> Float[Array, "*shape"]:
    r"""log10 of the Williams-Landel-Ferry shift factor,

        log10 a_T = -C1 (T - T_ref) / (C2 + T - T_ref),

    with T, T_ref and C2 in K (or all in °C: only differences enter), C1 dimensionless.
    Valid while C2 + T - T_ref > 0.
    """
    d = temperature - reference_temperature
    return -c1 * d / (c2 + d)


def reduced_time(
    cable: Cable, dt, log_a: Float[Array, ""]
) -> tuple[Float[Array, ""], Cable]:
    """The reduced time step dt / a_T and the cable as the base sees it on reduced
    time (crosshead speed per reduced second v a_T)."""
    a_t = 10.0**log_a
    cable_reduced = eqx.tree_at(lambda c: c.speed, cable, cable.speed * a_t)
    return dt / a_t, cable_reduced


def check_shifted(
    base: AbstractCableModel, cable: Cable, ok: Bool[Array, ""], log_a
) -> RESULTS:
    """The check of a time-shift extension (temperature or covariate): `ok`, whether
    the shift is in its domain, and the base's check on reduced time, at a = 1
    where the shift is out of its domain (the result is then
    `parameter_out_of_domain` anyway)."""
    _, reduced = reduced_time(cable, 0.0, jnp.where(ok, log_a, 0.0))
    return _checks.domain_result(ok, base.check(reduced))


def advance_shifted(
    base: AbstractCableModel,
    state: PyTree,
    cable: Cable,
    dt: Float[Array, ""],
    force: Float[Array, ""],
    direction: Int[Array, ""],
    log_a: Float[Array, ""],
) -> tuple[PyTree, StrainParts]:
    """The step of a time-shift extension: the base's step on reduced time
    (`reduced_time`), with shift log10 a = `log_a`."""
    dt_eff, reduced = reduced_time(cable, dt, log_a)
    return base.advance(state, reduced, dt_eff, force, direction)


class AbstractTemperatureShift(AbstractExtension[PyTree]):
    """Time-temperature superposition: every time-dependent process of the base runs
    on reduced time dt_eff = dt / a_T(T), T = `cable.temperature` (K) read at each
    step, and the base gets a cable whose crosshead speed is v a_T (the same strain
    per reduced second). The state is the base's.

    A concrete shift declares `base`, its own parameters and `T_ref` (the reference
    temperature, K, at which a_T = 1), and implements `log_shift` and `shift_ok`.
    """

    T_ref: eqx.AbstractVar[Float[Array, ""]]

    def __check_init__(self):
        _checks.check_parameters(
            type(self).__name__, self, ("T_ref",), reason="(K)", qualified=False
        )

    @abc.abstractmethod
    def log_shift(self, temperature) -> Float[Array, "*shape"]:
        """log10 a_T at `temperature` (K)."""

    @abc.abstractmethod
    def shift_ok(self, cable: Cable) -> Bool[Array, ""]:
        """Traced: whether the shift's own parameters are in their domain at the
        temperature of `cable` (`T_ref` is checked by `check`)."""

    def init(self, cable: Cable) -> PyTree:
        return self.base.init(cable)

    def check(self, cable: Cable) -> RESULTS:
        ok = _checks.all_ok(
            self.shift_ok(cable), _checks.parameters_ok(self, ("T_ref",))
        )
        return check_shifted(self.base, cable, ok, self.log_shift(cable.temperature))

    def advance(
        self,
        state: PyTree,
        cable: Cable,
        dt: Float[Array, ""],
        force: Float[Array, ""],
        direction: Int[Array, ""],
    ) -> tuple[PyTree, StrainParts]:
        log_a = self.log_shift(cable.temperature)
        return advance_shifted(self.base, state, cable, dt, force, direction, log_a)


class TemperatureShift(AbstractTemperatureShift):
    r"""Thermally activated creep by time-temperature superposition (Arrhenius).

    Every time-dependent process of the base runs on reduced time,

        dt_eff = dt / a_T(T),   log10 a_T = E_a / (R ln 10) (1 / T - 1 / T_ref),

    with T = `cable.temperature` (K) read at each step (the fit sets it per sample
    from a test's temperature record), so a hotter cable creeps and recovers faster
    (a_T < 1) and a colder one slower. The base model gets dt_eff and a cable whose
    crosshead speed is v a_T (the same strain per reduced second: e.g. Park's
    rate-dependent long-term retardation time, Eq. 8, is evaluated on reduced time);
    instantaneous (time-independent) strains are unchanged. The state is the base's.
    `activation_energy = 0` (a_T = 1) is the base exactly. For the WLF law see
    [`jaxcable.TemperatureShiftWLF`][].

    **Continuity.** a_T depends on the temperature, not on the force: the extension
    is as continuous in the force history as the base on reduced time.

    **Fields:**

    - `base`: the wrapped model.
    - `activation_energy`: E_a, J/mol (>= 0).
    - `T_ref`: the reference temperature, K (> 0; default 293.15 K, the default
        `Cable.temperature`), at which a_T = 1.

    `wrap(base)` starts a fit at `activation_energy = 1e4 J/mol` (a_T ~ 0.87 at 10 K
    above T_ref; thermally activated creep of UHMWPE is ~ 1e5 J/mol).
    """

    EXTENSION_ID: ClassVar[str] = "temperature"
    EFFECT_FIELDS: ClassVar[tuple[str, ...]] = ("activation_energy",)
    SIZE_FIELD: ClassVar[str] = "activation_energy"
    SIZE_UNIT: ClassVar[str] = "J/mol"
    SIZE_NULL: ClassVar[float] = 0.0
    FIT_INFO: ClassVar[dict[str, tuple]] = {"activation_energy": ("log", "J/mol")}

    base: AbstractCableModel
    activation_energy: Float[Array, ""] = eqx.field(converter=field_array, default=0.0)
    T_ref: Float[Array, ""] = eqx.field(converter=field_array, default=293.15)

    def __check_init__(self):
        _checks.check_parameters(
            "TemperatureShift",
            self,
            ("activation_energy",),
            allow_zero=True,
            reason="(J/mol)",
            qualified=False,
        )

    @classmethod
    def wrap(cls, base: AbstractCableModel) -> "TemperatureShift":
        """`base` with a fit's start value `activation_energy = 1e4` J/mol."""
        return cls(base, activation_energy=1e4)

    def log_shift(self, temperature) -> Float[Array, "*shape"]:
        """log10 a_T at `temperature` (K)."""
        return log_shift_arrhenius(temperature, self.activation_energy, self.T_ref)

    def shift_ok(self, cable: Cable) -> Bool[Array, ""]:
        return _checks.all_ok(
            _checks.parameters_ok(self, ("activation_energy",), allow_zero=True),
            jnp.isfinite(self.log_shift(cable.temperature)),
        )


class TemperatureShiftWLF(AbstractTemperatureShift):
    r"""Time-temperature superposition with the Williams-Landel-Ferry shift factor,

        dt_eff = dt / a_T(T),   log10 a_T = -C1 (T - T_ref) / (C2 + T - T_ref),

    otherwise as [`jaxcable.TemperatureShift`][] (reduced time for every
    time-dependent process of the base, T = `cable.temperature`, K). WLF suits
    amorphous polymers above their glass transition; `c1 = 0` is the base exactly.
    Like it, continuous in the force history as the base is (a_T does not depend on
    the force).
    Not a diagnosis candidate of its own (`EXTENSIONS["temperature"]` is the
    Arrhenius form, one parameter); its id is `temperature_wlf`.

    **Fields:**

    - `base`: the wrapped model.
    - `c1`: C1, dimensionless (>= 0).
    - `c2`: C2, K (> 0; C2 + T - T_ref must stay > 0).
    - `T_ref`: the reference temperature, K (> 0; default 293.15 K).

    `wrap(base)` starts a fit at the "universal" C2 = 51.6 K and a small C1 = 1.
    """

    EXTENSION_ID: ClassVar[str] = "temperature_wlf"
    EFFECT_FIELDS: ClassVar[tuple[str, ...]] = ("c1", "c2")
    SIZE_FIELD: ClassVar[str] = "c1"
    SIZE_UNIT: ClassVar[str] = "-"
    SIZE_NULL: ClassVar[float] = 0.0
    FIT_INFO: ClassVar[dict[str, tuple]] = {"c1": ("log", "-"), "c2": ("log", "K")}

    base: AbstractCableModel
    c1: Float[Array, ""] = eqx.field(converter=field_array, default=0.0)
    c2: Float[Array, ""] = eqx.field(converter=field_array, default=51.6)
    T_ref: Float[Array, ""] = eqx.field(converter=field_array, default=293.15)

    def __check_init__(self):
        _checks.check_parameters(
            "TemperatureShiftWLF", self, ("c1",), allow_zero=True, qualified=False
        )
        _checks.check_parameters(
            "TemperatureShiftWLF", self, ("c2",), reason="(K)", qualified=False
        )

    @classmethod
    def wrap(cls, base: AbstractCableModel) -> "TemperatureShiftWLF":
        """`base` with a fit's start values `c1 = 1`, `c2 = 51.6` K."""
        return cls(base, c1=1.0, c2=51.6)

    def log_shift(self, temperature) -> Float[Array, "*shape"]:
        """log10 a_T at `temperature` (K)."""
        return log_shift_wlf(temperature, self.c1, self.c2, self.T_ref)

    def shift_ok(self, cable: Cable) -> Bool[Array, ""]:
        return _checks.all_ok(
            _checks.parameters_ok(self, ("c1",), allow_zero=True),
            _checks.parameters_ok(self, ("c2",)),
            self.c2 + cable.temperature - self.T_ref > 0,
        )
