"""The hidden-effect confusion matrix and detection limits of `jaxcable.diagnose`.

For each hidden effect (and for none), `--seeds` data sets of
`jaxcable.papers.hidden_effect_dataset` (six tests: three lengths, two rates, three force
levels, three temperatures; 5 um elongation and 0.05 N force noise; the base
parameters perturbed by 10 % per seed) are diagnosed at the effect's documented size;
the named causes make the confusion matrix (its `unexplained` column: an excess over
the noise that no candidate explains enough to be named, see
`jaxcable._diagnose.rule`). With `--sweep`, each effect is also run at
its weaker sizes (`HIDDEN_EFFECTS[effect]["weaker"]`), and its detection limit is the
weakest size named in >= 9 of 10 seeds. For every run the held-out RMSE of the named
model is compared with the floor: the held-out RMSE of the data-generating model
itself (elongation noise plus its response to the force noise); every row also records
the noise estimated from the data (`Diagnosis.noise`), the verdict, and each
candidate's share of the base's excess over that noise (`explained_pct`). Prints JSON (one
object) and a table; `--out FILE` writes the JSON too.

With `--out-of-catalogue` the effects outside the catalogue
(`jaxcable.papers.OUT_OF_CATALOGUE`: mechano-sorptive creep with a recorded humidity,
cyclic softening, a slipping clamp) are run too, at their documented sizes (and
their weaker ones with `--sweep`). No
catalogue cause is right for them: each run records the named cause (which may be
`unexplained` or `discovered`, or any other name the diagnosis gives), the verdict
when the diagnosis has one, the data-generating model's held-out RMSE (driven by the
recorded force and covariates, `truth_elongations(..., tests=tests)`) against the
fitted base's, i.e. the true model's held-out gain, and the discovered term's gain
and its share of the true gain when a `discovered` candidate is scored.

    python benchmarks/diagnose_matrix.py --seeds 10 --sweep --out matrix.json
    python benchmarks/diagnose_matrix.py --seeds 10 --out-of-catalogue
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
from jaxcable._diagnose import heldout_rmse, heldout_start
from jaxcable._papers.synthetic import (
    HIDDEN_EFFECT_DESIGN,
    HIDDEN_EFFECTS,
    OUT_OF_CATALOGUE,
    hidden_effect_protocol,
)


# The named causes the tables always show; any other name a diagnosis gives is
# appended as it appears.
NAMES = ["none", *jc.EXTENSIONS, "unexplained", "discovered"]


def _spec(effect):
    """The hidden effect's documented size, parameter and unit."""
    if effect in OUT_OF_CATALOGUE:
        spec = OUT_OF_CATALOGUE[effect]
        return spec["size"], spec["parameter"], spec["unit"]
    cls = jc.EXTENSIONS[effect]
    return HIDDEN_EFFECTS[effect]["size"], cls.SIZE_FIELD, cls.SIZE_UNIT


def _heldout_um(tests, predictions):
    """Pooled RMSE of the elongation over the held-out samples of `diagnose`'s time
    split (the last 30 % of every test), um."""
    sq, n = 0.0, 0
    for t, p in zip(tests, predictions):
        first = heldout_start(len(t.time), 0.3)
        r = np.asarray(t.elongation)[first:] - np.asarray(p)[first:]
        sq, n = sq + float(np.sum(r**2)), n + r.size
    return float(1e6 * np.sqrt(sq / n))


def effect_magnitude(effect, seed, size):
    """(RMS, max) over all samples of the hidden effect's own contribution to the
    elongation, um: the true model minus its base, noise-free."""
    if effect is None:
        return 0.0, 0.0
    if effect in OUT_OF_CATALOGUE:
        with_effect = papers.truth_elongations(effect, seed=seed, size=size)
        without = papers.truth_elongations(None, seed=seed)
        d = 1e6 * np.concatenate([a - b for a, b in zip(with_effect, without)])
        return float(np.sqrt(np.mean(d**2))), float(np.max(np.abs(d)))
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
    outside = effect in OUT_OF_CATALOGUE
    if outside:
        # The data-generating model driven by the records, as diagnose drives a model.
        truth = papers.truth_elongations(effect, seed=seed, size=size, tests=tests)
        floor = 1e-3 * _heldout_um(tests, truth)
    else:
        floor = heldout_rmse(
            papers.hidden_effect_model(effect, seed=seed, size=size), tests
        )
    rms_um, max_um = effect_magnitude(effect, seed, size)
    d = jc.diagnose(jc.Problem(jc.IntegratedModel(), tests).with_scaled_start())
    gains = {c.id: c.gain_pct for c in d.candidates}
    base_um = 1e3 * d.base_heldout_rmse_mm
    true_gain = 100.0 * (1.0 - 1e3 * floor / base_um)
    covariate = OUT_OF_CATALOGUE[effect]["covariate"] if outside else None
    named = [c for c in d.candidates if c.id == d.named_cause]
    # What the verdict names: the named cause, its effect, and its candidate's fit.
    said = json.dumps(
        [d.named_cause, d.effect, *(c.to_dict() for c in named)], default=str
    )
    return {
        "effect": effect or "none",
        "seed": seed,
        "size": size,
        "documented": effect is None or size == _spec(effect)[0],
        "outside_catalogue": outside,
        "named": d.named_cause,
        "verdict": d.verdict,
        "noise_um": 1e3 * d.noise_mm,
        "wrong_catalogue_cause": bool(
            d.named_cause in jc.EXTENSIONS and d.named_cause != effect
        ),
        "covariate": covariate,
        "covariate_named": None if covariate is None else bool(covariate in said),
        "floor_um": 1e3 * floor,
        "effect_rms_um": rms_um,
        "effect_max_um": max_um,
        "base_heldout_um": base_um,
        "extended_heldout_um": 1e3 * d.extended_heldout_rmse_mm,
        "true_heldout_um": float(1e3 * floor),
        "true_gain_pct": float(true_gain),
        "discovered_gain_pct": gains.get("discovered"),
        "discovered_share_of_true_gain": (
            None
            if gains.get("discovered") is None or true_gain <= 0
            else gains["discovered"] / true_gain
        ),
        # The named candidate's held-out gain over the true one (a covariate's
        # extension or the discovered term, where one is named).
        "named_share_of_true_gain": (
            None
            if gains.get(d.named_cause) is None or true_gain <= 0
            else gains[d.named_cause] / true_gain
        ),
        "gains": gains,
        "explained_pct": {c.id: c.explained_pct for c in d.candidates},
        "effect_value": d.effect.get("value"),
        "effect_stderr": d.effect.get("stderr"),
        "discovered_equation": (d.discovered or {}).get("equation"),
    }


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=10)
    parser.add_argument("--first-seed", type=int, default=100)
    parser.add_argument("--effects", default="none," + ",".join(jc.EXTENSIONS))
    parser.add_argument(
        "--out-of-catalogue",
        action="store_true",
        help="also run the effects outside the catalogue (OUT_OF_CATALOGUE)",
    )
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
    if args.out_of_catalogue:
        effects += [e for e in OUT_OF_CATALOGUE if e not in effects]
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
        # Each effect's kernels are compiled once for its seeds; dropped after them,
        # or a process that runs every effect outside the catalogue (a discovered
        # term's model structure per support) outgrew 23 GB.
        jax.clear_caches()
        sizes = [None]
        if effect in chosen:
            sizes = chosen[effect]
        elif effect in OUT_OF_CATALOGUE:
            spec = OUT_OF_CATALOGUE[effect]
            sizes = [spec["size"], *(spec["weaker"] if args.sweep else ())]
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
                    f"(floor {row['floor_um']:.2f}, base {row['base_heldout_um']:.2f}) "
                    f"({time.perf_counter() - start:.0f} s)",
                    file=sys.stderr,
                    flush=True,
                )
    names = NAMES + list(
        dict.fromkeys(r["named"] for r in rows if r["named"] not in NAMES)
    )
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
                    **_outside_counts(sel),
                }
            )
        if effect is None:
            limits["none"] = {"runs": runs}
            continue
        detected = [r["size"] for r in runs if r["named"] >= 0.9 * r["seeds"]]
        # The weakest detected size: sizes run from strong to weak. No size of an
        # effect outside the catalogue can be named.
        _, parameter, unit = _spec(effect)
        limits[effect] = {
            "unit": unit,
            "parameter": parameter,
            "runs": runs,
            "detection_limit": None
            if effect in OUT_OF_CATALOGUE
            else (detected[-1] if detected else None),
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
    print("\nhidden \\ named  " + " ".join(f"{n[:8]:>8s}" for n in names))
    for effect, counts in matrix.items():
        print(
            f"{effect[:15]:15s} " + " ".join(f"{counts[n]:8d}" for n in names),
        )
    for effect, info in limits.items():
        runs = ", ".join(
            f"{r['size'] or 0:.3g}: named {r['named']}/{r['seeds']}, within 20 % of "
            f"the floor {r['within_20pct_of_floor']}/{r['seeds']}, of 5 um "
            f"{r['within_20pct_of_noise']}/{r['seeds']}"
            + (
                f", no wrong catalogue cause {r['no_wrong_catalogue_cause']}/"
                f"{r['seeds']}, true gain {r['true_gain_pct']:.0f} %, discovered "
                f">= 50 % of it {r['discovered_half_true_gain']}/{r['seeds']}, "
                f"named >= 50 % of it {r['named_half_true_gain']}/{r['seeds']}"
                + (
                    ""
                    if r["covariate_named"] is None
                    else f", covariate named {r['covariate_named']}/{r['seeds']}"
                )
                if "true_gain_pct" in r
                else ""
            )
            for r in info["runs"]
        )
        print(
            f"{effect:24s} {info.get('parameter', '')} [{info.get('unit', '')}]: {runs}"
        )


def _outside_counts(sel) -> dict:
    """The targets of effects outside the catalogue over the runs `sel` (empty for
    catalogued effects): no wrong catalogue cause named, the covariate named, the
    median true (data-generating) held-out gain and the runs whose discovered term
    reaches half of it."""
    if not sel or not sel[0]["outside_catalogue"]:
        return {}
    share = [r["discovered_share_of_true_gain"] for r in sel]
    return {
        "no_wrong_catalogue_cause": int(
            sum(not r["wrong_catalogue_cause"] for r in sel)
        ),
        "covariate_named": None
        if sel[0]["covariate"] is None
        else int(sum(bool(r["covariate_named"]) for r in sel)),
        "true_gain_pct": float(np.median([r["true_gain_pct"] for r in sel])),
        "base_over_true": float(
            np.median([r["base_heldout_um"] / r["true_heldout_um"] for r in sel])
        ),
        "discovered_half_true_gain": int(
            sum(x is not None and bool(x >= 0.5) for x in share)
        ),
        "named_half_true_gain": int(
            sum(
                r["named_share_of_true_gain"] is not None
                and bool(r["named_share_of_true_gain"] >= 0.5)
                for r in sel
            )
        ),
    }


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
    outside = [
        (e, r)
        for e, info in limits.items()
        for r in info["runs"]
        if "true_gain_pct" in r
    ]
    if outside:
        lines += [
            "",
            "| effect outside the catalogue | no wrong catalogue cause | covariate "
            "named | base / true held-out RMSE | true gain | discovered >= 50 % of it |",
            "| --- | ---: | ---: | ---: | ---: | ---: |",
        ]
        for e, r in outside:
            cov = (
                "-"
                if r["covariate_named"] is None
                else f"{r['covariate_named']}/{r['seeds']}"
            )
            lines.append(
                f"| `{e}` | {r['no_wrong_catalogue_cause']}/{r['seeds']} | {cov} | "
                f"{r['base_over_true']:.2f} | {r['true_gain_pct']:.0f} % | "
                f"{r['discovered_half_true_gain']}/{r['seeds']} |"
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
