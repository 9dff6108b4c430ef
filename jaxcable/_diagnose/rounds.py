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
`MIN_EXPLAINED_PCT` % of that excess in squares (`sufficient`); a chain that
starts with a known cause is confirmed by known causes only (a discovered term
fitted after a wrong partial cause absorbs what it got wrong). Otherwise they
are reported as tried (`accepted` False) and the verdict stays what the rounds
before them gave.

The first round checks the base's family before any candidate
(`family_stage`): when its base is far from the data, the other base
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

**The pruning.** At the end, every cause found before the last one is tried out
again, with the later ones in the model.

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
from .._models import AbstractExtension, DiscoveredTerm
from .._problem import LeastSquares, Problem
from .._progress import AbstractProgressMeter
from .diagnosis import Candidate, Diagnosis
from .library import base_start
from .methods import CandidateSearch, fit_quietly
from .plan import Plan
from .rule import (
    MAX_DELTA_BIC,
    MAX_FLOOR_RATIO,
    MIN_GAIN_PCT,
    MIN_PARTIAL_GAIN_PCT,
    sufficient,
)
from .scoring import bic
from .stages import RoundBase, effect_of, one_round


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

    - `plan`: the last round's `Plan` (its training and held-out samples).
    - `final`: the last round's named candidate's fit: every cause in its model,
        the last one outermost.
    - `heldout`: its held-out RMSE.
    - `count`: how many causes wrap the user's base in it.
    - `method`: the refits' [`jaxcable.LeastSquares`][].

    **Returns:**

    A `Pruned`.
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
    # Every cause wraps the model before it in an extension.
    assert isinstance(layer, AbstractExtension), type(layer).__name__
    return type(layer).EFFECT_FIELDS


def _train_rmse(result: FitResult, n: int) -> float:
    """The training RMSE of a fit in its residual unit, from its loss."""
    return math.sqrt(float(result.loss) / max(n, 1))


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


def _fit_of(cause: Candidate) -> FitResult:
    """The fit of a cause the rounds go on with: a named or partial cause is always
    a fitted candidate."""
    assert cause.fit is not None, f"the cause {cause.id!r} has no fit"
    return cause.fit


def next_base(base: RoundBase, cause: Candidate) -> RoundBase:
    """The base of the next round: the model of `cause`'s fit (per-test values
    averaged), its fitted parameters free."""
    fit = _fit_of(cause)
    names = tuple(dict.fromkeys(n.split("[")[0] for n in fit.names))
    problem = dataclasses.replace(
        base.problem,
        model=base_start(fit),
        fit=names,
        covariate=cause.covariate or base.problem.covariate,
    )
    # A covariate's candidate is tried once per form: `mechano_sorptive[h]` named,
    # `mechano_sorptive` is not tried again.
    return RoundBase(
        problem=problem,
        label=f"{base.label} + {cause.id}",
        exclude=base.exclude | {cause.id, cause.id.split("[")[0]},
    )


def diagnose_rounds(
    problem: Problem, search: CandidateSearch, progress_meter: AbstractProgressMeter
) -> Diagnosis:
    """Round after round until nothing is left to name (see the module's
    description); the first round's [`jaxcable.Diagnosis`][] with the causes,
    their gains, the final held-out RMSE and every round."""
    chain = _Chain()
    base = RoundBase(problem, type(problem.model).__name__)
    for k in range(search.max_rounds):
        if k:
            progress_meter.say(f"round {k + 1}: base {base.label}")
        d, plan, base = one_round(base, search, progress_meter, first=not k)
        cause = chain.add(d, plan, last=k + 1 == search.max_rounds)
        if cause is None or cause.heldout_rmse <= MAX_FLOOR_RATIO * d.noise:
            break
        base = next_base(base, cause)
    rounds = chain.marked()
    pruned = None
    if chain.kept:
        if chain.kept > 1:
            progress_meter.say("trying each earlier cause out of the final model")
        # The refits of the pruning start from a fitted model, with the fit's
        # default of four starts.
        method = LeastSquares(
            solver=search.least_squares.solver,
            max_steps=search.least_squares.max_steps,
        )
        pruned = prune(*chain.final_model(), chain.kept, method)
        for i, note in enumerate(pruned.notes):
            if note:
                rounds[i] = dataclasses.replace(rounds[i], accepted=False, note=note)
    return _combined(rounds, chain.kept, pruned)


class _Chain:
    """The rounds so far and which of their causes are kept.

    **Attributes:**

    - `rounds`, `plans`: every round's diagnosis (its cause named) and plan.
    - `kept`: the number of rounds whose causes are kept.
    - `pending`: the round of a partial cause not yet confirmed, or None.
    - `final`: `(plan, fit, held-out RMSE)` of a round whose base has every cause
        (it confirmed the chain while its own candidates named nothing), or None.
    """

    def __init__(self):
        self.rounds: list[Diagnosis] = []
        self.plans: list[Plan] = []
        self.kept = 0
        self.pending: int | None = None
        self.final: tuple[Plan, FitResult, float] | None = None

    def add(self, d: Diagnosis, plan: Plan, last: bool) -> Candidate | None:
        """Record round `d`: the cause the rounds go on with (named, or partial
        unless it is the `last` round), or None when they stop."""
        k = len(self.rounds)
        self.plans.append(plan)
        cause = d.candidate(d.named_cause) if d.verdict == "named" else None
        partial = partial_cause(d) if cause is None and not last else None
        cause = cause if cause is not None else partial
        if cause is None:
            self._confirm_by_base(d, plan, k)
            self.rounds.append(d)
            return None
        self.rounds.append(_with_cause(d, cause))
        if partial is not None:
            # A chain of partial causes is judged from its first round on.
            self.pending = k if self.pending is None else self.pending
        elif self.pending is not None:
            start = self.rounds[self.pending]
            if _known_chain(self.rounds, self.pending) and sufficient(
                start.base_heldout_rmse, cause.heldout_rmse, start.noise
            ):
                self.pending, self.kept = None, k + 1
        else:
            self.kept = k + 1
        return cause

    def _confirm_by_base(self, d: Diagnosis, plan: Plan, k: int) -> None:
        """A round `k` that names nothing with nothing left: refitted together, the
        causes so far leave only the noise (the last candidate's own fit can stop
        short of that), so this round's base confirms a pending chain and is the
        final model."""
        if not (d.verdict == "none" and k):
            return
        if self.pending is None and self.kept != k:
            return
        start = self.rounds[0 if self.pending is None else self.pending]
        if (
            self.pending is None or _known_chain(self.rounds, self.pending)
        ) and sufficient(start.base_heldout_rmse, d.base_heldout_rmse, start.noise):
            self.pending, self.kept = None, k
            self.final = (plan, d.base_fit, d.base_heldout_rmse)

    def marked(self) -> list[Diagnosis]:
        """Every round, a named cause of a round after the kept ones marked as not
        kept (a partial cause its later rounds did not confirm)."""
        return [
            r
            if i < self.kept or r.verdict != "named"
            else dataclasses.replace(
                r,
                accepted=False,
                note="a partial cause, tried as the base of the next round and not "
                "kept: the causes after it did not explain the rest",
            )
            for i, r in enumerate(self.rounds)
        ]

    def final_model(self) -> tuple[Plan, FitResult, float]:
        """`(plan, fit, held-out RMSE)` of the model with every kept cause: the last
        kept cause's fit, on its round's plan (driven by its covariate), unless a
        later round's base confirmed the chain."""
        if self.final is not None:
            return self.final
        last = self.rounds[self.kept - 1]
        cause = last.candidate(last.named_cause)
        plan = self.plans[self.kept - 1]
        how = plan.how._replace(covariate=cause.covariate or plan.how.covariate)
        return dataclasses.replace(plan, how=how), _fit_of(cause), cause.heldout_rmse


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
        effect=effect_of(cause),
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
    final_rmse, final_fit = first.base_heldout_rmse, None
    if causes:
        # Kept causes are always pruned (`diagnose_rounds`).
        assert pruned is not None, "kept causes without a pruning"
        final_rmse, final_fit = pruned.heldout_rmse, pruned.fit
    return dataclasses.replace(
        top,
        causes=tuple(r.named_cause for r in causes),
        cause_gains=tuple(r.gain_pct for r in causes),
        final_heldout_rmse=final_rmse,
        final_fit=final_fit,
        rounds=tuple(rounds) if len(rounds) > 1 else (),
    )
