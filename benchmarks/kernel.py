"""Kernel throughput: forward sample-steps per second against batch size, and the
grad/forward time ratio, for the rate-driven integrated model (Newton inside).

    python benchmarks/kernel.py [--samples 2000] [--batches 1,16,64,256,1024]
        [--repeats 5] [--x64] [--xla-default] [--json-out FILE]

The scans run with the CPU loop kernels that `import jaxcable` turns on;
`--xla-default` keeps XLA's own CPU loops (`JAXCABLE_NO_LOOP_KERNELS=1`), and the
JSON's `machine.loop_kernels` says which ran. Prints one JSON object and a table.
Timings: jit, one warm-up call, then the median of `--repeats` calls, each ended by
`jax.block_until_ready`. Results with machine details are kept in
benchmarks/README.md.
"""

import argparse
import json
import os
import platform
import time

import jax


def _parse():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--samples", type=int, default=2000)
    p.add_argument("--batches", default="1,16,64,256,1024")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--x64", action="store_true", help="run in float64")
    p.add_argument(
        "--xla-default",
        action="store_true",
        help="XLA's default CPU loops instead of the loop kernels that "
        "`import jaxcable` turns on (JAXCABLE_NO_LOOP_KERNELS=1)",
    )
    p.add_argument("--json-out", default=None)
    return p.parse_args()


def _loop_kernels() -> bool:
    # Whether XLA's CPU loop-kernel option is set (by `import jaxcable` or by hand).
    return "xla_cpu_small_while_loop_byte_threshold" in os.environ.get("XLA_FLAGS", "")


def _median_time(fn, *args, repeats):
    jax.block_until_ready(fn(*args))
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(fn(*args))
        times.append(time.perf_counter() - t0)
    times.sort()
    return times[len(times) // 2]


def main():
    args = _parse()
    if args.xla_default:
        # Read by `import jaxcable` (below), which otherwise sets the loop-kernel flag.
        os.environ["JAXCABLE_NO_LOOP_KERNELS"] = "1"
    load_at_start = list(os.getloadavg())
    if args.x64:
        jax.config.update("jax_enable_x64", True)
    import equinox as eqx
    import jax.numpy as jnp
    import numpy as np

    import jaxcable as jc

    model = jc.IntegratedModel()
    protocol = jc.Protocol.cycles(
        100.0, 1, samples_per_ramp=args.samples // 2, start=False
    )
    n = protocol.num_samples

    def cables(batch):
        # Lengths 100-500 mm at 3-10 mm/min: the paper's range of strain rates. The
        # other fields keep their defaults, broadcast to the batch (whatever they are).
        cable = jc.Cable(
            length=jnp.linspace(0.1, 0.5, batch),
            speed=jnp.linspace(3e-3, 10e-3, batch) / 60,
        )
        return jax.tree_util.tree_map(lambda x: jnp.broadcast_to(x, (batch,)), cable)

    @eqx.filter_jit
    def forward(model, cable):
        traj = jax.vmap(
            lambda c: jc.simulate_rate_test(
                model, c, protocol, method=jc.Simulation(throw=False)
            )
        )(cable)
        return traj.elongation, traj.result

    @eqx.filter_jit
    def loss_and_grad(model, cable):
        def loss(model):
            traj = jax.vmap(
                lambda c: jc.simulate_rate_test(
                    model, c, protocol, method=jc.Simulation(throw=False)
                )
            )(cable)
            return jnp.mean(traj.elongation**2)

        return eqx.filter_value_and_grad(loss)(model)

    rows = []
    for batch in [int(b) for b in args.batches.split(",")]:
        c = cables(batch)
        t0 = time.perf_counter()
        _, result = jax.block_until_ready(forward(model, c))
        compile_s = time.perf_counter() - t0
        ok = int(np.sum(np.asarray(result == jc.RESULTS.successful)))
        fwd = _median_time(forward, model, c, repeats=args.repeats)
        rows.append(
            dict(
                batch=batch,
                samples=n,
                forward_s=fwd,
                steps_per_s=batch * n / fwd,
                first_call_s=compile_s,
                successful=ok,
            )
        )
    big = cables(max(int(b) for b in args.batches.split(",")))
    fwd = _median_time(forward, model, big, repeats=args.repeats)
    grad = _median_time(loss_and_grad, model, big, repeats=args.repeats)
    out = dict(
        machine=dict(
            platform=platform.platform(),
            processor=platform.processor() or platform.machine(),
            cpu_count=os.cpu_count(),
            python=platform.python_version(),
            jax=jax.__version__,
            backend=jax.default_backend(),
            devices=[str(d) for d in jax.devices()],
            dtype="float64" if args.x64 else "float32",
            loop_kernels=_loop_kernels(),
            xla_flags=os.environ.get("XLA_FLAGS", ""),
            load_average_at_start=load_at_start,
            load_average_at_end=list(os.getloadavg()),
        ),
        throughput=rows,
        grad=dict(
            batch=big.length.shape[0],
            samples=n,
            forward_s=fwd,
            grad_s=grad,
            ratio=grad / fwd,
        ),
    )
    print(json.dumps(out, indent=1))
    print(
        "\nload average (1, 5, 15 min) at start "
        f"{load_at_start}, at end {out['machine']['load_average_at_end']}"
    )
    print(
        f"{'batch':>6} {'samples':>8} {'forward [s]':>12} {'M steps/s':>10} {'first call [s]':>15} {'ok':>6}"
    )
    for r in rows:
        print(
            f"{r['batch']:>6} {r['samples']:>8} {r['forward_s']:>12.4f} "
            f"{r['steps_per_s'] / 1e6:>10.2f} {r['first_call_s']:>15.2f} {r['successful']:>6}"
        )
    g = out["grad"]
    print(
        f"grad/forward at {g['batch']} x {g['samples']}: {g['grad_s']:.3f} s / {g['forward_s']:.3f} s = {g['ratio']:.2f}"
    )
    if args.json_out:
        with open(args.json_out, "w") as f:
            json.dump(out, f, indent=1)


if __name__ == "__main__":
    main()
