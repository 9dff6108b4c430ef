"""A model as a JSON document and back: the model part of a PARAMS.json.

A document is `{"model": class name, "parameters": {field: number or list},
"static": {field: bool, int, float or str}}`, with `"base": document` for the model a
wrapper (an extension) wraps. Class names are those of the model registry.
"""

import dataclasses
from collections.abc import Mapping
from typing import Any

import equinox as eqx
import numpy as np

from .._models import CLASSES_BY_NAME, AbstractCableModel


def model_document(model: AbstractCableModel) -> dict[str, Any]:
    """The JSON document of `model`.

    **Arguments:**

    - `model`: any registered model, possibly wrapping others.

    **Returns:**

    `{"model", "parameters", "static"[, "base"]}`: every inexact-array field as a
    number (a list for a per-test batch), every bool, int, float or str field in
    `static`, and each wrapped model as its own document.
    """
    parameters = {}
    static = {}
    document: dict[str, Any] = {"model": type(model).__name__}
    for field in dataclasses.fields(model):
        value = getattr(model, field.name)
        if eqx.is_inexact_array(value):
            v = np.asarray(value, float)
            parameters[field.name] = float(v) if v.ndim == 0 else [float(x) for x in v]
        elif isinstance(value, AbstractCableModel):
            document[field.name] = model_document(value)
        elif isinstance(value, (bool, int, float, str)):
            static[field.name] = value
    return {**document, "parameters": parameters, "static": static}


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


def model_from_document(document: Mapping[str, Any]) -> AbstractCableModel:
    """The model of a document of `model_document`, its parameters as NumPy arrays.

    The class names must be known (see `unknown_model`); a missing or wrong field
    raises `KeyError`, `TypeError` or `ValueError`.
    """
    fields: dict[str, Any] = {
        k: np.asarray(v, float) for k, v in document["parameters"].items()
    }
    if "base" in document:
        fields["base"] = model_from_document(document["base"])
    return CLASSES_BY_NAME[document["model"]](**fields, **document.get("static", {}))
