"""The plain-text summary of a [`jaxcable.Diagnosis`][]: per round, the base, every
candidate with its gain and its share of the excess (on the RMSEs and on their
squares), the flagged diverging candidates, what was named and what is left."""

import math

from .._drive import as_test_drive
from .rule import (
    MAX_DELTA_BIC,
    MAX_FLOOR_RATIO,
    MIN_AUTOCORRELATION,
    MIN_EXCESS,
    MIN_EXPLAINED_PCT,
    MIN_GAIN_PCT,
    MIN_SIZE_Z,
)


def summary(d) -> str:
    """The summary of the diagnosis `d`: one table per round, then the causes."""
    u = d.unit
    noise = f"{d.noise * 1e3:.3g} um" if u == "mm" else f"{d.noise:.3g} {u}"
    lines = [
        f"jaxcable diagnose: base {d.base_model}, {len(d.test_ids)} test(s), "
        f"held out: {d.split}",
    ]
    if u != "mm":
        lines.append(_scored_line(d.drives, u))
    lines += [
        f"noise (estimated from the data) {noise}; base "
        f"RMSE {d.base_train_rmse:.4g} {u} fitted, "
        f"{d.base_heldout_rmse:.4g} {u} held out",
        f"noise from: {d.noise_source or 'second differences'}",
        "",
    ]
    if d.family is not None:
        lines += [d.family.describe(u), ""]
    rounds = d.rounds or (d,)
    for k, r in enumerate(rounds):
        if len(rounds) > 1:
            lines.append(
                f"round {k + 1}: base {r.base_model}, held-out RMSE "
                f"{r.base_heldout_rmse:.4g} {u} ({_times(r.base_heldout_rmse, d)} "
                "the noise)"
            )
        lines += _table(r)
        lines += _round_lines(r, k, len(rounds))
        lines.append("")
    lines += _conclusion(d)
    return "\n".join(lines)


def _times(value: float, d) -> str:
    """`value` over the noise, e.g. `11.0 x`."""
    return f"{value / d.noise:.3g} x" if d.noise > 0 else "inf x"


def _table(r) -> list[str]:
    """The candidates of one round."""
    u = r.unit
    w = max(12, len(u) + 10)
    lines = [
        f"{'candidate':<24}{'held-out ' + u:>{w}}{'gain %':>9}{'expl %':>8}"
        f"{'(sq) %':>8}{'dBIC':>10}{'size':>12}{'+-':>10}  unit",
    ]
    for c in r.candidates:
        if not c.applicable:
            lines.append(f"{c.id:<24}{'n/a':>{w}}  {c.note}")
            continue
        if c.diverging:
            lines.append(f"{c.id:<24}{c.heldout_rmse:>{w}.4g}  diverges: {c.diverging}")
            continue
        mark = " *" if c.significant else ""
        lines.append(
            f"{c.id:<24}{c.heldout_rmse:>{w}.4g}{c.gain_pct:>9.1f}"
            f"{c.explained_rmse_pct:>8.0f}{c.explained_pct:>8.0f}"
            f"{c.delta_bic:>10.1f}{c.size:>12.4g}{c.size_stderr:>10.2g}  "
            f"{c.size_unit}{mark}"
        )
    lines += _references(r)
    if r.discovered:
        cov = r.discovered.get("covariate")
        covariate = f" (covariate {cov})" if cov else ""
        lines.append(f"discovered term{covariate}: {r.discovered['equation']}")
    return lines


def _references(r) -> list[str]:
    """Where each fitted time shift of round `r` takes its reference: the base
    beside it is the material there."""
    out = []
    for c in r.candidates:
        ref = c.reference if c.applicable and not c.diverging else {}
        if not ref:
            continue
        if ref["field"] == "T_ref":
            # The catalogue's note says where and why.
            at = f"{ref['celsius']:.1f} °C"
            text = c.note or f"reference {at}: its base is the material at {at}"
        else:
            at = f"{ref['value']:.4g} in the unit of {c.covariate!r}"
            text = (
                f"reference {at} (the median of {c.covariate!r}): its base is the "
                f"material at {at}"
            )
        out.append(f"{c.id}: {text}")
    return out


def _round_lines(r, k: int, count: int) -> list[str]:
    """What one round decided, said plainly, with what it leaves."""
    u = r.unit
    if r.verdict == "named":
        c = r.candidate(r.named_cause)
        e = r.effect
        left = r.extended_heldout_rmse / r.noise if r.noise > 0 else math.inf
        what = (
            f"named: {r.named_cause}: {e['parameter']} = {e['value']:.4g} +- "
            f"{e['stderr']:.2g} {e['unit']}; held-out RMSE {r.base_heldout_rmse:.4g}"
            f" -> {r.extended_heldout_rmse:.4g} {u} ({r.gain_pct:.1f} % gain); it "
            f"explains {c.explained_rmse_pct:.0f} % of the excess over the noise "
            f"({c.explained_pct:.0f} % in squares)"
        )
        if not r.accepted:
            what += f"; not kept: {r.note}"
        elif left > MAX_FLOOR_RATIO:
            nxt = (
                "looked at again in the next round"
                if k + 1 < count
                else "no round left to look again"
            )
            what += f"; left: {left:.3g} x the noise, {nxt}"
        else:
            what += f"; left: {left:.3g} x the noise"
        return [what]
    if r.verdict == "unexplained":
        shown = [
            c
            for c in r.candidates
            if math.isfinite(c.explained_pct) and not c.diverging
        ]
        partial = [c for c in shown if c.significant] or shown
        if not partial:
            return ["nothing named: no candidate could be fitted"]
        best = max(partial, key=lambda c: c.explained_rmse_pct)
        return [
            f"nothing named: the best candidate, {best.id}, explains "
            f"{best.explained_rmse_pct:.0f} % of the excess over the noise "
            f"({best.explained_pct:.0f} % in squares)"
            + ("" if best.significant else ", not significant")
            + f", leaving {_times(best.heldout_rmse, r)} the noise"
        ]
    return ["nothing named"]


def _conclusion(d) -> list[str]:
    """The verdict over every round, and the base residuals' structure."""
    u = d.unit
    structure = d.structure
    strongest = structure.get("strongest")
    r_lag = structure.get("autocorrelation", math.nan)
    strong = (
        f"{strongest} (r = {structure['correlation'][strongest]:.2f})"
        if strongest
        else "none"
    )
    if d.causes:
        path = " -> ".join(
            f"{x:.4g}"
            for x in (d.base_heldout_rmse, *(r.extended_heldout_rmse for r in d.rounds))
            if math.isfinite(x)
        )
        ids = list(d.causes)
        gains = ", ".join(f"{c} {g:.1f} %" for c, g in zip(ids, d.cause_gains))
        left = d.final_heldout_rmse
        lines = [
            f"named cause{'s' if len(ids) > 1 else ''}: {', '.join(ids)} (held-out "
            f"gain of each over its round's base: {gains})",
            f"verdict: named — held-out RMSE {d.base_heldout_rmse:.4g} -> "
            f"{left:.4g} {u}, {_times(left, d)} the noise"
            + (
                ""
                if left <= MAX_FLOOR_RATIO * d.noise
                else f"; above {MAX_FLOOR_RATIO:g} x the noise, a residual is left "
                "that no candidate explains"
            ),
        ]
        if len(d.rounds) > 1 and path:
            lines.append(f"held-out RMSE, round by round: {path} {u}")
    elif d.verdict == "unexplained":
        lines = [
            "verdict: unexplained — no candidate, alone or after another, explains "
            f"the excess; the residual stays systematic (lag-1 autocorrelation "
            f"{r_lag:.2f}); strongest structure: {strong}",
            f"(a cause is named when it comes within {MAX_FLOOR_RATIO:g} x the "
            f"noise held out or explains >= {MIN_EXPLAINED_PCT:g} % of the excess "
            "in squares)",
        ]
    elif not d.base_heldout_rmse > MIN_EXCESS * d.noise:
        against = (
            f"{d.base_heldout_rmse * 1e3:.3g} um against {d.noise * 1e3:.3g} um"
            if u == "mm"
            else f"{d.base_heldout_rmse:.3g} {u} against {d.noise:.3g} {u}"
        )
        lines = [
            f"verdict: none — the base predicts the held-out data to within "
            f"{MIN_EXCESS:g} x the noise ({against}): nothing to explain"
        ]
    else:
        lines = [
            "verdict: none — no candidate improves the held-out RMSE "
            f"significantly: gain >= {MIN_GAIN_PCT:g} %, dBIC <= "
            f"{MAX_DELTA_BIC:g}, size >= {MIN_SIZE_Z:g} standard errors; and "
            f"the residual left is not systematic (lag-1 autocorrelation "
            f"{r_lag:.2f} < {MIN_AUTOCORRELATION:g})"
        ]
    if strongest:
        lines.append(
            f"base residuals relate most to: {strong}; lag-1 "
            f"autocorrelation {r_lag:.2f} (white "
            f"noise: |r| < {structure['white_noise_band']:.2g})"
        )
    return lines


def _scored_line(drives: tuple, unit: str) -> str:
    """What a diagnosis not in mm scores: one line for the summary."""
    if unit == "N":
        return "scored: the force, N (every test driven by its elongation)"
    by_force = sum(not as_test_drive(d).scores_force for d in drives)
    return (
        f"scored: {by_force} force-driven test(s) by their elongation, "
        f"{len(drives) - by_force} elongation-driven by their force; residuals in "
        "noise units (each divided by the noise of its test's scored channel)"
    )
