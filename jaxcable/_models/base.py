"""What every cable model shares: the strain split by mechanism ([`StrainParts`][]), the
model interface ([`AbstractCableModel`][]) and the interface of a model extension
that wraps another model ([`AbstractExtension`][]).

A model class states its facts once: its parameters as declared fields
(`jaxcable._models.fields.parameter`, from which the checks and the fit information
are derived) and its command-line name, `CLI_NAME`, which also registers the class
([`REGISTERED`][]: every class a PARAMS.json may name).
"""

import abc
from typing import TYPE_CHECKING, ClassVar, Generic, TypeVar

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float, Int

from .. import _checks
from .._cable import Cable
from .._results import RESULTS
from . import fields


_State = TypeVar("_State")

REGISTERED: dict[str, type] = {}
"""Every model class that declares its `CLI_NAME`, by class name, in the order of
definition: filled as the classes are defined (the layers above `_models` register
theirs by defining them), so complete once `jaxcable` is imported."""


class StrainParts(eqx.Module):
    """The strain of one sample split by mechanism (dimensionless, elongation / L0).

    `total = instantaneous + creep - recovery_short - recovery_long + apparatus`.
    Recovery terms are reported as positive amounts removed from the strain. Models
    fill the parts they have and leave the others zero.

    **Fields:**

    - `instantaneous`: time-independent part (Park Eq. 1-2 with hardening; the spring of
        Burgers / five-element / Hooke; the Bouc-Wen loop).
    - `creep`: time-dependent lengthening (Park Eq. 3 and 5; Kelvin-Voigt elements and
        dashpot of the linear models).
    - `recovery_short`: short-term recovery (Park Eq. 4; the first unloading
        Kelvin-Voigt element of the five-element model).
    - `recovery_long`: long-term recovery (Park Eq. 7; the second unloading
        Kelvin-Voigt element of the five-element model).
    - `apparatus`: what the instrument adds to the measured elongation, not the
        cable's own strain ([`jaxcable.SensorDrift`][]). Kept apart so that an effect
        of the material (a stress-dependent creep) never scales it, in whichever
        order the extensions are nested.
    """

    instantaneous: Float[Array, "*shape"]
    creep: Float[Array, "*shape"]
    recovery_short: Float[Array, "*shape"]
    recovery_long: Float[Array, "*shape"]
    apparatus: Float[Array, "*shape"]

    @property
    def total(self) -> Float[Array, "*shape"]:
        """Total strain, dimensionless."""
        return (
            self.instantaneous
            + self.creep
            - self.recovery_short
            - self.recovery_long
            + self.apparatus
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
    - `check(cable)`: a traced domain check of the parameters for this cable (by
        default: every field declared with `jaxcable._models.fields.parameter` is
        in its domain).

    A model of the library declares `CLI_NAME` (its name on the command line and in
    the registry) and its parameters with their unit, domain and fit transform; the
    construction-time check of the declared fields, in field order, is derived from
    them, followed by the class's `check_more` for what a field alone cannot say.
    """

    # The name on the command line and in the registry; None: not registered. Class
    # facts are plain class attributes, so that they are no (pseudo-)fields of the
    # dataclass.
    CLI_NAME = None

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        if "CLI_NAME" in cls.__dict__:
            REGISTERED[cls.__name__] = cls

    def __check_init__(self):
        fields.check_declared(self, qualified=not isinstance(self, AbstractExtension))
        self.check_more()

    def check_more(self) -> None:
        """Raise `ValueError` for concrete parameters that the declared domains of
        single fields do not cover (run after those checks; none by default)."""

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

    def check(self, cable: Cable) -> RESULTS:
        """Traced check that the parameters are in their domain for `cable`.

        **Returns:**

        `RESULTS.successful` or `RESULTS.parameter_out_of_domain`.
        """
        del cable
        return _checks.domain_result(fields.declared_ok(self))


class _ClassFact:
    """A class attribute computed from the class (its declarations) when read."""

    def __init__(self, compute):
        self.compute = compute
        self.__doc__ = compute.__doc__

    def __get__(self, obj, owner=None):
        return self.compute(owner if owner is not None else type(obj))


def _size_field(cls) -> str:
    """The first own parameter with a declared null value."""
    facts = fields.field_facts(cls)
    return next(n for n in fields.fit_parameters(cls) if facts[n].null is not None)


class AbstractExtension(AbstractCableModel[_State]):
    """A physical effect that a base model lacks, as a wrapper around any
    [`jaxcable.AbstractCableModel`][] (wrap, don't subclass), composable by nesting,
    e.g. `SensorDrift(BeddingIn(IntegratedModel()))`.

    Its first field is `base`, the wrapped model. A concrete extension declares its
    own parameters (`jaxcable._models.fields.parameter`: the size of its effect with its
    `null` value, the `start` values of `wrap(base)`) and its `CLI_NAME`. Derived
    from these, read by the fit and the diagnosis:

    - `EXTENSION_ID`: the stable id, `CLI_NAME` with `_` for `-` (a key of
        [`jaxcable.EXTENSIONS`][] for the candidates of the diagnosis);
    - `EFFECT_FIELDS`: its own fit parameters, which a diagnosis fits together with
        the base model's;
    - `SIZE_FIELD`, `SIZE_UNIT`, `SIZE_NULL`: the first of them with a declared
        null value, reported as the size of the effect, its unit, and that null value
        (the base exactly).

    A candidate of the diagnosis may also declare `LIBRARY_TERM` and
    `applicability`. At the null value of its effect parameter an extension
    reproduces its base model exactly. It receives `direction` only to pass it on to
    the base.
    """

    base: AbstractCableModel

    if TYPE_CHECKING:
        # pyright does not take `eqx.AbstractClassVar` (typing's ClassVar re-exported
        # under another name) for a ClassVar, and would make it a field of __init__.
        CLI_NAME: ClassVar[str]
    else:
        CLI_NAME: eqx.AbstractClassVar[str]
    EXTENSION_ID = _ClassFact(lambda cls: cls.CLI_NAME.replace("-", "_"))
    EFFECT_FIELDS = _ClassFact(fields.fit_parameters)
    SIZE_FIELD = _ClassFact(_size_field)
    SIZE_UNIT = _ClassFact(lambda cls: fields.field_facts(cls)[cls.SIZE_FIELD].unit)
    SIZE_NULL = _ClassFact(lambda cls: fields.field_facts(cls)[cls.SIZE_FIELD].null)
    # The term of the discovery's library ([`jaxcable.TERMS`][]) whose regression
    # coefficient estimates this extension's effect, or None.
    LIBRARY_TERM = None

    def check(self, cable: Cable) -> RESULTS:
        """Traced: the declared fields in their domains, and the base's check."""
        return _checks.domain_result(fields.declared_ok(self), self.base.check(cable))

    @classmethod
    def applicability(cls, tests) -> str:
        """Why `tests` cannot show this extension's effect at all, or "" when they
        can (the diagnosis then reports the candidate as not applicable).

        **Arguments:**

        - `tests`: the measured tests (objects with the columns as attributes).

        **Returns:**

        The reason, a short phrase, or "".
        """
        del tests
        return ""

    @classmethod
    def wrap(cls, base: AbstractCableModel) -> "AbstractExtension":
        """The extension around `base` at the declared start values of its
        parameters for a fit (`start`: small but nonzero effects, so that a log
        transform works and the gradient is informative).

        **Arguments:**

        - `base`: the model to wrap.

        **Returns:**

        An instance of the extension.
        """
        return cls(base, **fields.starts(cls))

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


def innermost(model: AbstractCableModel) -> AbstractCableModel:
    """The model at the core of the extensions around `model` (following `.base`),
    `model` itself if it is no extension."""
    while isinstance(model, AbstractExtension):
        model = model.base
    return model


def add_parts(
    parts: StrainParts,
    *,
    instantaneous: Float[Array, ""] | None = None,
    creep: Float[Array, ""] | None = None,
    apparatus: Float[Array, ""] | None = None,
) -> StrainParts:
    """`parts` with an extension's strain added to its instantaneous, creep or
    apparatus part."""
    if instantaneous is not None:
        parts = eqx.tree_at(
            lambda p: p.instantaneous, parts, parts.instantaneous + instantaneous
        )
    if creep is not None:
        parts = eqx.tree_at(lambda p: p.creep, parts, parts.creep + creep)
    if apparatus is not None:
        parts = eqx.tree_at(lambda p: p.apparatus, parts, parts.apparatus + apparatus)
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
