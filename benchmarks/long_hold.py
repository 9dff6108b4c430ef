"""Long holds: the strain of the default 3 mm SK78 cable held at a constant force for
up to 30 days, and the creep rate after a day.

A robot holds its cables for hours; a rope in storage under tension for days. This
script loads the cable 0 -> F in 60 s, holds it for 30 days (log-spaced samples,
`jaxcable.simulate_force_history`, float64) at 5-30 % of the breaking load, and prints
one JSON line per force, then a table: the strain after 1 min, 2 h, 24 h and 30 days,
the strain accrued from 1 h to 30 days, the creep rate after one day and whether the
cable passed its breaking strain (`RESULTS.strain_beyond_break`).

    python benchmarks/long_hold.py [--days 30] [--samples 400]
"""

import argparse
import json

import jax


jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import jaxcable as jc  # noqa: E402


DAY = 86400.0
FORCES = (100.0, 150.0, 200.0, 400.0, 600.0)  # N: 5-30 % of 2000 N


def hold(model, cable, force, days, samples):
    time = np.concatenate([[0.0], np.geomspace(1.0, days * DAY, samples)])
    f = np.minimum(force * time / 60.0, force)
    traj = jc.simulate_force_history(
        model, cable, time, f, method=jc.Simulation(throw=False)
    )
    strain = np.asarray(traj.strain)

    def at(t):
        return float(strain[np.searchsorted(time, t)])

    day = np.searchsorted(time, DAY)
    rate = (strain[day + 5] - strain[day - 5]) / (time[day + 5] - time[day - 5])
    return dict(
        force_N=force,
        share_of_breaking_load=force / float(cable.breaking_load),
        strain_1min=at(60.0),
        strain_2h=at(7200.0),
        strain_24h=at(DAY),
        strain_end=float(strain[-1]),
        accrued_1h_to_end=float(strain[-1]) - at(3600.0),
        rate_after_1day_per_s=float(rate),
        beyond_break=bool(traj.result == jc.RESULTS.strain_beyond_break),
    )


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--days", type=float, default=30.0)
    parser.add_argument("--samples", type=int, default=400)
    args = parser.parse_args()
    model, cable = jc.IntegratedModel(), jc.Cable(length=0.3)
    rows = [hold(model, cable, f, args.days, args.samples) for f in FORCES]
    for row in rows:
        print(json.dumps(row))
    print()
    print(
        f"{'force':>7} {'1 min':>7} {'2 h':>7} {'24 h':>7} {'end':>7} "
        f"{'1 h->end':>8} {'rate 1 d':>10}  beyond break"
    )
    for r in rows:
        pct = [
            100 * r[k] for k in ("strain_1min", "strain_2h", "strain_24h", "strain_end")
        ]
        print(
            f"{r['force_N']:5.0f} N "
            + " ".join(f"{p:6.2f}%" for p in pct)
            + f" {100 * r['accrued_1h_to_end']:7.2f}% {r['rate_after_1day_per_s']:8.2e}/s"
            + f"  {r['beyond_break']}"
        )


if __name__ == "__main__":
    main()
