r"""Thermally activated creep by time-temperature superposition: the base model on
reduced time, with the Arrhenius ([`TemperatureShift`][]) or the Williams-Landel-Ferry
([`TemperatureShiftWLF`][]) shift factor."""

import abc
import math

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int, PyTree

from ... import _checks
from ..._cable import Cable
from ..._results import RESULTS
from ..base import AbstractExtension, StrainParts
from ..fields import declared_ok, parameter, setting


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


def reference_temperature():
    """The field `T_ref` of a temperature shift: the reference temperature, K (> 0;
    default 293.15 K, the default `Cable.temperature`), at which a_T = 1. A
    diagnosis tries it at the data's median temperature
    ([`jaxcable.with_data_reference`][])."""
    return setting(293.15, unit="K")


def median_temperature(tests) -> float | None:
    """The median of every sample of the tests' temperature records, K; None when a
    test records none (or a record is not finite)."""
    records = [getattr(t, "temperature", None) for t in tests]
    if not records or any(r is None for r in records):
        return None
    values = np.concatenate([np.asarray(r, float).ravel() for r in records])
    if values.size == 0 or not np.all(np.isfinite(values)):
        return None
    # TestData records °C.
    return float(np.median(values)) + 273.15


def median_covariate(tests, column: str | None) -> float | None:
    """The median of every sample of the extra column `column` of the tests, in the
    column's unit; None when `column` is None or a test lacks it."""
    if column is None:
        return None
    records = [(getattr(t, "extra", None) or {}).get(column) for t in tests]
    if not records or any(r is None for r in records):
        return None
    values = np.concatenate([np.asarray(r, float).ravel() for r in records])
    finite = values[np.isfinite(values)]
    return float(np.median(finite)) if finite.size else None


def with_data_reference(model, tests, covariate: str | None = None):
    """`model` with the reference of every time shift in it at the median of the
    data: `T_ref` of each temperature shift ([`jaxcable.TemperatureShift`][],
    [`jaxcable.TemperatureShiftWLF`][]) at the tests' median temperature, `c_ref`
    of each [`jaxcable.CovariateShift`][] at the median of the column `covariate`.

    A shift scales every time-dependent process of its base by a(T) with a(T_ref) =
    1, and only some of the base's time scales are refitted (Park's `t_r1`, `t_e`;
    not `eta0`, `t_c` or the Eq. 8 lambdas): away from the data's temperatures
    the unfitted ones stay at the start's values, off by a(T_data) for the whole
    data (1.28 for 60 kJ/mol at 23 °C against the default 20 °C). At the data's
    median the base, fitted beside the shift, is the material at that
    temperature, and a(T) carries only the contrast between the tests.

    **Arguments:**

    - `model`: any model; the extension layers are found through their `base`.
    - `tests`: the tests ([`jaxcable.TestData`][]; temperature records in °C).
    - `covariate`: the extra column a [`jaxcable.CovariateShift`][] reads (None:
        its `c_ref` is left as it is).

    **Returns:**

    The model, every shift's reference at the data's median; unchanged where the
    data record no temperature (or not the column).
    """
    temperature = median_temperature(tests)
    level = median_covariate(tests, covariate)

    def at(m):
        if isinstance(m, AbstractTemperatureShift) and temperature is not None:
            m = _set(m, "T_ref", temperature)
        # A covariate's shift (`CovariateShift`, in covariate.py, which imports
        # this module) is the time shift with a `c_ref`.
        if (
            isinstance(m, AbstractTimeShift)
            and hasattr(m, "c_ref")
            and level is not None
        ):
            m = _set(m, "c_ref", level)
        inner = getattr(m, "base", None)
        if isinstance(inner, eqx.Module):
            m = eqx.tree_at(lambda x: x.base, m, at(inner))
        return m

    return at(model)


def _set(model, name: str, value: float):
    """`model` with its field `name` at `value`, in the field's dtype."""
    old = getattr(model, name)
    return eqx.tree_at(
        lambda m: getattr(m, name), model, jnp.asarray(value, jnp.result_type(old))
    )


class AbstractTimeShift(AbstractExtension[PyTree]):
    """The base on reduced time, dt_eff = dt / a with log10 a set by the cable's
    conditions at each step (its temperature, a recorded covariate): every
    time-dependent process of the base runs on reduced time, and the base gets a
    cable whose crosshead speed is v a (the same strain per reduced second);
    instantaneous strains are unchanged. The state is the base's.

    A concrete shift implements `log_shift_at` and `shift_ok`.
    """

    @abc.abstractmethod
    def log_shift_at(self, cable: Cable) -> Float[Array, ""]:
        """log10 a at the conditions of `cable`."""

    @abc.abstractmethod
    def shift_ok(self, cable: Cable) -> Bool[Array, ""]:
        """Traced: whether the shift is in its domain at the conditions of `cable`
        beyond the declared domains of its fields (which `check` tests)."""

    def init(self, cable: Cable) -> PyTree:
        return self.base.init(cable)

    def check(self, cable: Cable) -> RESULTS:
        # The base is checked on reduced time, at a = 1 where the shift is out of
        # its domain (the result is then `parameter_out_of_domain` anyway).
        ok = _checks.all_ok(declared_ok(self), self.shift_ok(cable))
        log_a = jnp.where(ok, self.log_shift_at(cable), 0.0)
        _, reduced = reduced_time(cable, 0.0, log_a)
        return _checks.domain_result(ok, self.base.check(reduced))

    def advance(
        self,
        state: PyTree,
        cable: Cable,
        dt: Float[Array, ""],
        force: Float[Array, ""],
        direction: Int[Array, ""],
    ) -> tuple[PyTree, StrainParts]:
        dt_eff, reduced = reduced_time(cable, dt, self.log_shift_at(cable))
        return self.base.advance(state, reduced, dt_eff, force, direction)


class AbstractTemperatureShift(AbstractTimeShift):
    """Time-temperature superposition: the base on reduced time
    ([`AbstractTimeShift`][]), dt_eff = dt / a_T(T), T = `cable.temperature` (K)
    read at each step.

    A concrete shift declares `base`, its own parameters and `T_ref` (the reference
    temperature, K, at which a_T = 1: `reference_temperature()`), and implements
    `log_shift` and `shift_ok`.
    """

    T_ref: eqx.AbstractVar[Float[Array, ""]]

    @abc.abstractmethod
    def log_shift(self, temperature) -> Float[Array, "*shape"]:
        """log10 a_T at `temperature` (K)."""

    def log_shift_at(self, cable: Cable) -> Float[Array, ""]:
        return self.log_shift(cable.temperature)


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
        `Cable.temperature`), at which a_T = 1: the base's parameters are the
        material's at T_ref. [`jaxcable.diagnose`][] tries it at the data's
        median temperature ([`jaxcable.with_data_reference`][]) and keeps it
        there unless the start's own fits the training data better.

    `wrap(base)` starts a fit at `activation_energy = 1e4 J/mol` (a_T ~ 0.87 at 10 K
    above T_ref; thermally activated creep of UHMWPE is ~ 1e5 J/mol).
    """

    CLI_NAME = "temperature"

    activation_energy: Float[Array, ""] = parameter(
        0.0, unit="J/mol", domain="nonnegative", null=0.0, start=1e4
    )
    T_ref: Float[Array, ""] = reference_temperature()

    @classmethod
    def applicability(cls, tests) -> str:
        """Not applicable unless every test records its temperature and the records
        span at least 2 K (a temperature contrast)."""
        temps = [
            np.asarray(t.temperature, float)
            for t in tests
            if getattr(t, "temperature", None) is not None
        ]
        if len(temps) < len(tests):
            return "not every test records its temperature"
        span = float(np.ptp(np.concatenate(temps)))
        if span < 2.0:
            return f"the tests span {span:.2g} K: no temperature contrast"
        return ""

    def log_shift(self, temperature) -> Float[Array, "*shape"]:
        """log10 a_T at `temperature` (K)."""
        return log_shift_arrhenius(temperature, self.activation_energy, self.T_ref)

    def shift_ok(self, cable: Cable) -> Bool[Array, ""]:
        return jnp.isfinite(self.log_shift(cable.temperature))


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
    - `T_ref`: the reference temperature, K (> 0; default 293.15 K), at which
        a_T = 1 (see [`jaxcable.TemperatureShift`][]).

    `wrap(base)` starts a fit at the "universal" C2 = 51.6 K and a small C1 = 1.
    """

    CLI_NAME = "temperature-wlf"

    c1: Float[Array, ""] = parameter(
        0.0, unit="-", domain="nonnegative", null=0.0, start=1.0
    )
    c2: Float[Array, ""] = parameter(51.6, unit="K", start=51.6)
    T_ref: Float[Array, ""] = reference_temperature()

    def log_shift(self, temperature) -> Float[Array, "*shape"]:
        """log10 a_T at `temperature` (K)."""
        return log_shift_wlf(temperature, self.c1, self.c2, self.T_ref)

    def shift_ok(self, cable: Cable) -> Bool[Array, ""]:
        return self.c2 + cable.temperature - self.T_ref > 0
