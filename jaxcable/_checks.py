"""Validation at the Python boundary: raise `ValueError` naming the argument and the
value before anything is traced or compiled. Traced values (inside a user's `jit` or
`vmap`) are skipped here; the kernels flag them with `RESULTS` instead."""

import jax
import numpy as np


def is_concrete(*xs) -> bool:
    return not any(
        isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(xs)
    )


def _show(v) -> str:
    v = np.asarray(v)
    return np.array2string(v, threshold=6, precision=6)


def require_finite(name: str, value) -> None:
    v = np.asarray(value, dtype=float)
    bad = ~np.isfinite(v)
    if np.any(bad):
        idx = int(np.flatnonzero(bad.ravel())[0])
        raise ValueError(
            f"`{name}` must be finite; element {idx} is {v.ravel()[idx]} "
            f"(value {_show(v)})."
        )


def require_positive(name: str, value, *, allow_zero: bool = False) -> None:
    require_finite(name, value)
    v = np.asarray(value, dtype=float)
    bad = v < 0 if allow_zero else v <= 0
    if np.any(bad):
        idx = int(np.flatnonzero(bad.ravel())[0])
        kind = "non-negative" if allow_zero else "positive"
        raise ValueError(
            f"`{name}` must be {kind}; element {idx} is {v.ravel()[idx]} "
            f"(value {_show(v)})."
        )


def require_samples(name: str, value, ndim: int = 1) -> np.ndarray:
    v = np.asarray(value)
    if v.ndim != ndim:
        raise ValueError(
            f"`{name}` must be {ndim}-dimensional (samples), got shape {v.shape}. "
            "For a batch of histories, `jax.vmap` over the leading axis."
        )
    if v.shape[-1] == 0:
        raise ValueError(f"`{name}` is empty: a history needs at least one sample.")
    return v


def require_same_shape(**arrays) -> None:
    shapes = {k: np.shape(v) for k, v in arrays.items() if v is not None}
    if len(set(shapes.values())) > 1:
        desc = ", ".join(f"`{k}` {s}" for k, s in shapes.items())
        raise ValueError(f"Mismatched shapes: {desc}; they must be equal.")


def require_increasing(name: str, value, mask=None) -> None:
    v = np.asarray(value, dtype=float)
    if mask is not None:
        v = v[np.asarray(mask, dtype=bool)]
    d = np.diff(v)
    if np.any(d <= 0):
        idx = int(np.flatnonzero(d <= 0)[0]) + 1
        raise ValueError(
            f"`{name}` must be strictly increasing; sample {idx} is {v[idx]} after "
            f"{v[idx - 1]}."
        )


def require_below(name: str, value, limit, limit_name: str) -> None:
    v = np.asarray(value, dtype=float)
    lim = float(np.max(np.asarray(limit)))
    if np.any(v > lim):
        idx = int(np.flatnonzero(v.ravel() > lim)[0])
        raise ValueError(
            f"`{name}` exceeds the cable's {limit_name} ({lim:g} N): element {idx} is "
            f"{v.ravel()[idx]:g} N."
        )


def check_parameters(
    model_name: str,
    model,
    names,
    *,
    positive: bool = True,
    allow_zero: bool = False,
    reason: str = "",
) -> None:
    """Raise `ValueError` naming the first concrete parameter field that is not finite
    (and, with `positive`, not > 0, or not >= 0 with `allow_zero`).

    The one construction-time check of every model's parameters. Traced fields (a
    model built inside `jit`, `vmap` or `grad`) are skipped: the model's traced
    `check` flags them with `RESULTS.parameter_out_of_domain` instead.

    **Arguments:**

    - `model_name`: the class name, for the message (`IntegratedModel.E1c`).
    - `model`: the model (any object with the fields as attributes).
    - `names`: the field names to check.
    - `positive`, `allow_zero`: the sign required besides finiteness.
    - `reason`: appended to the message (why the domain is what it is).
    """
    for name in names:
        value = getattr(model, name)
        if not is_concrete(value):
            continue
        label = f"{model_name}.{name}"
        try:
            if positive:
                require_positive(label, value, allow_zero=allow_zero)
            else:
                require_finite(label, value)
        except (TypeError, ValueError) as e:
            raise ValueError(f"{e} {reason}".rstrip()) from None
