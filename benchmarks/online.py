"""A robot that calibrates its own cables, in a scenario that does not flatter it: the
8-cable robot of `jaxcable.cdpr` compensated by its online estimator
(`jaxcable.cdpr.OnlineEstimator` in `jaxcable.cdpr.simulate_online`), against the
nominal compensation and an oracle, over `--draws` draws of the real cables; the cost
of one estimator step; a day-long log fitted in bounded memory.

    python benchmarks/online.py [--draws 20] [--hours 2] [--day-samples 8640000]
        [--no-fix-draws N] [--drift D] [--json-out FILE]

**The scenario (per draw).** The pick-and-place of `jaxcable.cdpr.pick_and_place`
(`--hours`, 1 Hz). The real cables (`jaxcable.cdpr.real_cables`): every parameter of
the integrated model drawn log-normally with 30 % around the defaults, a termination
compliance of 2e-5 m/N (4 mm at 200 N on every cable, in no model of the
controller's), and a rope already bedded in on cables 1, 4 and 6 (E1r = 1.5 E1c). The
sensors (`jaxcable.cdpr.scenario.real_sensors`): load cells with 0.5 N of white noise
and a linear drift (rate drawn with 1 N/h standard deviation per cell), a position fix
every 10 s with 0.5 mm of noise per coordinate, one dropout of the fixes (10 minutes
from 55 % of the run; a sixth of the run when that is shorter) and load cell 2 stuck
for 60 s (from 25 % of the run).

**The compensations compared.** `nominal`: `jaxcable.cdpr.simulate_robot` with the
nominal model (exact forces: the library's own baseline). `online`: the estimator on
the imperfect sensors, learning (`--estimated terminations`, `TERMINATIONS`) seven
moduli and times of each cable (E1c, E1r, E3r, t_e, E2r, t_r1, E2c) and the
compliance of its terminations from a prior median of 1e-5 m/N (half the real one,
log standard deviation 1), its other options its defaults (a moving-horizon solve
every 600 samples over up to 7200); `--estimated default` learns the estimator's
default set (E1c, E1r, E3r, t_e; no compliance). `oracle`: the real cables' own
model, their true parameters and the termination compliance, predicting from the
same load-cell readings (noise, drift, the stuck cell) at the desired position's free
lengths: the best a compensation that knows the cables exactly can do with the
signals and the control law of the robot. `no_fix`: the estimator with no position
fix at all (geometry and load cells only; the first `--no-fix-draws` draws).

**Reported per draw:** the RMS position error (mm) over the second half of the run
(the second hour of 2 h) of each; `covered_95`, the share of the identified
parameters (those whose posterior standard deviation fell below half the prior's)
whose 95 % interval holds the truth, the others listed apart; `parameters`
(estimates, intervals, truth); the reduced chi-square of the fixes at the last
solve; the failures: divergence, `RESULTS.signal_lost` during the dropout and the
stuck cell, the time to `RESULTS.successful` after each, and the position error
around each (the RMS over the 10 minutes before, the worst 60 s RMS in the 5 minutes
after, and when the 60 s RMS first fell back below 1.5 times the one before).

**Coverage by load-cell error** (`--cause-draws` other draws, no dropout, no stuck
cell): the same share with exact load cells, with their noise only, with their
drift only, and with both: which error of the signals the intervals do not hold.

**Costs.** `step_us`: one estimator step for 8 cables, float64, CPU: the median per
call of a jitted step called from Python, and the total time of a jitted `lax.scan` of
steps divided by its samples; `step.solve`: one step that runs the horizon's solve
over an hour of samples (ms). `loop_seconds`: the 2 h closed loop (the compiling first
call apart). `day_log`: `benchmarks/day_log.py`'s worker (`jaxcable.fit` with
`jaxcable.StreamingLeastSquares`) on `--day-samples` samples at 100 Hz in a fresh
process: seconds and peak RSS.
"""

import argparse
import functools
import json
import os
import platform
import statistics
import subprocess
import sys
import time

import jax


jax.config.update("jax_enable_x64", True)

import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import jaxcable as jc  # noqa: E402
from jaxcable import cdpr  # noqa: E402
from jaxcable.cdpr.scenario import real_sensors  # noqa: E402


ROBOT = cdpr.Robot()
RELATIVE_STD = 0.3
COMPLIANCE = 2e-5
BEDDED_IN = (1, 4, 6)
STUCK_CABLE = 2
RECOVERY_S = 300.0
# What the robot's estimator learns (`--estimated terminations`): the moduli and
# times of the integrated model that a robot's fixes identify, and the compliance of
# the terminations (splices, the drum), which no compensation model has: its prior
# median 1e-5 m/N, half the real one, a factor e either way.
DRIFT_PRIOR = 2.0  # N/h: twice the drift rates' standard deviation
LEARNT = ("E1c", "E1r", "E3r", "t_e", "E2r", "t_r1", "E2c")
TERMINATIONS = dict(
    model=jc.TerminationCompliance(cdpr.NOMINAL, jnp.asarray(1e-5)),
    parameters=tuple(f"base.{name}" for name in LEARNT) + ("compliance",),
    prior_std=(RELATIVE_STD,) * len(LEARNT) + (1.0,),
)


def _parse():
    p = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    p.add_argument("--draws", type=int, default=20)
    p.add_argument("--hours", type=float, default=2.0)
    p.add_argument("--day-samples", type=int, default=8_640_000)
    p.add_argument(
        "--no-fix-draws", type=int, default=None, help="draws run without fixes"
    )
    p.add_argument("--seed", type=int, default=0)
    p.add_argument(
        "--drift",
        type=float,
        default=None,
        help="the estimator's random walk of the logs, 1/sqrt(s) (default: its own)",
    )
    p.add_argument(
        "--estimated",
        choices=("terminations", "drift", "default"),
        default="terminations",
        help="the estimated parameters: TERMINATIONS, with the load cells' drift "
        "too, or the estimator's defaults",
    )
    p.add_argument(
        "--cause-draws",
        type=int,
        default=6,
        help="draws of the coverage by load-cell error (exact, noise, drift, both)",
    )
    p.add_argument("--step-samples", type=int, default=600)
    p.add_argument("--repeats", type=int, default=300)
    p.add_argument("--json-out", default=None)
    return p.parse_args()


def _events(hours: float):
    span = hours * 3600.0
    dropout = (0.55 * span, min(600.0, span / 6))
    stuck = (STUCK_CABLE, 0.25 * span, 60.0)
    return dropout, stuck


@eqx.filter_jit
def _oracle(robot, scenario, real, sensors):
    """The closed loop of `simulate_online` with the real cables' own model (true
    parameters, per cable) as the compensation, fed with the load cells' readings."""
    x0, t0 = scenario.position[0], scenario.time[0]
    lengths0 = robot.free_lengths(x0)
    init = jc.controller_init(real, robot.cables(lengths0), t0, per_cable=True)
    carry = (init, init, x0, jnp.zeros_like(lengths0))

    def body(carry, sample):
        ctrl, real_state, x, last = carry
        t, x_d, payload, force_error, stuck = sample
        forces = cdpr.tension_distribution(robot, x, robot.platform_mass + payload)
        reading = jnp.where(stuck, last, forces + force_error)
        lengths = robot.free_lengths(x_d)
        ctrl, predicted = jc.controller_step(
            real, robot.cables(lengths), ctrl, t, reading, throw=False
        )
        command = lengths - predicted
        real_state, elongation = jc.controller_step(
            real, robot.cables(command), real_state, t, forces
        )
        x = cdpr.forward_kinematics(robot, command + elongation - robot.routing, x)
        return (ctrl, real_state, x, reading), x

    xs = (
        scenario.time,
        scenario.position,
        scenario.payload,
        sensors.force_error,
        sensors.stuck,
    )
    _, position = jax.lax.scan(body, carry, xs)
    return position


def _rms_mm(error, mask) -> float:
    return 1e3 * float(np.sqrt(np.mean(np.sum(np.asarray(error)[mask] ** 2, axis=-1))))


def _truth(estimator, real, scenario, sensors) -> np.ndarray:
    """The real cables' values of the estimated parameters, `(n, p)`: a name of the
    integrated model is looked up in the real cables' base model, a dotted one
    (`base.E1c`, `compliance`) in the real cables' wrapped model; a load cell's drift
    rate (N/h) is the slope of its errors."""
    values = []
    for name in estimator.parameters:
        if name == "load_cell_drift":
            t, error = np.asarray(scenario.time), np.asarray(sensors.force_error)
            values.append(3600.0 * np.polyfit(t, error, 1)[0])
            continue
        owner = real if "." in name or name == "compliance" else real.base
        values.append(np.asarray(functools.reduce(getattr, name.split("."), owner)))
    return np.stack(values, axis=1)


def _identified(estimator, state) -> np.ndarray:
    """The parameters the data identify: a posterior standard deviation below half
    the prior's, `(n, p)` booleans."""
    prior = np.sqrt(np.asarray(estimator.prior_variance))[None, :]
    return np.asarray(state.std) < 0.5 * prior


def _recovery(t, code, start, end, successful) -> dict:
    """Whether `signal_lost` was reported in [start + grace, end) and how long after
    `end` the estimator was successful again (s; None if never)."""
    lost = int(jc.RESULTS.signal_lost._value)  # noqa: SLF001
    during = (t >= start) & (t < end)
    after = np.nonzero((t >= end) & (code == successful))[0]
    return dict(
        start_s=float(start),
        end_s=float(end),
        lost_share=float(np.mean(code[during] == lost)) if during.any() else 0.0,
        recovered_after_s=float(t[after[0]] - end) if after.size else None,
    )


def _settling(t, error, start, end, span=60.0) -> dict:
    """The position error around an event: the RMS over the 10 minutes before it,
    the largest RMS over `span` seconds after it ends, and how long after its end
    the `span`-second RMS first falls back below 1.5 times the one before (s)."""
    norm = np.linalg.norm(np.asarray(error), axis=-1)
    before = np.sqrt(np.mean(norm[(t >= start - 600.0) & (t < start)] ** 2))
    ends = t[(t >= end) & (t <= end + 1800.0)]
    moving = np.array(
        [np.sqrt(np.mean(norm[(t >= e) & (t < e + span)] ** 2)) for e in ends]
    )
    back = np.nonzero(moving <= 1.5 * before)[0]
    return dict(
        rms_before_mm=1e3 * float(before),
        rms_after_max_mm=1e3 * float(moving[: int(300 / max(t[1] - t[0], 1e-9))].max())
        if moving.size
        else None,
        settled_after_s=float(ends[back[0]] - end) if back.size else None,
    )


def _code(result) -> np.ndarray:
    return np.asarray(result._value)  # noqa: SLF001


def _run_draw(draw, key, scenario, estimator, hours, no_fix: bool) -> dict:
    dropout, stuck = _events(hours)
    k_real, k_sensors = jax.random.split(key)
    real = cdpr.real_cables(
        k_real,
        relative_std=RELATIVE_STD,
        compliance=COMPLIANCE,
        bedded_in=BEDDED_IN,
    )
    sensors = real_sensors(
        k_sensors, scenario, ROBOT.num_cables, dropouts=(dropout,), stuck=(stuck,)
    )
    t = np.asarray(scenario.time)
    late = t >= t[0] + 0.5 * (t[-1] - t[0])
    t0 = time.perf_counter()
    online = cdpr.simulate_online(estimator, scenario, real, sensors)
    jax.block_until_ready(online)
    loop_seconds = time.perf_counter() - t0
    nominal = cdpr.simulate_robot(ROBOT, scenario, real, cdpr.NOMINAL)
    oracle = _oracle(ROBOT, scenario, real, sensors)
    state = online.state
    truth = _truth(estimator, real, scenario, sensors)
    low, high = (np.asarray(a) for a in state.interval())
    std = np.asarray(state.std)
    identified = _identified(estimator, state)
    covers = np.asarray(cdpr.interval_covers(state, truth))
    code = _code(online.result)
    ok = int(jc.RESULTS.successful._value)  # noqa: SLF001
    diverged = int(jc.RESULTS.estimator_diverged._value)  # noqa: SLF001
    names = list(estimator.parameters)
    row = dict(
        draw=draw,
        rms_nominal_mm=_rms_mm(nominal.error, late),
        rms_online_mm=_rms_mm(online.run.error, late),
        rms_oracle_mm=_rms_mm(oracle - scenario.position, late),
        covered_95=float(np.mean(covers[identified])) if identified.any() else None,
        parameters=dict(
            names=names,
            estimate=np.asarray(state.parameters).tolist(),
            low_95=low.tolist(),
            high_95=high.tolist(),
            truth=truth.tolist(),
            relative_std=std.tolist(),
            identified=identified.tolist(),
            not_identified=[
                f"cable {i} {names[j]}" for i, j in zip(*np.nonzero(~identified))
            ],
            covered=covers.tolist(),
            bedded_in=list(BEDDED_IN),
        ),
        identified=int(identified.sum()),
        covered=int((covers & identified).sum()),
        diverged=bool(np.any(code == diverged)),
        final_result=str(state.result) or "successful",
        dropout=_recovery(t, code, dropout[0] + 61.0, sum(dropout), ok)
        | _settling(t, online.run.error, dropout[0], sum(dropout)),
        stuck=_recovery(t, code, stuck[1] + 31.0, stuck[1] + stuck[2], ok)
        | _settling(t, online.run.error, stuck[1], stuck[1] + stuck[2]),
        reduced_chi2=float(state.reduced_chi2),
        loop_seconds=loop_seconds,
    )
    if no_fix:
        blind = eqx.tree_at(lambda s: s.fix, sensors, jnp.zeros_like(sensors.fix))
        run = cdpr.simulate_online(estimator, scenario, real, blind)
        row["rms_no_fix_mm"] = _rms_mm(run.run.error, late)
        row["no_fix_diverged"] = bool(np.any(_code(run.result) == diverged))
    return row


def _step_us(estimator, scenario, samples: int, repeats: int) -> dict:
    """One estimator step for the robot's cables: jitted scan / samples and the
    median jitted call from Python."""
    scenario = scenario[: samples + 1]
    real = cdpr.real_cables(jax.random.key(99), relative_std=RELATIVE_STD)
    sensors = real_sensors(jax.random.key(98), scenario, ROBOT.num_cables)
    run = cdpr.simulate_online(estimator, scenario, real, sensors).run
    lengths = jax.vmap(ROBOT.free_lengths)(scenario.position)
    fixes = cdpr.Fix(
        run.position + sensors.fix_error, run.command, jnp.asarray(sensors.fix)
    )
    x0 = scenario.position[0]
    state0 = estimator.init(lengths[0], x0, scenario.time[0])
    xs = (scenario.time[1:], run.forces[1:], lengths[1:])
    fix_xs = jax.tree.map(lambda a: a[:-1], fixes)

    @jax.jit
    def scan(state, xs, fix_xs):
        def body(s, sample):
            (t, f, length), fix = sample
            return estimator.step(s, t, f, length, fix)

        return jax.lax.scan(body, state, (xs, fix_xs))

    jax.block_until_ready(scan(state0, xs, fix_xs))
    scan_times = []
    for _ in range(5):
        t0 = time.perf_counter()
        jax.block_until_ready(scan(state0, xs, fix_xs))
        scan_times.append(time.perf_counter() - t0)
    step = jax.jit(lambda s, *args: estimator.step(s, *args))
    state = state0
    per_call = []
    for k in range(min(repeats, samples)):
        args = (xs[0][k], xs[1][k], xs[2][k], jax.tree.map(lambda a: a[k], fix_xs))
        if k < 20:  # warm-up
            state, _ = jax.block_until_ready(step(state, *args))
            continue
        t0 = time.perf_counter()
        state, _ = jax.block_until_ready(step(state, *args))
        per_call.append(time.perf_counter() - t0)
    return dict(
        scan_us=1e6 * statistics.median(scan_times) / samples,
        call_us=1e6 * statistics.median(per_call),
        call_p90_us=1e6 * float(np.percentile(per_call, 90)),
        samples=samples,
        dtype=str(state0.log_parameters.dtype),
    )


def _solve_ms(estimator, hours: float = 1.0) -> dict:
    """One step that runs the horizon's solve, after `hours` of samples (the
    window then holds them all): ms, the median of 3 jitted calls on the same
    state."""
    scenario = cdpr.pick_and_place(hours=hours)
    real = cdpr.real_cables(jax.random.key(97), relative_std=RELATIVE_STD)
    sensors = real_sensors(jax.random.key(96), scenario, ROBOT.num_cables)
    sensors = jax.tree.map(lambda a: a[:-1], sensors)
    run = cdpr.simulate_online(estimator, scenario[:-1], real, sensors)
    state = run.state
    step = jax.jit(lambda s, *args: estimator.step(s, *args))
    lengths = ROBOT.free_lengths(scenario.position[-1])
    args = (scenario.time[-1], run.run.forces[-1], lengths, cdpr.Fix.missing(lengths))
    jax.block_until_ready(step(state, *args))
    times = []
    for _ in range(3):
        t0 = time.perf_counter()
        jax.block_until_ready(step(state, *args))
        times.append(time.perf_counter() - t0)
    return dict(
        ms=1e3 * statistics.median(times),
        window_samples=int(state.window.count),
        due=bool(state.window.since >= estimator.every),
        passes=estimator.iterations + 2,
    )


def _coverage_by_cause(estimator, scenario, draws: int) -> dict:
    """The share of identified parameters covered by their 95 % intervals at the
    end of the run, by the load cells' errors (no dropout, no stuck cell): exact,
    0.5 N of noise, the drift, both."""
    causes = dict(
        exact=dict(force_noise=0.0, force_drift=0.0),
        noise=dict(force_drift=0.0),
        drift=dict(force_noise=0.0),
        both={},
    )
    out = {}
    for name, options in causes.items():
        covered = identified = 0
        for d in range(draws):
            k_real, k_sensors = jax.random.split(jax.random.key(1000 + d))
            real = cdpr.real_cables(
                k_real,
                relative_std=RELATIVE_STD,
                compliance=COMPLIANCE,
                bedded_in=BEDDED_IN,
            )
            sensors = real_sensors(k_sensors, scenario, ROBOT.num_cables, **options)
            state = cdpr.simulate_online(estimator, scenario, real, sensors).state
            truth = _truth(estimator, real, scenario, sensors)
            ident = _identified(estimator, state)
            identified += int(ident.sum())
            covers = np.asarray(cdpr.interval_covers(state, truth))
            covered += int((ident & covers).sum())
        out[name] = dict(
            draws=draws,
            identified=identified,
            covered=covered,
            share=covered / identified if identified else None,
        )
        print(f"coverage, load cells {name}: {out[name]}", file=sys.stderr, flush=True)
    return out


def _day_log(samples: int) -> dict:
    script = os.path.join(os.path.dirname(os.path.abspath(__file__)), "day_log.py")
    done = subprocess.run(
        [sys.executable, script, "--worker", str(samples)],
        capture_output=True,
        text=True,
    )
    if done.returncode != 0:
        return dict(samples=samples, error=done.stderr[-2000:])
    row = json.loads(done.stdout.strip().splitlines()[-1])
    return dict(
        samples=row["samples"],
        seconds=row["seconds"],
        peak_rss_mb=row["peak_rss_mb"],
        steps=row.get("steps"),
        result=row.get("result"),
    )


def _targets(rows, step, loop_seconds, day) -> dict:
    n = len(rows)
    good = [
        r["rms_online_mm"] <= 1.5 * r["rms_oracle_mm"]
        and r["rms_online_mm"] <= 0.2 * r["rms_nominal_mm"]
        for r in rows
    ]
    identified = sum(r["identified"] for r in rows)
    covered = sum(r["covered"] for r in rows)
    failures_ok = [
        not r["diverged"]
        and r[e]["lost_share"] > 0.99
        and r[e]["recovered_after_s"] is not None
        and r[e]["recovered_after_s"] <= RECOVERY_S
        for r in rows
        for e in ("dropout", "stuck")
    ]
    coverage = covered / identified if identified else None
    return dict(
        accuracy=dict(
            met=sum(good) >= int(np.ceil(0.9 * n)),
            draws_meeting=sum(good),
            draws=n,
            required=int(np.ceil(0.9 * n)),
        ),
        coverage=dict(
            met=coverage is not None and coverage >= 0.9,
            covered=covered,
            identified=identified,
            share=coverage,
        ),
        failures=dict(met=all(failures_ok), ok=sum(failures_ok), of=len(failures_ok)),
        step=dict(met=step["call_us"] <= 1000.0 and step["scan_us"] <= 1000.0),
        loop=dict(met=loop_seconds is not None and loop_seconds <= 60.0),
        day_log=dict(met=day.get("peak_rss_mb", np.inf) <= 2048.0),
    )


def main():
    args = _parse()
    scenario = cdpr.pick_and_place(hours=args.hours)
    options = {} if args.drift is None else dict(drift=args.drift)
    if args.estimated in ("terminations", "drift"):
        options |= TERMINATIONS
    if args.estimated == "drift":
        options["parameters"] += ("load_cell_drift",)
        options["prior_std"] += (DRIFT_PRIOR,)
    estimator = cdpr.OnlineEstimator(ROBOT, **options)
    no_fix_draws = args.draws if args.no_fix_draws is None else args.no_fix_draws
    keys = jax.random.split(jax.random.key(args.seed), args.draws)
    rows = []
    t_all = time.perf_counter()
    for d in range(args.draws):
        row = _run_draw(d, keys[d], scenario, estimator, args.hours, d < no_fix_draws)
        rows.append(row)
        print(
            f"draw {d}: nominal {row['rms_nominal_mm']:.2f} online "
            f"{row['rms_online_mm']:.2f} oracle {row['rms_oracle_mm']:.2f} mm "
            f"no-fix {row.get('rms_no_fix_mm', float('nan')):.2f} covered "
            f"{row['covered']}/{row['identified']} loop {row['loop_seconds']:.1f} s",
            file=sys.stderr,
            flush=True,
        )
    loops = [r["loop_seconds"] for r in rows[1:]] or [rows[0]["loop_seconds"]]
    loop_seconds = statistics.median(loops) * 2.0 / args.hours
    step = _step_us(estimator, scenario, args.step_samples, args.repeats)
    step["solve"] = _solve_ms(estimator)
    causes = _coverage_by_cause(estimator, scenario, args.cause_draws)
    day = _day_log(args.day_samples)
    no_fix = [r for r in rows if "rms_no_fix_mm" in r]
    out = dict(
        rows=rows,
        step_us=step["call_us"],
        step=step,
        day_log=day,
        loop_seconds=loop_seconds,
        loop=dict(
            hours=args.hours,
            first_call_s=rows[0]["loop_seconds"],
            median_s=statistics.median(loops),
            scaled_to_2h_s=loop_seconds,
        ),
        coverage_by_load_cell_error=causes,
        no_fix=dict(
            draws=len(no_fix),
            rms_no_fix_mm=[r["rms_no_fix_mm"] for r in no_fix],
            median_gain_over_nominal=statistics.median(
                [1.0 - r["rms_no_fix_mm"] / r["rms_nominal_mm"] for r in no_fix]
            )
            if no_fix
            else None,
        ),
        targets=_targets(rows, step, loop_seconds, day),
        setup=dict(
            hours=args.hours,
            draws=args.draws,
            relative_std=RELATIVE_STD,
            compliance_m_per_N=COMPLIANCE,
            bedded_in=list(BEDDED_IN),
            events=dict(zip(("dropout", "stuck"), _events(args.hours))),
            estimator=dict(
                parameters=list(estimator.parameters),
                model=type(estimator.model).__name__,
                prior_std=estimator.prior_std,
                drift=estimator.drift,
                fix_noise=estimator.fix_noise,
                window=estimator.window,
                every=estimator.every,
                iterations=estimator.iterations,
            ),
            oracle="the real cables' model and true parameters (termination "
            "compliance included) predicting from the load cells' readings",
            total_seconds=time.perf_counter() - t_all,
        ),
        machine=dict(
            platform=platform.platform(),
            cpu_count=os.cpu_count(),
            python=platform.python_version(),
            jax=jax.__version__,
        ),
    )
    print(json.dumps(out, indent=1, default=str))
    _table(out)
    if args.json_out:
        with open(args.json_out, "w") as f:
            json.dump(out, f, indent=1, default=str)


def _table(out):
    print(
        f"\n{'draw':>4} {'nominal':>8} {'online':>8} {'oracle':>8} {'no fix':>8} "
        f"{'on/or':>6} {'on/nom':>6} {'cov95':>6} {'ident':>5} {'drop rec s':>10} "
        f"{'stuck rec s':>11}"
    )
    for r in out["rows"]:
        cov = "-" if r["covered_95"] is None else f"{r['covered_95']:.2f}"
        print(
            f"{r['draw']:>4} {r['rms_nominal_mm']:>8.2f} {r['rms_online_mm']:>8.2f} "
            f"{r['rms_oracle_mm']:>8.2f} {r.get('rms_no_fix_mm', float('nan')):>8.2f} "
            f"{r['rms_online_mm'] / r['rms_oracle_mm']:>6.2f} "
            f"{r['rms_online_mm'] / r['rms_nominal_mm']:>6.2f} {cov:>6} "
            f"{r['identified']:>5} {str(r['dropout']['recovered_after_s']):>10} "
            f"{str(r['stuck']['recovered_after_s']):>11}"
        )
    s, d = out["step"], out["day_log"]
    print(
        f"\nstep: {s['call_us']:.0f} us per call, {s['scan_us']:.0f} us in a scan; "
        f"2 h loop {out['loop_seconds']:.1f} s; day log {d}"
    )
    print("targets: " + json.dumps(out["targets"]))


if __name__ == "__main__":
    main()
