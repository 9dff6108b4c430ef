"""The third stage of [`jaxcable.diagnose`][]: every candidate of the catalogue
([`jaxcable.EXTENSIONS`][]) fitted around the base and scored like it."""

from .._models import EXTENSIONS, AbstractCableModel
from .._models.extensions.temperature import with_data_reference
from .._progress import AbstractProgressMeter
from .base import BaseFit
from .plan import Plan
from .result import Candidate
from .scoring import score_folds, scored_candidate, size_of


def score_catalogue(
    plan: Plan,
    model: AbstractCableModel,
    base: BaseFit,
    *,
    progress_meter: AbstractProgressMeter,
) -> tuple[Candidate, ...]:
    """Fit and score every catalogue candidate of `plan` around the base `model`;
    those the data cannot show or the base cannot carry are not applicable."""
    stack, losses = base.stack, [r.loss for r in base.score.fits]
    out = []
    for ext_id in plan.ids:
        cls = EXTENSIONS[ext_id]
        if plan.reasons[ext_id] or ext_id not in stack.ids:
            reason = (
                plan.reasons[ext_id] or f"{cls.__name__} cannot wrap the base model"
            )
            out.append(Candidate.not_applicable(ext_id, cls, reason, plan.how.unit))
            continue
        progress_meter.say(f"fitting candidate {ext_id}")
        # From the user's start (not the base fit, which has absorbed part of the
        # effect into the base's parameters and is often a local minimum for the
        # extended model), then from the base fit when that fits the training data
        # worse than the base did. The candidates refit the base's fitted
        # parameters plus their own effect fields, never the extension's fixed ones.
        # A time shift's reference at the data's median temperature: the base's
        # time scales that are not refitted then belong to the data.
        starts = [
            with_data_reference(stack.model(m, ext_id), plan.tests)
            for m in [model, *(r.model for r in base.score.fits)]
        ]
        scored = score_folds(
            plan.parts,
            lambda k: [starts[0], starts[1 + k]],
            base.fitter(ext_id),
            base_losses=losses,
            how=plan.how,
            same_tests=plan.split == "time",
        )
        result = scored.fits[0]
        out.append(
            scored_candidate(
                ext_id,
                result,
                (scored.heldout_rmse, scored.train_rmse, scored.num_train),
                size_of(result, cls.SIZE_FIELD, cls.SIZE_UNIT),
                "",
                base.against,
                plan.how,
            )
        )
    return tuple(out)
