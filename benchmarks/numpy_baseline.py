"""A straightforward NumPy implementation of Park et al.'s integrated model and the
rate-driven test: the baseline a researcher would write, kept to measure jaxcable
against (benchmarks/throughput.py) and checked to give the same numbers as the kernel
(tests/test_numpy_baseline.py, float64, rtol 1e-8).

    python benchmarks/numpy_baseline.py [--batch 1,64] [--samples 2000] [--repeats 5]
        [--json-out F]

prints one JSON object and a table: NumPy time, the kernel's time on the same problem
(float64, jitted, median of `--repeats` calls after a warm-up call) and the largest
difference of elongation over a cable's samples relative to its peak (largest over
the cables).

It is the same model as `jaxcable.IntegratedModel.advance` (Park Eq. 1-9 with the
readings of docs/model_notes.md: the instantaneous strain with hardening and the
unloading line from the largest force, three delayed-elastic elements - permanent,
short- and long-term recoverable - and an Eyring flow) and the same time solve as
`jaxcable.simulate_rate_test` (Park Eq. 5 = Eq. 6 per force sample, relative strain
residual, Newton with an analytic derivative and the kernel's final refinement step):
a Python loop over the samples, vectorised over the batch of cables, Newton iterations
in NumPy until every cable of the batch has converged.
"""

import argparse
import json
import math
import os
import platform
import time
from collections.abc import Mapping

import numpy as np

import jaxcable as jc
from jaxcable._models.fields import field_facts


# The model's declared parameters, in their order.
PARAMETERS = tuple(field_facts(jc.IntegratedModel))
# As jaxcable._models.park: the parameters that must be finite and > 0.
_POSITIVE = (
    "E1c",
    "E1r",
    "E2c",
    "t_c",
    "eta0",
    "E2r",
    "t_r1",
    "E3r",
    "lambda1",
    "t_e",
    "strain_a",
)
# As jaxcable._drive.drives: residual = strain error / (|strain at the start of the
# step| + |crosshead strain at the guessed end| + floor).
_STRAIN_FLOOR = 1e-4


# As jaxcable._models.kernels.relaxation_terms in float64: its Taylor series below this
# x, sum_{k=1}^{9} (-1)^(k+1) x^k / (k+1)!.
_SERIES_BELOW = 0.1
_RAMP_SERIES = tuple((-1.0) ** (k + 1) / math.factorial(k + 1) for k in range(1, 10))
# As jaxcable._models.park: the Eyring flow's sinh argument is capped here.
_EYRING_CAP = 60.0


def _relaxation_terms(x):
    """As jaxcable._models.kernels.relaxation_terms: (expm1(-x), R(x)) for
    x = dt / tau, R(x) = 1 - (1 - e^-x) / x the share of a linear ramp that a
    Kelvin-Voigt element has not yet followed (Taylor series near x = 0); and
    their x-derivatives."""
    small = np.abs(x) < _SERIES_BELOW
    xs = np.where(small, 1.0, x)
    decay_m1 = np.exp(-xs) - 1.0
    series = np.zeros_like(x)
    d_series = np.zeros_like(x)
    for k in range(len(_RAMP_SERIES), 0, -1):  # Horner, highest power first
        series = (series + _RAMP_SERIES[k - 1]) * x
        d_series = d_series * x + k * _RAMP_SERIES[k - 1]
    decay_m1 = np.where(small, x * (series - 1.0), decay_m1)
    ramp = np.where(small, series, (xs + decay_m1) / xs)
    d_decay = -(1.0 + decay_m1)  # d/dx expm1(-x) = -e^-x
    d_ramp = np.where(small, d_series, (-decay_m1 + xs * d_decay) / xs**2)
    return decay_m1, ramp, d_decay, d_ramp


def _retarded(q0, target0, target1, dt, tau):
    """As jaxcable._models.kernels.retarded: q' = (target - q) / tau over dt with the
    target linear from target0 to target1, exactly; and its dt-derivative."""
    decay_m1, ramp, d_decay, d_ramp = _relaxation_terms(dt / tau)
    q1 = q0 + decay_m1 * (q0 - target0) + (target1 - target0) * ramp
    dq1 = (d_decay * (q0 - target0) + (target1 - target0) * d_ramp) / tau
    return q1, dq1


def _delayed_elastic(previous, target0, target1, dt, creep_time, recovery_time):
    """As jaxcable._models.park.delayed_elastic: an element that creeps towards its
    target with `creep_time` and recovers from above it with `recovery_time` (None:
    never recovers); and its dt-derivative."""
    creep, d_creep = _retarded(previous, target0, target1, dt, creep_time)
    if recovery_time is None:
        return np.maximum(creep, previous), np.where(creep > previous, d_creep, 0.0)
    recover, d_recover = _retarded(previous, target0, target1, dt, recovery_time)
    # Creep faster than recovery: the larger of the two updates, else the smaller.
    faster_creep = creep_time <= recovery_time
    q = np.where(faster_creep, np.maximum(creep, recover), np.minimum(creep, recover))
    takes_creep = np.where(faster_creep, creep >= recover, creep <= recover)
    return q, np.where(takes_creep, d_creep, d_recover)


def _safe_pow(base, exponent):
    """As jaxcable._models.kernels.safe_pow: base**exponent for base >= 0."""
    positive = base > 0
    safe = np.where(positive, base, 1.0)
    return np.where(positive, np.exp(exponent * np.log(safe)), 0.0)


def _eyring_rate(stress, viscosity, activation_stress):
    """As jaxcable._models.park.eyring_rate: (sigma_a / eta0) sinh(sigma / sigma_a),
    1/s."""
    x = np.minimum(stress / activation_stress, _EYRING_CAP)
    return activation_stress / viscosity * np.sinh(x)


def simulate_rate_test_numpy(
    params_dict: Mapping[str, float],
    lengths,
    speeds,
    protocol_arrays,
    *,
    diameter: float = 3e-3,
    breaking_load: float = 2000.0,
    breaking_strain: float = 0.07,
    tol: float = 1e-12,
    max_steps: int = 32,
):
    """Simulate a rate-driven test of a batch of cables with NumPy (float64).

    **Arguments:**

    - `params_dict`: the 14 parameters of `jaxcable.IntegratedModel` by name, SI
        (scalars, or arrays of shape (batch,)).
    - `lengths`: free lengths L0, m, shape (batch,).
    - `speeds`: crosshead speeds v, m/s, shape (batch,) or scalar.
    - `protocol_arrays`: a mapping with `force` (N), `direction` (+1, -1, 0), `duration`
        (s, holds) and optionally `mask`, each of shape (samples,) - the fields of a
        `jaxcable.Protocol` - or the tuple (force, direction, duration[, mask]).
    - `diameter`: cable diameter, m.
    - `breaking_load`, `breaking_strain`: the cable's breaking load, N, and
        strain: with hardening (beta > 0) the parameters are in their domain only
        where E1c A exceeds the load or the strain is at most 1, as
        `jaxcable.IntegratedModel.check`.
    - `tol`, `max_steps`: Newton tolerance on the relative strain residual, and the
        most Newton steps per sample.

    **Returns:**

    A dict of arrays of shape (batch, samples): `time` (solved sample times, s),
    `strain`, `elongation` (m); and `converged` (batch,): every sample's Newton solve
    converged to a non-negative finite time and the parameters are in their domain.
    """
    if max_steps < 1:
        raise ValueError(f"`max_steps` must be >= 1, got {max_steps}.")
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
    # The parameters' domain (as jaxcable.IntegratedModel.check).
    ok = np.isfinite(t_r2) & (t_r2 > 0)
    for k in _POSITIVE:
        ok &= np.isfinite(p[k]) & (p[k] > 0)
    ok &= (p["beta"] >= 0) & (p["gamma"] >= 0)
    ok &= (
        (p["beta"] == 0) | (breaking_strain <= 1.0) | (p["E1c"] * area > breaking_load)
    )

    # Compliances 1 / (E A) of the instantaneous strain and of the three elements.
    compliance_c = 1.0 / (p["E1c"] * area)
    compliance_r = 1.0 / (p["E1r"] * area)
    ca_permanent = 1.0 / (p["E2c"] * area)
    ca_short = 1.0 / (p["E2r"] * area)
    ca_long = 1.0 / (p["E3r"] * area)

    zeros = lambda: np.zeros(batch)
    # Model state (jaxcable.states.IntegratedState) and driver state (CableState).
    force_prev, strain_prev, force_max = zeros(), zeros(), zeros()
    permanent, short, long, flow = zeros(), zeros(), zeros(), zeros()
    short_max, long_max = zeros(), zeros()
    t_now, last_step = zeros(), zeros()

    out_time = np.empty((batch, n))
    out_strain = np.empty((batch, n))
    prev_direction = 0
    for i in range(n):
        F = force_seq[i]
        d = direction_seq[i]
        D = duration_seq[i]
        m = mask_seq[i]

        # The parts that do not depend on the step length: the running maximum, the
        # instantaneous strain (Park Eq. 1-2 with h from the previous strain, and
        # Eq. 9's unloading line from the largest force, never below the loading
        # curve), the elements' targets F / (E_k A) and the flow rate at both ends.
        f_max = np.maximum(force_max, F)
        h = 1.0 + p["beta"] * _safe_pow(np.maximum(strain_prev, 0.0), p["gamma"])
        static = _safe_pow(F * compliance_c, h)
        static_max = _safe_pow(f_max * compliance_c, h)
        inst = np.maximum(static_max - (f_max - F) * compliance_r, static)
        sigma_a = p["strain_a"] * p["E1c"]
        rate0 = _eyring_rate(force_prev / area, p["eta0"], sigma_a)
        rate1 = _eyring_rate(F / area, p["eta0"], sigma_a)
        flow_rate = 0.5 * (rate0 + rate1)

        def strain_and_slope(dt):
            """Total strain after a step dt and its derivative d strain / d dt."""
            q_p, dq_p = _delayed_elastic(
                permanent,
                force_prev * ca_permanent,
                F * ca_permanent,
                dt,
                p["t_c"],
                None,
            )
            q_s, dq_s = _delayed_elastic(
                short, force_prev * ca_short, F * ca_short, dt, p["t_e"], p["t_r1"]
            )
            q_l, dq_l = _delayed_elastic(
                long, force_prev * ca_long, F * ca_long, dt, p["t_e"], t_r2
            )
            eps_p = flow + flow_rate * dt
            s_max = np.maximum(short_max, q_s)
            l_max = np.maximum(long_max, q_l)
            creep = q_p + s_max + l_max + eps_p
            total = inst + creep - (s_max - q_s) - (l_max - q_l)
            slope = dq_p + dq_s + dq_l + flow_rate
            return total, slope, (q_p, q_s, q_l, eps_p, s_max, l_max)

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
        for _ in range(max_steps):
            r, dr = residual(dt)
            converged = np.abs(r) <= tol
            step = r / np.where(dr == 0, 1.0, dr)
            good = (dr * slope_sign > 0) & np.isfinite(step)
            if converged.all():
                break
            grown = np.where(good, dt - step, 2 * dt + growth)
            dt = np.where(converged, dt, np.maximum(grown, 0.0))
        # A converged time takes one more Newton step as a refinement where that step
        # is small (as the kernel): without it each sample's time is off by up to
        # tol in relative strain, and the error adds up along a ramp (5e-11 of the
        # peak over 1000 samples).
        small = np.abs(step) <= 1e-3 * np.abs(dt) + 1e3 * growth
        dt = np.where(converged & good & small, np.maximum(dt - step, 0.0), dt)
        ok &= converged & np.isfinite(dt) & (dt >= 0)

        total, _, new_state = strain_and_slope(dt)
        if m:
            force_max = f_max
            permanent, short, long, flow, short_max, long_max = new_state
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
            jax.vmap(
                lambda c: jc.simulate_rate_test(
                    model, c, protocol, method=jc.Simulation(throw=False)
                )
            )
        )
        traj = jax.block_until_ready(run(cable))
        times = []
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            jax.block_until_ready(run(cable))
            times.append(time.perf_counter() - t0)
        t_jax = sorted(times)[len(times) // 2]
        # The largest difference over a cable's samples / its peak elongation.
        el = np.asarray(traj.elongation)
        diff = np.max(
            np.max(np.abs(el - ref["elongation"]), axis=1) / np.max(np.abs(el), axis=1)
        )
        rows.append(
            dict(
                batch=batch,
                samples=protocol.num_samples,
                numpy_s=t_np,
                kernel_s=t_jax,
                speedup=t_np / t_jax,
                max_diff_of_peak=float(diff),
                numpy_converged=int(ref["converged"].sum()),
            )
        )
    print(json.dumps(dict(machine=machine("float64"), rows=rows), indent=1))
    print()
    print(
        f"{'batch':>6} {'samples':>8} {'numpy [s]':>10} {'kernel [s]':>11} {'speedup':>8} {'diff / peak':>12}"
    )
    for r in rows:
        print(
            f"{r['batch']:>6} {r['samples']:>8} {r['numpy_s']:>10.3f} {r['kernel_s']:>11.4f} "
            f"{r['speedup']:>8.1f} {r['max_diff_of_peak']:>12.2e}"
        )
    if args.json_out:
        with open(args.json_out, "w") as f:
            json.dump(dict(machine=machine("float64"), rows=rows), f, indent=1)


if __name__ == "__main__":
    main()
