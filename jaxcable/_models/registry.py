"""The one registry of cable models: names, command-line names and fit metadata.

Everything that needs to know "which models exist" reads this module: the command line
(`--model NAME`), `FitResult.from_json` (class names in PARAMS.json), the fit
(reparameterisation and units of each parameter) and the diagnosis (the candidate
extensions and the base parameters refitted by default).
"""

import dataclasses

from .base import AbstractCableModel, AbstractExtension
from .baselines import BoucWenModel, BurgersModel, HookeModel
from .extensions import EXTENSIONS, DiscoveredTerm
from .park import IntegratedModel
from .piao import FiveElementModel


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


_MODULUS = ParameterInfo("log", "Pa", 1.0)
_VISCOSITY = ParameterInfo("log", "Pa s", 1.0)

# Park's parameters that cyclic tests identify. Hardening (beta, gamma; 0 by default)
# and the long-term recovery law (lambda1, lambda2) are nearly degenerate on them, the
# flow (eta0, sigma_a) is a plateau creep of ~1e-9 /s, invisible in tests of minutes,
# and the permanent element (E2c, t_c = 0.9 s) is one compliance with the spring on
# ramps of seconds or more: a fit with all of them free wanders along flat valleys
# (correlations > 0.999) and does not converge, so these six are what the fit, the
# diagnosis, the demo and the synthetic generators vary by default.
PARK_IDENTIFIABLE = ("E1c", "E1r", "E2r", "t_r1", "E3r", "t_e")


@dataclasses.dataclass(frozen=True)
class ModelEntry:
    """One model of the registry.

    **Fields:**

    - `cls`: the model class.
    - `cli_name`: its name on the command line (`--model NAME`).
    - `parameters`: `{field: ParameterInfo}` of every fitted field.
    - `identifiable`: the fields fitted by default (all of `parameters` if empty).
    """

    cls: type
    cli_name: str
    parameters: dict[str, ParameterInfo]
    identifiable: tuple[str, ...] = ()


MODELS: tuple[ModelEntry, ...] = (
    ModelEntry(
        IntegratedModel,
        "integrated",
        {
            "E1c": _MODULUS,
            "beta": ParameterInfo("log", "-"),
            "gamma": ParameterInfo("log", "-"),
            "E1r": _MODULUS,
            "E2c": _MODULUS,
            "t_c": ParameterInfo("log", "s"),
            "eta0": _VISCOSITY,
            "E2r": _MODULUS,
            "t_r1": ParameterInfo("log", "s"),
            "E3r": _MODULUS,
            "lambda1": ParameterInfo("log", "1/s"),
            # t_r2 = lambda1 (L0/v)^2 - lambda2 (Park Eq. 8): either sign.
            "lambda2": ParameterInfo("linear", "s"),
            "t_e": ParameterInfo("log", "s"),
            "sigma_a": ParameterInfo("log", "Pa", 1.0),
        },
        PARK_IDENTIFIABLE,
    ),
    ModelEntry(
        FiveElementModel,
        "five-element",
        {
            **{
                n: _MODULUS for n in ("E_L1", "E_L2", "E_L3", "E_UL1", "E_UL2", "E_UL3")
            },
            **{n: _VISCOSITY for n in ("eta_L2", "eta_L3", "eta_UL2", "eta_UL3")},
        },
    ),
    ModelEntry(HookeModel, "hooke", {"E": _MODULUS}),
    ModelEntry(
        BurgersModel,
        "burgers",
        {"E1": _MODULUS, "eta0": _VISCOSITY, "E2": _MODULUS, "eta2": _VISCOSITY},
    ),
    ModelEntry(
        BoucWenModel,
        "bouc-wen",
        {
            "E": _MODULUS,
            "sigma_y": ParameterInfo("log", "Pa"),
            # eps = sigma / E + z_y (...): E -> c E with z_y -> z_y / c divides eps by c.
            "z_y": ParameterInfo("log", "-", -1.0),
            "A": ParameterInfo("log", "-"),
            "beta": ParameterInfo("log", "-"),
            # The model requires |gamma| <= beta (a dissipative loop).
            "gamma": ParameterInfo("tanh:beta", "-"),
            "n": ParameterInfo("log1", "-"),
        },
    ),
)
DEFAULT_CLI_MODEL = "integrated"

BY_CLI_NAME: dict[str, ModelEntry] = {e.cli_name: e for e in MODELS}
_BY_CLASS: dict[type, ModelEntry] = {e.cls: e for e in MODELS}

# Every class a PARAMS.json may name, by class name: the models and the extensions.
CLASSES_BY_NAME: dict[str, type] = {
    cls.__name__: cls for cls in (*_BY_CLASS, *EXTENSIONS.values(), DiscoveredTerm)
}


def parameter_info(cls: type, field: str) -> ParameterInfo | None:
    """How `field` of model class `cls` is fitted: the table above for the models,
    the class's own `FIT_INFO` for the extensions; None for a field not fitted."""
    entry = _BY_CLASS.get(cls)
    if entry is not None:
        return entry.parameters.get(field)
    if not issubclass(cls, AbstractExtension):
        return None
    declared = cls.FIT_INFO.get(field)
    return None if declared is None else ParameterInfo(*declared)


def identifiable(model: AbstractCableModel) -> tuple[str, ...] | None:
    """The fields fitted by default for `model`'s class, or None for all of them."""
    entry = _BY_CLASS.get(type(model))
    if entry is None or not entry.identifiable:
        return None
    return entry.identifiable


def cli_name(model: AbstractCableModel) -> str | None:
    """The command-line name of a model instance's class, or None."""
    entry = _BY_CLASS.get(type(model))
    return None if entry is None else entry.cli_name
