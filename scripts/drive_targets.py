"""Issue 11's synthetic targets for the elongation drive, measured.

    python scripts/drive_targets.py [--seeds 6] [--samples 200] [--model burgers]

1. Round trip: two relaxation tests and one constant-rate test made with the
   elongation drive (0.5 % force noise) are fitted; each test's force RMSE is
   compared with its noise (target <= 1.3x), and the fitted model, re-simulated
   through `simulate_elongation_history`, reproduces the fit's residuals.
2. Mixed fit: two force-controlled creep tests and two relaxation tests of one cable,
   fitted together (residuals in noise units), over `--seeds` seeds: every parameter
   within 3 standard errors of the truth (target: every seed).

Prints one JSON object and a table.
"""

import argparse
import json
import time

import jax


jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import jaxcable as jc  # noqa: E402
from jaxcable._papers import synthesize_history  # noqa: E402


CASES = {
    # truth, start, fitted names, cable, creep forces (N), relaxation strains
    "burgers": (
        jc.BurgersModel(E1=2.0e9, eta0=3.0e11, E2=4.0e8, eta2=2.0e10),
        jc.BurgersModel(E1=1.5e9, eta0=1.0e11, E2=6.0e8, eta2=1.0e10),
        None,
        jc.Cable.from_mm(length_mm=200.0, diameter_mm=3.0),
        (500.0, 1000.0),
        (0.01, 0.02),
    ),
    "integrated": (
        jc.IntegratedModel(),
        jc.IntegratedModel(E1c=2.2e9, E2c=5.0e8, t_c=6.0, eta0=3.0e11),
        ("E1c", "E2c", "t_c", "eta0"),
        jc.Cable.from_mm(length_mm=300.0, diameter_mm=3.0),
        (300.0, 600.0),
        (0.008, 0.016),
    ),
}


def _times(ramp, hold, n):
    k = n // 4
    return np.concatenate(
        [np.linspace(0.0, ramp, k), ramp + np.geomspace(0.5, hold, n - k)]
    )


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, default=6)
    p.add_argument("--samples", type=int, default=200)
    p.add_argument("--model", choices=sorted(CASES), default="burgers")
    args = p.parse_args()
    truth, start, names, cable, forces, strains = CASES[args.model]
    length = float(cable.length)
    n = args.samples

    def relaxation(strain, seed):
        t = _times(20.0, 600.0, n)
        e = np.minimum(t / 20.0, 1.0) * strain * length
        meta = {"id": f"relax-{strain}"}
        return synthesize_history(
            truth, cable, t, e, drive="elongation", seed=seed, metadata=meta
        )

    def constant_rate(strain, seed):
        t = np.linspace(0.0, 200.0, n)
        e = strain * length * (1.0 - np.abs(t / 100.0 - 1.0))
        meta = {"id": f"rate-{strain}"}
        return synthesize_history(
            truth, cable, t, e, drive="elongation", seed=seed, metadata=meta
        )

    def creep(force, seed):
        t = _times(10.0, 900.0, n)
        f = np.minimum(t / 10.0, 1.0) * force
        meta = {"id": f"creep-{force:g}"}
        return synthesize_history(
            truth, cable, t, f, drive="force", seed=seed, metadata=meta
        )

    out = {"model": args.model, "samples_per_test": n, "seeds": args.seeds}
    # 1. Round trip.
    made = [relaxation(strains[0], 1), relaxation(strains[1], 2)]
    made.append(constant_rate(0.5 * sum(strains), 3))
    t0 = time.perf_counter()
    problem = jc.Problem(start, [d for d, _ in made], fit=names)
    fit = jc.fit(problem, jc.LeastSquares(multistart=1))
    ratios, reproduced = [], []
    for i, (data, sigma) in enumerate(made):
        ratios.append(float(fit.rmse_N[i] / sigma))
        traj = jc.simulate_elongation_history(
            fit.models[i], data.cable(), data.time, data.elongation
        )
        rmse = float(np.sqrt(np.mean((np.asarray(traj.force) - data.force) ** 2)))
        reproduced.append(abs(rmse - float(fit.rmse_N[i])) / float(fit.rmse_N[i]))
    out["round_trip"] = {
        "tests": list(fit.test_ids),
        "rmse_over_noise": ratios,
        "simulate_vs_fit_rmse_rel_diff": reproduced,
        "met": bool(max(ratios) <= 1.3),
        "seconds": time.perf_counter() - t0,
    }
    # 2. Mixed fits.
    rows = []
    for seed in range(args.seeds):
        tests = [creep(forces[0], 10 * seed)[0], creep(forces[1], 10 * seed + 1)[0]]
        tests += [relaxation(strains[0], 10 * seed + 2)[0]]
        tests += [relaxation(strains[1], 10 * seed + 3)[0]]
        t0 = time.perf_counter()
        problem = jc.Problem(start, tests, fit=names)
        r = jc.fit(problem, jc.LeastSquares(multistart=1), throw=False)
        z = {
            k: float((v - float(getattr(truth, k))) / s)
            for k, v, s in zip(r.names, r.values, r.stderr)
        }
        rows.append(
            {
                "seed": seed,
                "converged": bool(r.converged),
                "z": z,
                "max_abs_z": max(abs(v) for v in z.values()),
                "ssr_per_sample": float(r.loss / np.sum(r.num_samples)),
                "seconds": time.perf_counter() - t0,
            }
        )
    out["mixed"] = rows
    out["mixed_met"] = all(r["converged"] and r["max_abs_z"] < 3 for r in rows)
    print(json.dumps(out, indent=1))
    print()
    print(
        "round trip: force RMSE / noise per test:", " ".join(f"{x:.3f}" for x in ratios)
    )
    print("  simulate vs fit RMSE, relative:", " ".join(f"{x:.1e}" for x in reproduced))
    print("mixed fit (2 creep + 2 relaxation): seed, max |z|, SSR/sample")
    for r in rows:
        print(f"  {r['seed']}  {r['max_abs_z']:.2f}  {r['ssr_per_sample']:.3f}")
    print(
        f"targets met: round trip {out['round_trip']['met']}, mixed {out['mixed_met']}"
    )


if __name__ == "__main__":
    main()
