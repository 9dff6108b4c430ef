"""The third stage of [`jaxcable.diagnose`][]: every candidate of the catalogue
([`jaxcable.EXTENSIONS`][]) fitted around the base and scored like it."""

from .._models import EXTENSIONS, AbstractCableModel, with_data_reference
from .._progress import AbstractProgressMeter
from .base import BaseFit
from .plan import Plan
from .result import Candidate, shift_reference
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
        starts = [
            stack.model(m, ext_id) for m in [model, *(r.model for r in base.score.fits)]
        ]
        try:
            scored, note = _score_at_reference(plan, base, ext_id, starts, losses)
        except ValueError as first:
            # The start given fails on a test (a base of another family, a start
            # outside the extension's domain): from the fitted base alone.
            try:
                starts = [starts[1], *starts[1:]]
                scored, note = _score_at_reference(plan, base, ext_id, starts, losses)
            except ValueError:
                reason = f"its fit failed: {str(first).splitlines()[0]}"
                out.append(Candidate.not_applicable(ext_id, cls, reason, plan.how.unit))
                continue
            note = (
                note + "; " if note else ""
            ) + "from the fitted base (the start fails)"
        result = scored.fits[0]
        out.append(
            scored_candidate(
                ext_id,
                result,
                (scored.heldout_rmse, scored.train_rmse, scored.num_train),
                size_of(result, cls.SIZE_FIELD, cls.SIZE_UNIT),
                note,
                base.against,
                plan.how,
            )
        )
    return tuple(out)


def _score_at_reference(plan: Plan, base: BaseFit, ext_id: str, starts, losses):
    """`(score, note)` of the candidate `ext_id` from `starts` (the stack with it
    on, from the user's start and from each fold's base fit).

    A time shift (a = 1 at its reference) is also scored with its reference at the
    data's median temperature ([`jaxcable.with_data_reference`][]): the base's time
    scales that are not refitted (eta0, t_c, the Eq. 8 lambdas) belong to the
    shift's reference, off by a(T) for the whole data when that is not the data's
    (1.28 for 60 kJ/mol at 23 °C against the default 20 °C). The one that fits the
    training data better is kept (the median on a tie); the note says which."""

    def score(models):
        return score_folds(
            plan.parts,
            lambda k: [models[0], models[1 + k]],
            base.fitter(ext_id),
            base_losses=losses,
            how=plan.how,
            same_tests=plan.split == "time",
        )

    moved = [with_data_reference(m, plan.tests) for m in starts]
    median = shift_reference(base.stack.own_model(moved[0], ext_id))
    own = shift_reference(base.stack.own_model(starts[0], ext_id))
    if not median or abs(median["value"] - own["value"]) < 0.05:
        return score(moved), _reference_note(median, "the tests' median")
    at_median, as_given = score(moved), score(starts)
    if as_given.train_rmse < at_median.train_rmse:
        return as_given, _reference_note(
            own,
            f"the start's; it fits the training data better than at the "
            f"tests' median, {median['value'] - 273.15:.1f} °C",
        )
    return at_median, _reference_note(median, "the tests' median")


def _reference_note(ref: dict, why: str) -> str:
    """The note of a time shift's candidate: where its reference is, and why."""
    if ref.get("field") != "T_ref":
        return ""
    at = f"{ref['celsius']:.1f} °C"
    return f"reference {at} ({why}): its base is the material at {at}"
