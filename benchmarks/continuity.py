"""Continuity of every model in its force history (issue 10), measured.

The history of the issue: a 300 mm cable, 0 -> 100 N in 300 s, a 2 h hold, unload to
2 N in 300 s, a 2 h rest, sampled every second. The same history with zero-mean force
noise of standard deviation d (clipped at 0 N): the largest change of the elongation,
mm, and its ratio to d / (E A) x L0 with E the model's smallest instantaneous
modulus... printed as JSON and a table.

    python benchmarks/continuity.py
"""

import json
import sys

import jax


jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import jaxcable as jc  # noqa: E402


NOISE = (1e-6, 1e-3, 1e-1, 5e-1, 1.0)


def history(dt=1.0):
    t = np.arange(0.0, 300 + 7200 + 300 + 7200 + dt, dt)
    f = np.interp(t, [0, 300, 7500, 7800, 15000], [0, 100, 100, 2, 2])
    return t, f


def models():
    yield "integrated", jc.IntegratedModel()
    yield (
        "five_element_asym",
        jc.FiveElementModel(E_UL2=2 * 9.5e9, eta_UL2=3e10, E_UL3=2.5e10, eta_UL3=2e13),
    )
    yield "burgers", jc.BurgersModel()
    yield "bouc_wen", jc.BoucWenModel()


def versus_printed():
    """On Park's own path (one loading to 100 N, a full unloading, a 24 h rest) the
    instantaneous and creep parts are Eq. 1-9 exactly; the recoveries ramp in with
    the force drop where Eq. 4 and 7 as printed start at full amplitude at the
    reversal. The difference of the recovered elongation, mm: largest, at the end of
    the unloading, and at the end of the rest."""
    model = jc.IntegratedModel()
    rows = []
    for length in (0.1, 0.3):
        for rate in (3.0, 50.0):
            cable = jc.Cable(length=length, speed=rate * 1e-3 / 60)
            protocol = jc.Protocol.concatenate(
                jc.Protocol.cycles(100.0, 1, samples_per_ramp=200),
                jc.Protocol.rest(86400.0, samples=200),
            )
            traj = jc.simulate_rate_test(model, cable, protocol)
            t = np.asarray(traj.time)
            f = np.asarray(traj.force)
            peak = int(np.argmax(f))
            end = peak + 200
            tau = np.maximum(t - t[peak], 0.0)
            # F_eq = I / T at each sample from the model's own creep (Eq. 5): the
            # creep is I (g(T) / (E2c A) + 1 / (eta0 A)); with T frozen after the
            # unloading the printed amplitude uses the same I / T.
            area = float(cable.area)
            impulse = np.concatenate(
                [[0.0], np.cumsum(0.5 * (f[1:] + f[:-1]) * np.diff(t))]
            )
            t_total = np.minimum(t, t[end])  # tension from 0 to the end of unloading
            f_eq = impulse / np.where(t_total > 0, t_total, 1.0)
            t_r2 = float(model.retardation_time_long(cable))
            printed = np.where(
                np.arange(t.size) > peak,
                f_eq
                * (1 - np.exp(-tau / float(model.t_r1)))
                / (float(model.E2r) * area)
                + (100.0 - f) * (1 - np.exp(-tau / t_r2)) / (float(model.E3r) * area),
                0.0,
            )
            ours = np.asarray(traj.recovery_short + traj.recovery_long)
            diff = (ours - printed) * length * 1e3
            rows.append(
                {
                    "length_mm": length * 1e3,
                    "rate_mm_per_min": rate,
                    "max_abs_diff_mm": float(np.max(np.abs(diff))),
                    "diff_end_of_unloading_mm": float(diff[end]),
                    "diff_end_of_rest_mm": float(diff[-1]),
                    "elongation_end_of_unloading_mm": float(traj.elongation[end]) * 1e3,
                    "recovery_capped_by_creep": bool(
                        np.any(
                            (ours >= np.asarray(traj.creep) * (1 - 1e-12))
                            & (np.asarray(traj.creep) > 0)
                        )
                    ),
                    "printed_end_of_rest_mm": float(
                        traj.elongation[-1] + diff[-1] * 1e-3
                    )
                    * 1e3,
                }
            )
    return rows


def main():
    cable = jc.Cable(length=0.3)
    t, f = history()
    rng = np.random.default_rng(0)
    rows = []
    for name, model in models():
        base = np.asarray(jc.simulate_force_history(model, cable, t, f).elongation)
        for d in NOISE:
            noisy = np.maximum(f + d * rng.standard_normal(f.shape), 0.0)
            e = np.asarray(jc.simulate_force_history(model, cable, t, noisy).elongation)
            change = float(np.max(np.abs(e - base))) * 1e3
            rows.append(
                {
                    "model": name,
                    "noise_N": d,
                    "max_change_mm": change,
                    "mm_per_N": change / d,
                    "peak_mm": float(base.max()) * 1e3,
                    "min_mm": float(base.min()) * 1e3,
                }
            )
    printed = versus_printed()
    print(json.dumps({"noise": rows, "versus_printed": printed}))
    print(
        f"{'model':<20}{'noise N':>10}{'max change mm':>16}{'mm/N':>12}",
        file=sys.stderr,
    )
    for r in rows:
        print(
            f"{r['model']:<20}{r['noise_N']:>10.0e}{r['max_change_mm']:>16.3e}"
            f"{r['mm_per_N']:>12.3g}",
            file=sys.stderr,
        )
    print(
        f"\n{'L mm':>6}{'mm/min':>8}{'max |diff| mm':>15}{'end unload':>12}"
        f"{'end rest':>10}{'capped':>8}{'printed end mm':>16}",
        file=sys.stderr,
    )
    for r in printed:
        print(
            f"{r['length_mm']:>6.0f}{r['rate_mm_per_min']:>8.0f}"
            f"{r['max_abs_diff_mm']:>15.3f}{r['diff_end_of_unloading_mm']:>12.3f}"
            f"{r['diff_end_of_rest_mm']:>10.3f}{str(r['recovery_capped_by_creep']):>8}"
            f"{r['printed_end_of_rest_mm']:>16.3f}",
            file=sys.stderr,
        )


if __name__ == "__main__":
    main()
