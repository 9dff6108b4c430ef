"""The designed next test against Park's standard protocol of the same duration:
how much more each shrinks the uncertainty of the least identified parameter.

    python benchmarks/design.py [--seeds 5] [--duration 3000] [--steps 40]
        [--posterior N] [--json-out FILE]

Truth: the default `IntegratedModel` on a 3 mm x 300 mm cable. What is known: one
test of Park's standard protocol (10 load-unload cycles to 100 N at 3 mm/min, a
30 min rest; 5 um elongation noise), fitted for E1c, E2c, t_c and eta0. Then
per seed:

1. `jaxcable.design_test` proposes a test of `--duration` s, forces up to 100 N
   (5 % of the breaking load), 1-100 mm/min, 160 samples.
2. The designed test and Park's 10-cycle protocol filling the same duration (at
   3 mm/min, then a rest) are each synthesised from the truth (new noise) and fitted
   together with the first test.
3. The standard deviation of the least identified parameter (largest relative
   standard error of the first fit) after each: the linearised standard error, and
   with `--posterior N` also the posterior's (NUTS, 2 chains x N draws).

Reported: the shrink ratio sd(standard) / sd(designed) per seed and its median
(target >= 3), and design_test's own expected standard deviations. Prints one JSON
object, then a table.
"""

import argparse
import json
import os
import time
import warnings

import jax


jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import jaxcable as jc  # noqa: E402
from jaxcable._papers import synthesize  # noqa: E402


TRUTH = jc.IntegratedModel()
NAMES = ("E1c", "E2c", "t_c", "eta0")
CABLE = jc.Cable.from_mm(length_mm=300.0, diameter_mm=3.0, rate_mm_per_min=3.0)
FORCE = 100.0


def _park(cable, duration, ramp_samples):
    """Park's 10 cycles to FORCE, then a rest filling `duration` (s)."""
    cycles = jc.Protocol.cycles(FORCE, 10, ramp_samples)
    spent = float(jc.simulate_rate_test(TRUTH, cable, cycles).time[-1])
    rest = jc.Protocol.rest(max(duration - spent, 1.0), 20)
    return jc.Protocol.concatenate(cycles, rest)


def _fit(tests):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", jc.IdentifiabilityWarning)
        problem = jc.Problem(TRUTH, tests, fit=NAMES)
        return jc.fit(problem, jc.LeastSquares(multistart=1), throw=False)


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, default=5)
    p.add_argument("--duration", type=float, default=3000.0)
    p.add_argument("--steps", type=int, default=40)
    p.add_argument("--posterior", type=int, default=0)
    p.add_argument("--json-out", default=None)
    args = p.parse_args()
    budget = jc.TestBudget(
        duration_s=args.duration,
        max_force_fraction=FORCE / float(CABLE.breaking_load),
        samples=160,
        blocks=2,
    )
    rows = []
    for seed in range(args.seeds):
        first = synthesize(
            TRUTH,
            CABLE,
            _park(CABLE, 1800.0 + 600.0, 10),
            seed=seed,
            metadata={"id": "park-known"},
        )
        known = _fit([first])
        least = int(np.argmax(known.relative_error))
        t0 = time.perf_counter()
        designed = jc.design_test(
            known, jc.TestDesign(budget, steps=args.steps), cable=CABLE
        )
        t_design = time.perf_counter() - t0
        new = synthesize(
            TRUTH,
            designed.cable,
            designed.protocol,
            seed=100 + seed,
            metadata={"id": "designed"},
        )
        std = synthesize(
            TRUTH,
            CABLE,
            _park(CABLE, designed.duration_s, 10),
            seed=200 + seed,
            metadata={"id": "standard"},
        )
        with_designed = _fit([first, new])
        with_standard = _fit([first, std])
        row = {
            "seed": seed,
            "least_identified": NAMES[least],
            "sd_known": float(known.stderr[least]),
            "sd_designed": float(with_designed.stderr[least]),
            "sd_standard": float(with_standard.stderr[least]),
            "design_seconds": t_design,
            "designed_duration_s": designed.duration_s,
            "expected_sd_designed": float(designed.sd_after[least]),
            "expected_sd_standard": float(designed.sd_standard[least]),
            "protocol": designed.document,
        }
        row["ratio"] = row["sd_standard"] / row["sd_designed"]
        if args.posterior:
            sds = []
            for tests, fit in (
                ([first, new], with_designed),
                ([first, std], with_standard),
            ):
                post = jc.sample_posterior(
                    jc.Problem(TRUTH, tests, fit=NAMES),
                    jc.NUTS(
                        num_samples=args.posterior,
                        num_chains=2,
                        num_warmup=args.posterior,
                        key=jax.random.key(seed),
                    ),
                    start=fit,
                )
                sds.append(float(post.sd[least]))
            row["posterior_sd_designed"], row["posterior_sd_standard"] = sds
            row["posterior_ratio"] = sds[1] / sds[0]
        rows.append(row)
        print(
            f"seed {seed}: {NAMES[least]} sd known {row['sd_known']:.3g}, designed "
            f"{row['sd_designed']:.3g}, standard {row['sd_standard']:.3g}, ratio "
            f"{row['ratio']:.2f}",
            flush=True,
        )
        if args.json_out:
            # What is measured so far survives a run cut short.
            with open(args.json_out + ".partial", "w") as f:
                json.dump(rows, f)
    ratios = [r["ratio"] for r in rows]
    out = {
        "benchmark": "design",
        "settings": vars(args),
        "median_ratio_linearised": float(np.median(ratios)),
        "target_met": bool(np.median(ratios) >= 3.0),
        "load_average": os.getloadavg(),
        "rows": rows,
    }
    if args.posterior:
        out["median_ratio_posterior"] = float(
            np.median([r["posterior_ratio"] for r in rows])
        )
    text = json.dumps(out, indent=1)
    print(text)
    if args.json_out:
        with open(args.json_out, "w") as f:
            f.write(text + "\n")
    print()
    print(
        f"{'seed':>4} {'parameter':>10} {'sd designed':>12} {'sd standard':>12} "
        f"{'ratio':>6}"
    )
    for r in rows:
        print(
            f"{r['seed']:>4} {r['least_identified']:>10} {r['sd_designed']:>12.3g} "
            f"{r['sd_standard']:>12.3g} {r['ratio']:>6.2f}"
        )
    print(
        f"median ratio {out['median_ratio_linearised']:.2f} (target >= 3: "
        f"{out['target_met']})"
    )


if __name__ == "__main__":
    main()
