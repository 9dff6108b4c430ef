"""Synthetic test data: Park's test protocol simulated by a model, plus realistic
measurement noise. Used for the bundled data set (`jaxcable/data/`, made by
`scripts/make_bundled_data.py`) and by tests that need data with known parameters."""

import equinox as eqx
import numpy as np

from .._cable import Cable
from .._drive import (
    Protocol,
    as_test_drive,
    simulate_force_history,
    simulate_rate_test,
)
from .._io import TestData
from .._models import (
    EXTENSIONS,
    PARK_IDENTIFIABLE,
    AbstractCableModel,
    IntegratedModel,
    TerminationCompliance,
)
from .hidden_effects import OUT_OF_CATALOGUE, effect_elongation
from .park import park_protocol


def synthesize(
    model: AbstractCableModel,
    cable: Cable,
    protocol: Protocol,
    *,
    seed: int,
    elongation_noise: float = 5e-6,
    force_noise: float = 0.05,
    force_deadband: float | None = None,
    temperature_C: float = 21.0,
    temperature_swing_C: float = 0.4,
    metadata: dict | None = None,
    added=None,
) -> TestData:
    """Simulate a rate-driven test and add measurement noise.

    **Arguments:**

    - `model`, `cable`, `protocol`: as in [`jaxcable.simulate_rate_test`][].
    - `seed`: seed of the noise (NumPy `default_rng`).
    - `elongation_noise`: standard deviation of the extensometer noise, m (5 um).
    - `force_noise`: standard deviation of the load-cell noise, N; forces stay >= 0.
    - `force_deadband`: readings below this are reported as 0 N, the zero suppression
        of a tester's load cell (default: 3 `force_noise`). Without it a resting
        cable would read the positive half of the noise (about 0.4 sigma on
        average), and a model driven by the readings would creep under it over a
        long rest: 0.02 N for 24 h adds about 0.15 mm to 300 mm of SK78 through
        Park's dashpot.
    - `temperature_C`, `temperature_swing_C`: lab temperature, a daily sinusoid of this
        amplitude around this mean plus 0.05 C of sensor noise, °C (recorded only).
    - `metadata`: extra `# key: value` metadata.
    - `added`: optional `added(time, force) -> (elongation, columns)`, an effect
        outside `model`: its elongation (m) is added to the simulated one before the
        noise, its columns (name -> values, recorded with their own noise) become
        `extra` columns. Given the noise-free time and force of the simulation.

    **Returns:**

    A [`jaxcable.TestData`][] with time, force, elongation and temperature (and the
    columns of `added`), and `control: force` in its metadata (fits drive it by its
    force history).
    """
    traj = simulate_rate_test(model, cable, protocol)
    rng = np.random.default_rng(seed)
    time = np.asarray(traj.time, dtype=float)
    n = time.shape[0]
    clean = np.asarray(traj.elongation, dtype=float)
    extra = {}
    if added is not None:
        more, extra = added(time, np.asarray(traj.force, dtype=float))
        clean = clean + more
    force = np.clip(
        np.asarray(traj.force) + force_noise * rng.standard_normal(n), 0, None
    )
    deadband = 3.0 * force_noise if force_deadband is None else force_deadband
    force = np.where(force < deadband, 0.0, force)
    elongation = clean + elongation_noise * rng.standard_normal(n)
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
        # The fits drive these tests by their recorded force history.
        "control": "force",
    }
    meta.update(metadata or {})
    return TestData(
        time=time,
        force=force,
        elongation=elongation,
        temperature=temperature,
        extra=extra,
        metadata=meta,
    )


def synthesize_history(
    model: AbstractCableModel,
    cable: Cable,
    time: np.ndarray,
    imposed: np.ndarray,
    *,
    drive,
    seed: int,
    relative_noise: float = 0.005,
    metadata: dict | None = None,
) -> tuple[TestData, float]:
    """A force- or displacement-controlled test simulated by `model`, with white
    noise on the measured (response) channel.

    **Arguments:**

    - `model`, `cable`: the truth.
    - `time`: sample times, s.
    - `imposed`: the imposed force (N, `drive="force"`: a creep test) or elongation
        (m, `drive="elongation"`: relaxation, a constant crosshead rate).
    - `drive`: [`jaxcable.FORCE_DRIVEN`][] or [`jaxcable.ELONGATION_DRIVEN`][], or
        its name (`"force"`, `"elongation"`); its name is written as the `control`
        metadata.
    - `seed`: seed of the noise (NumPy `default_rng`).
    - `relative_noise`: the noise standard deviation as a fraction of the response's
        peak (0.5 %); forces stay >= 0.
    - `metadata`: extra `# key: value` metadata.

    **Returns:**

    `(test, sigma)`: the [`jaxcable.TestData`][] and the noise standard deviation (m
    or N).
    """
    drive = as_test_drive(drive)
    time = np.asarray(time, float)
    imposed = np.asarray(imposed, float)
    rng = np.random.default_rng(seed)
    meta = {
        "length_mm": float(cable.length) * 1e3,
        "diameter_mm": float(cable.diameter) * 1e3,
        "control": drive.name,
        **(metadata or {}),
    }
    clean = np.asarray(drive.scored_of(drive.simulate(model, cable, time, imposed)))
    sigma = relative_noise * float(np.max(np.abs(clean)))
    measured = clean + sigma * rng.standard_normal(time.size)
    if drive.scores_force:
        measured = np.clip(measured, 0.0, None)
    channels = {drive.imposed: imposed, drive.scored: measured}
    test = TestData(time, channels["force"], channels["elongation"], metadata=meta)
    return test, sigma


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
    # Model fields convert numbers (`field_array`), which pyright does not see through
    # `fields.parameter`.
    model = TerminationCompliance(IntegratedModel(), compliance=BUNDLED_COMPLIANCE)  # pyright: ignore[reportArgumentType]
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


# ----------------------------------------------------------------------------------
# Data sets with one hidden effect: the diagnosis must name it.

# Six tests, a balanced design: each length, rate, force level and temperature
# appears twice (rates three times) and no two factors move together, so that the
# effects that depend on them (termination compliance on 1/L0, stress-nonlinear creep
# on force, temperature on T) are not confounded with one another.
# (length mm, crosshead speed mm/min, force N, temperature °C)
HIDDEN_EFFECT_DESIGN = (
    (100.0, 3.0, 120.0, 10.0),
    (200.0, 30.0, 160.0, 23.0),
    (300.0, 3.0, 80.0, 36.0),
    (100.0, 30.0, 80.0, 23.0),
    (200.0, 3.0, 160.0, 36.0),
    (300.0, 30.0, 120.0, 10.0),
)

# Each effect's size in the confusion matrix of docs/diagnosis.md ("size", its
# extension's SIZE_FIELD in SIZE_UNIT; at or just above the detection limit measured by
# `benchmarks/diagnose_matrix.py`), the weaker sizes of the sweep that found the limit,
# the size of the one-seed tests of `make test` (about 3x the limit, where detection is
# no coin toss) and the fixed values of the extension's other parameters. Re-measured
# for the delayed-elastic IntegratedModel (3 seeds per size, docs/diagnosis.md): its
# creep saturates within seconds, so the effects that scale or shift that creep
# (hereditary, stress_nonlinear_creep, temperature) need larger parameters than they
# did on the linear dashpot for the same few um of elongation.
HIDDEN_EFFECTS: dict[str, dict] = {
    # Provisional (not yet swept by `benchmarks/diagnose_matrix.py`): Park's beta
    # (gamma = 2) of a few um of elongation on these tests' 2-4 % strains.
    "hardening": {"size": 10.0, "weaker": (5.0,), "test": 30.0, "fixed": {}},
    "hereditary": {"size": 0.05, "weaker": (0.03,), "test": 0.15, "fixed": {}},
    "second_retardation": {
        "size": 1.5e11,
        "weaker": (3e11,),
        "test": 5e10,
        "fixed": {"tau_k": 1800.0},
    },
    "stress_nonlinear_creep": {
        "size": 5e-3,
        "weaker": (3e-3, 1e-3),
        "test": 1.5e-2,
        "fixed": {},
    },
    "temperature": {
        "size": 2000.0,
        "weaker": (1000.0, 500.0),
        "test": 6000.0,
        "fixed": {},
    },
    "termination_compliance": {
        "size": 2.5e-7,
        "weaker": (1.5e-7,),
        "test": 7.5e-7,
        "fixed": {},
    },
    "bedding_in": {
        "size": 3.5e-4,
        "weaker": (2e-4,),
        "test": 1e-3,
        "fixed": {"F_b": 60.0},
    },
    "sensor_drift": {
        "size": 9e-10,
        "weaker": (6e-10,),
        "test": 2.7e-9,
        "fixed": {},
    },
}


def hidden_effect_protocol(force_max: float) -> Protocol:
    """The protocol of every test of a hidden-effect data set (about 230 samples):
    two load-unload cycles to `force_max` (N), a 1 h creep hold, unloading and a 2 h
    rest; then the same loading, hold, unloading and rest once more. The repeat is
    the last ~30 % of the samples, so a blocked time split (`diagnose`'s default
    `holdout=0.3`) holds out a forecast of phases the fit has seen: creep under
    load, recovery at rest."""
    block = Protocol.concatenate(
        Protocol.ramp(0.0, force_max, 20),
        Protocol.hold(force_max, 600.0, 8),
        Protocol.hold(force_max, 3000.0, 8),
        Protocol.ramp(force_max, 0.0, 20),
        Protocol.rest(600.0, 8),
        Protocol.rest(6600.0, 10),
    )
    return Protocol.concatenate(Protocol.cycles(force_max, 2, 20), block, block)


def hidden_effect_model(
    effect: str | None,
    *,
    seed: int,
    size: float | None = None,
    spread: float = 0.1,
) -> AbstractCableModel:
    """The true model of a hidden-effect data set: the default
    [`jaxcable.IntegratedModel`][] with its six fitted parameters perturbed
    (log-normal, standard deviation `spread`, from `seed`), wrapped in the extension
    `effect` of the given `size` (its `SIZE_FIELD`; default `HIDDEN_EFFECTS`), or
    unwrapped for `effect=None`."""
    if effect is not None and effect not in EXTENSIONS:
        raise ValueError(
            f"`effect` must be None or one of {list(EXTENSIONS)}, got {effect!r}."
        )
    rng = np.random.default_rng(seed)
    base = IntegratedModel()
    # The parameters the diagnosis refits by default.
    factors = np.exp(spread * rng.standard_normal(len(PARK_IDENTIFIABLE)))
    base = eqx.tree_at(
        lambda m: [getattr(m, n) for n in PARK_IDENTIFIABLE],
        base,
        [getattr(base, n) * f for n, f in zip(PARK_IDENTIFIABLE, factors)],
    )
    if effect is None:
        return base
    cls = EXTENSIONS[effect]
    spec = HIDDEN_EFFECTS[effect]
    value = spec["size"] if size is None else size
    return cls(base, **{cls.SIZE_FIELD: value, **spec["fixed"]})


def _design_cable(length, rate, temp) -> Cable:
    """The cable of one row of `HIDDEN_EFFECT_DESIGN`."""
    return Cable(
        length=length * 1e-3, speed=rate * 1e-3 / 60, temperature=temp + 273.15
    )


def _adder(effect, cable, *, seed, index, size):
    """`synthesize`'s `added` for an out-of-catalogue effect."""

    def added(time, force):
        return effect_elongation(
            effect,
            time,
            force,
            length=float(cable.length),
            diameter=float(cable.diameter),
            size=size,
            seed=seed,
            index=index,
        )

    return added


def hidden_effect_dataset(
    effect: str | None,
    *,
    seed: int,
    size: float | None = None,
    elongation_noise: float = 5e-6,
    force_noise: float = 0.05,
) -> list[TestData]:
    """Tests from the base model plus exactly one hidden effect, with realistic noise.

    Six tests of `HIDDEN_EFFECT_DESIGN` (three lengths, two rates, three force levels,
    three temperatures) on the protocol of `hidden_effect_protocol`, simulated by
    `hidden_effect_model(effect, seed=seed, size=size)`, or for an effect outside the
    catalogue by the unwrapped base model plus the effect's elongation (see
    `jaxcable._papers.hidden_effects`); each test's noise is drawn from `seed` too.

    **Arguments:**

    - `effect`: an extension id of [`jaxcable.EXTENSIONS`][], an id of
        `OUT_OF_CATALOGUE`, or None (no effect).
    - `seed`: the seed of the base parameters and of the noise.
    - `size`: the effect's size in its extension's `SIZE_FIELD` unit, or its
        `OUT_OF_CATALOGUE` unit (default: the documented size).
    - `elongation_noise`, `force_noise`: standard deviations, m and N.

    **Returns:**

    Six [`jaxcable.TestData`][] with time, force, elongation and temperature (and
    the effect's covariate columns, e.g. `humidity_pct` for `mechano_sorptive`).
    """
    outside = effect in OUT_OF_CATALOGUE
    model = hidden_effect_model(None if outside else effect, seed=seed, size=size)

    def added(cable, i):
        return _adder(effect, cable, seed=seed, index=i, size=size) if outside else None

    noise = (elongation_noise, force_noise)
    return design_tests(model, seed, effect or "none", noise, added)


def design_tests(model, seed: int, label: str, noise, added=None) -> list[TestData]:
    """The six tests of `HIDDEN_EFFECT_DESIGN` simulated by `model`, each with the
    noise `noise = (elongation_noise m, force_noise N)` drawn from `seed` and the
    test's index, and `label` as its `hidden_effect` metadata; `added(cable, i)`, when
    given, is the elongation added to test `i` (an effect outside the catalogue)."""
    tests = []
    for i, (length, rate, force, temp) in enumerate(HIDDEN_EFFECT_DESIGN):
        cable = _design_cable(length, rate, temp)
        tests.append(
            synthesize(
                model,
                cable,
                hidden_effect_protocol(force),
                seed=seed * 1000 + i,
                elongation_noise=noise[0],
                force_noise=noise[1],
                temperature_C=temp,
                temperature_swing_C=0.0,
                metadata={
                    "id": f"L{length:.0f}-v{rate:.0f}-F{force:.0f}-T{temp:.0f}",
                    "hidden_effect": label,
                },
                added=None if added is None else added(cable, i),
            )
        )
    return tests


def truth_elongations(
    effect: str | None,
    *,
    seed: int,
    size: float | None = None,
    tests: list[TestData] | None = None,
) -> list[np.ndarray]:
    """The data-generating model's elongation of every test of
    `hidden_effect_dataset(effect, seed=seed, size=size)`, m: the reference for the
    true model's held-out gain.

    **Arguments:**

    - `effect`, `seed`, `size`: as in `hidden_effect_dataset`.
    - `tests`: None for the noise-free truth (the protocol's exact force); or the
        data set's tests, to drive the true model by their recorded force (and
        recorded covariates), as a diagnosis drives every model it scores.

    **Returns:**

    One array per test, the elongation at its samples, m.
    """
    outside = effect in OUT_OF_CATALOGUE
    model = hidden_effect_model(None if outside else effect, seed=seed, size=size)
    out = []
    for i, (length, rate, force, temp) in enumerate(HIDDEN_EFFECT_DESIGN):
        cable = _design_cable(length, rate, temp)
        if tests is None:
            traj = simulate_rate_test(model, cable, hidden_effect_protocol(force))
            time, f, humidity = np.asarray(traj.time), np.asarray(traj.force), None
        else:
            t = tests[i]
            time, f = np.asarray(t.time, float), np.asarray(t.force, float)
            traj = simulate_force_history(model, cable, time, f)
            humidity = t.extra.get("humidity_pct")
        e = np.asarray(traj.elongation, dtype=float)
        if outside:
            kw = dict(length=float(cable.length), diameter=float(cable.diameter))
            e = (
                e
                + effect_elongation(
                    effect,
                    time,
                    f,
                    size=size,
                    seed=seed,
                    index=i,
                    humidity=humidity,
                    **kw,
                )[0]
            )
        out.append(e)
    return out
