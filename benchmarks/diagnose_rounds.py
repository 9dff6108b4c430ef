"""Every cause in turn, and effects with memory: the multi-round targets of
`jaxcable.diagnose`.

Two families of synthetic data sets (the six tests, protocol and noise of
`jaxcable.papers.hidden_effect_dataset`), each diagnosed with `jaxcable.diagnose(problem)`
as a user would, seed by seed:

- pairs of catalogue effects (`jaxcable.papers.HIDDEN_PAIRS`, `hidden_pair_dataset`):
  per pair, the seeds where both effects are among the named causes
  (`Diagnosis.causes`) AND the held-out RMSE of the model with every cause
  (`final_heldout_rmse`) is within 1.5 x the floor (the true pair model's held-out
  RMSE, driven by the recorded force); and the seeds where no third cause is named
  (any cause outside the pair: a catalogue effect, a covariate form or a discovered
  term; the catalogue-only count is recorded too);
- effects with a state of their own, outside the catalogue
  (`jaxcable.papers.MEMORY_EFFECTS`): per effect, the seeds where a term reaches 80 %
  of the data-generating model's held-out gain over the fitted base (the model with
  the named causes when none of them is a catalogue cause, or the best `discovered`
  candidate of any round, each over the first round's base), the seeds where the
  NAMED causes alone reach it, and the seeds where no catalogue cause
  (`jaxcable.EXTENSIONS`) is named.

Runs on today's `Diagnosis` too: without `causes` the named cause is the only one,
without `final_heldout_rmse` the extended model's held-out RMSE is the final one.
Prints one line per run, then the JSON document and the tables; `--out FILE` writes
the JSON. `--jobs N` runs N spawned processes (the load average is recorded).

    python benchmarks/diagnose_rounds.py --seeds 10 --jobs 2 --out rounds.json
    python benchmarks/diagnose_rounds.py --seeds 1 --effects none \\
        --pairs termination_compliance+sensor_drift,hereditary+temperature
"""

import argparse
import json
import math
import multiprocessing
import os
import platform
import sys
import time
from concurrent.futures import ProcessPoolExecutor

import jax
import numpy as np


jax.config.update("jax_enable_x64", True)

import jaxcable as jc
from jaxcable import papers
from jaxcable._diagnose import heldout_rmse


sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from diagnose_matrix import _heldout_um  # noqa: E402


# The targets: final held-out RMSE over the floor, share of the true gain.
FLOOR_RATIO = 1.5
GAIN_SHARE = 0.8


def _causes(d) -> list[str]:
    """The named causes, in order (today's `Diagnosis`: its one named cause)."""
    causes = getattr(d, "causes", None)
    if causes is None:
        causes = () if d.named_cause in ("none", "unexplained") else (d.named_cause,)
    return list(causes)


def _final_mm(d) -> float:
    """The held-out RMSE of the model with every named cause, mm."""
    final = getattr(d, "final_heldout_rmse_mm", None)
    return float(d.extended_heldout_rmse_mm if final is None else final)


def _discovered_gains(d, base_mm) -> list[float]:
    """The held-out gain over the first round's base, %, of every `discovered`
    candidate of every round."""
    rounds = getattr(d, "rounds", ()) or (d,)
    return [
        100.0 * (1.0 - c.heldout_rmse_mm / base_mm)
        for r in rounds
        for c in r.candidates
        if c.id == "discovered" and math.isfinite(c.heldout_rmse_mm)
    ]


def _common(d, seconds) -> dict:
    """The fields every row records."""
    return {
        "named": d.named_cause,
        "verdict": d.verdict,
        "causes": _causes(d),
        "cause_gains_pct": [float(g) for g in getattr(d, "cause_gains", ())],
        "rounds": len(getattr(d, "rounds", ()) or ()),
        "noise_um": 1e3 * d.noise_mm,
        "base_heldout_um": 1e3 * d.base_heldout_rmse_mm,
        "final_heldout_um": 1e3 * _final_mm(d),
        "discovered_equation": (d.discovered or {}).get("equation"),
        "seconds": seconds,
    }


def run_pair(job) -> dict:
    """One pair data set, diagnosed."""
    pair, seed = job
    a, b = pair.split("+")
    tests = papers.hidden_pair_dataset((a, b), seed=seed)
    floor_um = 1e3 * heldout_rmse(papers.hidden_pair_model((a, b), seed=seed), tests)
    start = time.perf_counter()
    d = jc.diagnose(jc.Problem(jc.IntegratedModel(), tests).with_scaled_start())
    row = {"kind": "pair", "case": pair, "seed": seed, "floor_um": floor_um}
    row.update(_common(d, time.perf_counter() - start))
    causes = row["causes"]
    row["both_named"] = a in causes and b in causes
    row["final_over_floor"] = row["final_heldout_um"] / floor_um
    row["both_within_floor"] = bool(
        row["both_named"] and row["final_over_floor"] <= FLOOR_RATIO
    )
    third = [c for c in causes if c not in (a, b)]
    row["third_causes"] = third
    row["no_third_cause"] = not third
    row["no_third_catalogue_cause"] = not [c for c in third if c in jc.EXTENSIONS]
    _log(row)
    return row


def run_memory(job) -> dict:
    """One data set of an effect with memory, diagnosed."""
    effect, seed = job
    tests = papers.hidden_effect_dataset(effect, seed=seed)
    truth = papers.truth_elongations(effect, seed=seed, tests=tests)
    floor_um = _heldout_um(tests, truth)
    start = time.perf_counter()
    d = jc.diagnose(jc.Problem(jc.IntegratedModel(), tests).with_scaled_start())
    row = {"kind": "memory", "case": effect, "seed": seed, "floor_um": floor_um}
    row.update(_common(d, time.perf_counter() - start))
    base = row["base_heldout_um"]
    row["true_gain_pct"] = 100.0 * (1.0 - floor_um / base)
    row["named_gain_pct"] = (
        100.0 * (1.0 - row["final_heldout_um"] / base) if row["causes"] else 0.0
    )
    found = _discovered_gains(d, 1e-3 * base)
    row["discovered_gain_pct"] = max(found) if found else None
    row["wrong_catalogue_causes"] = [c for c in row["causes"] if c in jc.EXTENSIONS]
    # A wrong catalogue cause is no term for the effect: its gain does not count.
    right = row["named_gain_pct"] if not row["wrong_catalogue_causes"] else 0.0
    best = max([right, *found])
    true = row["true_gain_pct"]
    row["term_share_of_true_gain"] = best / true if true > 0 else None
    row["named_share_of_true_gain"] = row["named_gain_pct"] / true if true > 0 else None
    row["term_reaches_gain"] = bool(true > 0 and best >= GAIN_SHARE * true)
    row["named_reaches_gain"] = bool(true > 0 and right >= GAIN_SHARE * true)
    row["no_wrong_catalogue_cause"] = not row["wrong_catalogue_causes"]
    _log(row)
    return row


def run(job) -> dict:
    kind, case, seed = job
    return (run_pair if kind == "pair" else run_memory)((case, seed))


def _log(row):
    print(
        f"{row['case']:45s} seed {row['seed']}: causes {row['causes']} final "
        f"{row['final_heldout_um']:.2f} um (floor {row['floor_um']:.2f}, base "
        f"{row['base_heldout_um']:.2f}) {row['seconds']:.0f} s",
        file=sys.stderr,
        flush=True,
    )


def summarize(rows) -> dict:
    """The counts of the targets, per pair and per effect with memory."""
    out = {"pairs": {}, "memory_effects": {}}
    for case in dict.fromkeys(r["case"] for r in rows):
        sel = [r for r in rows if r["case"] == case]
        n = len(sel)
        if sel[0]["kind"] == "pair":
            out["pairs"][case] = {
                "seeds": n,
                "both_named_within_floor": sum(r["both_within_floor"] for r in sel),
                "both_named": sum(r["both_named"] for r in sel),
                "no_third_cause": sum(r["no_third_cause"] for r in sel),
                "no_third_catalogue_cause": sum(
                    r["no_third_catalogue_cause"] for r in sel
                ),
                "final_over_floor_median": float(
                    np.median([r["final_over_floor"] for r in sel])
                ),
                "seconds_median": float(np.median([r["seconds"] for r in sel])),
            }
        else:
            shares = [r["term_share_of_true_gain"] for r in sel]
            out["memory_effects"][case] = {
                "seeds": n,
                "term_reaches_80pct_of_true_gain": sum(
                    r["term_reaches_gain"] for r in sel
                ),
                "named_reaches_80pct_of_true_gain": sum(
                    r["named_reaches_gain"] for r in sel
                ),
                "no_wrong_catalogue_cause": sum(
                    r["no_wrong_catalogue_cause"] for r in sel
                ),
                "true_gain_pct_median": float(
                    np.median([r["true_gain_pct"] for r in sel])
                ),
                "term_share_median": float(
                    np.median([np.nan if s is None else s for s in shares])
                ),
                "seconds_median": float(np.median([r["seconds"] for r in sel])),
            }
    return out


def _tables(summary) -> str:
    lines = []
    if summary["pairs"]:
        lines += [
            f"| pair | both named, final <= {FLOOR_RATIO} x floor | no third cause "
            "| no third catalogue cause | final / floor, median | s / run |",
            "| --- | ---: | ---: | ---: | ---: | ---: |",
        ]
        for case, s in summary["pairs"].items():
            n = s["seeds"]
            lines.append(
                f"| `{case}` | {s['both_named_within_floor']}/{n} | "
                f"{s['no_third_cause']}/{n} | {s['no_third_catalogue_cause']}/{n} | "
                f"{s['final_over_floor_median']:.2f} | {s['seconds_median']:.0f} |"
            )
    if summary["memory_effects"]:
        lines += [
            "",
            "| effect with memory | a term >= 80 % of the true gain | named causes "
            ">= 80 % | no wrong catalogue cause | true gain | term / true, median "
            "| s / run |",
            "| --- | ---: | ---: | ---: | ---: | ---: | ---: |",
        ]
        for case, s in summary["memory_effects"].items():
            n = s["seeds"]
            lines.append(
                f"| `{case}` | {s['term_reaches_80pct_of_true_gain']}/{n} | "
                f"{s['named_reaches_80pct_of_true_gain']}/{n} | "
                f"{s['no_wrong_catalogue_cause']}/{n} | "
                f"{s['true_gain_pct_median']:.0f} % | {s['term_share_median']:.2f} | "
                f"{s['seconds_median']:.0f} |"
            )
    return "\n".join(lines)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--first-seed", type=int, default=100)
    parser.add_argument(
        "--pairs", default="all", help="'all', 'none' or pairs 'a+b,c+d'"
    )
    parser.add_argument(
        "--effects",
        default="all",
        help="'all' (MEMORY_EFFECTS), 'none' or ids of OUT_OF_CATALOGUE",
    )
    parser.add_argument("--jobs", type=int, default=1)
    parser.add_argument("--out", "--json-out", dest="out", default=None)
    args = parser.parse_args(argv)
    pairs = {
        "all": ["+".join(p) for p in papers.HIDDEN_PAIRS],
        "none": [],
    }.get(args.pairs, args.pairs.split(","))
    effects = {"all": list(papers.MEMORY_EFFECTS), "none": []}.get(
        args.effects, args.effects.split(",")
    )
    for p in pairs:
        if tuple(p.split("+")) not in papers.HIDDEN_PAIRS:
            parser.error(f"--pairs: {p!r} is not a pair of HIDDEN_PAIRS")
    for e in effects:
        if e not in papers.OUT_OF_CATALOGUE:
            parser.error(f"--effects: {e!r} is not an id of OUT_OF_CATALOGUE")
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    jobs = [("pair", p, s) for p in pairs for s in seeds]
    jobs += [("memory", e, s) for e in effects for s in seeds]
    start = time.perf_counter()
    load = os.getloadavg()
    if args.jobs > 1:
        # Spawned, not forked: JAX is already imported here and is multithreaded.
        spawn = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(args.jobs, mp_context=spawn) as pool:
            rows = list(pool.map(run, jobs))
    else:
        rows = [run(j) for j in jobs]
    summary = summarize(rows)
    document = {
        "benchmark": "diagnose_rounds",
        "machine": {
            "platform": platform.platform(),
            "python": platform.python_version(),
            "jax": jax.__version__,
            "devices": [str(d) for d in jax.devices()],
            "cpus": os.cpu_count(),
            "load_average_start": load,
            "load_average_end": os.getloadavg(),
        },
        "jobs": args.jobs,
        "seeds": list(seeds),
        "targets": {"final_over_floor": FLOOR_RATIO, "share_of_true_gain": GAIN_SHARE},
        "sizes": {p: list(papers.pair_sizes(tuple(p.split("+")))) for p in pairs}
        | {e: papers.OUT_OF_CATALOGUE[e]["size"] for e in effects},
        "summary": summary,
        "seconds": time.perf_counter() - start,
        "rows": rows,
    }
    text = json.dumps(document, indent=1, default=float)
    print(text)
    if args.out:
        with open(args.out, "w") as f:
            f.write(text + "\n")
    print()
    print(_tables(summary))


if __name__ == "__main__":
    main()
