"""Fit benchmark: jaxcable's Levenberg-Marquardt solve (Jacobians through the scan)
against scipy.optimize.least_squares, with the same JAX Jacobian and with finite
differences, on the same problems.

    python benchmarks/fit.py [--repeats 5] [--problems small,large,realistic]
        [--xla-default] [--json-out FILE]

Problems (Park's IntegratedModel, Dyneema SK78 defaults as the truth):

- `small`: 6 shared parameters (E1c, E2c, t_c, eta0, E2r, t_r1), 2 tests (300 mm at
    100 N, 100 mm at 150 N; load 60 s, hold 600 s, unload 60 s, rest 30 min, ~200
    samples each, 0.01 mm noise; start 0.6x-1.5x off).
- `large`: 6 tests (100/200/300 mm x 100/150 N) of cables whose E1c and E2c differ
    (+-10 %): E1c and E2c per test, t_c, eta0, E2r, t_r1 shared: 16 parameters.
- `realistic`: 8 tests of Park's protocol (10 cycles, 24 h rest, re-stretch; 100 and
    300 mm, 3 and 50 mm/min, 100 and 150 N) x 2000 samples, made by
    `jaxcable._papers.synthetic.synthesize` (5 um and 0.05 N noise); the 8 parameters
    of `PARK_IDENTIFIABLE` shared, from 0.6x-1.5x off.

All methods minimise the same sum of squares in the same unconstrained (log)
parameters from the same start (jaxcable.fit's data-derived start, computed before
the timing), with the same jitted forward simulation of all tests. Rows:

- `jaxcable solve`: `jaxcable._fit.solver.solve` (the solve `fit_kernel` maps over
    the starts) alone, jitted; its compile time is reported separately.
- `jaxcable.fit (all)`: `multistart=1`, everything included (checks, data-derived
    start, solve, standard errors).
- `scipy trf, FD J` and `scipy lm, FD J`: `least_squares(jac="2-point")` calling
    the jitted residual function, tolerances 1e-10 (tighter than jaxcable's, so that
    scipy does not stop early).
- `scipy trf, JAX J`: `least_squares` with the jitted forward-mode Jacobian of the
    same residuals (`residuals_and_jacobian`): the same gradient, so the comparison
    is of the solver loops.

"solve x faster" is the row's time over `jaxcable solve`'s. Compare the losses too:
on `realistic` scipy's trf stops at another stationary point (a higher loss).

OpenBLAS runs single-threaded (`OPENBLAS_NUM_THREADS=1` unless set): with its
threads on a busy machine, each LAPACK call on the tall Jacobian (scipy's trf takes
an SVD per step) can wait for a core far longer than it computes, which measures the
machine, not the methods. Timings: jit and warm up, then the median of `--repeats` runs, each
ended by `jax.block_until_ready`; the first call's extra time is reported as compile
time. float64. The scans run with the CPU loop kernels that `import jaxcable` turns on;
`--xla-default` keeps XLA's own CPU loops (`JAXCABLE_NO_LOOP_KERNELS=1`), and the
JSON's `machine.loop_kernels` says which ran. Prints one JSON object and a table;
results with machine details are kept in benchmarks/README.md.
"""

import argparse
import json
import os
import platform
import sys
import time


# Before numpy is imported (see the module docstring).
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
# `import jaxcable` (below) turns on XLA's CPU loop kernels unless this says no, so
# `--xla-default` is read here, before it (argparse declares it too, for --help).
if "--xla-default" in sys.argv[1:]:
    os.environ["JAXCABLE_NO_LOOP_KERNELS"] = "1"

import jax  # noqa: E402


jax.config.update("jax_enable_x64", True)

import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import optimistix as optx  # noqa: E402
import scipy  # noqa: E402
import scipy.optimize  # noqa: E402

import jaxcable as jc  # noqa: E402
from jaxcable._fit import problem as fit_problem, solver as fit_solver  # noqa: E402
from jaxcable._papers.park import park_protocol  # noqa: E402
from jaxcable._papers.synthetic import synthesize  # noqa: E402


SHARED = ("t_c", "eta0", "E2r", "t_r1")
START_FACTORS = {
    "E1c": 1.4,
    "E2c": 0.7,
    "t_c": 1.5,
    "eta0": 0.6,
    "E2r": 1.3,
    "t_r1": 0.7,
}


def _parse():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--problems", default="small,large,realistic")
    p.add_argument("--json-out", default=None)
    p.add_argument(
        "--xla-default",
        action="store_true",
        help="XLA's default CPU loops instead of the loop kernels that "
        "`import jaxcable` turns on (JAXCABLE_NO_LOOP_KERNELS=1)",
    )
    return p.parse_args()


def loop_kernels_on() -> bool:
    """Whether XLA's CPU loop-kernel option is set (by `import jaxcable` or by hand)."""
    return "xla_cpu_small_while_loop_byte_threshold" in os.environ.get("XLA_FLAGS", "")


def _history(peak, rest_samples):
    ramp = np.linspace(0.0, 60.0, 41)
    hold = 60.0 + np.linspace(0.0, 600.0, 61)[1:]
    unload = 660.0 + np.linspace(0.0, 60.0, 41)[1:]
    rest = 720.0 + np.geomspace(1.0, 1800.0, rest_samples)
    time_ = np.concatenate([ramp, hold, unload, rest])
    force = np.concatenate(
        [
            peak * ramp / 60.0,
            np.full(hold.shape, peak),
            peak * (1 - (unload - 660.0) / 60.0),
            np.zeros(rest.shape),
        ]
    )
    return time_, force


def _problem(name):
    """(start model, tests, fit names, per_test names)."""
    rng = np.random.default_rng(0)
    true = jc.IntegratedModel()
    if name == "small":
        designs = [(0.3, 100.0, 60), (0.1, 150.0, 40)]
        truths = [true, true]
        per_test = None
    else:
        designs = [
            (length, peak, 50) for length in (0.1, 0.2, 0.3) for peak in (100.0, 150.0)
        ]
        factors = rng.uniform(0.9, 1.1, (len(designs), 2))
        truths = [
            eqx.tree_at(lambda m: (m.E1c, m.E2c), true, (true.E1c * a, true.E2c * b))
            for a, b in factors
        ]
        per_test = ["E1c", "E2c"]
    tests = []
    for model, (length, peak, rest) in zip(truths, designs):
        time_, force = _history(peak, rest)
        traj = jc.simulate_force_history(model, jc.Cable(length=length), time_, force)
        noise = 1e-5 * rng.standard_normal(time_.shape)
        tests.append(
            jc.TestData(
                time_,
                force,
                np.asarray(traj.elongation) + noise,
                metadata={
                    "length_mm": 1e3 * length,
                    "id": f"{length}m-{peak:g}N",
                    "control": "force",
                },
            )
        )
    names = list(START_FACTORS)
    start = eqx.tree_at(
        lambda m: [getattr(m, n) for n in names],
        true,
        [getattr(true, n) * START_FACTORS[n] for n in names],
    )
    return start, tests, names, per_test


# The realistic problem: Park's protocol (10 load-unload cycles, a 24 h rest, a
# re-stretch; 90 samples per ramp, 2000 per test) on 100 and 300 mm cables at 3 and
# 50 mm/min to 100 and 150 N, simulated by the default IntegratedModel with
# `synthesize`'s noise (5 um elongation, 0.05 N force with its deadband), the 8
# parameters Park's tests identify fitted from 0.6x-1.5x off.
REALISTIC_START_FACTORS = {
    "E1c": 1.3,
    "E1r": 0.8,
    "E2c": 0.7,
    "t_c": 1.5,
    "eta0": 0.6,
    "E2r": 1.3,
    "t_r1": 0.7,
    "E3r": 1.2,
}


def _realistic_problem():
    """(start model, tests, fit names, per_test names) of the realistic problem."""
    true = jc.IntegratedModel()
    tests = []
    for length in (100.0, 300.0):
        for rate in (3.0, 50.0):
            for peak in (100.0, 150.0):
                cable = jc.Cable(length=length * 1e-3, speed=rate * 1e-3 / 60)
                tests.append(
                    synthesize(
                        true,
                        cable,
                        park_protocol(peak, samples_per_ramp=90, rest_samples=19),
                        seed=100 + len(tests),
                        metadata={"id": f"L{length:g}-v{rate:g}-F{peak:g}"},
                    )
                )
    names = list(REALISTIC_START_FACTORS)
    start = eqx.tree_at(
        lambda m: [getattr(m, n) for n in names],
        true,
        [getattr(true, n) * REALISTIC_START_FACTORS[n] for n in names],
    )
    return start, tests, names, None


class _Plain(fit_solver.LevenbergMarquardt):
    """jaxcable's solver with optimistix's own step and stopping test."""

    def step(self, fn, y, args, options, state, tags):
        return optx.AbstractGaussNewton.step(self, fn, y, args, options, state, tags)


def _median(fn, repeats):
    times, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return sorted(times)[len(times) // 2], out


def _run(name, repeats):
    start, tests, names, per_test = (
        _realistic_problem() if name == "realistic" else _problem(name)
    )
    samples = sum(t.num_samples for t in tests)

    def run_jax():
        problem = jc.Problem(start, tests, fit=names, per_test=per_test)
        return jc.fit(problem, jc.LeastSquares(multistart=1))

    t0 = time.perf_counter()
    run_jax()
    fit_first = time.perf_counter() - t0
    fit_time, result = _median(run_jax, repeats)

    # The same problem, start and jitted forward, for the solves alone.
    problem, u_user = fit_problem.make_problem(start, tests, names, per_test, None)
    solver = fit_solver.LevenbergMarquardt(rtol=1e-6, atol=1e-6)
    method = fit_solver.KernelMethod(solver, 256, "fwd", 1, 0.5)
    kernel = fit_solver.fit_kernel(problem, u_user, jax.random.key(0), method)
    u0 = np.asarray(kernel.starts[0])

    # jaxcable's solve alone: the library's `solve` (what `fit_kernel` maps over the
    # starts), compiled, from the same start as scipy.
    @jax.jit
    def jax_solve(u):
        value, _, steps, r, _ = fit_solver.solve(problem, u, solver, 256, "fwd")
        return value, steps, jnp.sum(r**2)

    def run_solve():
        return jax.block_until_ready(jax_solve(jnp.asarray(u0)))

    t0 = time.perf_counter()
    run_solve()
    solve_first = time.perf_counter() - t0
    solve_time, (_, solve_steps, solve_loss) = _median(run_solve, repeats)

    # The same solve with optimistix's own step (convergence tested only on steps
    # taken): the baseline of the early stop.
    @jax.jit
    def plain_solve(u):
        value, _, steps, r, _ = fit_solver.solve(
            problem, u, _Plain(1e-6, 1e-6), 256, "fwd"
        )
        return value, steps, jnp.sum(r**2)

    jax.block_until_ready(plain_solve(jnp.asarray(u0)))
    plain_time, (_, plain_steps, plain_loss) = _median(
        lambda: jax.block_until_ready(plain_solve(jnp.asarray(u0))), repeats
    )

    scale = float(np.max(np.abs(np.asarray(problem.data.elongation))))
    forward = jax.jit(lambda u: jnp.ravel(problem.residuals(u)) / scale)
    jacobian = jax.jit(
        lambda u: fit_solver.residuals_and_jacobian(problem, u, "fwd")[1]
    )

    calls = [0]

    def residual(u):
        calls[0] += 1
        return np.asarray(jax.block_until_ready(forward(jnp.asarray(u))))

    def exact_jacobian(u):
        return np.asarray(jax.block_until_ready(jacobian(jnp.asarray(u)))) / scale

    residual(u0)
    exact_jacobian(u0)
    forward_time, _ = _median(lambda: residual(u0), max(repeats, 20))
    jacobian_time, _ = _median(lambda: exact_jacobian(u0), max(repeats, 20))

    rows = {}
    for label, method, jac in (
        ("scipy trf, FD J", "trf", "2-point"),
        ("scipy lm, FD J", "lm", "2-point"),
        ("scipy trf, JAX J", "trf", exact_jacobian),
    ):

        def run_scipy(method=method, jac=jac):
            return scipy.optimize.least_squares(
                residual, u0, jac=jac, method=method, ftol=1e-10, xtol=1e-10, gtol=1e-10
            )

        try:
            seconds, sol = _median(run_scipy, repeats)
        except ValueError as e:
            # scipy stops on a non-finite Jacobian: its trf can step far outside the
            # data's range (measured: E1r = exp(-365) Pa), where the model's
            # derivatives overflow. Reported as the row's outcome, not timed.
            rows[label] = dict(seconds=None, error=str(e))
            continue
        calls[0] = 0
        run_scipy()
        loss = float(np.sum((sol.fun * scale) ** 2))
        rows[label] = dict(
            seconds=seconds,
            loss_m2=loss,
            forward_calls=calls[0],
            nfev=int(sol.nfev),
            njev=None if sol.njev is None else int(sol.njev),
            status=int(sol.status),
            solve_speedup=seconds / solve_time,
            relative_loss_vs_jaxcable=(loss - float(solve_loss)) / float(solve_loss),
        )
    return dict(
        problem=dict(
            name=name,
            model="IntegratedModel",
            fit=names,
            per_test=per_test or [],
            parameters=len(result.names),
            tests=len(tests),
            samples=samples,
        ),
        jaxcable_fit=dict(
            seconds=fit_time,
            compile_seconds=fit_first - fit_time,
            loss_m2=result.loss,
            steps=result.num_steps,
            converged=result.converged,
        ),
        jaxcable_solve=dict(
            seconds=solve_time,
            compile_seconds=solve_first - solve_time,
            loss_m2=float(solve_loss),
            steps=int(solve_steps),
        ),
        jaxcable_solve_optimistix_stop=dict(
            seconds=plain_time, loss_m2=float(plain_loss), steps=int(plain_steps)
        ),
        forward_ms=1e3 * forward_time,
        jacobian_ms=1e3 * jacobian_time,
        scipy=rows,
    )


def main():
    args = _parse()
    reports = [_run(name, args.repeats) for name in args.problems.split(",")]
    try:
        load = os.getloadavg()
    except OSError:
        load = None
    report = dict(
        problems=reports,
        machine=dict(
            platform=platform.platform(),
            processor=platform.processor() or platform.machine(),
            cpus=os.cpu_count(),
            load_average_after=load,
            python=platform.python_version(),
            jax=jax.__version__,
            backend=jax.default_backend(),
            scipy=scipy.__version__,
            jaxcable=jc.__version__,
            openblas_threads=os.environ.get("OPENBLAS_NUM_THREADS"),
            loop_kernels=loop_kernels_on(),
            xla_flags=os.environ.get("XLA_FLAGS", ""),
        ),
        repeats=args.repeats,
    )
    print(json.dumps(report, indent=2))
    for r in reports:
        p, f, j = r["problem"], r["jaxcable_fit"], r["jaxcable_solve"]
        print()
        print(
            f"{p['name']}: {p['parameters']} parameters, {p['tests']} tests, "
            f"{p['samples']} samples; one forward {r['forward_ms']:.2f} ms, one "
            f"Jacobian (forward mode) {r['jacobian_ms']:.2f} ms; compile: solve "
            f"{j['compile_seconds']:.1f} s, fit {f['compile_seconds']:.1f} s"
        )
        print(
            f"{'method':<22} {'time s':>8} {'loss m^2':>14} {'J evals':>8} "
            f"{'fwd calls':>9} {'solve x faster':>15}"
        )
        print(
            f"{'jaxcable solve':<22} {j['seconds']:>8.4f} {j['loss_m2']:>14.8g} "
            f"{j['steps']:>8} {'':>9} {'':>15}"
        )
        o = r["jaxcable_solve_optimistix_stop"]
        print(
            f"{'  optimistix stop':<22} {o['seconds']:>8.4f} {o['loss_m2']:>14.8g} "
            f"{o['steps']:>8} {'':>9} {o['seconds'] / j['seconds']:>15.1f}"
        )
        print(
            f"{'jaxcable.fit (all)':<22} {f['seconds']:>8.4f} {f['loss_m2']:>14.8g} "
            f"{f['steps']:>8} {'':>9} {'':>15}"
        )
        for label, s in r["scipy"].items():
            if s["seconds"] is None:
                print(f"{label:<22} failed: {s['error']}")
                continue
            njev = s["njev"] if s["njev"] is not None else "-"
            print(
                f"{label:<22} {s['seconds']:>8.4f} {s['loss_m2']:>14.8g} "
                f"{njev:>8} {s['forward_calls']:>9} {s['solve_speedup']:>15.1f}"
            )
    if args.json_out:
        with open(args.json_out, "w") as f:
            json.dump(report, f, indent=2)


if __name__ == "__main__":
    main()
