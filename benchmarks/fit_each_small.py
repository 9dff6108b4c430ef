"""Many small fits: `jaxcable.fit_each` of 256 Burgers specimens (3 creep tests of 200
samples each, 4 parameters) against a Python loop of `jaxcable.fit`, in one run.

    python benchmarks/fit_each_small.py [--specimens 256] [--samples 200]
        [--loop-specimens 16] [--multistart 4] [--json-out FILE]

Each specimen: a `jaxcable.BurgersModel` whose four parameters are the defaults
scaled by exp(0.1 z) (z standard normal), loaded to 10, 20 and 40 N in 10 s and held
for 600 s on 100, 200 and 300 mm, each test `--samples` samples, with 2 um of
elongation noise; fitted from the defaults with `jc.LeastSquares(multistart=...)`,
float64. Timed:

- `fit_each`: its first call (compilation included) and a second, warm call;
- `fit loop`: `jaxcable.fit` of the first specimen (its compilation included), then
    a warm loop over the next `--loop-specimens` specimens, scaled to all.

Ratios: the warm loop over all specimens / warm `fit_each`, and the loop with its
one compilation / `fit_each`'s first call. Check: the largest relative difference
of the looped specimens' identified parameters (E1, E2: relative standard error
below 10 %) from their `fit_each` values. Prints one JSON object and a table.
"""

import argparse
import json
import os
import platform
import time

import jax


jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import jaxcable as jc  # noqa: E402


NAMES = ("E1", "eta0", "E2", "eta2")
DESIGNS = ((10.0, 0.1), (20.0, 0.2), (40.0, 0.3))  # (force N, length m)


def specimens(count: int, samples: int, seed: int = 0) -> list[jc.Problem]:
    """The problems of `count` specimens (see the module's docstring)."""
    rng = np.random.default_rng(seed)
    base = jc.BurgersModel()
    t = np.linspace(0.0, 600.0, samples)
    problems = []
    for _ in range(count):
        z = np.exp(0.1 * rng.standard_normal(len(NAMES)))
        truth = jc.BurgersModel(**{n: getattr(base, n) * f for n, f in zip(NAMES, z)})
        tests = []
        for force, length in DESIGNS:
            f = force * np.minimum(t / 10.0, 1.0)
            traj = jc.simulate_force_history(
                truth, jc.Cable(length=length), jnp.asarray(t), jnp.asarray(f)
            )
            e = np.asarray(traj.elongation) + 2e-6 * rng.standard_normal(samples)
            meta = {"length_mm": 1e3 * length, "diameter_mm": 3.0, "control": "force"}
            tests.append(jc.TestData(time=t, force=f, elongation=e, metadata=meta))
        problems.append(jc.Problem(base, tests, fit=NAMES))
    return problems


def _timed(fn):
    t0 = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t0


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--specimens", type=int, default=256)
    p.add_argument("--samples", type=int, default=200)
    p.add_argument("--loop-specimens", type=int, default=16)
    p.add_argument("--multistart", type=int, default=4)
    p.add_argument("--json-out", default=None)
    args = p.parse_args()
    if args.specimens < 2 or args.samples < 20 or args.loop_specimens < 1:
        p.error("--specimens >= 2, --samples >= 20, --loop-specimens >= 1")
    problems = specimens(args.specimens, args.samples)
    method = jc.LeastSquares(multistart=args.multistart)
    each, each_first = _timed(lambda: jc.fit_each(problems, method))
    each, each_warm = _timed(lambda: jc.fit_each(problems, method))
    _, fit_first = _timed(lambda: jc.fit(problems[0], method, throw=False))
    looped = problems[1 : 1 + args.loop_specimens]
    alone, loop_s = _timed(lambda: [jc.fit(q, method, throw=False) for q in looped])
    per_fit = loop_s / len(looped)
    loop_warm = per_fit * args.specimens
    loop_cold = fit_first + per_fit * (args.specimens - 1)
    diffs = [
        abs(a.values[i] / b.values[i] - 1)
        for a, b in zip(alone, each[1:])
        for i, name in enumerate(a.names)
        if name in ("E1", "E2") and a.stderr[i] < 0.1 * abs(a.values[i])
    ]
    out = dict(
        specimens=args.specimens,
        tests=len(DESIGNS),
        samples=args.samples,
        parameters=len(NAMES),
        multistart=args.multistart,
        fit_each_first_s=each_first,
        fit_each_warm_s=each_warm,
        fit_first_s=fit_first,
        fit_warm_per_specimen_s=per_fit,
        loop_warm_s=loop_warm,
        loop_with_compile_s=loop_cold,
        ratio_warm=loop_warm / each_warm,
        ratio_with_compile=loop_cold / each_first,
        successful=sum(bool(r.result == jc.RESULTS.successful) for r in each),
        max_rel_diff_identified=float(max(diffs)) if diffs else None,
        loop_kernels="xla_cpu_small_while_loop_byte_threshold"
        in os.environ.get("XLA_FLAGS", ""),
        machine=dict(
            platform=platform.platform(),
            cpu_count=os.cpu_count(),
            jax=jax.__version__,
            backend=jax.default_backend(),
        ),
    )
    print(json.dumps(out, indent=1))
    print(f"\n{'':>24} {'first call [s]':>15} {'warm [s]':>10}")
    print(f"{'fit_each':>24} {each_first:>15.2f} {each_warm:>10.2f}")
    print(f"{'loop of fit (scaled)':>24} {loop_cold:>15.2f} {loop_warm:>10.2f}")
    print(
        f"{'loop / fit_each':>24} {out['ratio_with_compile']:>15.2f} "
        f"{out['ratio_warm']:>10.2f}"
    )
    if args.json_out:
        with open(args.json_out, "w") as f:
            json.dump(out, f, indent=1)


if __name__ == "__main__":
    main()
