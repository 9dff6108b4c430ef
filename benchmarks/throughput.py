"""Throughput of the rate-driven integrated model (Newton inside), with its baselines
measured in the same run: forward sample-steps/s against batch and against history
length, grad/forward time ratio, compile time, and the NumPy baseline
(benchmarks/numpy_baseline.py) at batch 1 and 1024.

    python benchmarks/throughput.py [--x64] [--samples 2000]
        [--batches 1,4,16,64,256,1024,4096] [--lengths 100,1000,10000,100000,1000000]
        [--length-batches 1,64] [--numpy-batches 1,1024] [--max-seconds 3]
        [--repeats 5] [--xla-default] [--json-out FILE]

The scans run with the CPU loop kernels that `import jaxcable` turns on;
`--xla-default` keeps XLA's own CPU loops (`JAXCABLE_NO_LOOP_KERNELS=1`), and the
JSON's `machine.loop_kernels` says which ran. Prints one JSON object, then a table.
Method: every function is `jax.jit`-ed and compiled ahead of the timed calls
(`lower(...).compile()`, whose wall time is the reported compile time); a timed call
ends with `jax.block_until_ready`; the reported time is the median of `--repeats`
calls (fewer when one call is slow, so that each combination takes a few seconds). A
(batch, length) combination whose predicted run time exceeds `--max-seconds` is
skipped and listed with its prediction. The NumPy baseline always runs in float64 (its
Newton tolerance, 1e-12, needs it); the kernel runs in float32 unless `--x64`. Results
with machine details: benchmarks/README.md.
"""

import argparse
import json
import os
import pathlib
import platform
import sys
import time

import jax


def _parse():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--x64", action="store_true", help="run the kernel in float64")
    p.add_argument(
        "--xla-default",
        action="store_true",
        help="XLA's default CPU loops instead of the loop kernels that "
        "`import jaxcable` turns on (JAXCABLE_NO_LOOP_KERNELS=1)",
    )
    p.add_argument("--samples", type=int, default=2000)
    p.add_argument("--batches", default="1,4,16,64,256,1024,4096")
    p.add_argument("--lengths", default="100,1000,10000,100000,1000000")
    p.add_argument("--length-batches", default="1,64")
    p.add_argument("--numpy-batches", default="1,1024")
    p.add_argument("--grad-batch", type=int, default=1024)
    p.add_argument("--max-seconds", type=float, default=3.0)
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--json-out", default=None)
    return p.parse_args()


def _machine(dtype, load_at_start):
    return dict(
        platform=platform.platform(),
        processor=platform.processor() or platform.machine(),
        cpu_count=os.cpu_count(),
        load_average_at_start=load_at_start,
        load_average_at_end=list(os.getloadavg()),
        python=platform.python_version(),
        jax=jax.__version__,
        backend=jax.default_backend(),
        devices=[str(d) for d in jax.devices()],
        dtype=dtype,
        # Whether XLA's CPU loop-kernel option is set (by `import jaxcable` or by hand).
        loop_kernels="xla_cpu_small_while_loop_byte_threshold"
        in os.environ.get("XLA_FLAGS", ""),
        xla_flags=os.environ.get("XLA_FLAGS", ""),
    )


def _time_calls(fn, args, repeats, budget):
    """Median wall time of calls of a compiled function (one untimed warm-up)."""
    t0 = time.perf_counter()
    jax.block_until_ready(fn(*args))
    first = time.perf_counter() - t0
    n = max(1, min(repeats, int(budget / max(first, 1e-9))))
    times = []
    for _ in range(n):
        t0 = time.perf_counter()
        jax.block_until_ready(fn(*args))
        times.append(time.perf_counter() - t0)
    times.sort()
    return times[len(times) // 2], n


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

    sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
    from numpy_baseline import default_parameters, simulate_rate_test_numpy

    dtype = "float64" if args.x64 else "float32"
    model = jc.IntegratedModel()

    def protocol_of(samples):
        # Load-unload cycles to 100 N, 1000 samples per ramp (Park sampled 2000 per
        # cycle); short histories are one cycle.
        per_ramp = min(1000, max(1, samples // 2))
        cycles = max(1, samples // (2 * per_ramp))
        return jc.Protocol.cycles(100.0, cycles, samples_per_ramp=per_ramp, start=False)

    def cables(batch):
        # Lengths 100-500 mm at 3-10 mm/min: the paper's range of strain rates. The
        # other fields keep their defaults, broadcast to the batch (whatever they are).
        cable = jc.Cable(
            length=jnp.linspace(0.1, 0.5, batch),
            speed=jnp.linspace(3e-3, 10e-3, batch) / 60,
        )
        return jax.tree_util.tree_map(lambda x: jnp.broadcast_to(x, (batch,)), cable)

    def forward(model, cable, protocol):
        traj = jax.vmap(
            lambda c: jc.simulate_rate_test(
                model, c, protocol, method=jc.Simulation(throw=False)
            )
        )(cable)
        return traj.elongation, traj.result

    def loss_and_grad(model, cable, protocol):
        def loss(model):
            return jnp.mean(forward(model, cable, protocol)[0] ** 2)

        return eqx.filter_value_and_grad(loss)(model)

    def compile_(fn, *a):
        t0 = time.perf_counter()
        compiled = eqx.filter_jit(fn).lower(*a).compile()
        return compiled, time.perf_counter() - t0

    def measure(batch, samples, fn=forward):
        protocol = protocol_of(samples)
        c = cables(batch)
        compiled, compile_s = compile_(fn, model, c, protocol)
        t, n = _time_calls(
            compiled, (model, c, protocol), args.repeats, args.max_seconds
        )
        out = compiled(model, c, protocol)
        ok = None
        if fn is forward:
            ok = int(np.sum(np.asarray(out[1] == jc.RESULTS.successful)))
        steps = batch * protocol.num_samples
        return dict(
            batch=batch,
            samples=protocol.num_samples,
            time_s=t,
            steps_per_s=steps / t,
            compile_s=compile_s,
            calls=n,
            successful=ok,
        )

    # 1. Throughput against batch.
    by_batch = [measure(int(b), args.samples) for b in args.batches.split(",")]
    print(f"[throughput] batch sweep done ({len(by_batch)} sizes)", file=sys.stderr)

    # 2. Throughput against history length, skipping what would take too long.
    by_length, skipped = [], []
    for batch in [int(b) for b in args.length_batches.split(",")]:
        rate = None
        for samples in [int(s) for s in args.lengths.split(",")]:
            if rate is not None:
                predicted = batch * samples / rate
                # A call is timed about 1 + repeats times.
                if predicted > args.max_seconds:
                    skipped.append(
                        dict(batch=batch, samples=samples, predicted_s=predicted)
                    )
                    continue
            row = measure(batch, samples)
            rate = row["steps_per_s"]
            by_length.append(row)
    print("[throughput] length sweep done", file=sys.stderr)

    # 3. grad / forward at the grad batch x samples.
    fwd = next(
        (r for r in by_batch if r["batch"] == args.grad_batch),
        None,
    ) or measure(args.grad_batch, args.samples)
    grad = measure(args.grad_batch, args.samples, fn=loss_and_grad)
    grad_row = dict(
        batch=args.grad_batch,
        samples=fwd["samples"],
        forward_s=fwd["time_s"],
        grad_s=grad["time_s"],
        ratio=grad["time_s"] / fwd["time_s"],
        forward_compile_s=fwd["compile_s"],
        grad_compile_s=grad["compile_s"],
    )

    # 4. The NumPy baseline (float64) on the same problems, timed in this run.
    params = default_parameters(model)
    protocol = protocol_of(args.samples)
    arrays = {
        k: np.asarray(getattr(protocol, k))
        for k in ("force", "direction", "duration", "mask")
    }
    numpy_rows = []
    for batch in [int(b) for b in args.numpy_batches.split(",")]:
        c = cables(batch)
        lengths, speeds = np.asarray(c.length, float), np.asarray(c.speed, float)
        t0 = time.perf_counter()
        ref = simulate_rate_test_numpy(params, lengths, speeds, arrays)
        t_np = time.perf_counter() - t0
        kernel = next(
            (
                r
                for r in by_batch
                if r["batch"] == batch and r["samples"] == protocol.num_samples
            ),
            None,
        ) or measure(batch, args.samples)
        elong = np.asarray(eqx.filter_jit(forward)(model, c, protocol)[0], dtype=float)
        diff = np.max(np.abs(elong - ref["elongation"])) / np.max(
            np.abs(ref["elongation"])
        )
        numpy_rows.append(
            dict(
                batch=batch,
                samples=protocol.num_samples,
                numpy_s=t_np,
                numpy_steps_per_s=batch * protocol.num_samples / t_np,
                kernel_s=kernel["time_s"],
                speedup=t_np / kernel["time_s"],
                max_diff_rel_to_peak=float(diff),
                numpy_converged=int(ref["converged"].sum()),
            )
        )
    print("[throughput] numpy baseline done", file=sys.stderr)

    out = dict(
        machine=_machine(dtype, load_at_start),
        model="IntegratedModel() defaults, rate-driven (Newton per sample)",
        by_batch=by_batch,
        by_length=by_length,
        skipped=skipped,
        grad=grad_row,
        numpy=numpy_rows,
    )
    print(json.dumps(out, indent=1))
    print()
    print(f"Kernel ({dtype}), forward, rate-driven")
    head = f"{'batch':>6} {'samples':>8} {'time [s]':>10} {'M steps/s':>10} {'compile [s]':>12} {'ok':>6}"
    print(head)
    for r in by_batch + by_length:
        print(
            f"{r['batch']:>6} {r['samples']:>8} {r['time_s']:>10.4f} "
            f"{r['steps_per_s'] / 1e6:>10.2f} {r['compile_s']:>12.2f} {r['successful']:>6}"
        )
    for s in skipped:
        print(
            f"{s['batch']:>6} {s['samples']:>8}   skipped: predicted {s['predicted_s']:.1f} s "
            f"> --max-seconds {args.max_seconds:g}"
        )
    g = grad_row
    print(
        f"\ngrad/forward at {g['batch']} x {g['samples']}: {g['grad_s']:.3f} s / "
        f"{g['forward_s']:.3f} s = {g['ratio']:.2f}  (compile {g['forward_compile_s']:.2f} s "
        f"forward, {g['grad_compile_s']:.2f} s grad)"
    )
    print(f"\nNumPy baseline (float64) vs kernel ({dtype})")
    print(
        f"{'batch':>6} {'samples':>8} {'numpy [s]':>10} {'kernel [s]':>11} {'speedup':>8} {'max diff':>9}"
    )
    for r in numpy_rows:
        print(
            f"{r['batch']:>6} {r['samples']:>8} {r['numpy_s']:>10.3f} {r['kernel_s']:>11.4f} "
            f"{r['speedup']:>8.1f} {r['max_diff_rel_to_peak']:>9.1e}"
        )
    if args.json_out:
        with open(args.json_out, "w") as f:
            json.dump(out, f, indent=1)


if __name__ == "__main__":
    main()
