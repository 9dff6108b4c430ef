"""The hidden-effect confusion matrix and detection limits of `jaxcable.diagnose`.

For each hidden effect (and for none), `--seeds` data sets of
`jaxcable.papers.hidden_effect_dataset` (six tests: three lengths, two rates, three force
levels, three temperatures; 5 um elongation and 0.05 N force noise; the base
parameters perturbed by 10 % per seed) are diagnosed at the effect's documented size;
the named causes make the confusion matrix (its `unexplained` column: an excess over
the noise that no candidate explains enough to be named, see
`jaxcable._diagnose.verdict`). With `--sweep`, each effect is also run at
its weaker sizes (`HIDDEN_EFFECTS[effect]["weaker"]`), and its detection limit is the
weakest size named in >= 9 of 10 seeds. For every run the held-out RMSE of the named
model is compared with the floor: the held-out RMSE of the data-generating model
itself (elongation noise plus its response to the force noise); every row also records
the noise estimated from the data (`Diagnosis.noise`), the verdict, and each
candidate's share of the base's excess over that noise (`explained_pct`). Prints JSON (one
object) and a table; `--out FILE` writes the JSON too.

    python benchmarks/diagnose_matrix.py --seeds 10 --sweep --out matrix.json
"""

import argparse
import json
import platform
import sys
import time

import jax
import numpy as np


jax.config.update("jax_enable_x64", True)

import jaxcable as jc
from jaxcable import papers
from jaxcable._diagnose import heldout_rmse
from jaxcable._papers.synthetic import (
    HIDDEN_EFFECT_DESIGN,
    HIDDEN_EFFECTS,
    hidden_effect_protocol,
)


def effect_magnitude(effect, seed, size):
    """(RMS, max) over all samples of the hidden effect's own contribution to the
    elongation, um: the true model minus its base, noise-free."""
    if effect is None:
        return 0.0, 0.0
    true = papers.hidden_effect_model(effect, seed=seed, size=size)
    diffs = []
    for length, rate, force, temp in HIDDEN_EFFECT_DESIGN:
        cable = jc.Cable(
            length=length * 1e-3, speed=rate * 1e-3 / 60, temperature=temp + 273.15
        )
        protocol = hidden_effect_protocol(force)
        with_effect = jc.simulate_rate_test(true, cable, protocol).elongation
        without = jc.simulate_rate_test(true.base, cable, protocol).elongation
        diffs.append(np.asarray(with_effect - without))
    d = 1e6 * np.concatenate(diffs)
    return float(np.sqrt(np.mean(d**2))), float(np.max(np.abs(d)))


def run(effect, seed, size):
    tests = papers.hidden_effect_dataset(effect, seed=seed, size=size)
    floor = heldout_rmse(
        papers.hidden_effect_model(effect, seed=seed, size=size), tests
    )
    rms_um, max_um = effect_magnitude(effect, seed, size)
    d = jc.diagnose(tests)
    return {
        "effect": effect or "none",
        "seed": seed,
        "size": size,
        "documented": effect is None or size == HIDDEN_EFFECTS[effect]["size"],
        "named": d.named_cause,
        "verdict": d.verdict,
        "noise_um": 1e3 * d.noise_mm,
        "floor_um": 1e3 * floor,
        "effect_rms_um": rms_um,
        "effect_max_um": max_um,
        "base_heldout_um": 1e3 * d.base_heldout_rmse_mm,
        "extended_heldout_um": 1e3 * d.extended_heldout_rmse_mm,
        "gains": {c.id: c.gain_pct for c in d.candidates},
        "explained_pct": {c.id: c.explained_pct for c in d.candidates},
        "effect_value": d.effect.get("value"),
        "effect_stderr": d.effect.get("stderr"),
    }


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--first-seed", type=int, default=100)
    parser.add_argument("--effects", default="none," + ",".join(jc.EXTENSIONS))
    parser.add_argument(
        "--sweep", action="store_true", help="also run the weaker sizes"
    )
    parser.add_argument(
        "--sizes",
        default=None,
        help="run these sizes instead, e.g. 'hereditary=0.01,0.003;sensor_drift=1e-9'",
    )
    parser.add_argument("--out", default=None)
    parser.add_argument(
        "--markdown", default=None, help="also write the tables as markdown here"
    )
    args = parser.parse_args(argv)
    effects = [None if e == "none" else e for e in args.effects.split(",")]
    seeds = range(args.first_seed, args.first_seed + args.seeds)
    rows = []
    start = time.perf_counter()
    chosen = {}
    if args.sizes:
        for item in args.sizes.split(";"):
            name, values = item.split("=")
            chosen[name] = [float(v) for v in values.split(",")]
        effects = list(chosen)
    for effect in effects:
        sizes = [None]
        if effect in chosen:
            sizes = chosen[effect]
        elif effect is not None:
            spec = HIDDEN_EFFECTS[effect]
            sizes = [spec["size"], *(spec["weaker"] if args.sweep else ())]
        for size in sizes:
            for seed in seeds:
                row = run(effect, seed, size)
                rows.append(row)
                print(
                    f"{row['effect']:24s} {size or 0:<9.3g} seed {seed}: named "
                    f"{row['named']:24s} held-out {row['extended_heldout_um']:.2f} um "
                    f"(floor {row['floor_um']:.2f}) "
                    f"({time.perf_counter() - start:.0f} s)",
                    file=sys.stderr,
                    flush=True,
                )
    names = ["none", *jc.EXTENSIONS, "unexplained"]
    matrix = {
        e: {n: 0 for n in names}
        for e in (["none"] if None in effects else []) + [e for e in effects if e]
    }
    for row in rows:
        if row["documented"]:
            matrix[row["effect"]][row["named"]] += 1
    limits = {}
    for effect in [None, *[e for e in effects if e]]:
        if effect is None and None not in effects:
            continue
        runs = []
        for size in dict.fromkeys(
            r["size"] for r in rows if r["effect"] == (effect or "none")
        ):
            sel = [
                r
                for r in rows
                if r["effect"] == (effect or "none") and r["size"] == size
            ]
            runs.append(
                {
                    "size": size,
                    "named": sum(r["named"] == (effect or "none") for r in sel),
                    "within_20pct_of_floor": sum(
                        r["extended_heldout_um"] <= 1.2 * r["floor_um"] for r in sel
                    ),
                    "within_20pct_of_noise": sum(
                        r["extended_heldout_um"] <= 1.2 * 5.0 for r in sel
                    ),
                    "seeds": len(sel),
                    "effect_rms_um": float(
                        np.median([r["effect_rms_um"] for r in sel])
                    ),
                    "effect_max_um": float(
                        np.median([r["effect_max_um"] for r in sel])
                    ),
                }
            )
        if effect is None:
            limits["none"] = {"runs": runs}
            continue
        detected = [r["size"] for r in runs if r["named"] >= 0.9 * r["seeds"]]
        # The weakest detected size: sizes run from strong to weak.
        limits[effect] = {
            "unit": jc.EXTENSIONS[effect].SIZE_UNIT,
            "parameter": jc.EXTENSIONS[effect].SIZE_FIELD,
            "runs": runs,
            "detection_limit": detected[-1] if detected else None,
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
    if args.markdown:
        with open(args.markdown, "w") as f:
            f.write(_markdown(matrix, limits, names, document))
    short = {
        "none": "none",
        **{k: k[:8] for k in jc.EXTENSIONS},
        "unexplained": "unexplai",
    }
    print("\nhidden \\ named  " + " ".join(f"{short[n]:>8s}" for n in names))
    for effect, counts in matrix.items():
        print(
            f"{effect:15s} " + " ".join(f"{counts[n]:8d}" for n in names),
        )
    for effect, info in limits.items():
        runs = ", ".join(
            f"{r['size'] or 0:.3g}: named {r['named']}/{r['seeds']}, within 20 % of "
            f"the floor {r['within_20pct_of_floor']}/{r['seeds']}, of 5 um "
            f"{r['within_20pct_of_noise']}/{r['seeds']}"
            for r in info["runs"]
        )
        print(
            f"{effect:24s} {info.get('parameter', '')} [{info.get('unit', '')}]: {runs}"
        )


def _markdown(matrix, limits, names, document) -> str:
    lines = [
        "| hidden \\ named | " + " | ".join(f"`{n}`" for n in names) + " |",
        "| --- | " + " | ".join("---:" for _ in names) + " |",
    ]
    for effect, counts in matrix.items():
        lines.append(
            f"| `{effect}` | " + " | ".join(str(counts[n]) for n in names) + " |"
        )
    lines += [
        "",
        "| hidden effect | size parameter | size | effect RMS / max, um | named | "
        "held-out RMSE within 20 % of the floor | within 20 % of 5 um |",
        "| --- | --- | ---: | ---: | ---: | ---: | ---: |",
    ]
    for effect, info in limits.items():
        for r in info["runs"]:
            size = "-" if r["size"] is None else f"{r['size']:.3g} {info['unit']}"
            lines.append(
                f"| `{effect}` | {info.get('parameter', '-')} | {size} | "
                f"{r['effect_rms_um']:.3g} / {r['effect_max_um']:.3g} | "
                f"{r['named']}/{r['seeds']} | {r['within_20pct_of_floor']}/{r['seeds']}"
                f" | {r['within_20pct_of_noise']}/{r['seeds']} |"
            )
    lines += [
        "",
        f"Seeds {document['seeds'][0]}-{document['seeds'][-1]}; "
        f"{document['seconds']:.0f} s on {document['machine']['platform']} "
        f"({document['machine']['devices']}).",
        "",
    ]
    return "\n".join(lines)


if __name__ == "__main__":
    main()
