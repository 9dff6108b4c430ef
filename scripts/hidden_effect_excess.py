"""How clearly the fitted base model misses each out-of-catalogue hidden effect.

For each effect of `jaxcable.papers.OUT_OF_CATALOGUE` (at its documented size, or
`--sizes`) and each seed, the base model (`IntegratedModel`, Park's eight parameters)
is fitted by `jaxcable.diagnose` with no candidates (the blocked time split, last
30 % of every test held out), and its held-out RMSE is compared with the floor: the
held-out RMSE of the data-generating model driven by the recorded force and
covariates (`truth_elongations(..., tests=tests)`). Prints one line per run and a
summary; `--out FILE` writes the rows as JSON. `--jobs N` runs N processes.

With `--pairs` (ids `a+b` of `jaxcable.papers.HIDDEN_PAIRS`, or `all`), each pair's
data set (`hidden_pair_dataset`) is fitted by the base with ONE of its two effects
(`diagnose(problem, CandidateSearch(candidates=[a], discover=False, max_rounds=1))`, the effect's
parameters free with the base's), and that fit's held-out RMSE is compared with the
floor (the true pair model driven by the recorded force): how clearly the effect
left out stays visible beside the other.

    python scripts/hidden_effect_excess.py --seeds 10 --jobs 2
    python scripts/hidden_effect_excess.py --effects saturating_sorptive --seeds 3
    python scripts/hidden_effect_excess.py --pairs all --seeds 2 --jobs 2
"""

import argparse
import json
import math
import multiprocessing
import sys
from concurrent.futures import ProcessPoolExecutor

import numpy as np


def heldout_rms(tests, predictions) -> float:
    """Pooled RMSE over the held-out samples (`diagnose`'s time split), um."""
    from jaxcable._diagnose import heldout_start

    sq, n = 0.0, 0
    for t, p in zip(tests, predictions):
        first = heldout_start(len(t.time), 0.3)
        r = np.asarray(t.elongation)[first:] - np.asarray(p)[first:]
        sq, n = sq + float(np.sum(r**2)), n + r.size
    return 1e6 * math.sqrt(sq / n)


def _base_only(jc, tests):
    """The base fitted alone (no candidate, no discovery: only its held-out RMSE is
    used)."""
    search = jc.CandidateSearch(candidates=[], discover=False, max_rounds=1)
    return jc.diagnose(
        jc.Problem(jc.IntegratedModel(), tests).with_scaled_start(), search
    )


def run_pair(job):
    """One pair and seed: the held-out RMSE of the base with each effect alone (and
    with none) over the floor."""
    pair, seed, _ = job
    import jax

    jax.config.update("jax_enable_x64", True)
    import jaxcable as jc
    from jaxcable import papers

    a, b = pair.split("+")
    tests = papers.hidden_pair_dataset((a, b), seed=seed)
    truth = papers.pair_truth_elongations((a, b), seed=seed, tests=tests)
    floor = heldout_rms(tests, truth)
    row = {"pair": pair, "seed": seed, "floor_um": floor}
    row["base_um"] = 1e3 * _base_only(jc, tests).base_heldout_rmse_mm
    for kept, missed in ((a, b), (b, a)):
        search = jc.CandidateSearch(candidates=[kept], discover=False, max_rounds=1)
        d = jc.diagnose(
            jc.Problem(jc.IntegratedModel(), tests).with_scaled_start(), search
        )
        (c,) = [c for c in d.candidates if c.id == kept]
        row[f"with_{kept}_um"] = 1e3 * c.heldout_rmse_mm
        row[f"{missed}_excess"] = row[f"with_{kept}_um"] / floor
    row["base_excess"] = row["base_um"] / floor
    print(json.dumps(row), file=sys.stderr, flush=True)
    return row


def run(job):
    effect, seed, size = job
    import jax

    jax.config.update("jax_enable_x64", True)
    import jaxcable as jc
    from jaxcable import papers

    tests = papers.hidden_effect_dataset(effect, seed=seed, size=size)
    truth = papers.truth_elongations(effect, seed=seed, size=size, tests=tests)
    clean = papers.truth_elongations(effect, seed=seed, size=size)
    base = papers.truth_elongations(None, seed=seed)
    d = _base_only(jc, tests)
    floor = heldout_rms(tests, truth)
    effect_rms = heldout_rms(
        [type(t)(t.time, t.force, c) for t, c in zip(tests, clean)], base
    )
    row = {
        "effect": effect,
        "seed": seed,
        "size": size,
        "base_heldout_um": 1e3 * d.base_heldout_rmse_mm,
        "floor_um": floor,
        "noise_free_floor_um": heldout_rms(tests, clean),
        "effect_heldout_rms_um": effect_rms,
        "noise_um": 1e3 * d.noise,
    }
    row["excess"] = row["base_heldout_um"] / row["floor_um"]
    row["true_gain_pct"] = 100 * (1 - row["floor_um"] / row["base_heldout_um"])
    print(json.dumps(row), file=sys.stderr, flush=True)
    return row


def main(argv=None):
    from jaxcable._papers.hidden_effects import OUT_OF_CATALOGUE

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--first-seed", type=int, default=100)
    parser.add_argument("--effects", default=",".join(OUT_OF_CATALOGUE))
    parser.add_argument("--sizes", default=None, help="e.g. 'clamp_slip=4e-10,2e-10'")
    parser.add_argument("--jobs", type=int, default=1)
    parser.add_argument(
        "--pairs", default=None, help="'all' or pairs 'a+b,c+d' of HIDDEN_PAIRS"
    )
    parser.add_argument("--out", default=None)
    args = parser.parse_args(argv)
    if args.pairs:
        return _pairs(args)
    sizes = {e: [None] for e in args.effects.split(",")}
    if args.sizes:
        for item in args.sizes.split(";"):
            name, values = item.split("=")
            sizes[name] = [float(v) for v in values.split(",")]
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    jobs = [(e, s, z) for e in sizes for z in sizes[e] for s in seeds]
    if args.jobs > 1:
        # Spawned, not forked: JAX is already imported here and is multithreaded.
        spawn = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(args.jobs, mp_context=spawn) as pool:
            rows = list(pool.map(run, jobs))
    else:
        rows = [run(j) for j in jobs]
    print("| effect | size | base / floor, median (min-max) | >= 2x | floor, um |")
    print("| --- | ---: | ---: | ---: | ---: |")
    for e in sizes:
        for z in sizes[e]:
            sel = [r for r in rows if r["effect"] == e and r["size"] == z]
            x = [r["excess"] for r in sel]
            value = OUT_OF_CATALOGUE[e]["size"] if z is None else z
            print(
                f"| `{e}` | {value:.3g} {OUT_OF_CATALOGUE[e]['unit']} | "
                f"{np.median(x):.2f} ({min(x):.2f}-{max(x):.2f}) | "
                f"{sum(v >= 2 for v in x)}/{len(x)} | "
                f"{np.median([r['floor_um'] for r in sel]):.2f} |"
            )
    if args.out:
        with open(args.out, "w") as f:
            json.dump(rows, f, indent=1)


def _map(function, jobs, n):
    """`function` over `jobs`, in `n` spawned processes when n > 1."""
    if n > 1:
        # Spawned, not forked: JAX is already imported here and is multithreaded.
        spawn = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(n, mp_context=spawn) as pool:
            return list(pool.map(function, jobs))
    return [function(j) for j in jobs]


def _pairs(args):
    """The `--pairs` table: per pair, each effect's excess with the other fitted."""
    from jaxcable._papers.combined_effects import HIDDEN_PAIRS, pair_sizes

    names = ["+".join(p) for p in HIDDEN_PAIRS]
    pairs = names if args.pairs == "all" else args.pairs.split(",")
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    rows = _map(run_pair, [(p, s, None) for p in pairs for s in seeds], args.jobs)
    print(
        "| pair (a + b) | sizes | a missed, with b: min | b missed, with a: min "
        "| base / floor | floor, um |"
    )
    print("| --- | --- | ---: | ---: | ---: | ---: |")
    for p in pairs:
        a, b = p.split("+")
        sel = [r for r in rows if r["pair"] == p]
        za, zb = pair_sizes((a, b))
        print(
            f"| `{a}` + `{b}` | {za:.3g}, {zb:.3g} | "
            f"{min(r[a + '_excess'] for r in sel):.2f} | "
            f"{min(r[b + '_excess'] for r in sel):.2f} | "
            f"{np.median([r['base_excess'] for r in sel]):.2f} | "
            f"{np.median([r['floor_um'] for r in sel]):.2f} |"
        )
    if args.out:
        with open(args.out, "w") as f:
            json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
