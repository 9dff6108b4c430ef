"""The hidden-effect confusion matrix and detection limits of `jaxcable.diagnose`.

For each hidden effect (and for none), `--seeds` data sets of
`jaxcable.hidden_effect_dataset` (six tests: three lengths, two rates, three force
levels, three temperatures; 5 um elongation and 0.05 N force noise; the base
parameters perturbed by 10 % per seed) are diagnosed; the named causes make the
confusion matrix. With `--factors`, each effect is also run at its documented size
times each factor, and the detection limit is the smallest size named in >= 9 of 10
seeds. Prints JSON (one object) and a table; `--out FILE` writes the JSON too.

    python benchmarks/diagnose_matrix.py --seeds 10 --factors 0.25,0.5,1 --out m.json
"""

import argparse
import json
import platform
import sys
import time

import jax


jax.config.update("jax_enable_x64", True)

import jaxcable as jc
from jaxcable._synthetic import HIDDEN_EFFECTS


def run(effect, seed, factor):
    size = None if effect is None else HIDDEN_EFFECTS[effect]["size"] * factor
    tests = jc.hidden_effect_dataset(effect, seed=seed, size=size)
    d = jc.diagnose(tests)
    return {
        "effect": effect or "none",
        "seed": seed,
        "size": size,
        "factor": factor,
        "named": d.named_cause,
        "base_heldout_um": 1e3 * d.base_heldout_rmse_mm,
        "extended_heldout_um": 1e3 * d.extended_heldout_rmse_mm,
        "gains": {c.id: c.gain_pct for c in d.candidates},
        "effect_value": d.effect.get("value"),
        "effect_stderr": d.effect.get("stderr"),
    }


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--first-seed", type=int, default=100)
    parser.add_argument("--effects", default="none," + ",".join(jc.EXTENSIONS))
    parser.add_argument(
        "--factors", default="1", help="size factors for the detection limits"
    )
    parser.add_argument("--out", default=None)
    args = parser.parse_args(argv)
    effects = [None if e == "none" else e for e in args.effects.split(",")]
    factors = [float(f) for f in args.factors.split(",")]
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    rows = []
    start = time.perf_counter()
    for effect in effects:
        for factor in [1.0] if effect is None else factors:
            for seed in seeds:
                row = run(effect, seed, factor)
                rows.append(row)
                print(
                    f"{row['effect']:24s} x{factor:<5g} seed {seed}: named "
                    f"{row['named']:24s} held-out {row['extended_heldout_um']:.2f} um "
                    f"({time.perf_counter() - start:.0f} s)",
                    file=sys.stderr,
                    flush=True,
                )
    names = ["none", *jc.EXTENSIONS]
    matrix = {
        e: {n: 0 for n in names}
        for e in (["none"] if None in effects else []) + [e for e in effects if e]
    }
    for row in rows:
        if row["factor"] == 1.0:
            matrix[row["effect"]][row["named"]] += 1
    limits = {}
    for effect in [e for e in effects if e]:
        ok = []
        for factor in factors:
            sel = [r for r in rows if r["effect"] == effect and r["factor"] == factor]
            hits = sum(r["named"] == effect for r in sel)
            near = sum(r["extended_heldout_um"] <= 6.0 for r in sel)
            ok.append((factor, hits, near, len(sel)))
        detected = [f for f, h, _, n in ok if h >= 0.9 * n]
        limits[effect] = {
            "unit": jc.EXTENSIONS[effect].SIZE_UNIT,
            "parameter": jc.EXTENSIONS[effect].SIZE_FIELD,
            "runs": [
                {
                    "size": HIDDEN_EFFECTS[effect]["size"] * f,
                    "named": h,
                    "within_20pct_of_noise": w,
                    "seeds": n,
                }
                for f, h, w, n in ok
            ],
            "detection_limit": (
                HIDDEN_EFFECTS[effect]["size"] * min(detected) if detected else None
            ),
        }
    document = {
        "benchmark": "diagnose_matrix",
        "machine": {
            "platform": platform.platform(),
            "processor": platform.processor(),
            "python": platform.python_version(),
            "jax": jax.__version__,
            "devices": [str(d) for d in jax.devices()],
        },
        "seeds": list(seeds),
        "confusion_matrix": matrix,
        "detection_limits": limits,
        "seconds": time.perf_counter() - start,
        "rows": rows,
    }
    text = json.dumps(document, indent=1)
    print(text)
    if args.out:
        with open(args.out, "w") as f:
            f.write(text + "\n")
    short = {"none": "none", **{k: k[:8] for k in jc.EXTENSIONS}}
    print("\nhidden \\ named  " + " ".join(f"{short[n]:>8s}" for n in names))
    for effect, counts in matrix.items():
        print(
            f"{effect:15s} " + " ".join(f"{counts[n]:8d}" for n in names),
        )
    for effect, info in limits.items():
        runs = ", ".join(
            f"{r['size']:.3g}: {r['named']}/{r['seeds']}" for r in info["runs"]
        )
        print(f"{effect:24s} {info['parameter']} [{info['unit']}]: {runs}")


if __name__ == "__main__":
    main()
