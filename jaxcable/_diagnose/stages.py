"""One round of [`jaxcable.diagnose`][]: a pipeline of stages over one round state.

Each stage takes the `Round` so far and gives it back with its part filled in:

1. `plan_stage`: the candidates the data can show, the held-out split, the base
    fitted on the training parts and scored on every fold, and the noise estimated
    from the data;
2. `family_stage` (the first round only): the base's family checked
    (`check_family`); the round runs on the family the data want;
3. `catalogue_stage`: every candidate of the catalogue fitted around the base and
    scored;
4. `covariates_stage`: the forms a recorded covariate drives (on the time split of
    force-driven tests);
5. `verdict_stage`: the rule on the scored candidates (`decide`);
6. `discovery_stage`: a discovered term, when the verdict would be
    `"unexplained"`, when it is asked for, or when the named cause leaves a
    recorded covariate unused; the verdict again with it.

`conclude` then gives the round's [`jaxcable.Diagnosis`][].
"""

import dataclasses
import math
from collections.abc import Sequence

from .._fit import test_id
from .._problem import Problem
from .._progress import AbstractProgressMeter
from .base import BaseFit, fit_base
from .candidates import (
    Discovered,
    covariate_candidates,
    departure,
    discovered_candidate,
    score_catalogue,
)
from .diagnosis import Candidate, Diagnosis
from .family import FamilyCheck, check_family
from .methods import CandidateSearch
from .plan import Plan, choose_candidates
from .rule import (
    MIN_EXCESS,
    MIN_GAIN_PCT,
    Verdict,
    decide,
    diverges,
    explained_rmse_pct,
)
from .scoring import noise_floor


@dataclasses.dataclass(frozen=True)
class RoundBase:
    """The base of one round.

    **Fields:**

    - `problem`: the base model with its start values (the previous round's fit),
        its parameters to fit (None: the registry's identifiable set), the tests,
        their drives and the extra column it reads (or None).
    - `label`: its name in the summary, e.g. `IntegratedModel + sensor_drift`.
    - `exclude`: the candidate ids not tried any more (named before).
    """

    problem: Problem
    label: str
    exclude: frozenset[str] = frozenset()


@dataclasses.dataclass(frozen=True)
class Round:
    """The state of one round, as its stages fill it in.

    **Fields:**

    - `base`: the round's `RoundBase`.
    - `first`: whether it is the first round (which checks the family).
    - `plan`, `fitted`, `noise`: the plan, the base's fit and the noise estimated
        from the data.
    - `family`: the family check of the first round, else None.
    - `found`: the scored candidates so far.
    - `decision`: the verdict on them.
    - `discovered`: the discovery stage's term, or None.

    A stage after `plan_stage` reads the plan and the base's fit as `planned` and
    `base_fit`, one after `verdict_stage` the verdict as `decided`: each says which
    stage it needs when that stage has not run.
    """

    base: RoundBase
    first: bool = False
    plan: Plan | None = None
    fitted: BaseFit | None = None
    noise: float = math.nan
    family: FamilyCheck | None = None
    found: tuple[Candidate, ...] = ()
    decision: Verdict | None = None
    discovered: Discovered | None = None

    @property
    def planned(self) -> Plan:
        """The round's plan (`plan_stage` has run)."""
        assert self.plan is not None, "plan_stage has not run"
        return self.plan

    @property
    def base_fit(self) -> BaseFit:
        """The base's fit and scores (`plan_stage` has run)."""
        assert self.fitted is not None, "plan_stage has not run"
        return self.fitted

    @property
    def decided(self) -> Verdict:
        """The verdict on the candidates (`verdict_stage` has run)."""
        assert self.decision is not None, "verdict_stage has not run"
        return self.decision


def plan_stage(state: Round, search: CandidateSearch, meter) -> Round:
    """The plan of the round, its base fitted and scored, the noise."""
    base = state.base
    ids = [i for i in search.ids if i not in base.exclude]
    plan = choose_candidates(base.problem, search.heldout, ids)
    fitted = fit_base(plan, base.problem.model, search.least_squares, meter)
    noise = noise_floor(plan.tests, plan.how, fitted)
    return dataclasses.replace(state, plan=plan, fitted=fitted, noise=noise)


def family_stage(state: Round, search: CandidateSearch, meter) -> Round:
    """The first round's family check; a round run again on the family the data
    want, when it is another."""
    if not state.first:
        return state
    family, start = check_family(
        state.base.problem, state.planned, state.base_fit, state.noise, search, meter
    )
    state = dataclasses.replace(state, family=family)
    if start is None:
        return state
    problem = dataclasses.replace(state.base.problem, model=start, fit=None)
    base = dataclasses.replace(state.base, problem=problem, label=type(start).__name__)
    return plan_stage(dataclasses.replace(state, base=base), search, meter)


def catalogue_stage(state: Round, search: CandidateSearch, meter) -> Round:
    """The catalogue's candidates fitted around the base and scored."""
    model = state.base.problem.model
    found = score_catalogue(state.planned, model, state.base_fit, progress_meter=meter)
    return dataclasses.replace(state, found=state.found + found)


def covariates_stage(state: Round, search: CandidateSearch, meter) -> Round:
    """The covariates' forms, on the time split of force-driven tests."""
    plan = state.planned
    if not plan.on_time_split_in_mm:
        return state
    found = covariate_candidates(plan, state.base_fit, search.one_start, meter)
    return dataclasses.replace(state, found=state.found + found)


def verdict_stage(state: Round, search: CandidateSearch, meter) -> Round:
    """The rule on the candidates scored so far."""
    return dataclasses.replace(state, decision=verdict(state))


def discovery_stage(state: Round, search: CandidateSearch, meter) -> Round:
    """A discovered term when the verdict would be `"unexplained"` (or always, or
    never: `search.discover`), or when the named cause may leave it something
    (`_discovery_may_beat`); named instead of that cause only when it beats it by
    `MIN_GAIN_PCT` %."""
    auto = search.discover is None
    before = state.decided
    wanted = before.verdict == "unexplained" if auto else search.discover
    unused = auto and _discovery_may_beat(state)
    plan = state.planned
    if not ((wanted or unused) and plan.on_time_split_in_mm):
        return state
    discovered = discovered_candidate(plan, state.base_fit, search.one_start, meter)
    if discovered is None:
        return state
    state = dataclasses.replace(
        state, found=state.found + (discovered.candidate,), discovered=discovered
    )
    decision = verdict(state)
    if unused:
        decision = _named_unless_beaten(before, decision, state.found)
    return dataclasses.replace(state, decision=decision)


STAGES = (
    plan_stage,
    family_stage,
    catalogue_stage,
    covariates_stage,
    verdict_stage,
    discovery_stage,
)


def one_round(
    base: RoundBase, search: CandidateSearch, meter: AbstractProgressMeter, first: bool
) -> tuple[Diagnosis, Plan, RoundBase]:
    """The stages of one round around `base` (see the module's description): its
    diagnosis, plan and base (another family's, when the `first` round's family
    check switched)."""
    state = Round(base, first=first)
    for stage in STAGES:
        state = stage(state, search, meter)
    return conclude(state), state.planned, state.base


def verdict(state: Round) -> Verdict:
    """The verdict on the round's candidates (`decide`)."""
    base = state.base_fit
    return decide(
        base.score.heldout_rmse,
        state.noise,
        [c.heldout_rmse for c in state.found],
        [c.significant for c in state.found],
        base.structure["autocorrelation"],
    )


def _discovery_may_beat(state: Round) -> bool:
    """Whether the round's verdict names a cause that leaves more than `MIN_EXCESS`
    x the noise held out and either reads none of the recorded covariates (nor does
    the base) or reads one through a covariate form (the catalogue's have no
    memory)."""
    decision = state.decided
    if decision.verdict != "named" or decision.named is None:
        return False
    named = state.found[decision.named]
    if not named.heldout_rmse > MIN_EXCESS * state.noise:
        return False
    read = {state.base.problem.covariate, named.covariate}
    unused = [c for c in state.planned.columns if c not in read]
    return bool(unused) or named.covariate is not None


def _named_unless_beaten(before: Verdict, after: Verdict, found) -> Verdict:
    """`after` (the verdict with the discovered term, last of `found`) when it names
    the term and the term's held-out RMSE is `MIN_GAIN_PCT` % below that of the
    cause `before` named; else `after` naming that cause."""
    term, named = found[-1], found[before.named]
    if (
        after.named == len(found) - 1
        and term.heldout_rmse <= (1.0 - MIN_GAIN_PCT / 100.0) * named.heldout_rmse
    ):
        return after
    return after._replace(verdict=before.verdict, named=before.named)


def _scored(state: Round) -> tuple[Candidate, ...]:
    """Each candidate with its shares of the excess (on squares and on RMSEs) and,
    when it diverges, where."""
    plan, base, noise = state.planned, state.base_fit, state.noise
    held = base.score.heldout_rmse
    return tuple(
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
        for c, share in zip(state.found, state.decided.explained_pct)
    )


def conclude(state: Round) -> Diagnosis:
    """The [`jaxcable.Diagnosis`][] of one round's stages: each candidate with its
    shares of the excess and, when it diverges, where; the named cause (or
    `"none"` / `"unexplained"`) and its effect."""
    plan, base, decision = state.planned, state.base_fit, state.decided
    held = base.score.heldout_rmse
    out = _scored(state)
    named, extended, gain, effect = _named(out, decision, held)
    return Diagnosis(
        base_model=state.base.label,
        named_cause=named,
        base_heldout_rmse=held,
        base_train_rmse=base.score.train_rmse,
        extended_heldout_rmse=extended,
        gain_pct=gain,
        effect=effect,
        candidates=out,
        structure=base.structure,
        noise=state.noise,
        split=plan.heldout.describe(len(plan.tests)),
        holdout=plan.heldout.fraction if plan.split == "time" else None,
        test_ids=tuple(test_id(t, i) for i, t in enumerate(plan.tests)),
        base_fit=base.fit,
        unit=plan.how.unit,
        drives=plan.how.drives,
        scales=tuple(float(x) for x in plan.how.scales),
        verdict=decision.verdict,
        discovered={} if state.discovered is None else state.discovered.description,
        covariate=plan.how.covariate,
        family=state.family,
    )


def _named(out: Sequence[Candidate], decision: Verdict, held: float):
    """`(named cause, its held-out RMSE, gain, effect)` of a verdict."""
    if decision.named is None:
        named = "unexplained" if decision.verdict == "unexplained" else "none"
        return named, held, 0.0, {}
    best = out[decision.named]
    return best.id, best.heldout_rmse, best.gain_pct, effect_of(best)


def effect_of(c: Candidate) -> dict:
    """The effect of a named candidate: `{"parameter", "value", "stderr", "unit"}`."""
    return {
        "parameter": c.size_name,
        "value": c.size,
        "stderr": c.size_stderr,
        "unit": c.size_unit,
    }
