"""The last step of the rounds of [`jaxcable.diagnose`][]: every cause found before the
last one is tried out again, with the later ones in the model.

A cause named early may only have stood in for one found later (a second retardation
time for a creep that comes with humidity changes, named before the discovery found
the humidity's term). With every later cause in the model, each earlier one is
switched off (its size at its null value) and the rest refitted: the cause is kept
when removing it costs the held-out gain and the BIC a cause needs to be named
(`MIN_GAIN_PCT`, `MAX_DELTA_BIC`); else it is dropped, and the model without it is
the final one.
"""

import dataclasses
import math

import equinox as eqx
import jax.numpy as jnp

from .._fit import FitResult, field_at
from .._models import DiscoveredTerm
from .._problem import LeastSquares, Problem
from .methods import fit_quietly
from .plan import Plan
from .rule import MAX_DELTA_BIC, MIN_GAIN_PCT
from .scoring import bic


@dataclasses.dataclass(frozen=True)
class Pruned:
    """What the pruning kept.

    **Fields:**

    - `kept`: for each cause, whether it stays.
    - `fit`: the fit of the final model (the last round's when nothing was
        dropped).
    - `heldout_rmse`: its held-out RMSE, in the diagnosis's unit.
    - `notes`: for each cause, why it was dropped ("" when kept).
    """

    kept: tuple[bool, ...]
    fit: FitResult
    heldout_rmse: float
    notes: tuple[str, ...]


def _layer_prefix(count: int, i: int) -> str:
    """The path prefix of cause `i` of `count` in the final model (the last cause
    outermost), with a trailing dot ('' for the outermost)."""
    return "base." * (count - 1 - i)


def switched_off(model, prefix: str):
    """`model` with the extension at `prefix` at its null effect: every theta 0 for a
    discovered term, else its size at `SIZE_NULL`."""
    layer = field_at(model, prefix[:-1]) if prefix else model
    if isinstance(layer, DiscoveredTerm):
        names = layer.used_fields()
        values = [jnp.zeros_like(getattr(layer, n)) for n in names if "theta" in n]
        names = [n for n in names if "theta" in n]
    else:
        names = [type(layer).SIZE_FIELD]
        null = type(layer).SIZE_NULL
        values = [jnp.asarray(null, jnp.result_type(getattr(layer, names[0])))]
    off = eqx.tree_at(lambda m: [getattr(m, n) for n in names], layer, values)
    if not prefix:
        return off, names
    return eqx.tree_at(lambda m: field_at(m, prefix[:-1]), model, off), names


def prune(
    plan: Plan, final: FitResult, heldout: float, count: int, method: LeastSquares
) -> Pruned:
    """Try each cause but the last out of the final model (see the module's
    description); on the time split only (cross-validation by tests keeps every
    cause).

    **Arguments:**

    - `plan`: the last round's [`Plan`][] (its training and held-out samples).
    - `final`: the last round's named candidate's fit: every cause in its model,
        the last one outermost.
    - `heldout`: its held-out RMSE.
    - `count`: how many causes wrap the user's base in it.
    - `method`: the refits' [`jaxcable.LeastSquares`][].

    **Returns:**

    A [`Pruned`][].
    """
    kept = [True] * count
    notes = [""] * count
    if plan.split != "time" or count < 2:
        return Pruned(tuple(kept), final, heldout, tuple(notes))
    how = plan.how
    held = [t.mask for t in plan.time_fold.held]
    current, current_rmse = final, heldout
    for i in range(count - 1):
        prefix = _layer_prefix(count, i)
        model, _ = switched_off(current.model, prefix)
        layer = {prefix + f for f in _layer_fields(current, prefix)}
        names = [
            n
            for n in dict.fromkeys(x.split("[")[0] for x in current.names)
            if n not in layer
        ]
        reduced = fit_quietly(
            Problem(
                model,
                plan.time_fold.train,
                fit=names,
                drive=how.drive_names,
                covariate=how.covariate,
            ),
            method,
        )
        if not math.isfinite(reduced.loss):
            continue
        rmse = how.rmse(reduced.model, plan.tests, range(len(plan.tests)), held)
        gain = 100.0 * (rmse - current_rmse) / rmse if rmse > 0 else 0.0
        n = int(sum(int(m.sum()) for m in (t.mask for t in plan.time_fold.train)))
        delta = bic(_train_rmse(current, n), n, len(current.names), 1.0) - bic(
            _train_rmse(reduced, n), n, len(reduced.names), 1.0
        )
        if gain < MIN_GAIN_PCT or delta > MAX_DELTA_BIC:
            kept[i] = False
            notes[i] = (
                f"dropped: with the causes found after it, it adds {gain:.1f} % of "
                f"held-out gain and dBIC {delta:.1f}"
            )
            current, current_rmse = reduced, rmse
    return Pruned(tuple(kept), current, current_rmse, tuple(notes))


def _layer_fields(result: FitResult, prefix: str) -> tuple[str, ...]:
    """The effect fields of the layer at `prefix` of `result.model`."""
    layer = field_at(result.model, prefix[:-1]) if prefix else result.model
    if isinstance(layer, DiscoveredTerm):
        return layer.used_fields()
    return type(layer).EFFECT_FIELDS


def _train_rmse(result: FitResult, n: int) -> float:
    """The training RMSE of a fit in its residual unit, from its loss."""
    return math.sqrt(float(result.loss) / max(n, 1))
