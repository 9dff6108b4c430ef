"""Random-draw sweep of the rate-driven solve: every failure classified, and checked.

Draws Park-model cables far from the defaults and runs each through the three drives:

- a rate-driven test (`jaxcable.simulate_rate_test`): two load-unload cycles to a
  peak force with a 60 s hold, 50 samples per ramp;
- the force history that test produced (`simulate_force_history`): its strains must
  be the rate test's, sample by sample;
- the elongation history it produced (`simulate_elongation_history`): the forces
  solved from it must be the rate test's.

Draws: each `IntegratedModel` parameter times a log-uniform factor in [0.3, 3] (the
sign of `lambda2` kept), length log-uniform in [0.1, 10] m, crosshead speed
log-uniform in [1, 1000] mm/min, peak force uniform in [5, 60] % of the breaking
load (2000 N).

Each rate test also runs on the robust path alone (one Newton step, then its loops:
`jaxcable.Newton(tol, unrolled=1, two_pass=False)`) and in two passes
(`two_pass=True`, as on an accelerator): the default's verdict must be theirs, and
its successful trajectories within 1e-10 of the robust path's peak.

Every rate test that fails is checked independently of the solver: the residual of
Park Eq. 6 at the first failing sample is evaluated on a grid of 400 loading times
(crosshead strains 1e-9 to 1e4) and its crossings of zero in the wanted direction
(the crosshead catching up with the cable on a loading ramp) counted. A verdict of
`unreachable_force` with a sign change on that grid, or a `newton_failed` without
one, is counted as misclassified.

    python scripts/sweep_draws.py --draws 100000 --out sweep.json

Prints a JSON summary and a table; exits 1 if a value is non-finite without a
failure status, a failure is misclassified, a verdict differs from the robust path's
or the two-pass one's, or the elongation history of a
successful rate test gives other forces (by more than 1e-6 of the peak) without a
failure status.
"""

import argparse
import dataclasses
import json
import math
import sys
import time

import equinox as eqx
import jax


jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import jaxcable as jc  # noqa: E402
from jaxcable._drive import Solve  # noqa: E402
from jaxcable._drive.drives import (  # noqa: E402
    _STRAIN_FLOOR,
    RateDrive,
    _time_residual,
    _TimeProblem,
    default_solver,
)


# Every field of the model is a parameter (the model's own list, not a copy).
PARAMETERS = tuple(f.name for f in dataclasses.fields(jc.IntegratedModel))
ROBUST_SOLVER = jc.Newton(tol=1e-12, unrolled=1, two_pass=False)
TWO_PASS_SOLVER = jc.Newton(tol=1e-12, two_pass=True)
PROTOCOL = jc.Protocol.cycles(1.0, cycles=2, samples_per_ramp=50, hold=60.0)
GRID = jnp.asarray(np.concatenate([[0.0], np.logspace(-9, 4, 399)]))
NAMES = [name for name in jc.RESULTS._name_to_item]  # noqa: SLF001


def draw(rng, n):
    base = jc.IntegratedModel()
    factor = lambda: np.exp(rng.uniform(np.log(0.3), np.log(3.0), n))  # noqa: E731
    params = {k: float(getattr(base, k)) * factor() for k in PARAMETERS}
    return dict(
        params=params,
        length_mm=1000 * np.exp(rng.uniform(np.log(0.1), np.log(10.0), n)),
        rate_mm_per_min=np.exp(rng.uniform(np.log(1.0), np.log(1000.0), n)),
        peak=rng.uniform(0.05, 0.6, n),
    )


def code(result):
    return result._value  # noqa: SLF001


def one(params, length_mm, rate_mm_per_min, peak):
    model = jc.IntegratedModel(**params)
    # No breaking strain: the sweep checks the solver's verdicts, which a break (a
    # strain beyond Cable.breaking_strain, checked after them) would hide.
    cable = jc.Cable.from_mm(
        length_mm=length_mm, rate_mm_per_min=rate_mm_per_min, breaking_strain=math.inf
    )
    protocol = eqx.tree_at(
        lambda p: p.force, PROTOCOL, PROTOCOL.force * peak * cable.breaking_load
    )
    rate = jc.simulate_rate_test(
        model, cable, protocol, method=jc.Simulation(throw=False)
    )
    robust = jc.simulate_rate_test(
        model, cable, protocol, method=jc.Simulation(solver=ROBUST_SOLVER, throw=False)
    )
    two_pass = jc.simulate_rate_test(
        model,
        cable,
        protocol,
        method=jc.Simulation(solver=TWO_PASS_SOLVER, throw=False),
    )

    # The solver-free check: the state before each sample, from the same drive.
    drive = RateDrive(protocol, default_solver(jnp.float64))
    state0, samples = drive.init(model, cable)

    def body(state, sample):
        new, _, _ = drive.step(model, cable, state, sample, Solve("robust"))
        return new, (state, code(new.result))

    _, (before, results) = jax.lax.scan(body, state0, samples)
    k = jnp.argmax(results != code(jc.RESULTS.successful))
    state = jax.tree_util.tree_map(lambda a: a[k], before)
    sample = jax.tree_util.tree_map(lambda a: a[k], samples)
    problem = _TimeProblem(
        model,
        cable,
        state,
        sample.force,
        sample.direction,
        sample.duration,
        jnp.abs(state.strain) + _STRAIN_FLOOR,
    )
    residual = jax.vmap(lambda dt: _time_residual(dt, problem)[0])(
        GRID / cable.strain_rate
    )
    # A root in the solver's sense: a crossing from "not reached" (r * s < 0) to
    # "past" (r * s > 0) as dt grows, s the sign of the residual's slope the drive
    # asks for (-1 on a loading ramp, +1 unloading).
    q = residual * jnp.where(sample.direction != 0, -sample.direction, 1)
    has_root = jnp.any(q == 0) | jnp.any((q[:-1] < 0) & (q[1:] > 0))

    # The same history through the two other entry points.
    ok = rate.result == jc.RESULTS.successful
    time_ = jnp.where(ok, rate.time, jnp.arange(rate.time.shape[0], dtype=float))
    force = jnp.where(ok, rate.force, 0.0)
    by_force = jc.simulate_force_history(
        model, cable, time_, force, method=jc.Simulation(throw=False)
    )
    by_elongation = jc.simulate_elongation_history(
        model,
        cable,
        time_,
        jnp.where(ok, rate.elongation, 0.0),
        method=jc.Simulation(throw=False),
    )
    scale_f = peak * cable.breaking_load
    both_ok = (rate.result == jc.RESULTS.successful) & (
        robust.result == jc.RESULTS.successful
    )
    peak = jnp.max(jnp.abs(jnp.where(both_ok, robust.elongation, 1.0)))
    return dict(
        rate=code(rate.result),
        robust=code(robust.result),
        two_pass=code(two_pass.result),
        robust_err=jnp.where(
            both_ok, jnp.max(jnp.abs(rate.elongation - robust.elongation)) / peak, 0.0
        ),
        rate_finite=jnp.all(jnp.isfinite(rate.time) & jnp.isfinite(rate.strain)),
        scan_agrees=results[-1] == code(rate.result),
        has_root=has_root,
        max_strain=jnp.max(jnp.abs(jnp.where(ok, rate.strain, 0.0))),
        force=code(by_force.result),
        force_finite=jnp.all(jnp.isfinite(by_force.strain)),
        force_strain_err=jnp.max(jnp.abs(by_force.strain - rate.strain)),
        elongation=code(by_elongation.result),
        elongation_finite=jnp.all(jnp.isfinite(by_elongation.force)),
        elongation_force_err=jnp.max(jnp.abs(by_elongation.force - rate.force))
        / scale_f,
    )


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--draws", type=int, default=100_000)
    parser.add_argument("--chunk", type=int, default=5000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", default=None, help="write the JSON summary here")
    args = parser.parse_args(argv)

    rng = np.random.default_rng(args.seed)
    run = jax.jit(jax.vmap(one))
    outs = []
    start = time.perf_counter()
    for lo in range(0, args.draws, args.chunk):
        n = min(args.chunk, args.draws - lo)
        d = draw(rng, n)
        if n < args.chunk:  # one shape for every chunk: no retracing
            d = jax.tree_util.tree_map(
                lambda a: np.concatenate([a, np.repeat(a[-1:], args.chunk - n)]), d
            )
        out = jax.device_get(
            run(d["params"], d["length_mm"], d["rate_mm_per_min"], d["peak"])
        )
        outs.append({k: np.asarray(v)[:n] for k, v in out.items()})
    seconds = time.perf_counter() - start
    o = {k: np.concatenate([x[k] for x in outs]) for k in outs[0]}

    def counts(codes):
        return {NAMES[c]: int(np.sum(codes == c)) for c in np.unique(codes)}

    rate_ok = o["rate"] == 0
    unreachable = o["rate"] == NAMES.index("unreachable_force")
    newton = o["rate"] == NAMES.index("newton_failed")
    silent = dict(
        rate=int(np.sum(rate_ok & ~o["rate_finite"])),
        force=int(np.sum((o["force"] == 0) & ~o["force_finite"])),
        elongation=int(np.sum((o["elongation"] == 0) & ~o["elongation_finite"])),
    )
    summary = dict(
        draws=args.draws,
        seed=args.seed,
        seconds=round(seconds, 1),
        rate_results=counts(o["rate"]),
        numerical_failure_percent=round(100 * float(np.mean(newton)), 3),
        misclassified=dict(
            unreachable_with_root=int(np.sum(unreachable & o["has_root"])),
            newton_failed_without_root=int(np.sum(newton & ~o["has_root"])),
        ),
        silent_nonfinite=silent,
        verdict_differs=dict(
            from_robust=int(np.sum(o["rate"] != o["robust"])),
            from_two_pass=int(np.sum(o["rate"] != o["two_pass"])),
        ),
        max_difference_from_robust_of_peak=float(o["robust_err"].max()),
        scan_disagrees=int(np.sum(~o["scan_agrees"])),
        on_successful_rate_tests=dict(
            count=int(rate_ok.sum()),
            force_history_results=counts(o["force"][rate_ok]),
            elongation_history_results=counts(o["elongation"][rate_ok]),
            max_strain=float(o["max_strain"][rate_ok].max(initial=0.0)),
            force_history_max_strain_error=float(
                o["force_strain_err"][rate_ok].max(initial=0.0)
            ),
            elongation_history_max_force_error_rel=float(
                o["elongation_force_err"][rate_ok & (o["elongation"] == 0)].max(
                    initial=0.0
                )
            ),
            # Successful both ways, yet forces apart by more than 1e-6 of the peak:
            # a silently different answer from another entry point.
            elongation_history_disagreements=int(
                np.sum(
                    rate_ok
                    & (o["elongation"] == 0)
                    & (o["elongation_force_err"] > 1e-6)
                )
            ),
        ),
    )
    print(json.dumps(summary, indent=2))
    print()
    print(f"{'rate-test result':<24}{'draws':>10}{'%':>9}")
    for name, c in summary["rate_results"].items():
        print(f"{name:<24}{c:>10}{100 * c / args.draws:>9.3f}")
    print(f"misclassified: {summary['misclassified']}")
    print(f"silent non-finite: {silent}")
    print(f"verdict differs: {summary['verdict_differs']}")
    print(
        "largest difference from the robust path: "
        f"{summary['max_difference_from_robust_of_peak']:.2e} of the peak"
    )
    if args.out:
        with open(args.out, "w") as f:
            json.dump(summary, f, indent=2)
    bad = (
        sum(silent.values())
        + sum(summary["misclassified"].values())
        + summary["on_successful_rate_tests"]["elongation_history_disagreements"]
        + sum(summary["verdict_differs"].values())
        + (summary["max_difference_from_robust_of_peak"] > 1e-10)
    )
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
