"""Controller latency: one jitted `jaxcable.controller_step` for the 8 cables of a
robot, called from Python as a real-time loop would call it, per model; and the
amortised cost of one closed-loop sample of the 8-cable robot example inside its
`lax.scan` (tension distribution + controller + real cables + forward kinematics).

    python benchmarks/controller.py [--cables 8] [--repeats 2000] [--x64] [--sync]
        [--scan-hours 0.5] [--xla-default] [--json-out FILE]

Timings: `jax.jit` of the step with the state, time and forces as arguments, warm-up
calls, then the median (and 10th/90th percentiles) over `--repeats` calls, each ended
by `jax.block_until_ready`. The scans run with the CPU loop kernels that `import
jaxcable` turns on; `--xla-default` keeps XLA's own CPU loops
(`JAXCABLE_NO_LOOP_KERNELS=1`), and the JSON's `loop_kernels` says which ran. Prints
one JSON object and a table.

Results with machine details: benchmarks/README.md. With `--sync` (no asynchronous
dispatch) every step runs on the calling thread: with asynchronous dispatch a step is
sometimes handed to another thread, and on a busy machine the hand-off costs more
than the step.
"""

import argparse
import json
import os
import platform
import statistics
import time

import jax


def _parse():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--cables", type=int, default=8)
    p.add_argument("--repeats", type=int, default=2000)
    p.add_argument("--x64", action="store_true", help="run in float64")
    p.add_argument(
        "--sync",
        action="store_true",
        help="jax_cpu_enable_async_dispatch=False: run each step on the calling "
        "thread (what a real-time loop wants; steadier latency on a busy CPU)",
    )
    p.add_argument("--scan-hours", type=float, default=0.5)
    p.add_argument(
        "--xla-default",
        action="store_true",
        help="XLA's default CPU loops instead of the loop kernels that "
        "`import jaxcable` turns on (JAXCABLE_NO_LOOP_KERNELS=1)",
    )
    p.add_argument("--json-out", default=None)
    return p.parse_args()


def _times(fn, args, repeats, warmup=50):
    for _ in range(warmup):
        jax.block_until_ready(fn(*args))
    out = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(fn(*args))
        out.append(time.perf_counter() - t0)
    out.sort()
    q = statistics.quantiles(out, n=10)
    return {
        "median_us": 1e6 * statistics.median(out),
        "p10_us": 1e6 * q[0],
        "p90_us": 1e6 * q[-1],
    }


def main():
    args = _parse()
    if args.xla_default:
        # Read by `import jaxcable` (below), which otherwise sets the loop-kernel flag.
        os.environ["JAXCABLE_NO_LOOP_KERNELS"] = "1"
    if args.x64:
        jax.config.update("jax_enable_x64", True)
    if args.sync:
        jax.config.update("jax_cpu_enable_async_dispatch", False)
    import jax.numpy as jnp

    import jaxcable as jc
    from jaxcable import cdpr

    n = args.cables
    robot = cdpr.Robot()
    lengths = jnp.linspace(6.5, 8.3, n)
    cables = robot.cables(lengths)
    forces = jnp.linspace(50.0, 260.0, n)
    real = cdpr.real_cables(jax.random.key(0), num_cables=n)
    cases = [
        ("integrated", jc.IntegratedModel(), False),
        ("five-element (Piao, live)", jc.LiveFiveElement(), False),
        ("Hooke", jc.HookeModel(), False),
        ("integrated + termination, per cable", real, True),
    ]
    rows = []
    for name, model, per_cable in cases:
        for throw in (True, False):
            state = jc.controller_init(model, cables, per_cable=per_cable)

            @jax.jit
            def control(
                state, t, forces, model=model, per_cable=per_cable, throw=throw
            ):
                return jc.controller_step(model, cables, state, t, forces, throw=throw)

            state, _ = control(state, 1.0, forces)
            t = jnp.asarray(2.0, state.cables.time.dtype)
            timing = _times(control, (state, t, forces), args.repeats)
            rows.append(
                {"model": name, "throw": throw, **timing}
                | {"rate_kHz": 1e3 / timing["median_us"]}
            )

    # The whole closed loop, amortised per sample inside one scan.
    scenario = cdpr.pick_and_place(args.scan_hours)
    samples = int(scenario.time.shape[0])
    loop = {}
    for name, model in cdpr.compensation_models().items():
        run = lambda: cdpr.simulate_robot(robot, scenario, real, model)  # noqa: E731
        jax.block_until_ready(run())
        reps = []
        for _ in range(3):
            t0 = time.perf_counter()
            jax.block_until_ready(run())
            reps.append(time.perf_counter() - t0)
        loop[name] = 1e6 * statistics.median(reps) / samples

    out = {
        "cables": n,
        "dtype": "float64" if args.x64 else "float32",
        "async_dispatch": not args.sync,
        "load_average": os.getloadavg(),
        "jax": jax.__version__,
        "backend": jax.default_backend(),
        "cpu": platform.processor() or platform.machine(),
        "cpu_count": os.cpu_count(),
        # Whether XLA's CPU loop-kernel option is set (by `import jaxcable` or by hand).
        "loop_kernels": "xla_cpu_small_while_loop_byte_threshold"
        in os.environ.get("XLA_FLAGS", ""),
        "controller_step": rows,
        "closed_loop_us_per_sample": loop,
        "closed_loop_samples": samples,
    }
    print(json.dumps(out, indent=2))
    print()
    print(
        f"{'model':38s} {'throw':6s} {'median_us':>9s} {'p10_us':>8s} "
        f"{'p90_us':>8s} {'rate_kHz':>9s}"
    )
    for r in rows:
        print(
            f"{r['model']:38s} {str(r['throw']):6s} {r['median_us']:9.1f} "
            f"{r['p10_us']:8.1f} {r['p90_us']:8.1f} {r['rate_kHz']:9.1f}"
        )
    print()
    print(f"closed loop, one sample inside the scan ({samples} samples):")
    for name, us in loop.items():
        print(f"  {name:36s} {us:8.1f} us")
    if args.json_out:
        with open(args.json_out, "w") as f:
            json.dump(out, f, indent=2)


if __name__ == "__main__":
    main()
