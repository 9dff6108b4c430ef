"""A straightforward NumPy implementation of Park et al.'s integrated model and the
rate-driven test: the baseline a researcher would write, kept to measure jaxcable
against (benchmarks/throughput.py) and checked to give the same numbers as the kernel
(tests/test_numpy_baseline.py, float64, rtol 1e-8).

    python benchmarks/numpy_baseline.py [--batch 1,64] [--samples 2000] [--repeats 5]
        [--json-out F]

prints one JSON object and a table: NumPy time, the kernel's time on the same problem
(float64, jitted, median of `--repeats` calls after a warm-up call) and the largest
relative difference.

It is the same model as `jaxcable.IntegratedModel.advance` (Park Eq. 1-9 with the
readings of MODEL_NOTES) and the same time solve as `jaxcable.simulate_rate_test`
(Park Eq. 5 = Eq. 6 per force sample, relative strain residual, Newton with an
analytic derivative): a Python loop over the samples, vectorised over the batch of
cables, Newton iterations in NumPy until every cable of the batch has converged.
"""

import argparse
import json
import os
import platform
import time
from collections.abc import Mapping

import numpy as np


PARAMETERS = (
    "E1c",
    "beta",
    "gamma",
    "E1r",
    "E2c",
    "t_c",
    "eta0",
    "E2r",
    "t_r1",
    "E3r",
    "lambda1",
    "lambda2",
)
# As jaxcable._simulate: residual = strain error / (|strain at the start of the step|
# + |crosshead strain at the guessed end| + floor).
_STRAIN_FLOOR = 1e-4


def _static_loading(p, area, strain_prev, force):
    # Park Eq. 1-2: (F / (E1c A))**h, h = 1 + beta * eps_{i-1}**gamma.
    h = 1.0 + p["beta"] * np.maximum(strain_prev, 0.0) ** p["gamma"]
    return (force / (p["E1c"] * area)) ** h


def simulate_rate_test_numpy(
    params_dict: Mapping[str, float],
    lengths,
    speeds,
    protocol_arrays,
    *,
    diameter: float = 3e-3,
    tol: float = 1e-12,
    max_steps: int = 32,
):
    """Simulate a rate-driven test of a batch of cables with NumPy (float64).

    **Arguments:**

    - `params_dict`: the 12 parameters of `jaxcable.IntegratedModel` by name, SI
        (scalars, or arrays of shape (batch,)).
    - `lengths`: free lengths L0, m, shape (batch,).
    - `speeds`: crosshead speeds v, m/s, shape (batch,) or scalar.
    - `protocol_arrays`: a mapping with `force` (N), `direction` (+1, -1, 0), `duration`
        (s, holds) and optionally `mask`, each of shape (samples,) - the fields of a
        `jaxcable.Protocol` - or the tuple (force, direction, duration[, mask]).
    - `diameter`: cable diameter, m.
    - `tol`, `max_steps`: Newton tolerance on the relative strain residual, and the
        most Newton steps per sample.

    **Returns:**

    A dict of arrays of shape (batch, samples): `time` (solved sample times, s),
    `strain`, `elongation` (m); and `converged` (batch,): every sample's Newton solve
    converged to a non-negative finite time and the parameters are in their domain.
    """
    if isinstance(protocol_arrays, Mapping):
        force_seq = protocol_arrays["force"]
        direction_seq = protocol_arrays["direction"]
        duration_seq = protocol_arrays["duration"]
        mask_seq = protocol_arrays.get("mask")
    else:
        force_seq, direction_seq, duration_seq, *rest = protocol_arrays
        mask_seq = rest[0] if rest else None
    force_seq = np.asarray(force_seq, float)
    direction_seq = np.asarray(direction_seq, int)
    duration_seq = np.asarray(duration_seq, float)
    n = force_seq.shape[0]
    mask_seq = np.ones(n, bool) if mask_seq is None else np.asarray(mask_seq, bool)

    lengths = np.atleast_1d(np.asarray(lengths, float))
    batch = lengths.shape[0]
    speeds = np.broadcast_to(np.asarray(speeds, float), (batch,))
    p = {
        k: np.broadcast_to(np.asarray(params_dict[k], float), (batch,))
        for k in PARAMETERS
    }
    area = np.pi / 4 * diameter**2
    rate = speeds / lengths  # strain rate, 1/s
    t_r2 = p["lambda1"] / rate**2 - p["lambda2"]  # Park Eq. 8
    ok = (t_r2 > 0) & (p["E1c"] * area > 0)

    zeros = lambda: np.zeros(batch)
    # Model state (jaxcable.IntegratedState) and driver state (CableState).
    force_prev, strain_prev, impulse, t_total = zeros(), zeros(), zeros(), zeros()
    branch = np.ones(batch, int)
    force_rev, force_peak, inst_rev, tau = zeros(), zeros(), zeros(), zeros()
    short_rev, long_rev = zeros(), zeros()
    p_inst, p_short, p_long = zeros(), zeros(), zeros()  # last sample's own parts
    t_now, last_step = zeros(), zeros()

    out_time = np.empty((batch, n))
    out_strain = np.empty((batch, n))
    prev_direction = 0
    for i in range(n):
        F = force_seq[i]
        d = direction_seq[i]
        D = duration_seq[i]
        m = mask_seq[i]

        # Branch bookkeeping at the previous sample (independent of the step length).
        new_branch = branch if d == 0 else np.full(batch, d)
        rev = new_branch != branch
        loading = new_branch > 0
        f_rev = np.where(rev, force_prev, force_rev)
        f_peak = np.where(rev & ~loading, force_prev, force_peak)
        i_rev = np.where(rev, p_inst, inst_rev)
        s_rev = np.where(rev, p_short, short_rev)
        l_rev = np.where(rev, p_long, long_rev)
        tau0 = np.where(rev, 0.0, tau)
        # Reloading rejoins the loading curve at the last peak (Masing-like).
        span = f_peak - f_rev
        weight = np.where(
            span > 0, np.clip((f_peak - F) / np.where(span > 0, span, 1.0), 0, 1), 0.0
        )
        static_rev = _static_loading(p, area, strain_prev, f_rev)
        inst = np.where(
            loading,
            _static_loading(p, area, strain_prev, F) + (i_rev - static_rev) * weight,
            i_rev - (f_rev - F) / (p["E1r"] * area),
        )
        d_impulse = 0.5 * (force_prev + F)
        # Time under tension: above 1e-4 of the (default 2000 N) breaking load.
        d_ttotal = (np.maximum(force_prev, F) > 1e-4 * 2000.0).astype(float)

        def strain_and_slope(dt):
            """Total strain after a step dt and its derivative d strain / d dt."""
            imp = impulse + d_impulse * dt
            T = t_total + d_ttotal * dt
            tau_ = tau0 + dt
            pos = T > 0
            Ts = np.where(pos, T, 1.0)
            e_c = np.exp(-Ts / p["t_c"])
            ra = np.where(pos, -np.expm1(-Ts / p["t_c"]) / Ts, 1.0 / p["t_c"])
            dra = np.where(pos, (e_c / p["t_c"] - ra) / Ts, 0.0)
            creep = imp * ra / (p["E2c"] * area) + imp / (p["eta0"] * area)
            dcreep = (d_impulse * ra + imp * dra * d_ttotal) / (
                p["E2c"] * area
            ) + d_impulse / (p["eta0"] * area)
            feq = imp / Ts
            dfeq = np.where(pos, (d_impulse * Ts - imp * d_ttotal) / Ts**2, d_impulse)
            # Recoveries relax towards Park's amplitudes while unloading, back to
            # zero while loading, from their values at the reversal.
            x1 = np.exp(-tau_ / p["t_r1"])
            amp_s = np.where(loading, 0.0, feq / (p["E2r"] * area))
            damp_s = np.where(loading, 0.0, dfeq / (p["E2r"] * area))
            short = amp_s * (1 - x1) + s_rev * x1
            dshort = damp_s * (1 - x1) + (amp_s - s_rev) * x1 / p["t_r1"]
            x2 = np.exp(-tau_ / t_r2)
            amp_l = np.where(loading, 0.0, (f_rev - F) / (p["E3r"] * area))
            long = amp_l * (1 - x2) + l_rev * x2
            dlong = (amp_l - l_rev) * x2 / t_r2
            total = inst + creep - short - long
            return total, dcreep - dshort - dlong, (creep, short, long)

        # Initial guess as the kernel: the previous step inside a ramp, else the time
        # of the instantaneous strain step at speed v (a ramp's first sample) or the
        # hold's duration.
        if d != 0 and d == prev_direction:
            dt = last_step.copy()
        elif d != 0:
            dt = np.abs(strain_and_slope(np.zeros(batch))[0] - strain_prev) / rate
        else:
            dt = np.full(batch, D)
        # The residual's strain scale, fixed for the sample (as the kernel): the
        # strain at the start and the crosshead's strain at the guessed end.
        scale = (
            np.abs(strain_prev) + np.abs(strain_prev + d * rate * dt) + _STRAIN_FLOOR
        )

        def residual(dt):
            # Park Eq. 5 = Eq. 6: model strain minus crosshead strain, relative.
            if d == 0:
                return (dt - D) / (D + 1.0), np.full(batch, 1.0 / (D + 1.0))
            total, slope, _ = strain_and_slope(dt)
            kin = strain_prev + d * rate * dt
            return (total - kin) / scale, (slope - d * rate) / scale

        slope_sign = -d if d != 0 else 1
        growth = 1e-6 / rate
        converged = np.zeros(batch, bool)
        for _ in range(max_steps):
            r, dr = residual(dt)
            converged = np.abs(r) <= tol
            if converged.all():
                break
            good = (dr * slope_sign > 0) & np.isfinite(r / np.where(dr == 0, 1, dr))
            step = np.where(good, dt - r / np.where(dr == 0, 1.0, dr), 2 * dt + growth)
            dt = np.where(converged, dt, np.maximum(step, 0.0))
        ok &= converged & np.isfinite(dt) & (dt >= 0)

        total, _, (creep, short, long) = strain_and_slope(dt)
        if m:
            branch, force_rev, force_peak, inst_rev = new_branch, f_rev, f_peak, i_rev
            short_rev, long_rev = s_rev, l_rev
            impulse = impulse + d_impulse * dt
            t_total = t_total + d_ttotal * dt
            tau = tau0 + dt
            p_inst, p_short, p_long = inst, short, long
            force_prev = np.full(batch, F)
            strain_prev = total
            t_now = t_now + dt
            last_step = dt
            prev_direction = d
        ok &= np.isfinite(strain_prev)
        out_time[:, i] = t_now
        out_strain[:, i] = strain_prev
    return dict(
        time=out_time,
        strain=out_strain,
        elongation=out_strain * lengths[:, None],
        converged=ok,
    )


def default_parameters(model=None) -> dict[str, float]:
    """The parameters of a `jaxcable.IntegratedModel` (default: the library's) as a
    dict of floats."""
    if model is None:
        import jaxcable as jc

        model = jc.IntegratedModel()
    return {k: float(getattr(model, k)) for k in PARAMETERS}


def machine(dtype: str) -> dict:
    import jax

    return dict(
        platform=platform.platform(),
        processor=platform.processor() or platform.machine(),
        cpu_count=os.cpu_count(),
        load_average=list(os.getloadavg()) if hasattr(os, "getloadavg") else None,
        python=platform.python_version(),
        numpy=np.__version__,
        jax=jax.__version__,
        backend=jax.default_backend(),
        devices=[str(d) for d in jax.devices()],
        dtype=dtype,
    )


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--batch", default="1,64")
    ap.add_argument("--samples", type=int, default=2000)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--json-out", default=None)
    args = ap.parse_args()

    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp

    import jaxcable as jc

    model = jc.IntegratedModel()
    params = default_parameters(model)
    protocol = jc.Protocol.cycles(100.0, 1, samples_per_ramp=args.samples // 2)
    arrays = {
        k: np.asarray(getattr(protocol, k))
        for k in ("force", "direction", "duration", "mask")
    }
    rows = []
    for batch in [int(b) for b in args.batch.split(",")]:
        lengths = np.linspace(0.1, 0.5, batch)
        speeds = np.linspace(3e-3, 10e-3, batch) / 60
        t0 = time.perf_counter()
        ref = simulate_rate_test_numpy(params, lengths, speeds, arrays)
        t_np = time.perf_counter() - t0
        # The other Cable fields keep their defaults, broadcast to the batch.
        cable = jax.tree_util.tree_map(
            lambda x: jnp.broadcast_to(x, (batch,)),
            jc.Cable(length=jnp.asarray(lengths), speed=jnp.asarray(speeds)),
        )
        run = jax.jit(
            jax.vmap(lambda c: jc.simulate_rate_test(model, c, protocol, throw=False))
        )
        traj = jax.block_until_ready(run(cable))
        times = []
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            jax.block_until_ready(run(cable))
            times.append(time.perf_counter() - t0)
        t_jax = sorted(times)[len(times) // 2]
        diff = np.max(
            np.abs(np.asarray(traj.elongation) - ref["elongation"])
            / np.maximum(np.abs(ref["elongation"]), 1e-12)
        )
        rows.append(
            dict(
                batch=batch,
                samples=protocol.num_samples,
                numpy_s=t_np,
                kernel_s=t_jax,
                speedup=t_np / t_jax,
                max_rel_diff=float(diff),
                numpy_converged=int(ref["converged"].sum()),
            )
        )
    print(json.dumps(dict(machine=machine("float64"), rows=rows), indent=1))
    print()
    print(
        f"{'batch':>6} {'samples':>8} {'numpy [s]':>10} {'kernel [s]':>11} {'speedup':>8} {'max rel diff':>13}"
    )
    for r in rows:
        print(
            f"{r['batch']:>6} {r['samples']:>8} {r['numpy_s']:>10.3f} {r['kernel_s']:>11.4f} "
            f"{r['speedup']:>8.1f} {r['max_rel_diff']:>13.2e}"
        )
    if args.json_out:
        with open(args.json_out, "w") as f:
            json.dump(dict(machine=machine("float64"), rows=rows), f, indent=1)


if __name__ == "__main__":
    main()
