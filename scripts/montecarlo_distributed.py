"""Launch one `jaxcable.monte_carlo` over P processes with JAX's multi-process runtime
(`jax.distributed`, gloo collectives on CPUs): every process simulates the draws of its
own devices, process 0 writes the result as JSON.

    # P processes (one per host, or several on one host), same arguments but the id:
    python scripts/montecarlo_distributed.py --coordinator HOST0:PORT \\
        --num-processes P --process-id I [--seed 0] [--draws 2000] [--cables 8] \\
        [--samples 200] [--chunk-size C] [--method exact|histogram|auto] \\
        [--cpu-devices 1] [--timeout-s 120] [--heartbeat-s 30] [--deadline-s 0] \\
        [--warmup] [--spec spec.json] [--out result.json]

    # the same from the environment: JAX_COORDINATOR_ADDRESS, JAX_NUM_PROCESSES,
    # JAX_PROCESS_ID; or under Slurm / Open MPI / Kubernetes (jax detects them):
    python scripts/montecarlo_distributed.py --auto ...

Without a coordinator (nor `--auto`) it runs in this process alone, without the
runtime: the single-process reference of the same seed.

The Monte-Carlo: `--cables` cables (0.1-0.5 m, 3-10 mm/min) of the default
`IntegratedModel`, 10 % log-normal uncertainty on E1c, E2c, t_c, eta0, E2r, E3r, one
load-unload cycle to 100 N of `--samples` samples (`Protocol.cycles`); draw i uses
`fold_in(key(seed), i)`, so the result does not depend on P. `--spec FILE` reads these
options from a JSON object (keys as the long options, `-` as `_`). The JSON: the
percentile levels `q`, `percentiles` (q x cables x samples, m), `status_counts` (per
`RESULTS` member, per cable), timings (`time_s`; `first_call_s` with `--warmup`, which
first runs one chunk to compile) and `draws_per_s`.

Failures stop the processes instead of hanging: a process that has not joined within
`--timeout-s` makes the others abort (jax: "Terminating process because the JAX
distributed service detected fatal errors"); a process that dies later is declared
dead after `--heartbeat-s` without a heartbeat and the others abort the same way;
`--deadline-s` (0: none) is a last guard that ends this process with exit status 3
if it has no result by then.

`jax.distributed.initialize` must run before jax creates its backend, and importing
jaxcable creates arrays (module constants): so this script initializes the runtime
first and imports jaxcable afterwards.
"""

import argparse
import json
import os
import sys
import threading
import time


ENV = ("JAX_COORDINATOR_ADDRESS", "JAX_NUM_PROCESSES", "JAX_PROCESS_ID")
SPEC_KEYS = ("seed", "draws", "cables", "samples", "chunk_size", "method", "bins")


def _say(text):
    print(f"[montecarlo_distributed] {text}", file=sys.stderr, flush=True)


def _parse(argv):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--coordinator", default=os.environ.get(ENV[0]))
    p.add_argument("--num-processes", type=int, default=os.environ.get(ENV[1]))
    p.add_argument("--process-id", type=int, default=os.environ.get(ENV[2]))
    p.add_argument("--auto", action="store_true", help="cluster manager detection")
    p.add_argument("--cpu-devices", type=int, default=1)
    p.add_argument("--timeout-s", type=int, default=120)
    p.add_argument("--heartbeat-s", type=int, default=30)
    p.add_argument("--deadline-s", type=float, default=0.0)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--draws", type=int, default=2000)
    p.add_argument("--cables", type=int, default=8)
    p.add_argument("--samples", type=int, default=200)
    p.add_argument("--chunk-size", type=int, default=None)
    p.add_argument("--method", default="auto")
    p.add_argument("--bins", type=int, default=1024)
    p.add_argument("--warmup", action="store_true")
    p.add_argument("--progress", action="store_true")
    p.add_argument("--spec", default=None)
    p.add_argument("--out", default=None)
    args = p.parse_args(argv)
    if args.spec:
        with open(args.spec, encoding="utf-8") as f:
            spec = json.load(f)
        unknown = set(spec) - set(SPEC_KEYS)
        if unknown:
            p.error(f"--spec: unknown keys {sorted(unknown)} (known: {SPEC_KEYS})")
        for k, v in spec.items():
            setattr(args, k, v)
    for name in ("num_processes", "process_id"):
        value = getattr(args, name)
        setattr(args, name, None if value is None else int(value))
    return args


def initialize(
    coordinator_address, num_processes, process_id, *, timeout_s, heartbeat_s
):
    """Join the P processes (`jax.distributed.initialize`) before jax's backend exists.

    **Arguments:**

    - `coordinator_address`: `"host:port"` of process 0 (None with the two others None:
        jax detects the cluster manager).
    - `num_processes`, `process_id`: P and this process's index (0 runs the
        coordinator service).
    - `timeout_s`: seconds to wait for every process to join; past them jax aborts
        the waiting processes.
    - `heartbeat_s`: seconds without a heartbeat after which a process is dead.

    **Returns:**

    `(process_index, process_count)` as jax sees them after joining.
    """
    import jax

    # gloo is jax 0.10's default for CPU collectives; set here (a launcher, not the
    # library) so that an older default (none) cannot leave the processes unable to
    # exchange data.
    jax.config.update("jax_cpu_collectives_implementation", "gloo")
    given = (coordinator_address, num_processes, process_id)
    if any(v is not None for v in given) and any(v is None for v in given):
        raise SystemExit(
            "montecarlo_distributed: give --coordinator, --num-processes and "
            f"--process-id together (or {', '.join(ENV)}), or --auto; got {given}."
        )
    where = coordinator_address or "the address of the detected cluster"
    _say(
        f"process {process_id}/{num_processes}: joining at {where}, waiting up to "
        f"{timeout_s} s for every process (heartbeat timeout {heartbeat_s} s)"
    )
    jax.distributed.initialize(
        coordinator_address,
        num_processes,
        process_id,
        initialization_timeout=timeout_s,
        heartbeat_timeout_seconds=heartbeat_s,
    )
    return jax.process_index(), jax.process_count()


def _watchdog(deadline_s):
    def fire():
        _say(f"no result after --deadline-s={deadline_s} s; stopping (exit 3)")
        os._exit(3)

    timer = threading.Timer(deadline_s, fire)
    timer.daemon = True
    timer.start()


def _problem(jc, jnp, n_cables, n_samples):
    model = jc.IntegratedModel()
    sampler = jc.IndependentParameters(
        model,
        {
            name: jc.LogNormal(float(getattr(model, name)), 0.1)
            for name in ("E1c", "E2c", "t_c", "eta0", "E2r", "E3r")
        },
    )
    loads = jc.Protocol.cycles(
        100.0, 1, samples_per_ramp=max(1, n_samples // 2), start=False
    )
    cables = jc.Cable(
        length=jnp.linspace(0.1, 0.5, n_cables),
        speed=jnp.linspace(3e-3, 10e-3, n_cables) / 60,
    )
    return sampler, cables, loads


def main(argv=None):
    args = _parse(argv)
    if args.deadline_s > 0:
        _watchdog(args.deadline_s)
    if args.cpu_devices < 1:
        raise SystemExit(f"--cpu-devices must be >= 1, got {args.cpu_devices}")
    import jax

    # Local CPU devices of this process; must precede the backend (a launcher option).
    jax.config.update("jax_num_cpu_devices", args.cpu_devices)
    distributed = args.auto or args.coordinator is not None
    if distributed:
        index, count = initialize(
            args.coordinator,
            args.num_processes,
            args.process_id,
            timeout_s=args.timeout_s,
            heartbeat_s=args.heartbeat_s,
        )
        _say(f"process {index}/{count}: joined, {len(jax.devices())} devices in all")
    else:
        index, count = 0, 1
    import jax.numpy as jnp
    import numpy as np

    import jaxcable as jc

    sampler, cables, loads = _problem(jc, jnp, args.cables, args.samples)
    kw = dict(
        key=jax.random.key(args.seed),
        chunk_size=args.chunk_size,
        method=args.method,
        bins=args.bins,
    )
    meter = (
        jc.TextProgressMeter() if args.progress and index == 0 else jc.NoProgressMeter()
    )
    first = None
    if args.warmup:
        # One chunk, the same shapes: compiles the chunk function outside the timing.
        t0 = time.perf_counter()
        warm = args.chunk_size or args.draws
        method = jc.MonteCarlo(num_draws=min(warm, args.draws), **kw)
        jc.monte_carlo(sampler, cables, loads, method, progress_meter=meter)
        first = time.perf_counter() - t0
    t0 = time.perf_counter()
    method = jc.MonteCarlo(num_draws=args.draws, **kw)
    res = jc.monte_carlo(sampler, cables, loads, method, progress_meter=meter)
    elapsed = time.perf_counter() - t0
    out = dict(
        process_count=count,
        devices=len(jax.devices()),
        local_devices=len(jax.local_devices()),
        spec={k: getattr(args, k) for k in SPEC_KEYS},
        method=res.method,
        q=np.asarray(res.q).tolist(),
        percentiles=np.asarray(res.percentiles, float).tolist(),
        max_resolution=float(np.nanmax(np.asarray(res.resolution))),
        num_successful=np.asarray(res.num_successful).tolist(),
        status_counts={k: np.asarray(v).tolist() for k, v in res.status_counts.items()},
        time_s=elapsed,
        first_call_s=first,
        draws_per_s=args.draws / elapsed,
        loadavg=list(os.getloadavg()),
    )
    if index == 0:
        text = json.dumps(out)
        if args.out:
            with open(args.out, "w", encoding="utf-8") as f:
                f.write(text + "\n")
        else:
            print(text)
    _say(f"process {index}/{count}: done in {elapsed:.2f} s")
    if distributed:
        # Every process waits here for the others (a barrier), then leaves.
        jax.distributed.shutdown()


if __name__ == "__main__":
    main()
