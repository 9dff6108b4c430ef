"""A robot's day-long log fitted in bounded memory: `jaxcable.fit` with
`jaxcable.StreamingLeastSquares` on records of 1e5, 1e6 and 8.6e6 samples (a day at
100 Hz), each in a fresh process, its time and peak memory (RSS).

    python benchmarks/day_log.py [--samples 100000,1000000,8640000] [--json-out FILE]

The record: one cable of a cable robot, 4 m of `jaxcable.IntegratedModel` at its
defaults with E1r, E2c and t_c scaled by 1.5, 1.3 and 0.7 (the cable the robot really
has, bedded in),
loaded by pick-and-place cycles at 100 Hz (a 20 s cycle: 30 N empty, 70 N with the
payload, smooth ramps between, and a slow 10 N daily swing), its elongation with
5 um of noise (the force as logged). Fitted from the defaults: E1c, E2c and t_c.
Reported per size: the samples, the fit's seconds (the record's synthesis
excluded), its steps, the fitted values against the truth, and the process's peak
RSS (MB). Memory should stay flat and the time grow linearly with the samples.
"""

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import time


# Factors on the defaults: a rope bedded in (E1r above E1c, so that Park's Eq. 9
# unloading line lies above the loading curve, away from the kink of their max), and
# other primary creep.
TRUTH = {"E1r": 1.5, "E2c": 1.3, "t_c": 0.7}
FIT = ("E1c", "E2c", "t_c")
RATE_HZ = 100.0


def _record(samples: int):
    import jax.numpy as jnp
    import numpy as np

    import jaxcable as jc

    t = np.arange(samples) / RATE_HZ
    phase = (t % 20.0) / 20.0
    # Empty (30 N) for the first half of the cycle, loaded (70 N) for the second,
    # smooth 2 s ramps between.
    ramp = lambda x: 0.5 - 0.5 * np.cos(np.pi * np.clip(x, 0.0, 1.0))  # noqa: E731
    f = 30.0 + 40.0 * (ramp((phase - 0.4) * 10.0) - ramp((phase - 0.9) * 10.0))
    f = f + 10.0 * np.sin(2 * np.pi * t / 86400.0)
    f[0] = 0.0
    defaults = jc.IntegratedModel()
    truth = jc.IntegratedModel(
        **{k: getattr(defaults, k) * v for k, v in TRUTH.items()}
    )
    cable = jc.Cable(length=4.0)
    traj = jc.simulate_force_history(truth, cable, jnp.asarray(t), jnp.asarray(f))
    rng = np.random.default_rng(0)
    e = np.asarray(traj.elongation) + 5e-6 * rng.standard_normal(samples)
    meta = {"length_mm": 4000.0, "diameter_mm": 3.0, "control": "force"}
    return jc.TestData(time=t, force=f, elongation=e, metadata=meta), truth


def _worker(samples: int) -> dict:
    import jax

    jax.config.update("jax_enable_x64", True)
    import jaxcable as jc

    test, truth = _record(samples)
    # The start: the defaults, bedded in as the truth (E1r is not fitted).
    start = jc.IntegratedModel(E1r=truth.E1r)
    problem = jc.Problem(start, [test], fit=FIT)
    t0 = time.perf_counter()
    result = jc.fit(problem, jc.StreamingLeastSquares(), throw=False)
    seconds = time.perf_counter() - t0
    return dict(
        samples=samples,
        seconds=seconds,
        peak_rss_mb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
        steps=result.num_steps,
        result="successful"
        if result.result == jc.RESULTS.successful
        else str(result.result),
        fitted={n: float(v) for n, v in zip(result.names, result.values)},
        truth={n: float(getattr(truth, n)) for n in FIT},
        stderr={n: float(s) for n, s in zip(result.names, result.stderr)},
    )


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--samples", default="100000,1000000,8640000")
    p.add_argument("--json-out", default=None)
    p.add_argument("--worker", type=int, help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.worker:
        print(json.dumps(_worker(args.worker)))
        return
    sizes = [int(s) for s in args.samples.split(",")]
    if min(sizes) < 1000:
        p.error("--samples: each at least 1000")
    rows = []
    for n in sizes:
        done = subprocess.run(
            [sys.executable, os.path.abspath(__file__), "--worker", str(n)],
            capture_output=True,
            text=True,
        )
        if done.returncode != 0:
            sys.exit(f"the run of {n} samples failed:\n{done.stderr[-3000:]}")
        rows.append(json.loads(done.stdout.strip().splitlines()[-1]))
    for row in rows:
        row["seconds_per_million_samples"] = 1e6 * row["seconds"] / row["samples"]
    out = dict(
        rows=rows,
        machine=dict(
            platform=platform.platform(),
            cpu_count=os.cpu_count(),
            python=platform.python_version(),
        ),
    )
    print(json.dumps(out, indent=1))
    print(
        f"\n{'samples':>10} {'fit [s]':>9} {'s / 1e6':>8} {'peak RSS [MB]':>14} {'steps':>6}"
    )
    for r in rows:
        print(
            f"{r['samples']:>10} {r['seconds']:>9.1f} "
            f"{r['seconds_per_million_samples']:>8.1f} {r['peak_rss_mb']:>14.0f} "
            f"{r['steps']:>6}"
        )
    if args.json_out:
        with open(args.json_out, "w") as f:
            json.dump(out, f, indent=1)


if __name__ == "__main__":
    main()
