"""A material's limits as the command line takes them from the data: the breaking
strain a file gives (or `--breaking-strain`), else, with only a breaking load, the
strain a fitted model reaches at that load; said in one line when the data give
none.

The rule (`jaxcable.TestData.cable` holds its first half):

- a file's `# breaking_strain:` (or `--breaking-strain`, which replaces it; `inf`
  for a material that does not break) is the limit of every simulation;
- a file with only `# breaking_load_N:` has no strain limit before a fit (the start
  values are no material's); after a fit (`simulate --params`, `design`), the limit
  is the model's strain at the breaking load in a tensile ramp from 0 N at the
  cable's crosshead speed, as a breaking load is measured;
- a file with neither has no strain limit (the default of `jaxcable.Cable` is a
  Dyneema rope's, which must not stop another material).
"""

import dataclasses
import math
import pathlib

import equinox as eqx
import numpy as np

from .._drive import Protocol, Simulation, simulate_rate_test
from .._io import TestData
from .._models import AbstractCableModel
from .._results import RESULTS


# Samples of the tensile ramp to the breaking load: its last strain is the limit.
_RAMP_SAMPLES = 16


def _name(test: TestData) -> str:
    return (
        pathlib.Path(test.source).name
        if test.source
        else str(test.metadata.get("id", "a test"))
    )


def limits_note(tests) -> str | None:
    """One line on what limits the strain of `tests` where their files leave it
    open (None when every file gives its breaking strain)."""
    open_ = [t for t in tests if "breaking_strain" not in t.metadata]
    if not open_:
        return None
    loads = [t for t in open_ if "breaking_load_N" in t.metadata]
    parts = []
    if loads:
        names = ", ".join(_name(t) for t in loads[:3]) + (
            ", ..." if len(loads) > 3 else ""
        )
        parts.append(
            f"{names}: a breaking load but no breaking strain; no strain limit "
            "before a fit, then the fitted model's strain at that load"
        )
    bare = len(open_) - len(loads)
    if bare:
        parts.append(f"{bare} file(s) give no breaking strain or load: no strain limit")
    return (
        "limits: "
        + "; ".join(parts)
        + " (--breaking-strain X, or a '# breaking_strain:' line, sets one)"
    )


def strain_at_load(model: AbstractCableModel, cable, load: float) -> float | None:
    """The strain `model` reaches at `load` in a tensile ramp from 0 N at
    `cable.speed`, as a tensile tester measures a breaking load; None where the
    model does not reach that load (its simulation fails).

    **Arguments:**

    - `model`: the (fitted) model.
    - `cable`: the cable and its crosshead speed, m/s.
    - `load`: the force at the end of the ramp, N (at most `cable.breaking_load`).

    **Returns:**

    The strain (elongation / L0, dimensionless), or None.
    """
    ramp = Protocol.concatenate(
        Protocol.start(), Protocol.ramp(0.0, float(load), _RAMP_SAMPLES)
    )
    # The ramp itself must not stop at an earlier limit.
    free = eqx.tree_at(lambda c: c.breaking_strain, cable, math.inf)
    traj = simulate_rate_test(model, free, ramp, method=Simulation(throw=False))
    strain = float(np.asarray(traj.strain)[-1])
    if traj.result != RESULTS.successful or not (math.isfinite(strain) and strain > 0):
        return None
    return strain


def with_strain_from_load(tests, models, log=None) -> list:
    """`tests`, each file that gives a breaking load but no breaking strain given
    the strain its model (`models`, one per test) reaches at that load
    ([`strain_at_load`][]) as its `breaking_strain`; one line each on
    `log` (default stdout) saying so, or that the model does not reach the load
    (then no strain limit)."""
    out = []
    for test, model in zip(tests, models, strict=True):
        if "breaking_strain" in test.metadata or "breaking_load_N" not in test.metadata:
            out.append(test)
            continue
        cable = test.cable()
        load = float(cable.breaking_load)
        strain = strain_at_load(model, cable, load)
        if strain is None:
            print(
                f"{_name(test)}: the model does not reach the breaking load "
                f"{load:g} N in a ramp at the crosshead speed; no strain limit.",
                file=log,
            )
            out.append(test)
            continue
        print(
            f"{_name(test)}: breaking strain {strain:.4g}, the model's strain at the "
            f"breaking load {load:g} N.",
            file=log,
        )
        metadata = {**test.metadata, "breaking_strain": strain}
        out.append(dataclasses.replace(test, metadata=metadata))
    return out
