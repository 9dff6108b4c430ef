"""What every cable model shares: the strain split by mechanism ([`StrainParts`][]), the
model interface ([`AbstractCableModel`][]) and the interface of a model extension
that wraps another model ([`AbstractExtension`][])."""

import abc
from typing import Generic, TypeVar

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float, Int

from .._cable import Cable
from .._results import RESULTS


_State = TypeVar("_State")


class StrainParts(eqx.Module):
    """The strain of one sample split by mechanism (dimensionless, elongation / L0).

    `total = instantaneous + creep - recovery_short - recovery_long`. Recovery terms are
    reported as positive amounts removed from the strain. Models fill the parts they
    have and leave the others zero.

    **Fields:**

    - `instantaneous`: time-independent part (Park Eq. 1-2 with hardening; the spring of
        Burgers / five-element / Hooke; the Bouc-Wen loop).
    - `creep`: time-dependent lengthening (Park Eq. 3 and 5; Kelvin-Voigt elements and
        dashpot of the linear models).
    - `recovery_short`: short-term recovery (Park Eq. 4; the first unloading
        Kelvin-Voigt element of the five-element model).
    - `recovery_long`: long-term recovery (Park Eq. 7; the second unloading
        Kelvin-Voigt element of the five-element model).
    """

    instantaneous: Float[Array, "*shape"]
    creep: Float[Array, "*shape"]
    recovery_short: Float[Array, "*shape"]
    recovery_long: Float[Array, "*shape"]

    @property
    def total(self) -> Float[Array, "*shape"]:
        """Total strain, dimensionless."""
        return (
            self.instantaneous + self.creep - self.recovery_short - self.recovery_long
        )


class AbstractCableModel(eqx.Module, Generic[_State]):
    """A constitutive law of a cable: force history in, strain history out.

    A model is written for one cable and one sample at a time; the drivers
    ([`jaxcable.simulate_rate_test`][], [`jaxcable.simulate_force_history`][],
    [`jaxcable.simulate_elongation_history`][], [`jaxcable.step`][]) run it inside one
    `lax.scan`. Parameters are array fields in SI units, so a model is a PyTree that can
    be `jax.vmap`-ed over (parameter sets) and differentiated (`eqx.filter_grad`).

    Concrete models implement three methods:

    - `init(cable)`: the state of the unloaded, virgin cable;
    - `advance(state, cable, dt, force, direction)`: the new state and the strain after
        a step of `dt` seconds ending at `force`, with the force changing linearly over
        the step. `direction` is +1 for a loading step, -1 for an unloading step and 0
        to keep the current branch (holds, rests). `advance` must be a smooth function
        of `dt` and `force` (the drivers solve for either by Newton's method);
    - `check(cable)`: a traced domain check of the parameters for this cable.
    """

    @abc.abstractmethod
    def init(self, cable: Cable) -> _State:
        """The state of a new, unloaded cable at time 0.

        **Arguments:**

        - `cable`: the [`jaxcable.Cable`][] (one cable).

        **Returns:**

        The model's state (an `eqx.Module`).
        """

    @abc.abstractmethod
    def advance(
        self,
        state: _State,
        cable: Cable,
        dt: Float[Array, ""],
        force: Float[Array, ""],
        direction: Int[Array, ""],
    ) -> tuple[_State, StrainParts]:
        """Advance the state by one sample.

        **Arguments:**

        - `state`: the state after the previous sample.
        - `cable`: the [`jaxcable.Cable`][].
        - `dt`: duration of the step, s (>= 0).
        - `force`: cable force at the end of the step, N (linear over the step).
        - `direction`: +1 loading, -1 unloading, 0 keep the current branch.

        **Returns:**

        `(new_state, parts)` with the [`jaxcable.StrainParts`][] at the end of the step.
        """

    @abc.abstractmethod
    def check(self, cable: Cable) -> RESULTS:
        """Traced check that the parameters are in their domain for `cable`.

        **Returns:**

        `RESULTS.successful` or `RESULTS.parameter_out_of_domain`.
        """


class AbstractExtension(AbstractCableModel[_State]):
    """A physical effect that a base model lacks, as a wrapper around any
    [`jaxcable.AbstractCableModel`][] (wrap, don't subclass), composable by nesting,
    e.g. `SensorDrift(BeddingIn(IntegratedModel()))`.

    A concrete extension declares `base` as its first field, then its own parameters,
    and these class variables, read by the fit and the diagnosis:

    - `EXTENSION_ID`: the stable id (a key of [`jaxcable.EXTENSIONS`][] for the
        candidates of the diagnosis);
    - `EFFECT_FIELDS`: its own parameters that a diagnosis fits together with the
        base model's;
    - `SIZE_FIELD`, `SIZE_UNIT`, `SIZE_NULL`: the one field reported as the size of
        the effect, its unit, and its null value (the base exactly);
    - `FIT_INFO`: `{field: (transform, unit[, stiffness])}` for each fitted field,
        with transform `"log"` (positive) or `"linear"` (either sign, scaled by
        |start|), and the optional power with which the field follows a stiffness
        scaling of the model;

    and the class method `wrap(base)`. At the null value of its effect parameter an
    extension reproduces its base model exactly. It receives `direction` only to pass
    it on to the base.
    """

    base: eqx.AbstractVar[AbstractCableModel]

    EXTENSION_ID: eqx.AbstractClassVar[str]
    EFFECT_FIELDS: eqx.AbstractClassVar[tuple[str, ...]]
    SIZE_FIELD: eqx.AbstractClassVar[str]
    SIZE_UNIT: eqx.AbstractClassVar[str]
    SIZE_NULL: eqx.AbstractClassVar[float]
    FIT_INFO: eqx.AbstractClassVar[dict[str, tuple]]

    @classmethod
    @abc.abstractmethod
    def wrap(cls, base: AbstractCableModel) -> "AbstractExtension":
        """The extension around `base` with small but nonzero start values of its
        effect parameters for a fit (so that a log transform works and the gradient
        is informative).

        **Arguments:**

        - `base`: the model to wrap.

        **Returns:**

        An instance of the extension.
        """

    @classmethod
    def switched_off(cls, base: AbstractCableModel) -> "AbstractExtension":
        """[`wrap`][]`(base)` with its size at `SIZE_NULL`: the base exactly, with the
        other effect fields at their start values (e.g. the nested extensions a
        diagnosis fits one at a time).

        **Arguments:**

        - `base`: the model to wrap.

        **Returns:**

        An instance of the extension.
        """
        model = cls.wrap(base)
        null = jnp.asarray(
            cls.SIZE_NULL, jnp.result_type(getattr(model, cls.SIZE_FIELD))
        )
        return eqx.tree_at(lambda m: getattr(m, cls.SIZE_FIELD), model, null)


def add_parts(
    parts: StrainParts,
    *,
    instantaneous: Float[Array, ""] | None = None,
    creep: Float[Array, ""] | None = None,
) -> StrainParts:
    """`parts` with an extension's strain added to its instantaneous or creep part."""
    if instantaneous is not None:
        parts = eqx.tree_at(
            lambda p: p.instantaneous, parts, parts.instantaneous + instantaneous
        )
    if creep is not None:
        parts = eqx.tree_at(lambda p: p.creep, parts, parts.creep + creep)
    return parts


def covariate_of(cable: Cable, like) -> Float[Array, ""]:
    """The covariate of `cable` (`Cable.covariate`, set per sample from a recorded
    column) in the dtype of `like`; 0 where none is set."""
    c = 0.0 if cable.covariate is None else cable.covariate
    return jnp.asarray(c, jnp.result_type(like))


def state_zero(cable: Cable, *like) -> Float[Array, ""]:
    """A scalar 0 of the dtype a model's state takes for `cable` and its parameters
    `like` (at least the default float)."""
    return jnp.zeros((), jnp.result_type(float, cable.length, *like))
