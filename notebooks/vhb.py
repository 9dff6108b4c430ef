"""Reading the real VHB 4910 loading-unloading tests of `../shared/data/vhb4910/` for
the notebooks (02_fit, 03_diagnose). The data are public but not ours to ship: they are
read from `../shared` (or `$JAXCABLE_SHARED`) and the notebooks skip them when absent.

Each file is one load-unload cycle of an 80 mm specimen at constant crosshead speed,
exported at 50 Hz as a raw tensile-tester file (GBK header, units row, quoted
numbers); `jaxcable.read_test` reads it with `columns="time_s,elongation_mm,force_N"`
and masks the slack stretch at the end of the unloading.
"""

import dataclasses
import math
import os
import pathlib

import numpy as np

import jaxcable as jc


SHARED = pathlib.Path(
    os.environ.get("JAXCABLE_SHARED", pathlib.Path.cwd().parent.parent / "shared")
)
FOLDER = SHARED / "data" / "vhb4910" / "loading-unloading"
GAUGE_MM = 80.0
BREAKING_LOAD = 1.5  # N: just above the largest force of the data set (1.43 N)
# An elastomer stretched to 6 times its length in these tests, which are not about its
# break: no strain is flagged as one (`breaking_strain` metadata).
BREAKING_STRAIN = math.inf
RATES = {"0d01": 0.01, "0d03": 0.03, "0d05": 0.05}  # stretch rate, 1/s
EXCLUDED = {"0d05_2d5_2.csv": "named stretch 2.5 but peaks at 80 mm (stretch 2.0)"}


def available() -> bool:
    return FOLDER.is_dir()


def thin(data: jc.TestData, samples: int) -> jc.TestData:
    """Every k-th sample (the last kept), so that about `samples` remain."""
    k = max(1, data.num_samples // samples)
    i = np.unique(np.append(np.arange(0, data.num_samples, k), data.num_samples - 1))
    return dataclasses.replace(
        data,
        time=data.time[i],
        force=data.force[i],
        elongation=data.elongation[i],
        mask=data.mask[i],
        lines=data.lines[i],
        force_raw=None,
    )


def read(path: pathlib.Path, samples: int = 200) -> jc.TestData:
    """One test, thinned to about `samples` samples, with a breaking load that suits
    a 1 N specimen and no breaking strain (`breaking_load_N` and `breaking_strain`
    metadata, read by `TestData.cable()`)."""
    rate = RATES[path.name[:4]]
    data = jc.read_test(
        path,
        columns="time_s,elongation_mm,force_N",
        metadata={
            "length_mm": GAUGE_MM,
            "rate_mm_per_min": rate * GAUGE_MM * 60,
            "id": path.stem,
        },
    )
    data.metadata["breaking_load_N"] = BREAKING_LOAD
    data.metadata["breaking_strain"] = BREAKING_STRAIN
    return thin(data, samples)


def paths() -> list[pathlib.Path]:
    """The test files, without the mislabelled one (`EXCLUDED`)."""
    return [p for p in sorted(FOLDER.glob("*.csv")) if p.name not in EXCLUDED]


RELAXATION = SHARED / "data" / "vhb4910" / "relaxation"
# The relaxation tests reach 3.7 N (stretch 6): a nominal breaking load above that.
RELAXATION_BREAKING_LOAD = 4.0


def read_relaxation(path: pathlib.Path, ramp: int = 40, hold: int = 80) -> jc.TestData:
    """One relaxation test (a ramp at 20 mm/s to a stretch of 1.5-6, held 1800 s),
    thinned to `ramp` samples evenly over the ramp and `hold` samples log-spaced over
    the hold (the force relaxes on every time scale from 0.05 s to 30 min), with the
    breaking load `RELAXATION_BREAKING_LOAD` and no breaking strain. The files are read as they come; their
    control (displacement) is detected from the data by `jaxcable.fit`."""
    data = jc.read_test(
        path,
        columns="time_s,elongation_mm,force_N",
        metadata={"length_mm": GAUGE_MM, "id": "relax_" + path.stem},
    )
    t, e = data.time, data.elongation
    top = int(np.flatnonzero(e >= 0.999 * e.max())[0])
    on_ramp = np.linspace(0, top, ramp).astype(int)
    times = t[top] + np.geomspace(0.05, t[-1] - t[top], hold)
    on_hold = np.clip(np.searchsorted(t, times), top + 1, t.size - 1)
    i = np.unique(np.concatenate([on_ramp, on_hold]))
    data = dataclasses.replace(
        data,
        time=t[i],
        force=data.force[i],
        elongation=e[i],
        mask=data.mask[i],
        lines=data.lines[i],
        force_raw=None,
    )
    data.metadata["breaking_load_N"] = RELAXATION_BREAKING_LOAD
    data.metadata["breaking_strain"] = BREAKING_STRAIN
    return data


def relaxation_paths() -> list[pathlib.Path]:
    """The relaxation files, by stretch."""
    return sorted(RELAXATION.glob("*.csv"))
