"""The model of a command: `--model NAME` and `--params PARAMS.json`, and the parameter
names of `--fit` / `--per-test`.

Model names come from the one registry (`jaxcable._models.BY_CLI_NAME`); a parameter
file is read with the one JSON reader, whose errors (a `ValueError` naming the file,
line and column) `main` reports as the command line's one-line error.
"""

import dataclasses
import json

import equinox as eqx
import numpy as np

from .. import _checks
from .._fit import FitResult
from .._io import read_json
from .._models import (
    BY_CLI_NAME,
    DEFAULT_CLI_MODEL,
    AbstractCableModel,
    cli_name,
    describe,
    innermost,
)
from .._problem import Problem
from .common import CliError


def parameter_names(model: AbstractCableModel, prefix: str = "") -> list[str]:
    """The model's fittable parameters: its inexact-array fields, and those of the
    model it wraps by their path (`base.E1c`), as `jaxcable.fit` names them."""
    names = []
    for f in dataclasses.fields(model):
        value = getattr(model, f.name)
        if eqx.is_inexact_array(value):
            names.append(prefix + f.name)
        elif isinstance(value, AbstractCableModel):
            names += parameter_names(value, f"{prefix}{f.name}.")
    return names


def names_option(
    value: str | None, option: str, model: AbstractCableModel, name: str
) -> list[str]:
    """Parse a comma-separated `--fit` / `--per-test` list of parameter names.

    **Arguments:**

    - `value`: the option's value, or None when it was not given.
    - `option`: the option, for the errors.
    - `model`: the model whose parameters the names must be.
    - `name`: the model's command-line name, for the errors.

    **Returns:**

    The names, in the order given (empty when `value` is None).
    """
    if value is None:
        return []
    names = [n.strip() for n in value.split(",")]
    available = parameter_names(model)
    unknown, repeated = _checks.unknown_names(names, available)
    if unknown and not unknown[0]:
        raise CliError(f"{option} {value!r}: an empty name.")
    if unknown:
        raise CliError(
            f"{option}: '{unknown[0]}' is not a parameter of model '{name}' (its "
            f"parameters: {', '.join(available)})."
        )
    if repeated:
        raise CliError(f"{option} {value!r}: a name is repeated.")
    return names


def _check_plain_params(path: str, params, cls: type, name: str) -> dict:
    """Validate a plain {parameter name: value (SI)} object for model `name`."""
    if not isinstance(params, dict):
        raise CliError(
            f"{path}: expected a JSON object of parameter name -> value (SI units), "
            f"got {type(params).__name__}."
        )
    fields = {f.name: f for f in dataclasses.fields(cls)}
    for key, value in params.items():
        if key not in fields:
            raise CliError(
                f"{path}, parameter '{key}': not a parameter of model '{name}' "
                f"(its parameters: {', '.join(fields)})."
            )
        # Static fields (settings, not parameters) may also be strings or booleans.
        static = fields[key].metadata.get("static", False)
        number = isinstance(value, int | float) and not isinstance(value, bool)
        if not number and not (static and isinstance(value, str | bool | int | float)):
            raise CliError(
                f"{path}, parameter '{key}': {json.dumps(value)} is not a number "
                "(SI units)."
            )
    return params


# The entries of a PARAMS.json that must be JSON objects, and the one that names the
# model class.
_OBJECTS = ("parameters", "static")


def _read_fit(path: str, doc: dict) -> FitResult:
    """The fit of the PARAMS.json `doc` read from `path`; a malformed one fails
    naming the file and the entry."""
    for document, where in _model_documents(doc):
        if not isinstance(document.get("model"), str):
            raise CliError(
                f"{path}, {where}model: {_kind(document.get('model'))} is not a model "
                'class name (a string such as "IntegratedModel").'
            )
        for key in _OBJECTS:
            if key in document and not isinstance(document[key], dict):
                raise CliError(
                    f"{path}, {where}{key}: {_kind(document[key])} is not an object "
                    "of name -> value."
                )
    try:
        return FitResult.from_json(path)  # ValueError -> exit 2, naming the file
    except (AttributeError, IndexError, KeyError, OverflowError, TypeError) as e:
        raise CliError(f"{path}: malformed PARAMS.json ({e}).") from None


def _model_documents(doc: dict, where: str = ""):
    """(document, key path) of a model document and of the bases it wraps."""
    yield doc, where
    if isinstance(doc.get("base"), dict):
        yield from _model_documents(doc["base"], f"{where}base.")


def _kind(value) -> str:
    """What `value` is, in a few words, for an error."""
    text = json.dumps(value)
    return text if len(text) <= 30 else f"a {type(value).__name__}"


def _build_model(name: str, params: dict, params_path: str | None):
    """Model `name` built from `params` (its defaults for the others)."""
    where = params_path or "default parameters"
    try:
        return BY_CLI_NAME[name].cls(**params)
    except (TypeError, ValueError) as e:
        raise CliError(f"{where}: cannot build model '{name}': {e}") from None


def _select_test(path: str, result: FitResult, test: str | None, purpose: str):
    """The model of one test of a fit with per-test parameters (`--test`)."""
    if not result.per_test:
        return result.model
    ids = list(result.test_ids)
    if test is None:
        raise CliError(
            f"{path}: parameters {', '.join(result.per_test)} were fitted per test "
            f"({', '.join(ids)}); {purpose}"
        )
    if test in ids:
        return result.models[ids.index(test)]
    if test.isdigit() and int(test) < len(ids):
        return result.models[int(test)]
    raise CliError(
        f"--test {test}: not a test of {path} (its tests: "
        f"{', '.join(f'{i} {t}' for i, t in enumerate(ids))})."
    )


@dataclasses.dataclass(frozen=True)
class ModelChoice:
    """The model a command was asked for: `--model`, `--params` and, for
    `simulate`, `--test`.

    **Fields:**

    - `name`: the `--model` name, or None when it was not given.
    - `params`: the `--params` file, or None.
    - `test`: the `--test` id or index of a PARAMS.json with per-test parameters.
    """

    name: str | None = None
    params: str | None = None
    test: str | None = None


def resolve_model(
    choice: ModelChoice, *, per_test_hint: str
) -> tuple[str, AbstractCableModel]:
    """The model of a command, from `--model` and `--params`.

    `--params` is either a plain {name: value} object of SI values replacing the
    model's defaults, or a PARAMS.json written by `jaxcable fit`
    (`FitResult.to_json`), whose model it names (any registered model, extensions
    around a base included); `--model`, when given, must name its base.

    **Arguments:**

    - `choice`: the model asked for.
    - `per_test_hint`: what to do instead, said when the PARAMS.json holds per-test
        parameters and no test is chosen.

    **Returns:**

    (the model's command-line name, e.g. `integrated` or, for extensions around
    a base, `bedding-in(integrated)`; the model).
    """
    requested = choice.name
    if not choice.params:
        name = requested or DEFAULT_CLI_MODEL
        return name, _build_model(name, {}, None)
    path = choice.params
    doc = read_json(path, "parameters")
    if isinstance(doc, dict) and doc.get("format") == "jaxcable-params":
        result = _read_fit(path, doc)
        # Every class a PARAMS.json may name is registered, with its name.
        name = describe(result.model) or type(result.model).__name__
        base = cli_name(innermost(result.model))
        if requested is not None and requested != base:
            raise CliError(
                f"{path}: holds a fit of model '{name}', not '{requested}' "
                f"(--model); drop --model or pass --model {base}."
            )
        return name, _select_test(path, result, choice.test, per_test_hint)
    name = requested or DEFAULT_CLI_MODEL
    params = _check_plain_params(path, doc, BY_CLI_NAME[name].cls, name)
    return name, _build_model(name, params, path)


def data_start(problem: Problem, choice: ModelChoice) -> Problem:
    """The start of a command that fits measured tests: the model `--params` gives,
    as given (a fit moves it only if it fails on a test); with no `--params`, the
    default model scaled to the data ([`jaxcable.Problem.with_scaled_start`][]: its
    moduli to the first loading, its times to the holds when far off).

    **Arguments:**

    - `problem`: the model of [`resolve_model`][] and the tests read, with their
        drives.
    - `choice`: the model asked for (whether `--params` was given).

    **Returns:**

    `problem` with its start model.
    """
    return problem if choice.params else problem.with_scaled_start()


def params_metadata(model: AbstractCableModel) -> str:
    """The model's parameters as compact JSON (SI), for an output file's metadata."""
    values = {}
    for name in parameter_names(model):
        v = model
        for part in name.split("."):
            v = getattr(v, part)
        v = np.asarray(v, float)
        values[name] = float(v) if v.ndim == 0 else v.tolist()
    return json.dumps(values, separators=(",", ":"))
