"""Outputs of fit, diagnosis and simulation, captured for a bit-identity check of a
change that must not change behaviour (a refactoring).

Capture with the tree before the change (a `git worktree` of the base commit, put
first on PYTHONPATH) and with the tree after, then compare:

    git worktree add /tmp/base BASE
    (cd /tmp/base && PYTHONPATH=/tmp/base python $OLDPWD/scripts/golden_outputs.py capture /tmp/g/base)
    PYTHONPATH=. python scripts/golden_outputs.py capture /tmp/g/new
    python scripts/golden_outputs.py compare /tmp/g/base /tmp/g/new

`capture OUT [cli] [api] [cdpr]` runs from a tree's root (it reads its bundled data,
and ../shared/data when present). What it runs, by the folder it exercises:
_cli/_fit/_diagnose/_report: `jaxcable demo`, `fit` (integrated and five-element, and
elongation-driven on the VHB 4910 relaxation exports), `diagnose --json`, `simulate`
of a protocol and of a history for every command-line model, with `--params` and
`--drive elongation`; _models/_drive: a rate test, its force history and its
elongation history for every registered class; _fit: `fit` from Python, both drives,
and `model_responses`; _montecarlo: an exact Monte-Carlo of 40 draws; _drive: 30
controller steps; cdpr and _papers: the robot's closed loop for every compensation
model, the SK78 targets report and a hidden-effect data set. `compare BASE NEW` prints
every difference: JSON numbers compared with ==, text files byte for byte (the output
folder's path normalised), arrays with `np.array_equal`; PNG files are not compared.
"""

import contextlib
import dataclasses
import glob
import io
import json
import math
import pathlib
import sys

import numpy as np


SHARED = pathlib.Path(__file__).resolve().parent.parent.parent / "shared" / "data"


def _problem_api(jc) -> bool:
    """Whether the tree captured fits a `jaxcable.Problem` (a base from before it
    takes the model, the tests and keywords)."""
    import inspect

    return "problem" in inspect.signature(jc.fit).parameters


def _fit(jc, model, tests, drive="auto", **method):
    """`jaxcable.fit` of `model` to `tests` by `drive`, with the `LeastSquares`
    fields `method`, in the captured tree's API."""
    if _problem_api(jc):
        problem = jc.Problem(model, tests, drive=drive)
        return jc.fit(problem, jc.LeastSquares(**method))
    return jc.fit(model, tests, drive=drive, **method)


def capture(out, stage):
    import jax

    jax.config.update("jax_enable_x64", True)
    import jaxcable as jc
    from jaxcable.cli import main

    print("jaxcable from", jc.__file__, flush=True)
    data = sorted(glob.glob("jaxcable/data/*.csv"))
    vhb_rel = sorted(glob.glob(str(SHARED / "vhb4910/relaxation/*.csv")))[:3]

    def cli(name, *argv):
        buf, err = io.StringIO(), io.StringIO()
        with contextlib.redirect_stdout(buf), contextlib.redirect_stderr(err):
            try:
                rc = main(list(argv))
            except SystemExit as e:
                rc = e.code
        (out / f"{name}.stdout").write_text(buf.getvalue())
        (out / f"{name}.rc").write_text(str(rc))
        print(name, rc, flush=True)

    if "cli" in stage:
        cli("demo", "demo", "--out", str(out / "demo"), "--quiet")
        cli(
            "fit_bundled",
            "fit",
            *data,
            "--out",
            str(out / "fit_bundled.json"),
            "--quiet",
        )
        cli(
            "fit_five",
            "fit",
            *data[:4],
            "--model",
            "five-element",
            "--out",
            str(out / "fit_five.json"),
            "--quiet",
            "--max-steps",
            "20",
        )
        cli("diag_bundled", "diagnose", *data, "--json", "--quiet")
        if vhb_rel:
            cli(
                "fit_vhb_rel",
                "fit",
                *vhb_rel,
                "--model",
                "five-element",
                "--length-mm",
                "50",
                "--drive",
                "elongation",
                "--out",
                str(out / "fit_vhb_rel.json"),
                "--quiet",
                "--max-steps",
                "15",
            )
        proto = out / "proto.json"
        proto.write_text(
            json.dumps(
                {
                    "length_mm": 300,
                    "diameter_mm": 3,
                    "rate_mm_per_min": 3,
                    "segments": [
                        {"cycles": 2, "force_max_N": 100, "samples_per_ramp": 50},
                        {"rest_h": 2},
                        {"ramp_to_N": 50, "samples": 20},
                        {"hold_s": 60, "force_N": 50},
                    ],
                }
            )
        )
        for m in ("integrated", "five-element", "hooke", "burgers", "bouc-wen"):
            cli(
                f"sim_proto_{m}",
                "simulate",
                str(proto),
                "--model",
                m,
                "--out",
                str(out / f"sim_proto_{m}.csv"),
            )
            cli(
                f"sim_hist_{m}",
                "simulate",
                data[0],
                "--model",
                m,
                "--out",
                str(out / f"sim_hist_{m}.csv"),
            )
        cli(
            "sim_params",
            "simulate",
            data[1],
            "--params",
            str(out / "fit_bundled.json"),
            "--out",
            str(out / "sim_params.csv"),
        )
        cli(
            "sim_elong",
            "simulate",
            str(out / "sim_hist_integrated.csv"),
            "--drive",
            "elongation",
            "--out",
            str(out / "sim_elong.csv"),
        )

    if "api" in stage:
        arrays = {}
        from jaxcable._models import CLASSES_BY_NAME

        cable = jc.Cable(length=0.3, diameter=3e-3, speed=3e-3 / 60)
        proto = jc.Protocol.concatenate(
            jc.Protocol.cycles(100.0, 2, 40),
            jc.Protocol.rest(3600.0, 20),
            jc.Protocol.cycles(100.0, 1, 40, start=False),
        )
        base = jc.IntegratedModel()
        for name, cls in sorted(CLASSES_BY_NAME.items()):
            try:
                model = cls.wrap(base) if hasattr(cls, "wrap") else cls()
            except Exception as e:
                print("skip", name, type(e).__name__, e)
                continue
            # Either tree's signature: `method=` (a jc.Simulation) or `throw=`.
            quiet = (
                dict(method=jc.Simulation(throw=False))
                if hasattr(jc, "Simulation")
                else dict(throw=False)
            )
            traj = jc.simulate_rate_test(model, cable, proto, **quiet)
            for f in ("time", "force", "elongation", "strain"):
                if hasattr(traj, f):
                    arrays[f"rate/{name}/{f}"] = np.asarray(getattr(traj, f))
            t = np.asarray(traj.time)
            F = np.asarray(traj.force)
            try:
                tf = jc.simulate_force_history(model, cable, t, F, **quiet)
                arrays[f"force/{name}/elongation"] = np.asarray(tf.elongation)
                te = jc.simulate_elongation_history(
                    model,
                    cable,
                    t,
                    np.asarray(tf.elongation),
                    **quiet,
                )
                arrays[f"elong/{name}/force"] = np.asarray(te.force)
            except ValueError as e:
                print("history skipped", name, e)
        # fit API on bundled data, both drives
        tests = [jc.read_test(p) for p in data[:3]]
        r = _fit(jc, jc.IntegratedModel(), tests, max_steps=15)
        (out / "api_fit.json").write_text(
            r.to_json() if hasattr(r, "to_json") else str(r)
        )
        for f in (
            "values",
            "stderr",
            "covariance",
            "rmse_mm",
            "singular_values",
            "start_losses",
        ):
            arrays[f"api_fit/{f}"] = np.asarray(getattr(r, f), float)
        if _problem_api(jc):
            resp = jc.model_responses(r, jc.Problem(r.model, tests))
        else:
            resp = jc.model_responses(r, tests)
        for i, x in enumerate(resp):
            arrays[f"api_fit/resp{i}"] = np.asarray(x)
        r2 = _fit(jc, jc.IntegratedModel(), tests, max_steps=10, drive="elongation")
        (out / "api_fit_elong.json").write_text(r2.to_json())
        # Monte Carlo
        cables = jc.Cable(
            length=np.array([0.3, 1.0, 8.0]), diameter=3e-3, speed=3e-3 / 60
        )
        tt = np.linspace(0.0, 600.0, 60)
        FF = 80.0 * np.sin(np.linspace(0, 3, 60)) ** 2
        loads = jc.ForceHistory(tt, FF)
        sampler = jc.IndependentParameters(
            jc.IntegratedModel(),
            {
                "E2r": jc.LogNormal(float(jc.IntegratedModel().E2r), 0.1),
                "t_e": jc.Uniform(1.0, 100.0),
            },
        )
        kw = dict(
            parameters=sampler,
            cables=cables,
            loads=loads,
            key=jax.random.key(0),
            num_draws=40,
            chunk_size=20,
            method="exact",
            keep_draws=True,
        )
        if hasattr(jc, "MonteCarlo"):
            fields = ("key", "num_draws", "chunk_size", "method", "keep_draws")
            method = jc.MonteCarlo(**{f: kw.pop(f) for f in fields})
            mc = jc.monte_carlo(
                **kw, method=method, progress_meter=jc.NoProgressMeter()
            )
        else:
            try:
                mc = jc.monte_carlo(**kw, progress=False)
            except TypeError:
                mc = jc.monte_carlo(**kw)
        for f in ("draws", "percentiles", "mean", "std", "num_broken", "status_counts"):
            v = getattr(mc, f, None)
            if v is not None and not isinstance(v, dict):
                arrays[f"mc/{f}"] = np.asarray(v)
        # controller
        st = jc.controller_init(base, cables)
        for k in range(30):
            st, y = jc.controller_step(
                base, cables, st, 0.5 * (k + 1), FF[2 * k] * np.array([1.0, 0.8, 0.5])
            )
            arrays[f"ctrl/{k}"] = np.asarray(y)
        np.savez(out / "api.npz", **arrays)
        print("api done", len(arrays), flush=True)
    if "cdpr" in stage:
        from jaxcable import cdpr, papers

        robot = cdpr.Robot()
        scen = cdpr.pick_and_place(0.1, dt=2.0)
        real = cdpr.real_cables(jax.random.key(1))
        arrays = {}
        for name, model in cdpr.compensation_models().items():
            run = cdpr.simulate_robot(robot, scen, real, model)
            for f in dataclasses.fields(run):
                arrays[f"cdpr/{name}/{f.name}"] = np.asarray(getattr(run, f.name))
        rep = (
            papers.sk78_targets_report(samples_per_ramp=20)
            if "samples_per_ramp" in papers.sk78_targets_report.__code__.co_varnames
            else papers.sk78_targets_report()
        )
        (out / "sk78.txt").write_text(str(rep))
        ds = (
            papers.hidden_effect_dataset("bedding_in", seed=0)
            if hasattr(papers, "hidden_effect_dataset")
            else None
        )
        if ds is not None:
            tests = ds[0] if isinstance(ds, tuple) else ds
            for i, t in enumerate(getattr(tests, "tests", tests)):
                arrays[f"hidden/{i}/elongation"] = np.asarray(t.elongation)
        np.savez(out / "cdpr.npz", **arrays)
        print("cdpr done", len(arrays))


def compare(base, new):
    problems = []
    checked = 0

    def same(a, b, where):
        nonlocal checked
        if isinstance(a, dict) and isinstance(b, dict):
            for k in sorted(set(a) | set(b)):
                if k not in a or k not in b:
                    problems.append(
                        f"{where}: key {k!r} only in {'new' if k in b else 'base'}"
                    )
                else:
                    same(a[k], b[k], f"{where}.{k}")
        elif isinstance(a, list) and isinstance(b, list):
            if len(a) != len(b):
                problems.append(f"{where}: length {len(a)} != {len(b)}")
            for i, (x, y) in enumerate(zip(a, b)):
                same(x, y, f"{where}[{i}]")
        elif isinstance(a, float) and isinstance(b, float):
            checked += 1
            if not (a == b or (math.isnan(a) and math.isnan(b))):
                problems.append(f"{where}: {a!r} != {b!r}")
        else:
            checked += 1
            if a != b:
                problems.append(f"{where}: {str(a)[:80]!r} != {str(b)[:80]!r}")

    for p in sorted(base.rglob("*")):
        if p.is_dir():
            continue
        rel = p.relative_to(base)
        q = new / rel
        if not q.exists():
            problems.append(f"{rel}: missing in new")
            continue
        if p.suffix == ".json":
            try:
                same(json.loads(p.read_text()), json.loads(q.read_text()), str(rel))
            except json.JSONDecodeError:
                if p.read_bytes() != q.read_bytes():
                    problems.append(f"{rel}: differs (not JSON)")
        elif p.suffix == ".npz":
            a, b = np.load(p), np.load(q)
            for k in sorted(set(a.files) | set(b.files)):
                if k not in a.files or k not in b.files:
                    problems.append(f"{rel}:{k} only in one")
                    continue
                checked += a[k].size
                if a[k].shape != b[k].shape or not np.array_equal(
                    a[k], b[k], equal_nan=True
                ):
                    d = (
                        np.nanmax(np.abs(a[k] - b[k]))
                        if a[k].shape == b[k].shape
                        else "shape"
                    )
                    problems.append(f"{rel}:{k} differs (max {d})")
        elif p.suffix == ".png":
            continue
        else:
            checked += 1
            ta = p.read_text(errors="replace").replace(str(base.resolve()), "OUT")
            tb = q.read_text(errors="replace").replace(str(new.resolve()), "OUT")
            if ta != tb:
                la, lb = ta.splitlines(), tb.splitlines()
                diff = [(i, x, y) for i, (x, y) in enumerate(zip(la, lb)) if x != y][:3]
                problems.append(
                    f"{rel}: text differs ({len(la)} vs {len(lb)} lines) first: {diff}"
                )
    for q in sorted(new.rglob("*")):
        if q.is_file() and not (base / q.relative_to(new)).exists():
            problems.append(f"{q.relative_to(new)}: only in new")
    print(f"{checked} values/files compared; {len(problems)} differences")
    for x in problems[:200]:
        print(" ", x)


if __name__ == "__main__":
    if len(sys.argv) >= 3 and sys.argv[1] == "capture":
        out = pathlib.Path(sys.argv[2])
        out.mkdir(parents=True, exist_ok=True)
        capture(out, set(sys.argv[3:]) or {"cli", "api", "cdpr"})
    elif len(sys.argv) == 4 and sys.argv[1] == "compare":
        compare(pathlib.Path(sys.argv[2]), pathlib.Path(sys.argv[3]))
    else:
        sys.exit(__doc__)
