"""Synthetic test data: Park's test protocol simulated by a model, plus realistic
measurement noise. Used for the bundled data set (`jaxcable/data/`, made by
`scripts/make_bundled_data.py`) and by tests that need data with known parameters."""

import numpy as np

from ._abstract import AbstractCableModel
from ._cable import Cable
from ._io import TestData
from ._protocol import Protocol
from ._simulate import simulate_rate_test


def park_protocol(
    force_max: float,
    *,
    cycles: int = 10,
    samples_per_ramp: int = 50,
    rest_hours: float = 24.0,
    rest_samples: int = 24,
) -> Protocol:
    """Park et al.'s long-term recovery protocol (Section 4): `cycles` load-unload
    cycles 0 -> `force_max` (N) -> 0 at constant crosshead speed, a rest of
    `rest_hours` at 0 N, then one more cycle to the same force (the re-stretch that
    measures the recovery)."""
    return Protocol.concatenate(
        Protocol.cycles(force_max, cycles, samples_per_ramp),
        Protocol.rest(rest_hours * 3600.0, rest_samples),
        Protocol.cycles(force_max, 1, samples_per_ramp, start=False),
    )


def synthesize(
    model: AbstractCableModel,
    cable: Cable,
    protocol: Protocol,
    *,
    seed: int,
    elongation_noise: float = 5e-6,
    force_noise: float = 0.05,
    temperature_C: float = 21.0,
    temperature_swing_C: float = 0.4,
    metadata: dict | None = None,
) -> TestData:
    """Simulate a rate-driven test and add measurement noise.

    **Arguments:**

    - `model`, `cable`, `protocol`: as in [`jaxcable.simulate_rate_test`][].
    - `seed`: seed of the noise (NumPy `default_rng`).
    - `elongation_noise`: standard deviation of the extensometer noise, m (5 um).
    - `force_noise`: standard deviation of the load-cell noise, N; forces stay >= 0.
    - `temperature_C`, `temperature_swing_C`: lab temperature, a daily sinusoid of this
        amplitude around this mean plus 0.05 C of sensor noise, °C (recorded only).
    - `metadata`: extra `# key: value` metadata.

    **Returns:**

    A [`jaxcable.TestData`][] with time, force, elongation and temperature.
    """
    traj = simulate_rate_test(model, cable, protocol)
    rng = np.random.default_rng(seed)
    time = np.asarray(traj.time, dtype=float)
    n = time.shape[0]
    force = np.clip(
        np.asarray(traj.force) + force_noise * rng.standard_normal(n), 0, None
    )
    elongation = np.asarray(traj.elongation) + elongation_noise * rng.standard_normal(n)
    temperature = (
        temperature_C
        + temperature_swing_C * np.sin(2 * np.pi * time / 86400.0 + rng.uniform(0, 6.3))
        + 0.05 * rng.standard_normal(n)
    )
    meta = {
        "length_mm": float(cable.length) * 1e3,
        "diameter_mm": float(cable.diameter) * 1e3,
        "rate_mm_per_min": float(cable.speed) * 6e4,
        "temperature_C": temperature_C,
    }
    meta.update(metadata or {})
    return TestData(
        time=time,
        force=force,
        elongation=elongation,
        temperature=temperature,
        metadata=meta,
    )


# The bundled data set: Park's protocol at two lengths, two crosshead speeds and two
# force levels, with rests of 24/48/72 h, simulated by the default IntegratedModel
# wrapped in ONE effect it lacks (a termination compliance of 2 um/N: splices and
# grips add 0.2 mm at 100 N whatever the length). `make demo` diagnoses it.
BUNDLED_EFFECT = "termination_compliance"
BUNDLED_COMPLIANCE = 2e-6  # m/N
_BUNDLED_LENGTHS_MM = (100.0, 300.0)
_BUNDLED_RATES_MM_PER_MIN = (3.0, 50.0)
_BUNDLED_FORCES_N = (100.0, 150.0)
_BUNDLED_REST_HOURS = (24.0, 48.0, 72.0)


def bundled_dataset(seed: int = 20261121) -> list[TestData]:
    """The tests of the bundled data set, regenerated from the model (see
    `scripts/make_bundled_data.py`, which writes them to `jaxcable/data/`).

    **Arguments:**

    - `seed`: the noise seed; each test uses `seed + index`.

    **Returns:**

    A list of eight [`jaxcable.TestData`][] with an `id` in their metadata.
    """
    from ._extensions import TerminationCompliance
    from ._integrated import IntegratedModel

    model = TerminationCompliance(IntegratedModel(), compliance=BUNDLED_COMPLIANCE)
    tests = []
    index = 0
    for length in _BUNDLED_LENGTHS_MM:
        for rate in _BUNDLED_RATES_MM_PER_MIN:
            for force in _BUNDLED_FORCES_N:
                rest = _BUNDLED_REST_HOURS[index % len(_BUNDLED_REST_HOURS)]
                cable = Cable(length=length * 1e-3, speed=rate * 1e-3 / 60)
                test_id = f"sk78-L{length:.0f}-v{rate:.0f}-F{force:.0f}-rest{rest:.0f}h"
                tests.append(
                    synthesize(
                        model,
                        cable,
                        park_protocol(force, rest_hours=rest),
                        seed=seed + index,
                        metadata={
                            "id": test_id,
                            "material": "Dyneema SK78 3 mm (synthetic)",
                            "rest_h": rest,
                        },
                    )
                )
                index += 1
    return tests
