"""The one validation system: the checks of inputs and model parameters.

Two halves with the same domains:

- at the Python boundary (`require_*`, [`check_parameter`][]): raise `ValueError`
    naming the argument and the value before anything is traced or compiled. Traced
    values (inside a user's `jit`, `vmap` or `grad`) are skipped here;
- traced ([`parameter_ok`][], [`all_ok`][], [`domain_result`][]): the boolean and
    the `RESULTS` member that a model's `check` returns, so that the kernels flag
    what the Python boundary could not see.
"""

import jax
import jax.core  # jax imports it; named here for a type checker
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool

from ._results import RESULTS


def is_concrete(*xs) -> bool:
    """True unless a leaf of `xs` is a tracer (inside `jit`, `vmap` or `grad`)."""
    return not any(
        isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(xs)
    )


def _show(v) -> str:
    v = np.asarray(v)
    return np.array2string(v, threshold=6, precision=6)


# A parameter's domain, by name: whether +inf is admitted and the sign required
# besides (None: any finite value).
DOMAINS: dict[str, tuple[bool, str | None]] = {
    "positive": (False, "positive"),
    "nonnegative": (False, "non-negative"),
    "positive_or_inf": (True, "positive"),
    "any": (False, None),
}


def _require(name: str, v: np.ndarray, bad: np.ndarray, kind: str) -> None:
    if np.any(bad):
        idx = int(np.flatnonzero(bad.ravel())[0])
        raise ValueError(
            f"`{name}` must be {kind}; element {idx} is {v.ravel()[idx]} "
            f"(value {_show(v)})."
        )


def require_finite(name: str, value, *, allow_inf: bool = False) -> None:
    """Raise `ValueError` naming `name` unless every element of `value` is finite
    (with `allow_inf`: is not NaN)."""
    v = np.asarray(value, dtype=float)
    bad = np.isnan(v) if allow_inf else ~np.isfinite(v)
    _require(name, v, bad, "a number (not NaN)" if allow_inf else "finite")


def require_positive(
    name: str, value, *, allow_zero: bool = False, allow_inf: bool = False
) -> None:
    """Raise `ValueError` naming `name` unless every element of `value` is finite
    (or +inf, with `allow_inf`) and > 0 (>= 0 with `allow_zero`)."""
    require_finite(name, value, allow_inf=allow_inf)
    v = np.asarray(value, dtype=float)
    bad = v < 0 if allow_zero else v <= 0
    _require(name, v, bad, "non-negative" if allow_zero else "positive")


def is_int(value) -> bool:
    """Whether `value` is an `int` or NumPy integer, not a `bool`."""
    return isinstance(value, int | np.integer) and not isinstance(
        value, bool | np.bool_
    )


def is_number(value) -> bool:
    """Whether `value` is an `int`, `float` or NumPy number, not a `bool`."""
    return isinstance(value, int | float | np.integer | np.floating) and not isinstance(
        value, bool | np.bool_
    )


def require_int(
    name: str, value, low: int | None = None, high: int | None = None
) -> int:
    """The one check of a count or an index given at the Python boundary (a field of
    a method, a reader's option, a command-line flag).

    **Arguments:**

    - `name`: the argument or field, for the message.
    - `value`: an `int` or NumPy integer (`bool` refused).
    - `low`, `high`: the inclusive bounds, or `None` for none.

    **Returns:**

    `value` as an `int`.

    **Raises:**

    `TypeError` naming `name` unless `value` is an integer; `ValueError` naming it
    when it is outside the bounds.
    """
    if not is_int(value):
        raise TypeError(f"`{name}` must be an integer, got {value!r}.")
    if low is not None and value < low:
        raise ValueError(f"`{name}` must be >= {low}, got {value!r}.")
    if high is not None and value > high:
        raise ValueError(f"`{name}` must be <= {high}, got {value!r}.")
    return int(value)


def require_number(
    name: str,
    value,
    low: float | None = None,
    high: float | None = None,
    *,
    strict: bool = False,
) -> float:
    """The one check of a scalar number given at the Python boundary (a threshold,
    a frequency, a spread).

    **Arguments:**

    - `name`: the argument or field, for the message.
    - `value`: an `int`, `float` or NumPy number (`bool` refused).
    - `low`, `high`: the bounds, or `None` for none; inclusive unless `strict`.
    - `strict`: whether `value` must exceed `low` (fall below `high`), not equal it.

    **Returns:**

    `value` as a `float`.

    **Raises:**

    `TypeError` naming `name` unless `value` is a number; `ValueError` naming it
    unless it is finite and within the bounds.
    """
    if not is_number(value):
        raise TypeError(f"`{name}` must be a number, got {type(value).__name__}.")
    v = float(value)
    bounds = []
    if low is not None:
        bounds.append((v > low) if strict else (v >= low))
    if high is not None:
        bounds.append((v < high) if strict else (v <= high))
    if not (np.isfinite(v) and all(bounds)):
        parts = ["finite"]
        if low is not None:
            parts.append(f"{'>' if strict else '>='} {low:g}")
        if high is not None:
            parts.append(f"{'<' if strict else '<='} {high:g}")
        kind = (
            ", ".join(parts[:-1]) + " and " + parts[-1] if len(parts) > 1 else "finite"
        )
        raise ValueError(f"`{name}` must be {kind}, got {value!r}.")
    return v


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


def check_parameter(
    owner: str, name: str, value, domain: str, *, qualified: bool, reason: str = ""
) -> None:
    """Raise `ValueError` naming the parameter unless its concrete `value` is in
    `domain` (a key of [`DOMAINS`][]).

    The one construction-time check of every model's parameters. A traced value (a
    model built inside `jit`, `vmap` or `grad`) is skipped: the model's traced
    `check` flags it with `RESULTS.parameter_out_of_domain` instead (see
    [`parameter_ok`][], which takes the same domain).

    **Arguments:**

    - `owner`: the class name, for the message.
    - `name`, `value`: the field and its value.
    - `domain`: `"positive"`, `"nonnegative"`, `"positive_or_inf"` (a modulus whose
        element inf switches off) or `"any"` (finite).
    - `qualified`: name the field `` `Model.field` `` (the models); with False,
        `` Model `field` ``: the wrappers, whose fields a fit names by their own name.
    - `reason`: appended to the message (why the domain is what it is, the unit).
    """
    if not is_concrete(value):
        return
    allow_inf, sign = DOMAINS[domain]
    label = f"{owner}.{name}" if qualified else name
    prefix = "" if qualified else f"{owner} "
    try:
        if sign is None:
            require_finite(label, value, allow_inf=allow_inf)
        else:
            require_positive(
                label, value, allow_zero=sign == "non-negative", allow_inf=allow_inf
            )
    except (TypeError, ValueError) as e:
        raise ValueError(f"{prefix}{e} {reason}".rstrip()) from None


def all_ok(*conditions) -> Bool[Array, ""]:
    """True where every condition holds for every element (traced)."""
    ok = jnp.array(True)
    for c in conditions:
        ok = ok & jnp.all(c)
    return ok


def parameter_ok(value, domain: str) -> list[Bool[Array, "*shape"]]:
    """The traced counterpart of [`check_parameter`][]: the conditions (elementwise)
    of `value` being in `domain`."""
    allow_inf, sign = DOMAINS[domain]
    conditions = [~jnp.isnan(value) if allow_inf else jnp.isfinite(value)]
    if sign is not None:
        conditions.append(value >= 0 if sign == "non-negative" else value > 0)
    return conditions


def domain_result(ok: Bool[Array, ""], result: RESULTS = RESULTS.successful) -> RESULTS:
    """`result` where `ok`, else `RESULTS.parameter_out_of_domain` (traced)."""
    return RESULTS.where(ok, result, RESULTS.parameter_out_of_domain)


def unknown_names(names, known) -> tuple[list, bool]:
    """The members of `names` that are not strings in `known`, in order, and whether
    a name is repeated."""
    unknown = [n for n in names if not isinstance(n, str) or n not in known]
    return unknown, len(set(names)) != len(names)


def require_names(argname: str, names, known, owner: str, what: str) -> tuple:
    """Raise `ValueError` naming `argname` unless `names` are distinct members of
    `known` (the `what` of `owner`, e.g. "parameters" of "BurgersModel"); return them
    as a tuple."""
    names = tuple(names)
    unknown, repeated = unknown_names(names, known)
    if unknown:
        raise ValueError(
            f"`{argname}` names {unknown}, which are not {what} of {owner}; its "
            f"{what} are {list(known)}."
        )
    if repeated:
        raise ValueError(f"`{argname}` repeats a name: {list(names)}.")
    return names
