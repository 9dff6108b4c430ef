"""A model's parameters declared once, on its class: each field's unit, domain and
fit transform ([`parameter`][], [`setting`][]), and what is derived from them: the
construction-time and traced checks, the fit information ([`parameter_info`][],
[`identifiable`][]) and the table of a docstring ([`parameter_table`][]).
"""

import dataclasses
import functools
from typing import Any

import equinox as eqx
from jaxtyping import Array, Bool

from .. import _checks
from .._arrays import field_array


_KEY = "jaxcable"

# How each domain reads in a table.
_DOMAIN_TEXT = {
    "positive": "> 0",
    "nonnegative": ">= 0",
    "positive_or_inf": "> 0 (inf: off)",
    "any": "finite",
}
# The domain a transform implies unless one is declared.
_TRANSFORM_DOMAIN = {
    "log": "positive",
    "linear": "any",
    "log1": "any",
    None: "positive",
}


# The facts of a modulus and of a viscosity (both follow a stiffness scaling; a
# viscosity, a modulus times a time, also follows a time scaling).
MODULUS: dict[str, Any] = {"unit": "Pa", "stiffness": 1.0}
VISCOSITY: dict[str, Any] = {"unit": "Pa s", "stiffness": 1.0, "time": 1.0}


@dataclasses.dataclass(frozen=True)
class ParameterInfo:
    """How a parameter is fitted, and its unit.

    Each fitted parameter x is a function of one unconstrained number u:

    - `"log"`: x = exp(u) (x > 0: moduli, viscosities, times, ...);
    - `"log1"`: x = 1 + exp(u) (x > 1: the Bouc-Wen exponent n >= 1);
    - `"linear"`: x = s u, s = |x_start| (signed or possibly zero: Park's lambda2);
    - `"tanh:OTHER"`: x = OTHER tanh(u) (|x| < OTHER: Bouc-Wen |gamma| <= beta).

    `stiffness` is the power k with which the parameter is multiplied by c**k when a
    data-derived initial guess scales the model's stiffness by c (moduli and viscosities
    k = 1, compliances k = -1, the rest 0): for the linear models this divides every
    strain by exactly c.
    """

    transform: str
    unit: str
    stiffness: float = 0.0


@dataclasses.dataclass(frozen=True)
class FieldFacts:
    """What a class declares about one array field ([`parameter`][], [`setting`][]).

    **Fields:**

    - `unit`: the SI unit (`"-"` for a dimensionless field, `"[c]"` for the unit of
        a recorded covariate).
    - `domain`: a key of `jaxcable._checks.DOMAINS`.
    - `transform`: the fit's reparameterisation ([`ParameterInfo`][]), or None for a
        setting (not described to the fit).
    - `stiffness`: the power of a stiffness scaling ([`ParameterInfo`][]).
    - `fitted`: whether a fit varies it by default.
    - `null`: the value at which an extension is its base exactly, or None.
    - `start`: an extension's start value for a fit (its `wrap`), or None.
    - `note`: why the domain is what it is, for an error (default: the unit).
    - `time`: the power with which it follows a time scaling of the start
        (`jaxcable.scaled_start`): retardation times and viscosities 1, the rest 0.
    """

    unit: str
    domain: str
    transform: str | None
    stiffness: float
    fitted: bool
    null: float | None
    start: float | None
    note: str
    time: float = 0.0


def parameter(
    default: Any = dataclasses.MISSING,
    *,
    unit: str,
    transform: str | None = "log",
    domain: str | None = None,
    stiffness: float = 0.0,
    fitted: bool = True,
    null: float | None = None,
    start: float | None = None,
    note: str = "",
    time: float = 0.0,
) -> Any:
    """A model's array field with its facts declared (an `eqx.field` converted by
    `jaxcable._arrays.field_array`).

    **Arguments:**

    - `default`: the default value (SI).
    - `unit`: the SI unit.
    - `transform`: how a fit reparameterises it (`"log"`, `"log1"`, `"linear"`,
        `"tanh:OTHER"`; [`ParameterInfo`][]); None for a setting.
    - `domain`: `"positive"`, `"nonnegative"`, `"positive_or_inf"` or `"any"`
        (finite); default `"any"` for a `"linear"`, `"log1"` or `"tanh"` transform,
        else `"positive"`.
    - `stiffness`: the power with which it follows a stiffness scaling of the start.
    - `fitted`: False for a parameter a fit keeps by default (not identifiable).
    - `null`: for an extension, the value of its effect at which it is its base.
    - `start`: for an extension, the value its `wrap` starts a fit at (small but
        nonzero for an effect, so that a log transform works and the gradient is
        informative).
    - `note`: why the domain is what it is, for the error (default: the unit).
    - `time`: the power with which it follows a time scaling of the start (a
        retardation time 1; [`jaxcable.scaled_start`][]).

    **Returns:**

    The field, for a class body.
    """
    if domain is None:
        domain = _TRANSFORM_DOMAIN.get(transform, "any")
    if domain not in _checks.DOMAINS:
        raise ValueError(f"unknown domain {domain!r}")
    facts = FieldFacts(
        unit, domain, transform, stiffness, fitted, null, start, note, time
    )
    return eqx.field(default=default, converter=field_array, metadata={_KEY: facts})


def setting(
    default: Any = dataclasses.MISSING,
    *,
    unit: str,
    domain: str = "positive",
    note: str = "",
) -> Any:
    """A model's array field that is a setting, not a fit parameter (e.g. a
    reference temperature): [`parameter`][] with no transform, not fitted."""
    return parameter(
        default, unit=unit, transform=None, domain=domain, fitted=False, note=note
    )


def signed_effect(unit: str, start: float | None = None) -> Any:
    """An extension's effect coefficient of either sign, 0 by default (the base
    exactly): a [`parameter`][] fitted on a linear scale.

    **Arguments:**

    - `unit`: its unit.
    - `start`: the value `wrap` starts a fit at (None: 0).

    **Returns:**

    The field, for a class body.
    """
    return parameter(0.0, unit=unit, transform="linear", null=0.0, start=start)


@functools.cache
def field_facts(cls: type) -> dict[str, FieldFacts]:
    """`{field: FieldFacts}` of the declared fields of `cls`, in field order."""
    return {
        f.name: f.metadata[_KEY] for f in dataclasses.fields(cls) if _KEY in f.metadata
    }


def fit_parameters(cls: type) -> tuple[str, ...]:
    """The fields of `cls` declared as fit parameters (with a transform)."""
    return tuple(n for n, f in field_facts(cls).items() if f.transform is not None)


def starts(cls: type) -> dict[str, float]:
    """`{field: start}` of the fields of `cls` with a declared start value."""
    return {n: f.start for n, f in field_facts(cls).items() if f.start is not None}


def parameter_info(cls: type, field: str) -> ParameterInfo | None:
    """How `field` of model class `cls` is fitted, from its declaration; None for a
    field that is not a declared fit parameter."""
    facts = field_facts(cls).get(field)
    if facts is None or facts.transform is None:
        return None
    return ParameterInfo(facts.transform, facts.unit, facts.stiffness)


def parameter_infos(cls: type) -> dict[str, ParameterInfo]:
    """`{field: ParameterInfo}` of the fit parameters of `cls`, in field order."""
    return {
        n: ParameterInfo(f.transform, f.unit, f.stiffness)
        for n, f in field_facts(cls).items()
        if f.transform is not None
    }


def fitted_by_default(cls: type) -> tuple[str, ...] | None:
    """The declared parameters of `cls` that a fit varies by default, or None when
    that is every one of them."""
    names = fit_parameters(cls)
    chosen = tuple(n for n in names if field_facts(cls)[n].fitted)
    return None if len(chosen) == len(names) else chosen


def identifiable(model) -> tuple[str, ...] | None:
    """The fields fitted by default for `model`'s class, or None for all of them."""
    return fitted_by_default(type(model))


def check_declared(model, *, qualified: bool) -> None:
    """Raise `ValueError` for the first concrete declared field of `model` (in field
    order) outside its domain (`jaxcable._checks.check_parameter`)."""
    owner = type(model).__name__
    for name, facts in field_facts(type(model)).items():
        unit = "" if facts.unit == "-" else f"({facts.unit})"
        _checks.check_parameter(
            owner,
            name,
            getattr(model, name),
            facts.domain,
            qualified=qualified,
            reason=facts.note or unit,
        )


def declared_ok(model, domain: str | None = None) -> Bool[Array, ""]:
    """Traced: whether every declared field of `model` (of `domain`, if given) is in
    its domain."""
    conditions = []
    for name, facts in field_facts(type(model)).items():
        if domain is None or facts.domain == domain:
            conditions += _checks.parameter_ok(getattr(model, name), facts.domain)
    return _checks.all_ok(*conditions)


def parameter_table(cls: type) -> str:
    """The declared fields of `cls` as a markdown table: field, unit, domain, fit
    transform and whether a fit varies it by default (for its parameters; a setting
    has no transform).

    **Arguments:**

    - `cls`: a model class.

    **Returns:**

    The table, one row per declared field in field order.
    """
    rows = [
        "| field | unit | domain | fit transform | fitted by default |",
        "| --- | --- | --- | --- | --- |",
    ]
    for name, f in field_facts(cls).items():
        fitted = "-" if f.transform is None else "yes" if f.fitted else "no"
        transform = "(a setting)" if f.transform is None else f.transform
        rows.append(
            f"| `{name}` | {f.unit} | {_DOMAIN_TEXT[f.domain]} | {transform} | "
            f"{fitted} |"
        )
    return "\n".join(rows)


# Each fit transform as the reparameterisation x = f(u) it stands for.
_TRANSFORM_TEXT = {
    "log": "exp(u)",
    "log1": "1 + exp(u)",
    "linear": "s u, s = abs(start)",
}


def transform_table(classes) -> str:
    """The fit's reparameterisation of every declared parameter of `classes`, as a
    markdown table: one row per class and transform, naming its parameters (and
    whether a fit varies them by default).

    **Arguments:**

    - `classes`: model classes.

    **Returns:**

    The table.
    """
    rows = ["| model | parameters | x = f(u) |", "| --- | --- | --- |"]
    for cls in classes:
        by_transform: dict[str, list[str]] = {}
        for name, f in field_facts(cls).items():
            if f.transform is not None:
                shown = f"`{name}`" if f.fitted else f"(`{name}`)"
                by_transform.setdefault(f.transform, []).append(shown)
        for transform, names in by_transform.items():
            other = transform.partition(":")[2]
            text = _TRANSFORM_TEXT.get(transform, f"{other} tanh(u)")
            rows.append(f"| `{cls.__name__}` | {', '.join(names)} | {text} |")
    return "\n".join(rows)
