"""The one registry of cable models, derived from what each class declares: its
command-line name (`CLI_NAME`, which registers it) and its parameters
(`jaxcable._models.fields`).

Everything that needs to know "which models exist" reads this module: the command line
(`--model NAME`, the base models of [`MODELS`][]; a PARAMS.json may name any
registered class), `FitResult.from_json` (class names in PARAMS.json), the fit
(reparameterisation and units of each parameter) and the diagnosis (the candidate
extensions and the base parameters refitted by default).
"""

import dataclasses

from .base import (
    REGISTERED,
    AbstractCableModel,
    AbstractExtension,
    innermost as innermost,
)
from .baselines import BoucWenModel, BurgersModel, HookeModel
from .fields import (
    ParameterInfo as ParameterInfo,
    fitted_by_default,
    identifiable as identifiable,
    parameter_info as parameter_info,
    parameter_infos,
)
from .findley import FindleyModel
from .park import IntegratedModel
from .piao import FiveElementModel


def _park_identifiable() -> tuple[str, ...]:
    chosen = fitted_by_default(IntegratedModel)
    # IntegratedModel declares parameters a fit keeps, so not every one is fitted.
    assert chosen is not None
    return chosen


PARK_IDENTIFIABLE: tuple[str, ...] = _park_identifiable()
"""Park's parameters fitted by default (declared on
[`jaxcable.IntegratedModel`][]'s fields: the ones cyclic tests identify)."""


@dataclasses.dataclass(frozen=True)
class ModelEntry:
    """One base model of the registry (a view of what its class declares).

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


def _entry(cls: type) -> ModelEntry:
    return ModelEntry(
        cls, cls.CLI_NAME, parameter_infos(cls), fitted_by_default(cls) or ()
    )


# The base models, in the order of `--model`'s choices.
MODELS: tuple[ModelEntry, ...] = tuple(
    _entry(cls)
    for cls in (
        IntegratedModel,
        FiveElementModel,
        HookeModel,
        BurgersModel,
        BoucWenModel,
        FindleyModel,
    )
)
DEFAULT_CLI_MODEL = IntegratedModel.CLI_NAME

BY_CLI_NAME: dict[str, ModelEntry] = {e.cli_name: e for e in MODELS}

CLASSES_BY_NAME: dict[str, type] = REGISTERED
"""Every class a PARAMS.json may name, by class name: every class that declares its
`CLI_NAME` (the models, the extensions, the covariate extensions, the discovered
terms, and the classes of the layers above that declare one, registered when they are
defined)."""


def cli_name(model: AbstractCableModel) -> str | None:
    """The command-line name of a model instance's class (`CLI_NAME`), or None."""
    return type(model).CLI_NAME


def describe(model: AbstractCableModel) -> str | None:
    """The command-line names of `model` and the models it wraps, outermost first,
    e.g. `bedding-in(integrated)`; None if one of them has no name."""
    name = cli_name(model)
    if name is None or not isinstance(model, AbstractExtension):
        return name
    inner = describe(model.base)
    return None if inner is None else f"{name}({inner})"
