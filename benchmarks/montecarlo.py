"""Monte-Carlo of a CDPR's cable set: `jaxcable.monte_carlo` over parameter draws x 8
cables x 2000-sample force histories (a 2 h job), percentiles of elongation over
time, with its baselines measured in the same run.

    python benchmarks/montecarlo.py [--draws 100000] [--cables 8] [--samples 2000]
        [--driver force|rate] [--cpu-devices N] [--chunk-size C] [--bins 1024]
        [--method histogram|exact|auto]
        [--baseline-draws 2048] [--x64] [--xla-default] [--no-progress]
        [--json-out FILE]

Measured, each after its compilation (reported separately):

- `monte_carlo`: `--draws` draws, the draw batch sharded over `--cpu-devices` CPU
  devices (default: one per core; `XLA_FLAGS=--xla_force_host_platform_device_count`
  is set before jax is imported, so each core runs its share of the draws);
  histogram percentiles (bounded memory; `--method`).
- baseline "one device": the same call on one device, `--baseline-draws` draws.
- baseline "hand-written": what a user writes with the public single-cable API: one
  `jax.jit(vmap(vmap(simulate_force_history)))` over all `--baseline-draws` draws at
  once (memory grows with the draws), then `numpy.percentile`.

The scans run with the CPU loop kernels that `import jaxcable` turns on;
`--xla-default` keeps XLA's own CPU loops (`JAXCABLE_NO_LOOP_KERNELS=1`), and the
JSON's `machine.loop_kernels` says which ran. Rates are compared per draw (draws/s,
and sample-steps/s = draws x cables x samples / time). Prints one JSON object, then a
table; `ru_maxrss` is the process's peak resident memory. Results with machine
details: benchmarks/README.md.
"""

import argparse
import json
import os
import platform
import resource
import sys
import time


def _parse():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--draws", type=int, default=100_000)
    p.add_argument("--cables", type=int, default=8)
    p.add_argument("--samples", type=int, default=2000)
    p.add_argument("--driver", choices=("force", "rate"), default="force")
    p.add_argument("--cpu-devices", type=int, default=os.cpu_count() or 1)
    p.add_argument("--chunk-size", type=int, default=None)
    p.add_argument("--bins", type=int, default=1024)
    p.add_argument(
        "--method", choices=("auto", "exact", "histogram"), default="histogram"
    )
    p.add_argument("--baseline-draws", type=int, default=2048)
    p.add_argument("--x64", action="store_true")
    p.add_argument(
        "--xla-default",
        action="store_true",
        help="XLA's default CPU loops instead of the loop kernels that "
        "`import jaxcable` turns on (JAXCABLE_NO_LOOP_KERNELS=1)",
    )
    p.add_argument("--no-progress", action="store_true")
    p.add_argument("--json-out", default=None)
    return p.parse_args()


def main():
    args = _parse()
    if args.xla_default:
        # Read by `import jaxcable` (below), which otherwise sets the loop-kernel flag.
        os.environ["JAXCABLE_NO_LOOP_KERNELS"] = "1"
    load_at_start = list(os.getloadavg())
    # Must precede the first import of jax.
    flags = os.environ.get("XLA_FLAGS", "")
    os.environ["XLA_FLAGS"] = (
        f"{flags} --xla_force_host_platform_device_count={args.cpu_devices}".strip()
    )
    import jax

    if args.x64:
        jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    import numpy as np

    import jaxcable as jc

    n_c, n_s = args.cables, args.samples
    model = jc.IntegratedModel()
    # 10 % log-normal uncertainty on the creep and stiffness parameters (a fit's
    # typical relative standard errors).
    sampler = jc.IndependentParameters(
        model,
        {
            name: jc.LogNormal(float(getattr(model, name)), 0.1)
            for name in ("E1c", "E2c", "t_c", "eta0", "E2r", "E3r")
        },
    )
    if args.driver == "force":
        # A 2 h job logged every 3.6 s: each cable carries a share of a payload that
        # is picked, moved and placed every 30 min (30-120 N), phase-shifted between
        # cables.
        t = np.linspace(0.0, 2 * 3600.0, n_s)
        phase = np.linspace(0, 2 * np.pi, n_c, endpoint=False)[:, None]
        force = 75 + 45 * np.sin(2 * np.pi * t / 1800 + phase)
        loads = jc.ForceHistory(t, force)
        cables = jc.Cable(length=jnp.linspace(2.0, 8.0, n_c), speed=0.05)
    else:
        loads = jc.Protocol.cycles(100.0, 1, samples_per_ramp=n_s // 2, start=False)
        cables = jc.Cable(
            length=jnp.linspace(0.1, 0.5, n_c),
            speed=jnp.linspace(3e-3, 10e-3, n_c) / 60,
        )
    key = jax.random.key(0)
    steps_per_draw = n_c * n_s

    devices = jax.devices()
    # The library's default chunk: about 2**23 values per device.
    chunk = args.chunk_size or max(1, 2**23 // steps_per_draw) * len(devices)
    chunk = -(-chunk // len(devices)) * len(devices)

    def timed_mc(draws, devices, progress):
        # The first call (one chunk, same shapes) compiles; the second is timed.
        kw = dict(
            key=key,
            chunk_size=min(chunk, draws),
            bins=args.bins,
            method=args.method,
            devices=devices,
        )
        meter = jc.TextProgressMeter() if progress else jc.NoProgressMeter()
        warm = jc.MonteCarlo(num_draws=min(chunk, draws), **kw)
        t0 = time.perf_counter()
        jc.monte_carlo(sampler, cables, loads, warm, progress_meter=meter)
        first = time.perf_counter() - t0
        method = jc.MonteCarlo(num_draws=draws, **kw)
        t0 = time.perf_counter()
        res = jc.monte_carlo(sampler, cables, loads, method, progress_meter=meter)
        elapsed = time.perf_counter() - t0
        return res, elapsed, first

    res, elapsed, first = timed_mc(args.draws, devices, not args.no_progress)
    main_row = dict(
        name=f"monte_carlo, {len(devices)} devices",
        draws=args.draws,
        time_s=elapsed,
        first_call_s=first,
        draws_per_s=args.draws / elapsed,
        steps_per_s=args.draws * steps_per_draw / elapsed,
        method=res.method,
        successful=np.asarray(res.num_successful).tolist(),
        max_resolution_over_spread=float(
            np.nanmax(
                np.asarray(res.resolution) / np.asarray(res.max - res.min + 1e-30)
            )
        ),
    )
    print(f"[montecarlo] main run done in {elapsed:.1f} s", file=sys.stderr)

    rows = [main_row]
    nb = min(args.baseline_draws, args.draws)
    one, elapsed1, first1 = timed_mc(nb, devices[:1], False)
    rows.append(
        dict(
            name="baseline: monte_carlo, 1 device",
            draws=nb,
            time_s=elapsed1,
            first_call_s=first1,
            draws_per_s=nb / elapsed1,
            steps_per_s=nb * steps_per_draw / elapsed1,
            method=one.method,
        )
    )

    # Hand-written: all baseline draws in one vmap, then numpy.percentile.
    keys = jax.vmap(lambda i: jax.random.fold_in(key, i))(jnp.arange(nb))

    @jax.jit
    def hand(keys):
        models = jax.vmap(sampler.draw)(keys)

        def per_draw(m):
            if args.driver == "force":
                sim = lambda c, tt, ff: jc.simulate_force_history(
                    m, c, tt, ff, method=jc.Simulation(throw=False)
                )
                traj = jax.vmap(sim)(cables_b, loads.time, loads.force)
            else:
                traj = jax.vmap(
                    lambda c: jc.simulate_rate_test(
                        m, c, loads, method=jc.Simulation(throw=False)
                    )
                )(cables_b)
            return traj.elongation, traj.result == jc.RESULTS.successful

        return jax.vmap(per_draw)(models)

    cables_b = jax.tree_util.tree_map(lambda x: jnp.broadcast_to(x, (n_c,)), cables)
    t0 = time.perf_counter()
    compiled = hand.lower(keys).compile()
    compile_hand = time.perf_counter() - t0
    t0 = time.perf_counter()
    elong, ok = jax.block_until_ready(compiled(keys))
    elong, ok = np.asarray(elong), np.asarray(ok)
    pct = [np.percentile(elong[ok[:, j], j], res.q, axis=0) for j in range(n_c)]
    elapsed_h = time.perf_counter() - t0
    del pct
    rows.append(
        dict(
            name="baseline: hand-written vmap + numpy.percentile, 1 device",
            draws=nb,
            time_s=elapsed_h,
            first_call_s=compile_hand,
            draws_per_s=nb / elapsed_h,
            steps_per_s=nb * steps_per_draw / elapsed_h,
            method="exact",
        )
    )

    q99 = np.asarray(res.percentile(99.0))[:, -1]
    q50 = np.asarray(res.percentile(50.0))[:, -1]
    out = dict(
        machine=dict(
            platform=platform.platform(),
            processor=platform.processor() or platform.machine(),
            cpu_count=os.cpu_count(),
            load_average_at_start=load_at_start,
            load_average_at_end=list(os.getloadavg()),
            python=platform.python_version(),
            jax=jax.__version__,
            backend=jax.default_backend(),
            devices=[str(d) for d in jax.devices()],
            dtype="float64" if args.x64 else "float32",
            # Whether XLA's CPU loop-kernel option is set (by `import jaxcable` or
            # by hand).
            loop_kernels="xla_cpu_small_while_loop_byte_threshold"
            in os.environ.get("XLA_FLAGS", ""),
        ),
        problem=dict(
            driver=args.driver,
            cables=n_c,
            samples=n_s,
            draws=args.draws,
            bins=args.bins,
            chunk_size=chunk,
        ),
        runs=rows,
        end_of_history_elongation_mm=dict(
            p50=(1e3 * q50).tolist(), p99=(1e3 * q99).tolist()
        ),
        peak_rss_MiB=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
    )
    print(json.dumps(out, indent=1))
    print()
    print(
        f"Monte-Carlo: {args.draws} draws x {n_c} cables x {n_s} samples ({args.driver} "
        f"driver, {out['machine']['dtype']}, {len(devices)} devices)"
    )
    print(
        f"{'run':<58} {'draws':>7} {'time [s]':>9} {'draws/s':>9} {'M steps/s':>10} {'first call [s]':>15}"
    )
    for r in rows:
        print(
            f"{r['name']:<58} {r['draws']:>7} {r['time_s']:>9.2f} {r['draws_per_s']:>9.0f} "
            f"{r['steps_per_s'] / 1e6:>10.1f} {r['first_call_s']:>15.2f}"
        )
    print(
        f"percentile method: {main_row['method']}; largest resolution / (max - min): "
        f"{main_row['max_resolution_over_spread']:.1e}; peak RSS {out['peak_rss_MiB']:.0f} MiB"
    )
    if args.json_out:
        with open(args.json_out, "w") as f:
            json.dump(out, f, indent=1)


if __name__ == "__main__":
    main()
