"""The posterior of the bundled data set: R-hat, ESS and time of
`jaxcable.sample_posterior` on the eight bundled files, eight parameters: the demo's
six and the long-term retardation time's lambda1, lambda2 (Park Eq. 8).

    python benchmarks/posterior_bundled.py [--every 1] [--chains 4] [--draws 500]
        [--warmup 500] [--max-doublings 8] [--fit NAMES] [--xla-default]
        [--progress] [--json-out FILE]

The scans' loops run as single CPU kernels (which `import jaxcable` turns on;
`--xla-default` keeps XLA's own CPU loops, `JAXCABLE_NO_LOOP_KERNELS=1`, and the
JSON's `loop_kernels` says which ran), and each core is a CPU device
(`XLA_FLAGS=--xla_force_host_platform_device_count=N`, as benchmarks/montecarlo.py),
over which `sample_posterior` lays out its chains.
The least-squares fit comes first (`jaxcable.fit`, timed apart), then NUTS from it. `--every K` keeps one sample in K of every file (as
`jaxcable fit --every`), which shortens each gradient K times. Reported: per
parameter the posterior mean, sd, R-hat and bulk ESS, beside the fit's value and
linearised standard error; the sampler's time, compilation included. Target: R-hat <= 1.01 and ESS >= 400 for every parameter within
5 minutes on the 2-core CPU. Prints one JSON object, then a table.
"""

import argparse
import importlib.resources
import json
import os
import platform
import sys
import time
import warnings


# `import jaxcable` (below) turns on XLA's CPU loop kernels unless this says no, so
# `--xla-default` is read here, before it (argparse declares it too, for --help).
if "--xla-default" in sys.argv[1:]:
    os.environ["JAXCABLE_NO_LOOP_KERNELS"] = "1"
# One CPU device per core (before JAX starts), over which the chains are laid out.
os.environ["XLA_FLAGS"] = (
    os.environ.get("XLA_FLAGS", "")
    + f" --xla_force_host_platform_device_count={os.cpu_count()}"
)

import jax  # noqa: E402


jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import jaxcable as jc  # noqa: E402

# The command line's `--every`, so that the thinned files are the ones it fits.
from jaxcable._cli.data import _thin as thin  # noqa: E402
from jaxcable._models import PARK_IDENTIFIABLE  # noqa: E402


# Park's long-term retardation time (Eq. 8), which the demo keeps at Park's values
# and the bundled tests' rests of 24-72 h identify (relative standard errors of
# the least-squares fit 0.4 % and 10 %).
EXTRA = ("lambda1", "lambda2")


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--every", type=int, default=1)
    p.add_argument("--chains", type=int, default=4)
    p.add_argument("--draws", type=int, default=500)
    p.add_argument("--warmup", type=int, default=500)
    p.add_argument("--max-doublings", type=int, default=8)
    p.add_argument(
        "--fit",
        default=",".join(PARK_IDENTIFIABLE + EXTRA),
        help="the fitted parameters (default: the demo's and lambda1, lambda2)",
    )
    p.add_argument(
        "--xla-default",
        action="store_true",
        help="XLA's default CPU loops instead of the loop kernels that "
        "`import jaxcable` turns on (JAXCABLE_NO_LOOP_KERNELS=1)",
    )
    p.add_argument("--progress", action="store_true")
    p.add_argument("--json-out", default=None)
    args = p.parse_args()
    folder = importlib.resources.files("jaxcable").joinpath("data")
    files = sorted(f for f in folder.iterdir() if f.name.endswith(".csv"))
    tests = [thin(jc.read_test(f), args.every) for f in files]
    model = jc.IntegratedModel()
    names = args.fit.split(",")
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", jc.IdentifiabilityWarning)
        fit = jc.fit(jc.Problem(model, tests, fit=names), throw=False)
    t_fit = time.perf_counter() - t0
    meter = jc.TextProgressMeter() if args.progress else jc.NoProgressMeter()
    t0 = time.perf_counter()
    post = jc.sample_posterior(
        jc.Problem(model, tests, fit=names),
        jc.NUTS(
            num_samples=args.draws,
            num_chains=args.chains,
            num_warmup=args.warmup,
            max_doublings=args.max_doublings,
            key=jax.random.key(0),
        ),
        start=fit,
        progress_meter=meter,
    )
    t_post = time.perf_counter() - t0
    out = {
        "benchmark": "posterior_bundled",
        "settings": vars(args),
        "samples_per_test": [t.num_samples for t in tests],
        "names": list(post.names),
        "fit_seconds": t_fit,
        "posterior_seconds": t_post,
        "rhat": [float(r) for r in post.rhat],
        "ess": [float(e) for e in post.ess],
        "mean": [float(m) for m in post.mean],
        "sd": [float(s) for s in post.sd],
        "fit_values": [float(v) for v in fit.values],
        "fit_stderr": [float(s) for s in fit.stderr],
        "divergences": post.divergences,
        "mean_steps_per_draw": post.mean_steps,
        "target_met": bool(
            np.all(post.rhat <= 1.01) and np.all(post.ess >= 400) and t_post <= 300
        ),
        "machine": f"{platform.machine()}, {os.cpu_count()} cores",
        "devices": len(jax.devices()),
        # Whether XLA's CPU loop-kernel option is set (by `import jaxcable` or by hand).
        "loop_kernels": "xla_cpu_small_while_loop_byte_threshold"
        in os.environ.get("XLA_FLAGS", ""),
        "xla_flags": os.environ.get("XLA_FLAGS", ""),
        "load_average": os.getloadavg(),
    }
    text = json.dumps(out, indent=1)
    print(text)
    if args.json_out:
        with open(args.json_out, "w") as f:
            f.write(text + "\n")
    print()
    print(post.summary())
    print(
        f"fit {t_fit:.1f} s; posterior {t_post:.1f} s "
        f"({args.chains} chains x ({args.warmup} + {args.draws})); "
        f"target met: {out['target_met']}"
    )


if __name__ == "__main__":
    main()
