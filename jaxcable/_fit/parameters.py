"""Which parameters of a model are fitted, and how: the layout of the unconstrained
vector u and the reparameterisation x = f(u) of each parameter.

How each field is fitted (transform, unit, stiffness power) is read from the model
classes' declarations (`parameter_info`); this module names the fields of nested models by their
path (`base.E1`) and maps between u and natural values.
"""

import dataclasses
import math
from collections.abc import Mapping
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, PyTree

from .._models import AbstractCableModel, ParameterInfo, parameter_info


# A start exactly on the bound of "log1" / "tanh" (e.g. the Bouc-Wen default n = 1) is
# moved inside by this much, so that its unconstrained value is finite.
_BOUND_NUDGE = 1e-2


def field_at(obj, path: str) -> Any:
    """`obj.a.b` for the path `"a.b"`."""
    for part in path.split("."):
        obj = getattr(obj, part)
    return obj


def bound_of(transform: str) -> str | None:
    """The path of the parameter bounding a `"tanh:OTHER"` transform (`OTHER`), else
    None."""
    return transform.split(":", 1)[1] if transform.startswith("tanh:") else None


def _info(owner: AbstractCableModel, field: str, prefix: str) -> ParameterInfo | None:
    """How `field` of `owner` is fitted, with a `tanh` bound named by its full path."""
    info = parameter_info(type(owner), field)
    other = None if info is None else bound_of(info.transform)
    if info is not None and other is not None:
        # The bound is a sibling parameter: name it by its full path.
        info = dataclasses.replace(info, transform="tanh:" + prefix + other)
    return info


def declared_parameters(
    model: AbstractCableModel, prefix: str = ""
) -> dict[str, ParameterInfo | None]:
    """The fittable parameters of `model`.

    **Arguments:**

    - `model`: any cable model, possibly wrapping others.
    - `prefix`: prepended to every path (used for the recursion).

    **Returns:**

    `{path: fit info}` of every inexact-array field, in field order, descending into
    wrapped models: a wrapper's own fields are named as they are, its base's as
    `base.NAME` (`base.base.NAME`, ... for deeper nesting). The info is None for a
    field the registry does not describe.
    """
    out = {}
    for f in dataclasses.fields(model):
        value = getattr(model, f.name)
        if eqx.is_inexact_array(value):
            out[prefix + f.name] = _info(model, f.name, prefix)
        elif isinstance(value, AbstractCableModel):
            out.update(declared_parameters(value, prefix + f.name + "."))
    return out


def test_slice(tree: PyTree, index: int) -> PyTree:
    """Test `index`'s values of a tree with per-test parameters: entry `index` of every
    leaf of shape `(tests,)`, every other leaf as it is. A module inside a model that
    is no model itself (a parameter surface) is kept whole: its leaves are not
    parameters."""

    def part(x) -> bool:
        return isinstance(x, eqx.Module) and not isinstance(x, AbstractCableModel)

    return jax.tree_util.tree_map(
        lambda x: x if part(x) else x[index] if np.ndim(x) == 1 else x,
        tree,
        is_leaf=part,
    )


@dataclasses.dataclass(frozen=True)
class Layout:
    """Which parameters are fitted and how (hashable: the static part of the kernel).

    The unconstrained vector u holds the shared parameters, one entry each, then the
    per-test parameters, `num_tests` entries each, in the order of `names`.

    **Fields:**

    - `names`: the fitted parameters' paths, in the model's field order.
    - `per_test`: for each name, whether it takes one value per test.
    - `transforms`: for each name, its reparameterisation (see `to_natural`).
    - `stiffness`: for each name, the power of the stiffness factor of the start.
    - `units`: for each name, its SI unit.
    - `num_tests`: the number of tests.
    """

    names: tuple[str, ...]
    per_test: tuple[bool, ...]
    transforms: tuple[str, ...]
    stiffness: tuple[float, ...]
    units: tuple[str, ...]
    num_tests: int

    @property
    def sizes(self) -> tuple[int, ...]:
        """The number of entries of u of each name."""
        return tuple(self.num_tests if p else 1 for p in self.per_test)

    @property
    def size(self) -> int:
        """The length of u."""
        return sum(self.sizes)

    @property
    def labels(self) -> tuple[str, ...]:
        """A label for each entry of u: the name, `name[i]` for test i's value."""
        out = []
        for name, p in zip(self.names, self.per_test):
            out.extend([f"{name}[{i}]" for i in range(self.num_tests)] if p else [name])
        return tuple(out)

    def split(self, u: Float[Array, " p"]) -> dict[str, Array]:
        """Flat u -> {name: scalar (shared) or (num_tests,) array (per test)}."""
        out = {}
        start = 0
        for name, p, size in zip(self.names, self.per_test, self.sizes):
            out[name] = u[start : start + size] if p else u[start]
            start += size
        return out

    def join(self, values: Mapping[str, Any]) -> Float[Array, " p"]:
        """{name: value} -> flat u (the inverse of `split`)."""
        parts = [
            jnp.broadcast_to(jnp.asarray(values[n]), (s,))
            if p
            else jnp.reshape(jnp.asarray(values[n]), (1,))
            for n, p, s in zip(self.names, self.per_test, self.sizes)
        ]
        return jnp.concatenate(parts)


def to_natural(transform: str, u, scale, bound):
    """The natural value x = f(u) of one parameter.

    **Arguments:**

    - `transform`: `"log"` (x = exp(u), x > 0), `"log1"` (x = 1 + exp(u), x > 1),
        `"linear"` (x = scale u) or `"tanh:OTHER"` (x = bound tanh(u), |x| < bound).
    - `u`: the unconstrained value (traced).
    - `scale`: the scale of `"linear"`, |start value| (or 1 for a zero start).
    - `bound`: the value of the bounding parameter of `"tanh:OTHER"` (else unused).

    **Returns:**

    x.
    """
    if transform == "log":
        return jnp.exp(u)
    if transform == "log1":
        return 1.0 + jnp.exp(u)
    if transform == "linear":
        return scale * u
    return bound * jnp.tanh(u)  # "tanh:OTHER"


def to_unconstrained(transform: str, x: float, scale: float, bound) -> float:
    """The unconstrained start u = f^-1(x) of one parameter (host-side), the inverse of
    `to_natural`; a start on the bound of `"log1"` or `"tanh"` is moved `_BOUND_NUDGE`
    inside."""
    if transform == "log":
        return math.log(x)
    if transform == "log1":
        return math.log(max(x - 1.0, _BOUND_NUDGE))
    if transform == "linear":
        return x / scale
    ratio = min(max(x / bound, -1 + _BOUND_NUDGE), 1 - _BOUND_NUDGE)
    return math.atanh(ratio)
