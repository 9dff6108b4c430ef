"""Peer baseline: the rate-driven simulation of `jaxcable.IntegratedModel` written as
the plain Numba loop a scientist would write, checked against jaxcable and timed
against it in one run (Park's 10-cycle test and one load-unload ramp; float64 and
float32; one cable with and without a batch axis, and batches).

    python benchmarks/peer_numba.py [--protocols park10,ramp] [--samples 2000]
        [--batches 1,1024] [--repeats 9] [--threads N] [--json-out FILE]

Needs numba, a benchmark-only dependency: `pip install -e .[bench]`.

The loop: `@njit` per cable (the model of `jaxcable.IntegratedModel.advance`, Park
Eq. 1-9 in the reading of docs/model_notes.md, and the per-sample Newton solve of the
loading time of `jaxcable.simulate_rate_test`: Park Eq. 6 as a relative strain
residual, its initial guess, its turning-point safeguard and final refinement step,
a bracket search and bisection where Newton fails), `prange` over the cables
(`parallel=True`; a single cable runs the same loop without starting the thread pool,
which on a busy machine can cost milliseconds); float64 and float32 are two
specialisations of the same code.

The protocols: `park10`, Park's 10 cycles to 100 N as a user runs them
(`Protocol.cycles(100.0, 10, samples_per_ramp=100)`, 2001 samples), one cable of
0.3 m at 3 mm/min; `ramp`, one load-unload cycle to 100 N in `--samples` samples. A
batch of several cables spreads their lengths over 0.1-0.5 m and their speeds over
3-10 mm/min, so that the lanes differ.

First the agreement with jaxcable in float64 (x64 enabled in this process), for each
protocol: the largest |difference of elongation| over every sample of a cable,
divided by that cable's peak elongation, largest over the cables of the largest
batch. Then the timings: jaxcable at the library's defaults runs in a fresh
subprocess per dtype (float32 with x64 disabled, the library's default dtype; float64
with x64 enabled) whose environment has no `XLA_FLAGS` and no
`JAXCABLE_NO_LOOP_KERNELS`, so that it sees what a fresh user process sees, flags
jaxcable sets at import included (reported as `worker_xla_flags`). A batch of one is
timed twice: without a batch axis, `jax.jit` of `jaxcable.simulate_rate_test(model,
cable, protocol, method=Simulation(throw=False))` on an unbatched `Cable` returning
its `Trajectory` (a user's first call), and as a `jax.vmap` over a batch of one
returning the elongation and result; larger batches are vmapped. Numba runs in this
process after each worker. Each time is the median of `--repeats` calls after a
warm-up call; the first call (compilation included) is reported apart. Each row's
`ratio` is to Numba in its dtype, `ratio_to_numba_float64` to Numba in float64 on the
same protocol and batch. Prints one JSON object and a table.
"""

import argparse
import json
import math
import os
import platform
import subprocess
import sys
import tempfile
import time
from collections.abc import Mapping

import numpy as np

import jaxcable as jc
from jaxcable._models.fields import field_facts


try:
    import numba
    from numba import njit, prange
except ImportError:  # pragma: no cover - depends on the environment
    numba = None

# The parameters of `jaxcable.IntegratedModel`, in the order of the parameter arrays.
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
    "t_e",
    "strain_a",
)
# The model's declared parameters must be the Numba loop's, in its positional order.
assert PARAMETERS == tuple(field_facts(jc.IntegratedModel)), "IntegratedModel changed"
# Indices of the parameters that must be finite and > 0: those the model declares
# positive (its `check`).
_POSITIVE = tuple(
    i
    for i, (name, facts) in enumerate(field_facts(jc.IntegratedModel).items())
    if facts.domain == "positive"
)

# The agreement required of the two in float64: |difference| / peak elongation.
AGREEMENT = 1e-12

# A cable's status after the simulation: 0 successful, else its first failure.
STATUS = (
    "successful",
    "out_of_domain",
    "newton_failed",
    "unreachable_force",
    "nonphysical_time",
    "nonphysical_strain",
    "strain_beyond_break",
)


def _build(dtype):
    """The Numba kernels in `dtype` (float32 or float64): every constant of the
    code is a `dtype` scalar, so that no operation is promoted to float64."""
    f = np.dtype(dtype).type
    double = np.dtype(dtype) == np.float64
    ZERO, HALF, ONE, TWO = f(0.0), f(0.5), f(1.0), f(2.0)
    INF = f(np.inf)
    # The relaxation terms' Taylor series below this x (more terms in float64).
    SERIES_BELOW = f(0.1 if double else 0.25)
    TERMS = 9 if double else 6
    # Coefficients of x^k, k = TERMS .. 1 (Horner), and of the series' derivative.
    COEF = tuple(
        f((-1.0) ** (k + 1) / math.factorial(k + 1)) for k in range(TERMS, 0, -1)
    )
    DCOEF = tuple(
        f(k * (-1.0) ** (k + 1) / math.factorial(k + 1)) for k in range(TERMS, 0, -1)
    )
    EYRING_CAP = f(60.0)  # sinh's argument is capped: a finite flow rate
    STRAIN_FLOOR = f(1e-4)  # of the residual's strain scale
    STRAIN_LIMIT = f(1.0)  # solved only up to this strain
    GROWTH = f(1e-6)  # growth of a step past a turning point, strain
    # A solved sample's residual is re-verified against this (looser than tol).
    LOOSE = f(1e-6 if double else 1e-3)
    PI4 = f(math.pi / 4)
    MILLI, KILO = f(1e-3), f(1e3)  # a refinement step is small below these
    SEARCH_STEPS, BISECTION_STEPS = 60, 100

    @njit(error_model="numpy", cache=False)
    def relaxation(x):
        # expm1(-x) and R(x) = 1 - (1 - e^-x) / x of a Kelvin-Voigt element over a
        # step x = dt / tau, and their derivatives in x.
        if abs(x) < SERIES_BELOW:
            s = ZERO
            ds = ZERO
            for k in range(TERMS):
                s = (s + COEF[k]) * x
                ds = ds * x + DCOEF[k]
            dm1 = x * (s - ONE)
            return dm1, s, -(ONE + dm1), ds
        dm1 = math.exp(-x) - ONE
        ramp = (x + dm1) / x
        return dm1, ramp, -(ONE + dm1), (-dm1 - ramp) / x

    @njit(error_model="numpy")
    def retarded(q0, a0, a1, dt, tau):
        # q' = (a - q) / tau over dt, a linear from a0 to a1: exact; and d/d dt.
        dm1, ramp, d_dm1, d_ramp = relaxation(dt / tau)
        q1 = q0 + dm1 * (q0 - a0) + (a1 - a0) * ramp
        return q1, (d_dm1 * (q0 - a0) + (a1 - a0) * d_ramp) / tau

    @njit(error_model="numpy")
    def element(q0, a0, a1, dt, creep_time, recovery_time):
        # A delayed-elastic element: creeps with creep_time, recovers with
        # recovery_time; the larger update where creep is the faster, else the
        # smaller.
        c, dc = retarded(q0, a0, a1, dt, creep_time)
        r, dr = retarded(q0, a0, a1, dt, recovery_time)
        if c == r:
            return c, HALF * (dc + dr)
        if (c > r) == (creep_time <= recovery_time):
            return c, dc
        return r, dr

    @njit(error_model="numpy")
    def safe_pow(base, exponent):
        return math.exp(exponent * math.log(base)) if base > ZERO else ZERO

    @njit(error_model="numpy")
    def eyring(stress, eta0, sigma_a):
        return sigma_a / eta0 * math.sinh(min(stress / sigma_a, EYRING_CAP))

    @njit(error_model="numpy")
    def strain_at(dt, sample):
        # The total strain after a step dt, its derivative in dt and the memories.
        # `sample`: the instantaneous strain, the memories before the step
        # (permanent, short, long, short_max, long_max, flow), the elements'
        # targets F / (E_k A) at both ends of the step, the flow rate and the
        # retardation times (t_c, t_e, t_r1, t_r2).
        inst, (perm, short, long_, smax, lmax, flow), tg, flow_rate, times = sample
        t_c, t_e, t_r1, t_r2 = times
        c, dc = retarded(perm, tg[0], tg[1], dt, t_c)
        # The permanent element never recovers.
        if c > perm:
            qp, dqp = c, dc
        elif c < perm:
            qp, dqp = perm, ZERO
        else:
            qp, dqp = perm, HALF * dc
        qs, dqs = element(short, tg[2], tg[3], dt, t_e, t_r1)
        ql, dql = element(long_, tg[4], tg[5], dt, t_e, t_r2)
        fl = flow + flow_rate * dt
        sm = max(smax, qs)
        lm = max(lmax, ql)
        total = inst + (qp + sm + lm + fl) - (sm - qs) - (lm - ql)
        return total, dqp + dqs + dql + flow_rate, (qp, qs, ql, sm, lm, fl)

    @njit(error_model="numpy")
    def residual(dt, sample, ramp):
        # Park Eq. 6 on a ramp: (model strain - crosshead strain) / scale; on a
        # hold (dt - duration) / (duration + 1 s). And its slope in dt.
        strain, sign, rate, scale, duration = ramp
        if sign == ZERO:
            return (dt - duration) / (duration + ONE), ONE / (duration + ONE)
        total, slope = strain_at(dt, sample)[:2]
        kinematic = strain + sign * rate * dt
        return (total - kinematic) / scale, (slope - sign * rate) / scale

    @njit(error_model="numpy")
    def see(y, r, slope_sign, bracket):
        # A bracket (left, right, has_left, has_right) of the wanted root updated
        # with r(y): left of it r s < 0, right of it r s > 0.
        left, right, has_left, has_right = bracket
        q = r * slope_sign
        if q < ZERO and (not has_left or y > left):
            left, has_left = y, True
        has_right = has_right and (not has_left or right > left)
        if q > ZERO and (not has_left or y > left) and (not has_right or y < right):
            right, has_right = y, True
        return left, right, has_left, has_right

    @njit(error_model="numpy")
    def solve(y, sample, ramp, slope_sign, growth, top, tol, max_steps):
        # The loading time from the guess y: (dt, converged, no_root).
        # Newton's method; where the slope has the wrong sign (past a turning point)
        # the iterate grows instead; a converged iterate takes one more (small)
        # step as a refinement.
        bracket = (y, y, False, False)
        stuck = False
        r = INF
        steps = 0
        while steps < max_steps and not (abs(r) <= tol or stuck):
            r, slope = residual(y, sample, ramp)
            step = r / (slope if slope != ZERO else ONE)
            good = slope != ZERO and math.isfinite(step) and slope * slope_sign > ZERO
            y_new = y - step if good else TWO * y + growth
            if abs(r) <= tol:
                small = abs(step) <= MILLI * abs(y) + KILO * growth
                y_new = y - step if good and small else y
            stuck = y <= ZERO and r * slope_sign > ZERO
            bracket = see(y, r, slope_sign, bracket)
            y = min(max(y_new, ZERO), top)
            steps += 1
        if abs(r) <= tol and math.isfinite(y):
            return y, True, False
        # Where Newton failed: a scan dt = growth (2^k - 1) for a bracket unless
        # one was seen, then bisection.
        k = 0
        searching = True
        y_end, r_end = y, INF
        while True:
            found = bracket[2] and bracket[3]
            if searching and not (k <= SEARCH_STEPS and not found):
                searching, k, r_end = False, 0, INF
            if not searching and not (
                k < BISECTION_STEPS and found and not abs(r_end) <= tol
            ):
                break
            if searching:
                y_end = min(growth * (f(2.0**k) - ONE), top)
            else:
                y_end = HALF * (bracket[0] + bracket[1])
            r_end = residual(y_end, sample, ramp)[0]
            bracket = see(y_end, r_end, slope_sign, bracket)
            k += 1
        if bracket[2] and bracket[3]:
            return y_end, abs(r_end) <= tol, False
        return y, False, True

    @njit(error_model="numpy")
    def cable(
        force, direction, duration, mask, p, fields, tol, max_steps, out_time, out_elong
    ):
        """One cable through the protocol; its status (`STATUS`)."""
        out_time[:] = np.nan
        out_elong[:] = np.nan
        E1c, beta, gamma, E1r, E2c, t_c, eta0 = p[:7]
        E2r, t_r1, E3r, lambda1, lambda2, t_e, strain_a = p[7:]
        sigma_a = strain_a * E1c
        length, speed, diameter, breaking_load, breaking_strain = fields
        area = PI4 * (diameter * diameter)
        rate = speed / length
        t_r2 = lambda1 / (rate * rate) - lambda2  # Park Eq. 8
        ok = math.isfinite(t_r2) and t_r2 > ZERO and beta >= ZERO and gamma >= ZERO
        for k in _POSITIVE:
            ok = ok and math.isfinite(p[k]) and p[k] > ZERO
        hardening_ok = (
            beta == ZERO or breaking_strain <= ONE or E1c * area > breaking_load
        )
        if not (ok and hardening_ok):
            return 1
        times = (t_c, t_e, t_r1, t_r2)
        cc = ONE / (E1c * area)
        ca = (ONE / (E2c * area), ONE / (E2r * area), ONE / (E3r * area))
        growth = GROWTH / rate
        f_prev = strain = f_max = t = last = ZERO
        memories = (ZERO, ZERO, ZERO, ZERO, ZERO, ZERO)
        previous_direction = 0
        for i in range(force.shape[0]):
            F, d, D = force[i], direction[i], duration[i]
            continues = d != 0 and d == previous_direction
            previous_direction = d
            if not mask[i]:
                out_time[i] = t
                out_elong[i] = strain * length
                continue
            # What does not depend on the step: Eq. 1-2 and 9 (h from the previous
            # strain), the elements' targets, the flow rate (trapezoid rule).
            fm = max(f_max, F)
            h = ONE + beta * safe_pow(max(strain, ZERO), gamma)
            static = safe_pow(F * cc, h)
            inst = max(safe_pow(fm * cc, h) - (fm - F) / (E1r * area), static)
            targets = (
                f_prev * ca[0],
                F * ca[0],
                f_prev * ca[1],
                F * ca[1],
                f_prev * ca[2],
                F * ca[2],
            )
            rate0 = eyring(f_prev / area, eta0, sigma_a)
            flow_rate = HALF * (rate0 + eyring(F / area, eta0, sigma_a))
            sample = (inst, memories, targets, flow_rate, times)

            # Initial guess: the previous step inside a ramp; the time the
            # instantaneous strain step takes at speed v at a ramp's start; a
            # hold's duration. The residual's scale is fixed for the sample.
            if continues:
                y = last
            elif d != 0:
                y = abs(strain_at(ZERO, sample)[0] - strain) / rate
            else:
                y = D
            sign = f(d)
            scale = (
                abs(strain)
                + abs(strain + (sign if d != 0 else ONE) * rate * y)
                + STRAIN_FLOOR
            )
            ramp = (strain, sign, rate, scale, D)
            slope_sign = -sign if d != 0 else ONE
            top = (TWO * STRAIN_LIMIT + abs(strain)) / rate if d != 0 else INF
            y, converged, no_root = solve(
                y, sample, ramp, slope_sign, growth, top, tol, max_steps
            )

            total, _, memories = strain_at(y, sample)
            miss = (total - (strain + sign * rate * y)) / scale if d != 0 else ZERO
            status = 0
            if not (converged and abs(miss) <= LOOSE):
                status = 3 if no_root else 2
            if not (y >= ZERO and math.isfinite(y)):
                status = 4
            if status == 0 and not (abs(total) <= STRAIN_LIMIT):
                status = 5
            if status == 0 and total > breaking_strain:
                status = 6
            if status != 0:
                return status
            f_prev, strain, f_max = F, total, fm
            t_new = t + y
            last = t_new - t
            t = t_new
            out_time[i] = t
            out_elong[i] = strain * length
        return 0

    def batch(
        force,
        direction,
        duration,
        mask,
        params,
        cables,
        tol,
        max_steps,
        out_time,
        out_elong,
        status,
    ):
        for c in prange(cables.shape[0]):
            status[c] = cable(
                force,
                direction,
                duration,
                mask,
                params[c],
                cables[c],
                tol,
                max_steps,
                out_time[c],
                out_elong[c],
            )

    # One cable needs no thread pool (whose start would dominate its time).
    return njit(error_model="numpy")(batch), njit(parallel=True, error_model="numpy")(
        batch
    )


_KERNELS = {}


def simulate_rate_test_numba(
    params,
    lengths,
    speeds,
    protocol_arrays,
    *,
    dtype=np.float64,
    diameter=3e-3,
    breaking_load=2000.0,
    breaking_strain=0.07,
    tol: float | None = None,
    max_steps: int = 32,
    parallel: bool | None = None,
):
    """Simulate a rate-driven test of a batch of cables with the Numba loop.

    **Arguments:**

    - `params`: the 14 parameters of `jaxcable.IntegratedModel` (SI), in the order of
        `PARAMETERS`: an array of shape (14,) or (batch, 14), or a mapping by name.
    - `lengths`: free lengths L0, m, shape (batch,).
    - `speeds`: crosshead speeds v, m/s, shape (batch,) or scalar.
    - `protocol_arrays`: a mapping with `force` (N), `direction` (+1, -1, 0),
        `duration` (s) and optionally `mask`, each of shape (samples,): a
        `jaxcable.Protocol`'s fields.
    - `dtype`: np.float64 or np.float32, the precision of the whole computation.
    - `diameter` (m), `breaking_load` (N), `breaking_strain`: the other `Cable`
        fields, scalars or shape (batch,).
    - `tol`, `max_steps`: Newton's tolerance on the relative strain residual (default
        1e-12 in float64, 2e-6 in float32, as jaxcable) and its most steps.
    - `parallel`: the cables over Numba's threads (default: where batch > 1).

    **Returns:**

    A dict: `time` (s) and `elongation` (m), shape (batch, samples), NaN from a
    cable's first failure on; `status` (batch,), indices into `STATUS`.
    """
    if numba is None:
        raise ImportError("numba is not installed: pip install -e .[bench]")
    dtype = np.dtype(dtype)
    if dtype not in (np.float32, np.float64):
        raise TypeError(f"`dtype` must be float32 or float64, got {dtype}.")
    if not isinstance(protocol_arrays, Mapping):
        raise TypeError("`protocol_arrays` must be a mapping of a Protocol's fields.")
    lengths = np.atleast_1d(np.asarray(lengths, dtype))
    if lengths.ndim != 1:
        raise ValueError(f"`lengths` must be 1-D, got shape {lengths.shape}.")
    n = lengths.shape[0]
    fields = dict(
        lengths=lengths,
        speeds=speeds,
        diameter=diameter,
        breaking_load=breaking_load,
        breaking_strain=breaking_strain,
    )
    for name, x in fields.items():
        try:
            fields[name] = np.broadcast_to(np.asarray(x, dtype), (n,))
        except ValueError:
            raise ValueError(f"`{name}` must be a scalar or of shape ({n},).") from None
    cables = np.ascontiguousarray(np.stack(list(fields.values()), axis=1))
    if isinstance(params, Mapping):
        params = [params[k] for k in PARAMETERS]
    params = np.asarray(params, dtype)
    if params.shape not in ((14,), (n, 14)):
        raise ValueError(
            f"`params` must be of shape (14,) or ({n}, 14), got {params.shape}."
        )
    params = np.ascontiguousarray(np.broadcast_to(params, (n, 14)))
    force = np.ascontiguousarray(protocol_arrays["force"], dtype)
    samples = force.shape[0]
    protocol = (
        force,
        np.ascontiguousarray(protocol_arrays["direction"], np.int32),
        np.ascontiguousarray(protocol_arrays["duration"], dtype),
        np.ascontiguousarray(
            np.broadcast_to(protocol_arrays.get("mask", True), (samples,)), np.bool_
        ),
    )
    if any(x.shape != (samples,) for x in protocol[1:]):
        raise ValueError("`protocol_arrays` must hold arrays of one shape (samples,).")
    if tol is None:
        tol = 1e-12 if dtype == np.float64 else 2e-6
    if dtype not in _KERNELS:
        _KERNELS[dtype] = _build(dtype)
    kernel = _KERNELS[dtype][n > 1 if parallel is None else bool(parallel)]
    out_time = np.empty((n, samples), dtype)
    out_elong = np.empty((n, samples), dtype)
    status = np.empty(n, np.int32)
    kernel(
        *protocol,
        params,
        cables,
        dtype.type(tol),
        max_steps,
        out_time,
        out_elong,
        status,
    )
    return dict(time=out_time, elongation=out_elong, status=status)


# ----------------------------------------------------------------------------------
# The problems, and jaxcable on them.

# The timed protocols: Park's 10-cycle test, and one load-unload ramp.
PROTOCOLS = ("park10", "ramp")


def problem(samples: int, batch: int, protocol: str = "ramp"):
    """The protocol, its arrays, the cables' lengths (m) and speeds (m/s), and the
    default parameters (float64) of a rate-driven test of `batch` cables.

    **Arguments:**

    - `samples`: the samples of "ramp" (unused by "park10").
    - `batch`: the number of cables.
    - `protocol`: "ramp", one load-unload cycle to 100 N in `samples` samples; or
        "park10", Park's 10 cycles to 100 N, 100 samples a ramp from a sample at
        0 N (2001 samples), on one cable of 0.3 m at 3 mm/min where `batch` is 1.
        Otherwise the lengths spread over 0.1-0.5 m, the speeds over 3-10 mm/min.

    **Returns:**

    `(protocol, arrays, lengths, speeds, params)`.
    """
    if protocol == "ramp":
        proto = jc.Protocol.cycles(100.0, 1, samples_per_ramp=samples // 2, start=False)
    elif protocol == "park10":
        proto = jc.Protocol.cycles(100.0, 10, samples_per_ramp=100)
    else:
        raise ValueError(f"`protocol` must be one of {PROTOCOLS}, got {protocol!r}.")
    arrays = {
        k: np.asarray(getattr(proto, k))
        for k in ("force", "direction", "duration", "mask")
    }
    # Read off the class, not an instance: an instance's fields follow JAX's dtype.
    defaults = jc.IntegratedModel.__dataclass_fields__
    params = np.array([float(defaults[k].default) for k in PARAMETERS])
    if protocol == "park10" and batch == 1:
        lengths, speeds = np.array([0.3]), np.array([3e-3 / 60])
    else:
        lengths = np.linspace(0.1, 0.5, batch)
        speeds = np.linspace(3e-3, 10e-3, batch) / 60
    return proto, arrays, lengths, speeds, params


def jaxcable_forward(protocol, batch_axis: bool = True):
    """The jitted jaxcable simulation at the library's defaults: with `batch_axis`,
    (model, batched cable) -> (elongation, result) through `jax.vmap`; without,
    (model, cable) -> the `Trajectory`, a user's plain call."""
    import jax

    method = jc.Simulation(throw=False)
    if not batch_axis:
        return jax.jit(
            lambda model, cable: jc.simulate_rate_test(
                model, cable, protocol, method=method
            )
        )

    def forward(model, cable):
        simulate = lambda c: jc.simulate_rate_test(model, c, protocol, method=method)
        traj = jax.vmap(simulate)(cable)
        return traj.elongation, traj.result

    return jax.jit(forward)


def jaxcable_inputs(params, lengths, speeds, batch_axis: bool = True):
    """The model (parameters `params`) and the Cable, in JAX's default dtype, the
    other Cable fields at their defaults: batched over `lengths` with
    `batch_axis`, else the first cable without a batch axis."""
    import jax
    import jax.numpy as jnp

    model = jc.IntegratedModel(**dict(zip(PARAMETERS, params)))
    if not batch_axis:
        return model, jc.Cable(length=float(lengths[0]), speed=float(speeds[0]))
    cable = jc.Cable(length=jnp.asarray(lengths), speed=jnp.asarray(speeds))
    batch = len(lengths)
    cable = jax.tree_util.tree_map(lambda x: jnp.broadcast_to(x, (batch,)), cable)
    return model, cable


def agreement(reference, elongation):
    """Largest |difference| over a cable's samples / its peak |elongation|, largest
    over the cables."""
    ref = np.asarray(reference, np.float64)
    diff = np.max(np.abs(np.asarray(elongation, np.float64) - ref), axis=-1)
    return float(np.max(diff / np.max(np.abs(ref), axis=-1)))


def check_agreement(
    samples: int, batch: int, parallel: bool | None = None, protocol: str = "ramp"
) -> dict:
    """Numba against jaxcable in float64 (needs x64 enabled), on `batch` cables of
    `problem(samples, batch, protocol)`: {"agreement", "successful_jaxcable",
    "successful_numba"} (`parallel`: as `simulate_rate_test_numba`)."""
    import jax

    if not jax.config.jax_enable_x64:
        raise RuntimeError("check_agreement needs jax_enable_x64.")
    proto, arrays, lengths, speeds, params = problem(samples, batch, protocol)
    elongation, result = jaxcable_forward(proto)(
        *jaxcable_inputs(params, lengths, speeds)
    )
    out = simulate_rate_test_numba(params, lengths, speeds, arrays, parallel=parallel)
    return dict(
        agreement=agreement(elongation, out["elongation"]),
        successful_jaxcable=int(np.sum(np.asarray(result == jc.RESULTS.successful))),
        successful_numba=int(np.sum(out["status"] == 0)),
    )


def _median(fn, repeats):
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return sorted(times)[len(times) // 2]


def _cases(args):
    """(protocol, batch, batch_axis) of every timed case: a batch of one both
    without a batch axis and vmapped, a larger batch vmapped."""
    return [
        (protocol, batch, axis)
        for protocol in args.protocol_list
        for batch in args.batch_list
        for axis in ((False, True) if batch == 1 else (True,))
    ]


def _case_name(protocol, batch, axis, samples):
    return f"{protocol}:{batch}x{samples}" + (" vmap" if axis else "")


def _dump_path(dump, dtype, protocol, batch, axis):
    return os.path.join(dump, f"{dtype}_{protocol}_{batch}_{int(axis)}.npy")


def _jax_worker(args):
    """Time jaxcable in this (fresh) process in one dtype; print the rows as JSON."""
    import jax

    # What a fresh user process runs with once jaxcable is imported.
    xla_flags = os.environ.get("XLA_FLAGS")
    if args.worker == "float64":
        jax.config.update("jax_enable_x64", True)
    rows = []
    for protocol, batch, axis in _cases(args):
        proto, arrays, lengths, speeds, params = problem(args.samples, batch, protocol)
        forward = jaxcable_forward(proto, axis)
        model, cable = jaxcable_inputs(params, lengths, speeds, axis)
        t0 = time.perf_counter()
        out = jax.block_until_ready(forward(model, cable))
        first = time.perf_counter() - t0
        elongation = out[0] if axis else out.elongation
        if elongation.dtype != np.dtype(args.worker):
            raise RuntimeError(
                f"jaxcable ran in {elongation.dtype}, not {args.worker}."
            )
        run = lambda: jax.block_until_ready(forward(model, cable))
        run()
        rows.append(
            dict(
                protocol=protocol,
                batch=batch,
                batch_axis=axis,
                samples=int(arrays["force"].shape[0]),
                jaxcable_s=_median(run, args.repeats),
                jaxcable_first_call_s=first,
            )
        )
        np.save(
            _dump_path(args.dump, args.worker, protocol, batch, axis),
            np.asarray(elongation).reshape(batch, -1),
        )
    info = dict(jax=jax.__version__, backend=jax.default_backend())
    print(json.dumps(dict(rows=rows, xla_flags=xla_flags, **info)))


def _run_worker(args, dtype, dump):
    # The worker sees the environment a fresh user process sees: no XLA flags, and
    # jaxcable's own choice of them at import.
    stripped = ("XLA_FLAGS", "JAX_ENABLE_X64", "JAXCABLE_NO_LOOP_KERNELS")
    env = {k: v for k, v in os.environ.items() if k not in stripped}
    cmd = [
        sys.executable,
        os.path.abspath(__file__),
        "--worker",
        dtype,
        "--dump",
        dump,
        "--samples",
        str(args.samples),
        "--batches",
        args.batches,
        "--protocols",
        args.protocols,
        "--repeats",
        str(args.repeats),
    ]
    done = subprocess.run(cmd, env=env, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"the jaxcable {dtype} run failed:\n{done.stderr[-4000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def _parse():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--samples", type=int, default=2000, help="samples of 'ramp'")
    p.add_argument("--batches", default="1,1024")
    p.add_argument("--protocols", default=",".join(PROTOCOLS))
    p.add_argument("--repeats", type=int, default=9)
    p.add_argument(
        "--threads", type=int, default=None, help="Numba threads (default: all cores)"
    )
    p.add_argument("--json-out", default=None)
    p.add_argument("--worker", choices=("float32", "float64"), help=argparse.SUPPRESS)
    p.add_argument("--dump", help=argparse.SUPPRESS)
    args = p.parse_args()
    args.batch_list = [int(b) for b in args.batches.split(",")]
    args.protocol_list = [s.strip() for s in args.protocols.split(",") if s.strip()]
    if args.samples < 2 or args.repeats < 1 or min(args.batch_list) < 1:
        p.error("--samples must be >= 2, --repeats and every batch >= 1")
    if not args.protocol_list or set(args.protocol_list) - set(PROTOCOLS):
        p.error(f"--protocols must be a comma-separated subset of {PROTOCOLS}")
    if args.threads is not None and args.threads < 1:
        p.error("--threads must be >= 1")
    return args


def _compile_numba(samples):
    """Seconds of the first calls of the serial kernel (one cable) and of the
    parallel one, by dtype: the compilation of the Numba kernels."""
    _, arrays, lengths, speeds, params = problem(samples, 1)
    numba_compile = {}
    for dtype in ("float64", "float32"):
        t0 = time.perf_counter()
        for parallel in (False, True):
            simulate_rate_test_numba(
                params, lengths, speeds, arrays, dtype=dtype, parallel=parallel
            )
        numba_compile[dtype] = time.perf_counter() - t0
    return numba_compile


def _check_all(args):
    """The float64 agreement of every protocol on the largest batch: the list of
    checks, each with its protocol, case and verdict."""
    big = max(args.batch_list)
    checks = []
    for protocol in args.protocol_list:
        check = check_agreement(args.samples, big, protocol=protocol)
        samples = problem(args.samples, big, protocol)[1]["force"].shape[0]
        ok = (
            check["agreement"] <= AGREEMENT
            and check["successful_numba"] == check["successful_jaxcable"] == big
        )
        checks.append(
            dict(
                check,
                protocol=protocol,
                case=_case_name(protocol, big, True, samples),
                dtype="float64",
                ok=ok,
            )
        )
        print(
            f"agreement (float64, {checks[-1]['case']}): {check['agreement']:.2e} of "
            f"the peak ({'ok' if ok else f'FAILED: more than {AGREEMENT:g}'})",
            file=sys.stderr,
        )
    return checks


class _NumbaTimes:
    """The Numba loop's median time and its last simulation per (dtype, protocol,
    batch), each timed once; one cable runs the serial kernel."""

    def __init__(self, args):
        self.args, self.cache = args, {}

    def __call__(self, dtype, protocol, batch):
        key = (dtype, protocol, batch)
        if key not in self.cache:
            _, arrays, lengths, speeds, params = problem(
                self.args.samples, batch, protocol
            )
            call = lambda: simulate_rate_test_numba(
                params, lengths, speeds, arrays, dtype=dtype
            )
            sim = call()
            self.cache[key] = (_median(call, self.args.repeats), sim)
        return self.cache[key]


def _row(w, dtype, dump, numba_times, numba_compile):
    """One row of the table from a worker's row `w`."""
    protocol, batch, axis = w["protocol"], w["batch"], w["batch_axis"]
    numba_s, sim = numba_times(dtype, protocol, batch)
    numba_f64_s = numba_times("float64", protocol, batch)[0]
    ref = np.load(_dump_path(dump, dtype, protocol, batch, axis))
    return dict(
        case=_case_name(protocol, batch, axis, w["samples"]),
        protocol=protocol,
        batch=batch,
        batch_axis=axis,
        samples=w["samples"],
        dtype=dtype,
        jaxcable_s=w["jaxcable_s"],
        numba_s=numba_s,
        ratio=w["jaxcable_s"] / numba_s,
        ratio_to_numba_float64=w["jaxcable_s"] / numba_f64_s,
        jaxcable_first_call_s=w["jaxcable_first_call_s"],
        numba_compile_s=numba_compile[dtype],
        agreement=agreement(ref, sim["elongation"]),
        numba_successful=int(np.sum(sim["status"] == 0)),
    )


def _timed_rows(args, numba_compile):
    """jaxcable (a fresh worker per dtype, float64 first), then Numba in this
    process: the rows and what the workers report of their JAX."""
    rows, info = [], {}
    numba_times = _NumbaTimes(args)
    with tempfile.TemporaryDirectory() as dump:
        for dtype in ("float64", "float32"):
            worker = _run_worker(args, dtype, dump)
            info = dict(
                jax=worker["jax"],
                backend=worker["backend"],
                worker_xla_flags=worker["xla_flags"],
            )
            for w in worker["rows"]:
                rows.append(_row(w, dtype, dump, numba_times, numba_compile))
    return rows, info


def _print_table(out):
    print(
        f"\nagreement (float64, largest batch, of each cable's peak): "
        f"{out['agreement']:.2e}"
    )
    load = out["load"]
    print(f"load average (1, 5, 15 min) at start {load['start']}, at end {load['end']}")
    print(
        f"worker XLA_FLAGS after import jaxcable: {out['machine']['worker_xla_flags']}"
    )
    print(
        f"{'protocol':>8} {'batch':>6} {'axis':>5} {'dtype':>8} {'jaxcable [s]':>13} "
        f"{'numba [s]':>11} {'ratio':>8} {'/numba64':>9} {'jax 1st [s]':>12} "
        f"{'numba compile [s]':>18} {'agreement':>10}"
    )
    for r in out["rows"]:
        print(
            f"{r['protocol']:>8} {r['batch']:>6} {'vmap' if r['batch_axis'] else '-':>5} "
            f"{r['dtype']:>8} {r['jaxcable_s']:>13.5f} {r['numba_s']:>11.5f} "
            f"{r['ratio']:>8.2f} {r['ratio_to_numba_float64']:>9.2f} "
            f"{r['jaxcable_first_call_s']:>12.2f} {r['numba_compile_s']:>18.2f} "
            f"{r['agreement']:>10.1e}"
        )


def main():
    args = _parse()
    if numba is None:
        sys.exit("peer_numba.py needs numba: pip install -e .[bench]")
    if args.worker:
        return _jax_worker(args)
    load_start = list(os.getloadavg())
    if args.threads:
        numba.set_num_threads(args.threads)
    import jax

    jax.config.update("jax_enable_x64", True)  # this process: the float64 check only
    numba_compile = _compile_numba(args.samples)
    checks = _check_all(args)
    worst = max(checks, key=lambda c: c["agreement"])
    rows, jax_info = _timed_rows(args, numba_compile)
    out = dict(
        agreement=worst["agreement"],
        agreement_check=worst,
        agreement_checks=checks,
        rows=rows,
        machine=dict(
            platform=platform.platform(),
            processor=platform.processor() or platform.machine(),
            cpu_count=os.cpu_count(),
            python=platform.python_version(),
            numpy=np.__version__,
            numba=numba.__version__,
            numba_threads=numba.get_num_threads(),
            numba_threading_layer=numba.threading_layer(),
            **jax_info,
        ),
        load=dict(start=load_start, end=list(os.getloadavg())),
    )
    print(json.dumps(out, indent=1))
    _print_table(out)
    if args.json_out:
        with open(args.json_out, "w") as f:
            json.dump(out, f, indent=1)
    if not all(c["ok"] for c in checks):
        sys.exit(f"Numba and jaxcable disagree: {worst}")


if __name__ == "__main__":
    main()
