"""The last stage of [`jaxcable.diagnose`][]: the verdict on the scored candidates
([`decide`][]) and the [`jaxcable.Diagnosis`][] it gives."""

import dataclasses
from collections.abc import Sequence

from .._fit import test_id
from .._models import AbstractCableModel
from .base import BaseFit
from .diverging import departure
from .plan import Plan
from .result import Candidate, Diagnosis
from .stage import Discovered
from .verdict import Verdict, decide, diverges, explained_rmse_pct


def verdict(base: BaseFit, noise: float, candidates: Sequence[Candidate]) -> Verdict:
    """The verdict on `candidates` ([`decide`][])."""
    return decide(
        base.score.heldout_rmse,
        noise,
        [c.heldout_rmse for c in candidates],
        [c.significant for c in candidates],
        base.structure["autocorrelation"],
    )


def conclude(
    plan: Plan,
    model: AbstractCableModel | str,
    base: BaseFit,
    candidates: Sequence[Candidate],
    decision: Verdict,
    noise: float,
    discovered: Discovered | None,
) -> Diagnosis:
    """The [`jaxcable.Diagnosis`][] of one round's stages: each candidate with its
    shares of the excess (on squares and on RMSEs) and, when it diverges, where;
    the named cause (or `"none"` / `"unexplained"`) and its effect. `model`: the
    base model, or its name."""
    held = base.score.heldout_rmse
    out = tuple(
        dataclasses.replace(
            c,
            explained_pct=share,
            explained_rmse_pct=explained_rmse_pct(held, c.heldout_rmse, noise),
            diverging=(
                departure(plan, base, c)
                if c.applicable and diverges(held, c.heldout_rmse)
                else ""
            ),
        )
        for c, share in zip(candidates, decision.explained_pct)
    )
    if decision.named is not None:
        best = out[decision.named]
        named, extended, gain = best.id, best.heldout_rmse, best.gain_pct
        effect = {
            "parameter": best.size_name,
            "value": best.size,
            "stderr": best.size_stderr,
            "unit": best.size_unit,
        }
    else:
        named = "unexplained" if decision.verdict == "unexplained" else "none"
        extended, gain, effect = held, 0.0, {}
    return Diagnosis(
        base_model=model if isinstance(model, str) else type(model).__name__,
        named_cause=named,
        base_heldout_rmse=held,
        base_train_rmse=base.score.train_rmse,
        extended_heldout_rmse=extended,
        gain_pct=gain,
        effect=effect,
        candidates=out,
        structure=base.structure,
        noise=noise,
        split=plan.split_text(),
        holdout=plan.holdout if plan.split == "time" else None,
        test_ids=tuple(test_id(t, i) for i, t in enumerate(plan.tests)),
        base_fit=base.fit,
        unit=plan.how.unit,
        drives=plan.how.drives,
        scales=tuple(float(x) for x in plan.how.scales),
        verdict=decision.verdict,
        discovered={} if discovered is None else discovered.description,
        covariate=plan.how.covariate,
    )
