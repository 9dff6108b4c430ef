"""A model as a JSON document and back: the model part of a PARAMS.json.

A document is `{"model": class name, "parameters": {field: number or list},
"static": {field: bool, int, float, str or a list of them}}`, with
`"base": document` for the model a wrapper (an extension) wraps, and
`FIELD: document` for any other module a model holds (e.g. the parameter surface of
`jaxcable.LiveFiveElement`). Class names are those of the model registry (every
class that declares a `CLI_NAME`) and of `PARTS`.
"""

import dataclasses
from collections.abc import Mapping
from typing import Any

import equinox as eqx
import numpy as np

from .._models import CLASSES_BY_NAME, AbstractCableModel, ParameterSurface


PARTS: dict[str, type] = {ParameterSurface.__name__: ParameterSurface}
"""The modules other than models that a model may hold as a field, by class name."""


def model_document(model: eqx.Module) -> dict[str, Any]:
    """The JSON document of `model`.

    **Arguments:**

    - `model`: any registered model, possibly wrapping others.

    **Returns:**

    `{"model", "parameters", "static"[, "base"]}`: every inexact-array field as a
    number (a list for a per-test batch), every bool, int, float or str field (or
    tuple of them, as a list) in `static`, and each wrapped model (or other module)
    as its own document.
    """
    parameters = {}
    static = {}
    document: dict[str, Any] = {"model": type(model).__name__}
    for field in dataclasses.fields(model):
        value = getattr(model, field.name)
        if eqx.is_inexact_array(value):
            v = np.asarray(value, float)
            parameters[field.name] = float(v) if v.ndim == 0 else [float(x) for x in v]
        elif isinstance(value, eqx.Module):
            document[field.name] = model_document(value)
        elif _is_setting(value):
            static[field.name] = list(value) if isinstance(value, tuple) else value
    return {**document, "parameters": parameters, "static": static}


def _is_setting(value) -> bool:
    """Whether a static field's value is written: a bool, int, float or str, or a
    tuple of them (e.g. the terms of a `DiscoveredTerm`, a JSON list)."""
    if isinstance(value, tuple):
        return all(_is_setting(v) and not isinstance(v, tuple) for v in value)
    return isinstance(value, (bool, int, float, str))


def unknown_model(document: Mapping[str, Any]) -> str | None:
    """The first class name in `document` or its wrapped models' documents that
    jaxcable does not know, as an error message; None when all are known."""
    sub = document
    while isinstance(sub, dict):
        if sub.get("model") not in CLASSES_BY_NAME:
            return (
                f"unknown model {sub.get('model')!r}; known: {sorted(CLASSES_BY_NAME)}."
            )
        sub = sub.get("base")
    return None


def _class_of(name) -> type:
    return PARTS[name] if name in PARTS else CLASSES_BY_NAME[name]


def model_from_document(document: Mapping[str, Any]) -> AbstractCableModel:
    """The model of a document of `model_document`, its parameters as NumPy arrays.

    The class names must be known (see `unknown_model`); a missing or wrong field
    raises `KeyError`, `TypeError` or `ValueError`.
    """
    fields: dict[str, Any] = {
        k: np.asarray(v, float) for k, v in document["parameters"].items()
    }
    for key, value in document.items():
        if key not in ("parameters", "static") and isinstance(value, dict):
            fields[key] = model_from_document(value)
    static = {
        k: tuple(v) if isinstance(v, list) else v
        for k, v in document.get("static", {}).items()
    }
    return _class_of(document["model"])(**fields, **static)
