"""fit_each benchmark: many specimens fitted at once by `jaxcable.fit_each` (one
vmapped Levenberg-Marquardt), against a Python loop of `jaxcable.fit` and a loop of
scipy.optimize.least_squares (trf) with the same JAX residuals and Jacobian, in one
run.

    python benchmarks/fit_each.py [--specimens 256] [--loop-specimens N]
        [--scipy-specimens N] [--samples-per-ramp 90] [--repeats 1] [--xla-default]
        [--json-out FILE]

The problem (Park's `IntegratedModel`; the realistic problem of `benchmarks/fit.py`
cut to one specimen of three tests): each specimen is three tests of Park's protocol
(10 cycles, 24 h rest, re-stretch; `--samples-per-ramp` 90: 2000 samples a test) on
100 mm at 3 mm/min to 100 N, 300 mm at 50 mm/min to 150 N and 300 mm at 3 mm/min to
150 N, made by `jaxcable._papers.synthetic.synthesize` with 5 um of elongation noise
and the force recorded exactly (a force error would be an error in the fit's input,
which its standard errors do not account for). Each specimen's truth is the SK78
default with E1r = 1.5 E1c (Eq. 9's unloading line lies above the loading curve only
for E1r > E1c: at the default, E1r = E1c, the residuals do not depend on E1r) and each
fitted parameter scaled by exp(0.1 z), z standard normal. Fitted: the 8 parameters
E1c, E1r, E2c, t_c, E2r, t_r1, E3r, t_e (eta0 of `benchmarks/fit.py`'s set is not
identified by three tests; t_e is), from the nominal truth 0.7x-1.5x off, one start
(`multistart=1`), float64.

Rows:

- `fit_each`: `jaxcable.fit_each` of all specimens; the first call (its compile
    included) is reported apart, then the median of `--repeats` calls.
- `fit loop`: `jaxcable.fit` of each specimen in a Python loop, warm (one fit first
    compiles the kernel every specimen shares); timed over the first
    `--loop-specimens` specimens and scaled to all of them when fewer.
- `scipy loop`: `least_squares(method="trf")` of each specimen from the same
    data-derived start, with the jitted residuals and forward-mode Jacobian of the
    same problem (`residuals_and_jacobian`; compiled once for all specimens),
    tolerances 1e-10 as in `benchmarks/fit.py`; over `--scipy-specimens`, scaled.

Checks: each looped specimen's parameters against its `fit_each` parameters
(largest relative difference), and the fraction of specimens whose every fitted
parameter is within 3 standard errors of its truth (and per parameter).
OpenBLAS runs single-threaded, as in `benchmarks/fit.py`. The scans run with the CPU
loop kernels that `import jaxcable` turns on; `--xla-default` keeps XLA's own CPU
loops (`JAXCABLE_NO_LOOP_KERNELS=1`), and the JSON's `loop_kernels` says which ran.
Prints one JSON object and a table; results with machine details are kept in
benchmarks/README.md.
"""

import argparse
import json
import os
import sys
import time
import warnings


# Before numpy is imported (see benchmarks/fit.py).
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
# `import jaxcable` (below, and in benchmarks/fit.py) turns on XLA's CPU loop kernels
# unless this says no, so `--xla-default` is read here, before it (argparse declares
# it too, for --help).
if "--xla-default" in sys.argv[1:]:
    os.environ["JAXCABLE_NO_LOOP_KERNELS"] = "1"

import jax  # noqa: E402


jax.config.update("jax_enable_x64", True)

import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import scipy  # noqa: E402
import scipy.optimize  # noqa: E402

# benchmarks/fit.py and numpy_baseline.py, beside this file: the timing helper and
# the machine's description.
from fit import _median, loop_kernels_on  # noqa: E402
from numpy_baseline import machine  # noqa: E402

import jaxcable as jc  # noqa: E402
from jaxcable._fit import problem as fit_problem, solver as fit_solver  # noqa: E402
from jaxcable._papers.park import park_protocol  # noqa: E402
from jaxcable._papers.synthetic import synthesize  # noqa: E402


NAMES = ("E1c", "E1r", "E2c", "t_c", "E2r", "t_r1", "E3r", "t_e")
START_FACTORS = (0.8, 1.2, 0.7, 1.5, 1.3, 0.7, 1.2, 0.8)
# (length mm, crosshead speed mm/min, peak force N) of each specimen's tests.
DESIGNS = ((100.0, 3.0, 100.0), (300.0, 50.0, 150.0), (300.0, 3.0, 150.0))
TARGETS = dict(vs_fit_loop=20.0, vs_scipy_loop=50.0, relative=1e-6, coverage=0.95)


def _parse():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--specimens", type=int, default=256)
    p.add_argument(
        "--loop-specimens",
        type=int,
        default=None,
        help="specimens the jaxcable.fit loop runs (default: all), scaled to all",
    )
    p.add_argument(
        "--scipy-specimens",
        type=int,
        default=None,
        help="specimens the scipy loop runs (default: all), scaled to all",
    )
    p.add_argument("--samples-per-ramp", type=int, default=90)
    p.add_argument("--repeats", type=int, default=1)
    p.add_argument("--json-out", default=None)
    p.add_argument(
        "--xla-default",
        action="store_true",
        help="XLA's default CPU loops instead of the loop kernels that "
        "`import jaxcable` turns on (JAXCABLE_NO_LOOP_KERNELS=1)",
    )
    return p.parse_args()


def _scaled(model, factors):
    return eqx.tree_at(
        lambda m: [getattr(m, n) for n in NAMES],
        model,
        [getattr(model, n) * f for n, f in zip(NAMES, factors)],
    )


def _specimens(n: int, samples_per_ramp: int):
    """(start model, truths, specimens)."""
    nominal = jc.IntegratedModel()
    nominal = eqx.tree_at(lambda m: m.E1r, nominal, 1.5 * nominal.E1c)
    rng = np.random.default_rng(0)
    truths, specimens = [], []
    for k in range(n):
        truth = _scaled(nominal, np.exp(0.1 * rng.standard_normal(len(NAMES))))
        tests = []
        for i, (length, rate, peak) in enumerate(DESIGNS):
            cable = jc.Cable(length=length * 1e-3, speed=rate * 1e-3 / 60)
            protocol = park_protocol(
                peak, samples_per_ramp=samples_per_ramp, rest_samples=19
            )
            tests.append(
                synthesize(
                    truth,
                    cable,
                    protocol,
                    seed=1000 * k + i,
                    force_noise=0.0,
                    metadata={"id": f"specimen{k}-L{length:g}-v{rate:g}-F{peak:g}"},
                )
            )
        truths.append(truth)
        specimens.append(tests)
    return _scaled(nominal, START_FACTORS), truths, specimens


def _scipy_loop(start, specimens, tol):
    """(seconds per specimen, fits, compile seconds) of scipy's trf with the jitted
    JAX residuals and Jacobian of each specimen's problem."""
    problems = [
        fit_problem.make_problem(start, tests, NAMES, None, None) for tests in specimens
    ]
    u_start = eqx.filter_jit(
        lambda problem, u: fit_solver._data_derived_start(problem, u)[0]
    )
    forward = eqx.filter_jit(lambda problem, u: jnp.ravel(problem.residuals(u)))
    jacobian = eqx.filter_jit(
        lambda problem, u: fit_solver.residuals_and_jacobian(problem, u, "fwd")[1]
    )

    def solve(problem, u_user):
        u0 = np.asarray(u_start(problem, u_user))
        scale = float(np.max(np.abs(np.asarray(problem.data.measured))))

        def residual(u):
            return np.asarray(forward(problem, jnp.asarray(u))) / scale

        def exact_jacobian(u):
            return np.asarray(jacobian(problem, jnp.asarray(u))) / scale

        sol = scipy.optimize.least_squares(
            residual, u0, jac=exact_jacobian, method="trf", ftol=tol, xtol=tol, gtol=tol
        )
        natural = np.asarray(problem.natural_flat(jnp.asarray(sol.x)))
        return natural, sol, float(np.sum((sol.fun * scale) ** 2))

    t0 = time.perf_counter()
    solve(*problems[0])
    compile_seconds = time.perf_counter() - t0
    t0 = time.perf_counter()
    fits = [solve(*p) for p in problems]
    return (time.perf_counter() - t0) / len(problems), fits, compile_seconds


def main():
    args = _parse()
    t0 = time.perf_counter()
    start, truths, specimens = _specimens(args.specimens, args.samples_per_ramp)
    synthesis_seconds = time.perf_counter() - t0
    n = len(specimens)
    problems = [jc.Problem(start, tests, fit=NAMES) for tests in specimens]
    method = jc.LeastSquares(multistart=1)
    warnings.simplefilter("ignore", jc.IdentifiabilityWarning)

    t0 = time.perf_counter()
    jc.fit_each(problems, method)
    each_first = time.perf_counter() - t0
    each_seconds, each = _median(lambda: jc.fit_each(problems, method), args.repeats)

    looped = problems[: args.loop_specimens or n]
    t0 = time.perf_counter()
    jc.fit(looped[0], method, throw=False)
    fit_compile = time.perf_counter() - t0
    t0 = time.perf_counter()
    loop = [jc.fit(problem, method, throw=False) for problem in looped]
    fit_per_specimen = (time.perf_counter() - t0) / len(looped)

    scipy_looped = specimens[: args.scipy_specimens or n]
    scipy_per_specimen, scipy_fits, scipy_compile = _scipy_loop(
        start, scipy_looped, 1e-10
    )

    relative = max(
        float(np.max(np.abs(a.values - b.values) / np.abs(b.values)))
        for a, b in zip(each, loop)
    )
    within = np.array(
        [
            [
                abs(v - float(getattr(t, name))) < 3 * s
                for name, v, s in zip(NAMES, r.values, r.stderr)
            ]
            for r, t in zip(each, truths)
        ]
    )
    steps = np.array([r.num_steps for r in each])
    # scipy's loss over jaxcable's, per specimen (m^2 / m^2).
    loss_ratio = np.array([loss / r.loss for (_, _, loss), r in zip(scipy_fits, each)])
    fit_loop_seconds = fit_per_specimen * n
    scipy_loop_seconds = scipy_per_specimen * n
    report = dict(
        problem=dict(
            model="IntegratedModel",
            fit=list(NAMES),
            specimens=n,
            tests_per_specimen=len(DESIGNS),
            samples_per_test=int(specimens[0][0].num_samples),
            multistart=1,
            synthesis_seconds=synthesis_seconds,
        ),
        fit_each=dict(
            seconds=each_seconds,
            first_call_seconds=each_first,
            steps_max=int(steps.max()),
            steps_mean=float(steps.mean()),
            converged=int(sum(r.converged for r in each)),
        ),
        fit_loop=dict(
            specimens_timed=len(looped),
            seconds_per_specimen=fit_per_specimen,
            seconds=fit_loop_seconds,
            scaled=len(looped) < n,
            compile_seconds=fit_compile - fit_per_specimen,
        ),
        scipy_loop=dict(
            specimens_timed=len(scipy_looped),
            seconds_per_specimen=scipy_per_specimen,
            seconds=scipy_loop_seconds,
            scaled=len(scipy_looped) < n,
            compile_seconds=scipy_compile - scipy_per_specimen,
            njev_mean=float(np.mean([sol.njev for _, sol, _ in scipy_fits])),
            nfev_mean=float(np.mean([sol.nfev for _, sol, _ in scipy_fits])),
            max_relative_parameter_difference_vs_fit_each=max(
                float(np.max(np.abs(x - r.values) / np.abs(r.values)))
                for (x, _, _), r in zip(scipy_fits, each)
            ),
            loss_over_fit_each_loss_max=float(loss_ratio.max()),
            loss_over_fit_each_loss_min=float(loss_ratio.min()),
        ),
        speedup_vs_fit_loop=fit_loop_seconds / each_seconds,
        speedup_vs_scipy_loop=scipy_loop_seconds / each_seconds,
        max_relative_difference_vs_fit=relative,
        within_3_stderr_all_parameters=float(np.mean(np.all(within, axis=1))),
        within_3_stderr_per_parameter=dict(
            zip(NAMES, (float(x) for x in np.mean(within, axis=0)))
        ),
        targets=TARGETS,
        machine=dict(
            machine("float64"),
            scipy=scipy.__version__,
            jaxcable=jc.__version__,
            openblas_threads=os.environ.get("OPENBLAS_NUM_THREADS"),
            xla_flags=os.environ.get("XLA_FLAGS", ""),
        ),
        repeats=args.repeats,
        loop_kernels=loop_kernels_on(),
    )
    print(json.dumps(report, indent=2))
    p, e = report["problem"], report["fit_each"]
    print()
    print(
        f"{n} specimens x {p['tests_per_specimen']} tests x {p['samples_per_test']} "
        f"samples, {len(NAMES)} parameters; fit_each steps max {e['steps_max']}, "
        f"mean {e['steps_mean']:.1f}; first call {e['first_call_seconds']:.1f} s"
    )
    print(
        f"{'method':<12} {'specimens timed':>16} {'time s':>10} {'fit_each x faster':>18}"
    )
    print(f"{'fit_each':<12} {n:>16} {each_seconds:>10.2f} {'':>18}")
    for label, row in (("fit loop", "fit_loop"), ("scipy loop", "scipy_loop")):
        r = report[row]
        scaled = " (scaled)" if r["scaled"] else ""
        print(
            f"{label:<12} {r['specimens_timed']:>16} {r['seconds']:>10.2f} "
            f"{r['seconds'] / each_seconds:>18.1f}{scaled}"
        )
    print(
        f"parameters vs own fit: max relative difference {relative:.2e} "
        f"(target {TARGETS['relative']:g}); truth within 3 SE (all 8): "
        f"{100 * report['within_3_stderr_all_parameters']:.1f} % "
        f"(target {100 * TARGETS['coverage']:g} %)"
    )
    if args.json_out:
        with open(args.json_out, "w") as f:
            json.dump(report, f, indent=2)


if __name__ == "__main__":
    main()
