"""Every cause in turn: the rounds of [`jaxcable.diagnose`][].

A round is one pass of the stages (plan, base fit, catalogue, covariates' forms,
discovery, verdict) around a base model. After a round names a cause, the next round
takes the extended model as its base (the named effect's parameters free with the
base's, from their fitted values) and looks again, at every candidate not yet named.
The rounds stop when what is left is within `MAX_FLOOR_RATIO` x the noise held out,
when a round names nothing, or after `max_rounds`.

A round that names nothing but has significant candidates (each explains part of the
excess, none enough: two effects of similar size, say) takes its best one as a
*partial* cause and goes on: its best catalogue or covariate candidate, a discovered
term only when none is significant. Partial causes are kept only when a later round
names its cause and, together with them, it explains what the first partial
cause's round's base left: within `MAX_FLOOR_RATIO` x the noise, or
`MIN_EXPLAINED_PCT` % of that excess in squares ([`sufficient`][]); a chain that
starts with a known cause is confirmed by known causes only (a discovered term
fitted after a wrong partial cause absorbs what it got wrong). Otherwise they
are reported as tried (`accepted` False) and the verdict stays what the rounds
before them gave.

The first round checks the base's family before any candidate
(`jaxcable._diagnose.family`): when its base is far from the data, the other base
models are fitted on the same split, and one clearly better held out becomes the
base of every round.

A round whose named cause leaves more than `MIN_EXCESS` x the noise runs the
discovery as well when that cause reads none of the covariates the data record (an
unused measured channel beside a residual above the noise is a lead: an extra
Kelvin element comes within 2 x the noise of a mechano-sorptive creep that
saturates), or reads one through a form without memory (the library's terms with
state in that covariate, a lag or a saturation, may be what it is: a strain
proportional to the humidity comes within 2 x the noise of one that lags it by 40
min). The discovered term is named instead only when its held-out RMSE is
`MIN_GAIN_PCT` % below the named cause's.
"""

import dataclasses
from collections.abc import Sequence

from .._models import COVARIATE_EXTENSIONS, EXTENSIONS, AbstractCableModel
from .._progress import AbstractProgressMeter
from .base import fit_base
from .catalogue import score_catalogue
from .covariates import covariate_candidates
from .family import check_family
from .library import base_start
from .outcome import conclude, verdict
from .plan import Plan, choose_candidates
from .prune import Pruned, prune
from .result import Candidate, Diagnosis
from .scoring import noise_floor
from .stage import discovery_stage
from .verdict import (
    MAX_DELTA_BIC,
    MAX_FLOOR_RATIO,
    MIN_EXCESS,
    MIN_GAIN_PCT,
    MIN_PARTIAL_GAIN_PCT,
    Verdict,
    sufficient,
)


@dataclasses.dataclass(frozen=True)
class RoundBase:
    """The base of one round.

    **Fields:**

    - `model`: the base model, with its start values (the previous round's fit).
    - `label`: its name in the summary, e.g. `IntegratedModel + sensor_drift`.
    - `names`: its parameters to fit (None: the registry's identifiable set).
    - `covariate`: the extra column it reads, or None.
    - `exclude`: the candidate ids not tried any more (named before).
    """

    model: AbstractCableModel
    label: str
    names: tuple[str, ...] | None
    covariate: str | None
    exclude: frozenset[str]


def _base_stage(tests, base: RoundBase, candidates, options: dict, meter):
    """`(plan, fitted base)` of a round around `base`."""
    ids = [*EXTENSIONS, *COVARIATE_EXTENSIONS] if candidates is None else candidates
    ids = [i for i in ids if i not in base.exclude]
    plan = choose_candidates(
        tests,
        base.model,
        fit_names=base.names,
        candidates=ids,
        split=options["split"],
        holdout=options["holdout"],
        folds=options["folds"],
        drive=options["drive"],
        covariate=base.covariate,
    )
    fitted = fit_base(
        plan,
        base.model,
        multistart=options["multistart"],
        max_steps=options["max_steps"],
        key=options["key"],
        progress_meter=meter,
    )
    return plan, fitted


def one_round(
    tests, base: RoundBase, candidates, options: dict, meter, *, first: bool = False
) -> tuple[Diagnosis, Plan, RoundBase]:
    """One pass of the stages around `base` (see `jaxcable._diagnose.diagnose`): its
    diagnosis, plan and base. The `first` round checks the base's family
    ([`check_family`][]) before any candidate, and runs on the family the data
    want (its base then that family's)."""
    plan, fitted = _base_stage(tests, base, candidates, options, meter)
    noise = noise_floor(plan.tests, plan.how, fitted)
    family = None
    if first:
        family, start = check_family(
            tests, plan, fitted, noise, base.model, options, meter
        )
        if start is not None:
            base = dataclasses.replace(
                base, model=start, label=type(start).__name__, names=None
            )
            plan, fitted = _base_stage(tests, base, candidates, options, meter)
            noise = noise_floor(plan.tests, plan.how, fitted)
    max_steps = options["max_steps"]
    found = score_catalogue(plan, base.model, fitted, progress_meter=meter)
    if plan.on_time_split_in_mm:
        found += covariate_candidates(
            plan, fitted, max_steps=max_steps, progress_meter=meter
        )
    decision = verdict(fitted, noise, found)
    discovered = None
    auto = options["discover"] is None
    wanted = decision.verdict == "unexplained" if auto else options["discover"]
    unused = auto and _discovery_may_beat(plan, base, found, decision, noise)
    if (wanted or unused) and plan.on_time_split_in_mm:
        discovered = discovery_stage(
            plan, fitted, max_steps=max_steps, progress_meter=meter
        )
        if discovered is not None:
            before = decision
            found += (discovered.candidate,)
            decision = verdict(fitted, noise, found)
            if unused:
                decision = _named_unless_beaten(before, decision, found)
    d = conclude(plan, base.label, fitted, found, decision, noise, discovered)
    return dataclasses.replace(d, family=family), plan, base


def _discovery_may_beat(plan: Plan, base: RoundBase, found, decision: Verdict, noise):
    """Whether `decision` names a cause that leaves more than `MIN_EXCESS` x `noise`
    held out and either reads none of the recorded covariates (nor does the base)
    or reads one through a covariate form (the catalogue's have no memory)."""
    if decision.verdict != "named":
        return False
    named = found[decision.named]
    if not named.heldout_rmse > MIN_EXCESS * noise:
        return False
    read = {base.covariate, named.covariate}
    unused = [c for c in plan.columns if c not in read]
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


def partial_cause(d: Diagnosis) -> Candidate | None:
    """The cause a round that named nothing though its base is above the noise goes
    on with: its significant catalogue or covariate candidate of largest held-out
    gain, else one whose held-out gain (>= `MIN_PARTIAL_GAIN_PCT`) and ΔBIC support it
    though its size is within 3 standard errors of 0, else a significant
    discovered term (the discovery is the last resort, as
    in a round: a term fitted to two effects at once stands in for both and leaves
    the next round nothing it can name); or None."""
    if d.verdict != "unexplained":
        return None
    fitted = [c for c in d.candidates if c.fit is not None and not c.diverging]
    able = [c for c in fitted if c.significant]
    known = [c for c in able if c.id != "discovered"]
    if not known:
        # A known cause whose held-out gain and BIC support it while its size is
        # within 3 standard errors of 0: its size correlates with the base's
        # parameters while the other effect is missing (a bedding-in beside a
        # stress-nonlinear creep). Only a starting point: a partial cause is kept
        # only when the causes after it explain the rest.
        known = [
            c
            for c in fitted
            if c.id != "discovered"
            and c.applicable
            and c.gain_pct >= MIN_PARTIAL_GAIN_PCT
            and c.delta_bic <= MAX_DELTA_BIC
        ]
    return max(known or able, key=lambda c: c.gain_pct, default=None)


def next_base(base: RoundBase, cause: Candidate) -> RoundBase:
    """The base of the next round: the model of `cause`'s fit (per-test values
    averaged), its fitted parameters free."""
    fit = cause.fit
    model = base_start(fit)
    names = tuple(dict.fromkeys(n.split("[")[0] for n in fit.names))
    covariate = cause.covariate or base.covariate
    # A covariate's candidate is tried once per form: `mechano_sorptive[h]` named,
    # `mechano_sorptive` is not tried again.
    return RoundBase(
        model=model,
        label=f"{base.label} + {cause.id}",
        names=names,
        covariate=covariate,
        exclude=base.exclude | {cause.id, cause.id.split("[")[0]},
    )


def diagnose_rounds(
    tests,
    model: AbstractCableModel,
    *,
    fit_names: Sequence[str] | None,
    candidates: Sequence[str] | None,
    max_rounds: int,
    options: dict,
    progress_meter: AbstractProgressMeter,
) -> Diagnosis:
    """Round after round until nothing is left to name (see the module's
    description); the first round's [`jaxcable.Diagnosis`][] with the causes,
    their gains, the final held-out RMSE and every round."""
    base = RoundBase(
        model,
        type(model).__name__,
        None if fit_names is None else tuple(fit_names),
        None,
        frozenset(),
    )
    rounds: list[Diagnosis] = []
    plans: list[Plan] = []
    kept = 0  # the rounds whose causes are kept
    pending = None  # the round of a partial cause not yet confirmed
    final = None  # (plan, fit, held-out RMSE) of a round whose base has every cause
    for k in range(max_rounds):
        if k:
            progress_meter.say(f"round {k + 1}: base {base.label}")
        d, plan, base = one_round(
            tests, base, candidates, options, progress_meter, first=not k
        )
        plans.append(plan)
        cause = d.candidate(d.named_cause) if d.verdict == "named" else None
        partial = None
        if cause is None and k + 1 < max_rounds:
            partial = partial_cause(d)
        if cause is None and partial is None:
            if d.verdict == "none" and k and (pending is not None or kept == k):
                # Refitted together, the causes so far leave only the noise (the
                # last candidate's own fit can stop short of that): this round's
                # base confirms a pending chain, and is the final model.
                start = rounds[0 if pending is None else pending]
                if (pending is None or _known_chain(rounds, pending)) and sufficient(
                    start.base_heldout_rmse, d.base_heldout_rmse, start.noise
                ):
                    pending, kept = None, k
                    final = (plan, d.base_fit, d.base_heldout_rmse)
            rounds.append(d)
            break
        cause = cause or partial
        d = _with_cause(d, cause)
        rounds.append(d)
        if partial is not None:
            # A chain of partial causes is judged from its first round on.
            pending = k if pending is None else pending
        elif pending is not None:
            start = rounds[pending]
            if _known_chain(rounds, pending) and sufficient(
                start.base_heldout_rmse, cause.heldout_rmse, start.noise
            ):
                pending, kept = None, k + 1
        else:
            kept = k + 1
        if cause.heldout_rmse <= MAX_FLOOR_RATIO * d.noise:
            break
        base = next_base(base, cause)
    rounds = [
        r
        if i < kept or r.verdict != "named"
        else dataclasses.replace(
            r,
            accepted=False,
            note="a partial cause, tried as the base of the next round and not "
            "kept: the causes after it did not explain the rest",
        )
        for i, r in enumerate(rounds)
    ]
    pruned = None
    if kept:
        last = rounds[kept - 1]
        cause = last.candidate(last.named_cause)
        plan = plans[kept - 1]
        plan = dataclasses.replace(
            plan, how=plan.how._replace(covariate=cause.covariate or plan.how.covariate)
        )
        fit, heldout = cause.fit, cause.heldout_rmse
        if final is not None:
            plan, fit, heldout = final
        if kept > 1:
            progress_meter.say("trying each earlier cause out of the final model")
        pruned = prune(plan, fit, heldout, kept, options)
        for i, note in enumerate(pruned.notes):
            if note:
                rounds[i] = dataclasses.replace(rounds[i], accepted=False, note=note)
    return _combined(rounds, kept, pruned)


def _known_chain(rounds: list[Diagnosis], pending: int) -> bool:
    """Whether the chain of causes from round `pending` on may be confirmed: a known
    partial cause is confirmed by known causes only (a discovered term fitted after
    it can absorb whatever it got wrong: a slipping clamp read as a sensor drift,
    then "completed")."""
    return (
        all(r.named_cause != "discovered" for r in rounds[pending:])
        or rounds[pending].named_cause == "discovered"
    )


def _with_cause(d: Diagnosis, cause: Candidate) -> Diagnosis:
    """Round `d` naming `cause` (a partial one is named in its round)."""
    return dataclasses.replace(
        d,
        verdict="named",
        named_cause=cause.id,
        extended_heldout_rmse=cause.heldout_rmse,
        gain_pct=cause.gain_pct,
        effect={
            "parameter": cause.size_name,
            "value": cause.size,
            "stderr": cause.size_stderr,
            "unit": cause.size_unit,
        },
    )


def _combined(rounds: list[Diagnosis], kept: int, pruned: Pruned | None) -> Diagnosis:
    """The first round's diagnosis with the causes of the first `kept` rounds that
    the pruning kept, and every round."""
    first = rounds[0]
    causes = [r for r in rounds[:kept] if r.accepted]
    top = first
    if causes and causes[0] is not first:
        # The first round's cause was not kept: the first kept one is "the" cause.
        lead = causes[0]
        top = dataclasses.replace(
            first,
            verdict="named",
            named_cause=lead.named_cause,
            extended_heldout_rmse=lead.extended_heldout_rmse,
            gain_pct=lead.gain_pct,
            effect=lead.effect,
            accepted=True,
            note="",
        )
    elif not causes and first.verdict == "named":
        # The first round's cause was partial and not confirmed: as without rounds.
        top = dataclasses.replace(
            first,
            verdict="unexplained",
            named_cause="unexplained",
            extended_heldout_rmse=first.base_heldout_rmse,
            gain_pct=0.0,
            effect={},
        )
    return dataclasses.replace(
        top,
        causes=tuple(r.named_cause for r in causes),
        cause_gains=tuple(r.gain_pct for r in causes),
        final_heldout_rmse=(pruned.heldout_rmse if causes else first.base_heldout_rmse),
        final_fit=pruned.fit if causes else None,
        rounds=tuple(rounds) if len(rounds) > 1 else (),
    )


def check_max_rounds(max_rounds) -> int:
    """`max_rounds` checked: an int >= 1."""
    if (
        isinstance(max_rounds, bool)
        or not isinstance(max_rounds, int)
        or max_rounds < 1
    ):
        raise ValueError(f"`max_rounds` must be an int >= 1, got {max_rounds!r}.")
    return max_rounds
