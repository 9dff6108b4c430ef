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
readings of docs/model_notes.md) and the same time solve as `jaxcable.simulate_rate_test`
(Park Eq. 5 = Eq. 6 per force sample, relative strain residual, Newton with an
analytic derivative): a Python loop over the samples, vectorised over the batch of
cables, Newton iterations in NumPy until every cable of the batch has converged.
"""

import argparse
import json
import math
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
# As jaxcable._drive.simulate: residual = strain error / (|strain at the start of the step|
# + |crosshead strain at the guessed end| + floor).
_STRAIN_FLOOR = 1e-4


# As jaxcable._models.kernels: time counts as under tension in proportion to the force below
# F_on = max(this share of the breaking load, this fraction of the largest force).
_TENSION_SHARE = 1e-4
_TENSION_FRACTION = 0.1
# As jaxcable._models.kernels.relaxation_terms in float64: its Taylor series below this x.
_SERIES_BELOW = 0.1


def _tension_share(f0, f1, f_on):
    """Mean of min(F / F_on, 1) (0 below 0 N) over a step with the force linear from
    f0 to f1 (as jaxcable._models.kernels.tension_time_step: the chord of its primitive,
    the value at the mean force below a change of 1e-6 F_on)."""

    def primitive(f):
        f = np.maximum(f, 0.0)
        return np.where(f < f_on, 0.5 * f * f / f_on, f - 0.5 * f_on)

    change = f1 - f0
    small = np.abs(change) < 1e-6 * f_on
    chord = (primitive(f1) - primitive(f0)) / np.where(small, 1.0, change)
    mid = np.clip(0.5 * (f0 + f1) / f_on, 0.0, 1.0)
    return np.where(small, mid, chord)


def _ramp_factor(x):
    """(1 - (1 - e^-x) / x, its x-derivative): the share of a linear ramp that a
    Kelvin-Voigt element has not yet followed after x = dt / tau (Taylor series near
    x = 0, as the kernel)."""
    small = np.abs(x) < _SERIES_BELOW
    xs = np.where(small, 1.0, x)
    direct = (xs + np.expm1(-xs)) / xs
    d_direct = (-np.expm1(-xs) - xs * np.exp(-xs)) / xs**2
    # sum_{k>=1} (-1)^(k+1) x^k / (k+1)!, and its derivative.
    series = sum((-1.0) ** (k + 1) * x**k / math.factorial(k + 1) for k in range(1, 10))
    d_series = sum(
        (-1.0) ** (k + 1) * k * x ** (k - 1) / math.factorial(k + 1)
        for k in range(1, 10)
    )
    return np.where(small, series, direct), np.where(small, d_series, d_direct)


def _retarded(q0, target0, target1, dt, tau):
    """As jaxcable._models.kernels.retarded: q' = (target - q) / tau over dt with the
    target linear from target0 to target1, exactly; and its dt-derivative for a
    fixed target1 (the caller adds d target1 / d dt times the ramp factor)."""
    x = dt / tau
    decay = np.exp(-x)
    ramp, d_ramp = _ramp_factor(x)
    q1 = decay * q0 - np.expm1(-x) * target0 + (target1 - target0) * ramp
    dq1 = (-decay * q0 + decay * target0 + (target1 - target0) * d_ramp) / tau
    return q1, dq1


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
    breaking_load: float = 2000.0,
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
    - `breaking_load`: the cable's breaking load, N (sets the force below which a
        step counts only in part as time under tension, as `jaxcable.Cable`).
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
    force_max = zeros()
    short, long, short_target, long_target = zeros(), zeros(), zeros(), zeros()
    t_now, last_step = zeros(), zeros()
    f_on = _TENSION_SHARE * breaking_load

    out_time = np.empty((batch, n))
    out_strain = np.empty((batch, n))
    prev_direction = 0
    for i in range(n):
        F = force_seq[i]
        d = direction_seq[i]
        D = duration_seq[i]
        m = mask_seq[i]

        # The parts that do not depend on the step length: the running maximum, the
        # instantaneous strain (Park Eq. 1-2 and Eq. 9's unloading line from the
        # largest force, never below the loading curve), the recovery depth.
        f_max = np.maximum(force_max, F)
        drop = f_max - F
        inst = np.maximum(
            _static_loading(p, area, strain_prev, f_max) - drop / (p["E1r"] * area),
            _static_loading(p, area, strain_prev, F),
        )
        depth = drop / np.maximum(f_max, f_on)
        long_tgt = drop / (p["E3r"] * area)
        d_impulse = 0.5 * (force_prev + F)
        # Time under tension per second of the step: the mean over the step of
        # min(F / F_on, 1) for the force linear over the step, F_on at the step's
        # largest force so far (as jaxcable._models.kernels).
        d_ttotal = _tension_share(
            force_prev, F, np.maximum(f_on, _TENSION_FRACTION * f_max)
        )

        def strain_and_slope(dt):
            """Total strain after a step dt and its derivative d strain / d dt."""
            imp = impulse + d_impulse * dt
            T = t_total + d_ttotal * dt
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
            # Each recovery relaxes towards its amplitude, linear over the step.
            short_tgt = feq * depth / (p["E2r"] * area)
            dshort_tgt = dfeq * depth / (p["E2r"] * area)
            s, ds = _retarded(short, short_target, short_tgt, dt, p["t_r1"])
            s_slope = ds + dshort_tgt * _ramp_factor(dt / p["t_r1"])[0]
            lg, dlg = _retarded(long, long_target, long_tgt, dt, t_r2)
            # The recoveries remove at most the creep that produced them.
            recovery = s + lg
            excess = recovery > creep
            total = inst + creep - np.where(excess, creep, recovery)
            slope = np.where(excess, 0.0, dcreep - s_slope - dlg)
            return total, slope, (s, lg, short_tgt)

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

        total, _, (s_new, l_new, s_tgt) = strain_and_slope(dt)
        if m:
            impulse = impulse + d_impulse * dt
            t_total = t_total + d_ttotal * dt
            force_max = f_max
            short, long, short_target, long_target = s_new, l_new, s_tgt, long_tgt
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
