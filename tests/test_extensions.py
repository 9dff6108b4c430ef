"""The candidate model extensions of the diagnosis.

Each extension wraps any base model; at its null effect it is the base exactly; each
test below checks one closed form of its physics, composability, jit/vmap and the
gradient of every effect parameter against finite differences (float64)."""

import dataclasses
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxcable as jc
from jaxcable import (
    EXTENSIONS,
    BeddingIn,
    Hereditary,
    SecondRetardation,
    SensorDrift,
    StressNonlinearCreep,
    TemperatureShift,
    TemperatureShiftWLF,
    TerminationCompliance,
    log_shift_arrhenius,
    log_shift_wlf,
)
from jaxcable.internal import parameter_info

from .helpers import PARK_CABLE as CABLE, PARK_MODEL as BASE


ORDER = (
    "hardening",
    "hereditary",
    "second_retardation",
    "stress_nonlinear_creep",
    "temperature",
    "termination_compliance",
    "bedding_in",
    "sensor_drift",
)


def _history(n=81):
    """Load to 100 N in 100 s, hold to 600 s, unload to 0 N by 700 s, rest to 2000 s;
    then reload to 60 N (s, N)."""
    time = np.concatenate(
        [
            np.linspace(0.0, 100.0, 21),
            np.linspace(150.0, 600.0, 10),
            np.linspace(625.0, 700.0, 4),
            np.linspace(800.0, 2000.0, 13),
            np.linspace(2010.0, 2100.0, n - 48),
        ]
    )
    force = np.interp(time, [0, 100, 600, 700, 2000, 2100], [0, 100, 100, 0, 0, 60])
    return jnp.asarray(time), jnp.asarray(force)


TIME, FORCE = _history()


def _simulate(model, cable=CABLE, time=TIME, force=FORCE):
    return jc.simulate_force_history(model, cable, time, force)


NULL = {
    "hardening": lambda b: jc.Hardening(b, beta=0.0),
    "hereditary": lambda b: Hereditary(b, weight=0.0),
    "second_retardation": lambda b: SecondRetardation(b, E_k=jnp.inf, tau_k=50.0),
    "stress_nonlinear_creep": lambda b: StressNonlinearCreep(b, n=0.0),
    "temperature": lambda b: TemperatureShift(b, activation_energy=0.0),
    "termination_compliance": lambda b: TerminationCompliance(b, compliance=0.0),
    "bedding_in": lambda b: BeddingIn(b, s_b=0.0, F_b=30.0),
    "sensor_drift": lambda b: SensorDrift(b, drift_rate=0.0),
}


# ----------------------------------------------------------------------------------
# Interface


def test_registry_and_class_interface():
    assert tuple(EXTENSIONS) == ORDER
    for ext_id, cls in EXTENSIONS.items():
        assert cls.EXTENSION_ID == ext_id
        fields = {f.name for f in dataclasses.fields(cls)}
        assert set(cls.EFFECT_FIELDS) <= fields, cls
        assert cls.SIZE_FIELD in cls.EFFECT_FIELDS
        assert isinstance(cls.SIZE_UNIT, str) and cls.SIZE_UNIT
        infos = {n: parameter_info(cls, n) for n in fields}
        assert {n for n, i in infos.items() if i is not None} == set(cls.EFFECT_FIELDS)
        for name in cls.EFFECT_FIELDS:
            assert infos[name].transform in ("log", "linear") and infos[name].unit
        model = cls.wrap(BASE)
        assert isinstance(model, cls) and model.base is BASE
        for name in cls.EFFECT_FIELDS:
            value = float(getattr(model, name))
            assert math.isfinite(value) and value != 0.0, (ext_id, name)
            if infos[name].transform == "log":
                assert value > 0


# ----------------------------------------------------------------------------------
# Null effect == base


@pytest.mark.parametrize("ext_id", ORDER)
def test_null_effect_is_base(ext_id):
    cable = jc.Cable(length=0.3, temperature=330.0)  # away from T_ref
    base = _simulate(BASE, cable)
    ext = _simulate(NULL[ext_id](BASE), cable)
    # Equal to rounding: the wrapper's "+ 0" compiles to a differently fused graph,
    # which may differ from the base in the last bit.
    np.testing.assert_allclose(ext.elongation, base.elongation, rtol=1e-13, atol=0)
    np.testing.assert_allclose(ext.time, base.time, rtol=1e-13, atol=0)


def test_start_values_change_the_model():
    base = _simulate(BASE).elongation
    for ext_id, cls in EXTENSIONS.items():
        cable = CABLE
        if ext_id == "temperature":
            cable = jc.Cable(length=0.3, temperature=313.15)
        diff = np.max(np.abs(_simulate(cls.wrap(BASE), cable).elongation - base))
        assert 1e-7 < diff < 5e-3, (ext_id, diff)  # informative, but small (m)


# ----------------------------------------------------------------------------------
# Physics


def test_second_retardation_kelvin_voigt_creep_and_recovery():
    E_k, tau_k, F = 2e9, 40.0, 80.0
    base = jc.HookeModel()
    time = jnp.linspace(0.0, 400.0, 201)
    force = jnp.where(time <= 200.0, F, jnp.maximum(F * (1 - (time - 200.0)), 0.0))
    force = force.at[0].set(F)  # applied at t = 0
    ext = _simulate(SecondRetardation(base, E_k=E_k, tau_k=tau_k), CABLE, time, force)
    ref = _simulate(base, CABLE, time, force)
    extra = np.asarray(ext.strain - ref.strain)
    hold = np.asarray(time) <= 200.0
    expected = F / (CABLE.area * E_k) * -np.expm1(-np.asarray(time)[hold] / tau_k)
    np.testing.assert_allclose(extra[hold], expected, rtol=1e-12, atol=1e-17)
    # at rest it recovers exponentially with tau_k
    rest = np.asarray(time) >= 202.0
    ratio = extra[rest][1:] / extra[rest][:-1]
    np.testing.assert_allclose(ratio, math.exp(-2.0 / tau_k), rtol=1e-10)


def test_sensor_drift_is_linear_in_time():
    r = -3e-9
    time, force = TIME + 5.0, FORCE  # t0 = 5 s
    ext = _simulate(SensorDrift(BASE, drift_rate=r), CABLE, time, force)
    ref = _simulate(BASE, CABLE, time, force)
    np.testing.assert_allclose(
        ext.elongation - ref.elongation, r * (time - 5.0), rtol=1e-9, atol=1e-15
    )


def test_bedding_in_depends_only_on_the_largest_force():
    s_b, F_b = 2e-3, 40.0
    model = BeddingIn(jc.HookeModel(), s_b=s_b, F_b=F_b)
    time = jnp.linspace(0.0, 60.0, 61)
    # one load to 70 N, versus three cycles to 50, 70, 60 N; both end at 20 N
    once = jnp.interp(time, jnp.array([0.0, 30.0, 60.0]), jnp.array([0.0, 70.0, 20.0]))
    knots = jnp.array([0.0, 10.0, 20.0, 30.0, 40.0, 50.0, 60.0])
    three = jnp.interp(time, knots, jnp.array([0.0, 50.0, 0.0, 70.0, 10.0, 60.0, 20.0]))
    a = _simulate(model, CABLE, time, once)
    b = _simulate(model, CABLE, time, three)
    hooke = _simulate(jc.HookeModel(), CABLE, time, once)
    bed_a = np.asarray(a.strain - hooke.strain)
    expected = s_b * -math.expm1(-70.0 / F_b)
    # the smooth max lags a rising force by <= smoothing / 2 = 0.005 N
    tol = s_b * math.exp(-70.0 / F_b) / F_b * 0.01
    assert abs(bed_a[-1] - expected) < tol
    assert abs(float(b.strain[-1] - a.strain[-1])) < tol
    # permanent: constant after the peak while the force falls
    np.testing.assert_allclose(bed_a[30:], bed_a[30], rtol=0, atol=1e-15)


def test_termination_compliance_same_millimetres_at_two_lengths():
    c = 2e-6
    diffs = []
    for length in (0.1, 0.3):
        cable = jc.Cable(length=length)
        ext = _simulate(TerminationCompliance(BASE, compliance=c), cable)
        ref = _simulate(BASE, cable)
        diffs.append(np.asarray(ext.elongation - ref.elongation))
    np.testing.assert_allclose(diffs[0], c * FORCE, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(diffs[1], c * FORCE, rtol=1e-9, atol=1e-15)


def test_temperature_shift_factor_laws():
    assert float(log_shift_arrhenius(293.15, 1e5, 293.15)) == 0.0
    assert float(log_shift_wlf(293.15, 17.4, 51.6, 293.15)) == 0.0
    # Arrhenius: E_a / (R ln 10) (1/T - 1/T_ref)
    expected = 1e5 / (8.314462618 * math.log(10)) * (1 / 313.15 - 1 / 293.15)
    assert float(log_shift_arrhenius(313.15, 1e5, 293.15)) == pytest.approx(expected)
    assert float(log_shift_wlf(303.15, 17.4, 51.6, 293.15)) == pytest.approx(
        -17.4 * 10 / 61.6
    )
    model = TemperatureShift(BASE, activation_energy=1e5)
    assert float(model.log_shift(293.15)) == 0.0
    assert float(model.log_shift(313.15)) < 0 < float(model.log_shift(273.15))


def test_temperature_reduced_time_and_hotter_creeps_faster():
    model = TemperatureShift(BASE, activation_energy=8e4)
    at_ref = _simulate(model, jc.Cable(length=0.3, temperature=293.15))
    np.testing.assert_array_equal(at_ref.elongation, _simulate(BASE).elongation)
    creep = {}
    for T in (273.15, 293.15, 313.15):
        traj = _simulate(model, jc.Cable(length=0.3, temperature=T))
        # Creep accrued by the end of the 100 s ramp (the delayed-elastic elements
        # of the base saturate within seconds of the hold).
        creep[T] = float(traj.parts.creep[20])
    assert creep[273.15] < creep[293.15] < creep[313.15]
    # time-temperature superposition: at T the model is the base on t / a_T
    T = 313.15
    a_T = 10.0 ** float(model.log_shift(T))
    hot = _simulate(model, jc.Cable(length=0.3, temperature=T))
    reduced = _simulate(BASE, jc.Cable(length=0.3, speed=CABLE.speed * a_T), TIME / a_T)
    np.testing.assert_allclose(hot.elongation, reduced.elongation, rtol=1e-10)
    # WLF as well
    wlf = TemperatureShiftWLF(BASE, c1=5.0, c2=60.0)
    a_T = 10.0 ** float(wlf.log_shift(T))
    hot = _simulate(wlf, jc.Cable(length=0.3, temperature=T))
    reduced = _simulate(BASE, jc.Cable(length=0.3, speed=CABLE.speed * a_T), TIME / a_T)
    np.testing.assert_allclose(hot.elongation, reduced.elongation, rtol=1e-10)


def test_hereditary_ramp_matches_exact_superposition():
    # docs/model_notes.md, point 4: under F = F0 + k t (F0 applied at t = 0) the exact
    # Kelvin-Voigt creep of (E2c, t_c) is [F0 (1 - e) + k (t - t_c (1 - e))] / (E2c A),
    # e = exp(-t / t_c), and Park's equivalent-force reading of it is
    # (I / t)(1 - e) / (E2c A); the extension adds w times their difference. F0 = 1 N
    # is above the 0.2 N where the tension clock ramps in
    # (the kernels' `tension_time_step`), so the clock is the real time.
    k, f0 = 0.5, 1.0  # N/s, N
    time = jnp.linspace(0.0, 200.0, TIME.shape[0])
    force = f0 + k * time
    ext = _simulate(Hereditary(BASE, weight=1.0), CABLE, time, force)
    base = _simulate(BASE, CABLE, time, force)
    area = CABLE.area
    t = np.asarray(time)
    impulse = f0 * t + 0.5 * k * t**2
    t_c, E2c = float(BASE.t_c), float(BASE.E2c)
    relaxed = -np.expm1(-t / t_c)
    exact = (f0 * relaxed + k * (t - t_c * relaxed)) / (E2c * area)
    equivalent = impulse[1:] / t[1:] * relaxed[1:] / (E2c * area)
    added = np.asarray(ext.parts.creep - base.parts.creep)
    np.testing.assert_allclose(added[1:], exact[1:] - equivalent, rtol=1e-9)


def test_hereditary_runs_on_the_base_clock():
    """Regression: the clock of the exact Kelvin-Voigt term is the base's
    continuous tension clock. A rest held at exactly the old switching force (1e-4 of
    the breaking load, 0.2 N) with +-1e-9 N of noise switched whole steps of
    relaxation on and off; now the strain moves by a multiple of the noise."""
    n = TIME.shape[0]
    f_old = 1e-4 * float(CABLE.breaking_load)  # the old switch
    time = jnp.asarray(
        np.concatenate([[0.0, 100.0, 400.0, 500.0], 500 + 20.0 * np.arange(1, n - 3)])
    )
    clean = np.concatenate([[0.0, 100.0, 100.0, f_old], np.full(n - 4, f_old)])
    noise = 1e-9 * (-1.0) ** np.arange(n)
    noise[:4] = 0.0
    model = Hereditary(BASE, weight=1.0)
    a = _simulate(model, CABLE, time, jnp.asarray(clean))
    b = _simulate(model, CABLE, time, jnp.asarray(clean + noise))
    # The clock moves by at most (rest length) d / F_on ~ 1500 s x 1e-9 N / 10 N (F_on
    # is >= 0.2 N, here a tenth of the 100 N peak), and the strain by that times
    # (Kelvin-Voigt strain) / t_c ~ 3e-3 / 8.6 s: ~5e-11 (bound 1e-6). The old switch
    # relaxed the whole rest: ~3e-3.
    assert np.max(np.abs(np.asarray(a.strain - b.strain))) < 1e-9 * 1e3


def test_stress_nonlinear_creep_power_law():
    n = 0.7
    model = StressNonlinearCreep(BASE, n=n)
    gain = (200.0 / CABLE.area / float(model.stress_ref)) ** n
    # at sigma_ref (100 N) the base; a force step to 200 N within 1 us leaves the
    # extra creep (a state variable) unchanged; from then on the base's creep
    # increments are scaled by (sigma / sigma_ref)^n
    time = np.linspace(0.0, 600.0, TIME.shape[0])
    step = 40
    time[step] = time[step - 1] + 1e-6
    force = np.where(np.arange(time.size) < step, 100.0, 200.0)
    ext = _simulate(model, CABLE, jnp.asarray(time), jnp.asarray(force))
    ref = _simulate(BASE, CABLE, jnp.asarray(time), jnp.asarray(force))
    extra = np.asarray(ext.parts.creep - ref.parts.creep)
    creep = np.asarray(ref.parts.creep)
    np.testing.assert_array_equal(extra[:step], 0.0)
    assert abs(extra[step]) < 1e-6 * creep[step]
    np.testing.assert_allclose(
        extra[step + 1 :] - extra[step],
        (gain - 1) * (creep[step + 1 :] - creep[step]),
        rtol=1e-9,
    )


def test_stress_nonlinear_creep_no_drift_when_the_base_creep_is_stationary():
    """Regression: each creep increment was scaled by g when positive and
    by the extra/creep share when negative. Where the base creep is stationary, force
    noise flips the sign of every increment, and the extra creep drifted with the
    total variation of the noise (towards (g - 1) creep). Now it follows the base
    creep's running maximum: no drift."""
    n, E_k, tau_k, d = 0.5, 1e10, 10.0, 1e-3
    hooke = jc.HookeModel()
    model = StressNonlinearCreep(SecondRetardation(hooke, E_k, tau_k), n=n)
    # 200 N until the element is relaxed, then 150 N (the base creep recovers to
    # its 150 N value and stays there), with +-d alternating noise from t = 600 s.
    time = jnp.linspace(0.0, 4000.0, 400)
    clean = jnp.where(time < 300.0, 200.0, 150.0)
    noise = d * (-1.0) ** jnp.arange(time.shape[0]) * (time > 600.0)
    a = _simulate(model, CABLE, time, clean)
    b = _simulate(model, CABLE, time, clean + noise)
    # The spring moves by d / (A E), the base creep (a Kelvin-Voigt strain) by
    # <= d / (A E_k), the extra creep by (X / M) = g(200 N) - 1 times that. The old
    # reading drifted to ~1.6 times this bound over these 340 noisy samples.
    g_max = (200.0 / CABLE.area / model.stress_ref) ** n
    bound = d / CABLE.area * (1 / hooke.E + g_max / E_k)
    assert np.max(np.abs(np.asarray(a.strain - b.strain))) < bound
    # Below its largest value the extra creep follows the base creep at the
    # proportion it was laid down with, X / M = g(200 N) - 1.
    creep = np.asarray(_simulate(model.base, CABLE, time, clean).parts.creep)
    extra = np.asarray(a.parts.creep) - creep
    late = np.asarray(time) > 400.0
    np.testing.assert_allclose(extra[late] / creep[late], g_max - 1.0, rtol=1e-3)


def test_hereditary_rejects_linear_bases():
    for base in (jc.HookeModel(), jc.BurgersModel(), jc.FiveElementModel()):
        with pytest.raises(ValueError, match="already exact"):
            Hereditary(base)
    # found through other extensions
    Hereditary(SensorDrift(BeddingIn(BASE)))


# ----------------------------------------------------------------------------------
# Composability, jit, vmap, rate tests


def _all_nested():
    model = Hereditary(BASE, weight=0.5)
    model = TemperatureShift(model, activation_energy=3e4)
    model = SecondRetardation(model, E_k=2e10, tau_k=300.0)
    model = StressNonlinearCreep(model, n=0.2)
    model = TerminationCompliance(model, compliance=1e-6)
    model = BeddingIn(model, s_b=1e-4, F_b=30.0)
    return SensorDrift(model, drift_rate=2e-9)


def test_two_nested_add_up():
    drift = SensorDrift(BASE, drift_rate=2e-9)
    bed = BeddingIn(BASE, s_b=1e-4, F_b=30.0)
    both = SensorDrift(BeddingIn(BASE, s_b=1e-4, F_b=30.0), drift_rate=2e-9)
    base = _simulate(BASE).elongation
    expected = (_simulate(drift).elongation - base) + (_simulate(bed).elongation - base)
    np.testing.assert_allclose(
        _simulate(both).elongation - base, expected, rtol=1e-9, atol=1e-15
    )


def test_a_material_effect_never_scales_the_drift():
    # The drift is the instrument's (the apparatus part), so a stress-dependent creep
    # leaves it alone in either nesting: the rounds of the diagnosis nest the causes
    # in the order they find them, not the order the data were made in.
    outside = StressNonlinearCreep(SensorDrift(BASE, drift_rate=2e-9), n=0.7)
    inside = SensorDrift(StressNonlinearCreep(BASE, n=0.7), drift_rate=2e-9)
    a, b = _simulate(outside), _simulate(inside)
    np.testing.assert_allclose(a.elongation, b.elongation, rtol=1e-12, atol=1e-15)
    drift = SensorDrift(BASE, drift_rate=2e-9)
    np.testing.assert_allclose(
        _simulate(drift).apparatus * CABLE.length, 2e-9 * (TIME - TIME[0]), rtol=1e-9
    )
    np.testing.assert_array_equal(_simulate(drift).creep, _simulate(BASE).creep)


def _cables(lengths, temperatures):
    n = len(lengths)
    return jc.Cable(
        length=jnp.asarray(lengths),
        diameter=jnp.full(n, 3e-3),
        speed=jnp.full(n, CABLE.speed),
        breaking_load=jnp.full(n, 2000.0),
        breaking_strain=jnp.full(n, jc.DEFAULT_BREAKING_STRAIN),
        temperature=jnp.asarray(temperatures),
    )


def test_vmap_over_cables_and_drift_rates():
    model = TemperatureShift(SensorDrift(BASE, drift_rate=2e-9), activation_energy=3e4)
    lengths, temperatures = [0.1, 0.3], [283.15, 303.15]
    batched = jax.vmap(
        lambda c: jc.simulate_force_history(model, c, TIME, FORCE).elongation
    )(_cables(lengths, temperatures))
    for i in range(2):
        cable = jc.Cable(length=lengths[i], temperature=temperatures[i])
        one = _simulate(model, cable).elongation
        np.testing.assert_allclose(batched[i], one, rtol=1e-12, atol=1e-18)
    # a batch of parameter sets: vmap over the effect parameter
    rates = jnp.array([-1e-9, 3e-9])
    by_rate = jax.vmap(lambda r: _simulate(SensorDrift(BASE, drift_rate=r)).elongation)(
        rates
    )
    base = _simulate(BASE).elongation
    np.testing.assert_allclose(
        by_rate - base, rates[:, None] * (TIME - TIME[0]), rtol=1e-9, atol=1e-15
    )


@pytest.mark.slow
def test_all_nested_jit_vmap_and_rate_test():
    model = _all_nested()
    lengths, temperatures = [0.1, 0.3], [283.15, 303.15]
    cables = _cables(lengths, temperatures)
    batched = jax.vmap(
        lambda c: jc.simulate_force_history(model, c, TIME, FORCE).elongation
    )(cables)
    for i in range(2):
        cable = jc.Cable(length=lengths[i], temperature=temperatures[i])
        one = _simulate(model, cable).elongation
        np.testing.assert_allclose(batched[i], one, rtol=1e-12, atol=1e-18)
    jitted = eqx.filter_jit(_simulate)(model, CABLE).elongation
    np.testing.assert_allclose(jitted, _simulate(model).elongation, rtol=1e-12)
    # the rate-driven Newton solve goes through every extension
    protocol = jc.Protocol.concatenate(
        jc.Protocol.cycles(100.0, cycles=2, samples_per_ramp=40),
        jc.Protocol.rest(3600.0, samples=6),
    )
    traj = jc.simulate_rate_test(model, CABLE, protocol)
    assert bool(jnp.all(jnp.isfinite(traj.elongation)))
    assert traj.result == jc.RESULTS.successful


# ----------------------------------------------------------------------------------
# Gradients against finite differences (float64)

GRADIENT_CASES = [
    ("hereditary", "weight", Hereditary(BASE, weight=0.3), CABLE),
    ("second_retardation", "E_k", SecondRetardation.wrap(BASE), CABLE),
    ("second_retardation", "tau_k", SecondRetardation.wrap(BASE), CABLE),
    ("stress_nonlinear_creep", "n", StressNonlinearCreep.wrap(BASE), CABLE),
    (
        "temperature",
        "activation_energy",
        TemperatureShift.wrap(BASE),
        jc.Cable(length=0.3, temperature=313.15),
    ),
    ("termination_compliance", "compliance", TerminationCompliance.wrap(BASE), CABLE),
    ("bedding_in", "s_b", BeddingIn.wrap(BASE), CABLE),
    ("bedding_in", "F_b", BeddingIn.wrap(BASE), CABLE),
    ("sensor_drift", "drift_rate", SensorDrift.wrap(BASE), CABLE),
]


def _loss(value, model, name, cable):
    model = eqx.tree_at(lambda m: getattr(m, name), model, value)
    traj = jc.simulate_force_history(model, cable, TIME, FORCE)
    return jnp.sum(traj.elongation * jnp.linspace(1.0, 2.0, TIME.shape[0])) * 1e3


@pytest.mark.parametrize(
    "ext_id, name, model, cable",
    [
        c if c[1] == "E_k" else pytest.param(*c, marks=pytest.mark.slow)
        for c in GRADIENT_CASES
    ],
    ids=[f"{c[0]}-{c[1]}" for c in GRADIENT_CASES],
)
def test_gradient_matches_finite_differences(ext_id, name, model, cable):
    value = jnp.asarray(getattr(model, name), jnp.float64)
    grad = jax.grad(_loss)(value, model, name, cable)
    h = 1e-5 * abs(float(value))
    fd = (
        _loss(value + h, model, name, cable) - _loss(value - h, model, name, cable)
    ) / (2 * h)
    assert float(jnp.abs(grad)) > 0
    np.testing.assert_allclose(float(grad), float(fd), rtol=1e-6)


# ----------------------------------------------------------------------------------
# Bad inputs


BAD = [
    (Hereditary, "weight", -0.1),
    (Hereditary, "weight", np.nan),
    (SecondRetardation, "E_k", 0.0),
    (SecondRetardation, "E_k", np.nan),
    (SecondRetardation, "tau_k", -1.0),
    (SecondRetardation, "tau_k", np.inf),
    (StressNonlinearCreep, "n", -0.5),
    (StressNonlinearCreep, "stress_ref", 0.0),
    (TemperatureShift, "activation_energy", -1.0),
    (TemperatureShift, "T_ref", 0.0),
    (TemperatureShiftWLF, "c1", np.inf),
    (TemperatureShiftWLF, "c2", -5.0),
    (TerminationCompliance, "compliance", -1e-6),
    (BeddingIn, "s_b", -1e-4),
    (BeddingIn, "F_b", 0.0),
    (BeddingIn, "smoothing", 0.0),
    (SensorDrift, "drift_rate", np.nan),
]


@pytest.mark.parametrize(
    "cls, name, value", BAD, ids=[f"{c.__name__}-{n}-{v}" for c, n, v in BAD]
)
def test_bad_values_raise_naming_the_field(cls, name, value):
    with pytest.raises(ValueError, match=f"`{name}`"):
        cls(BASE, **{name: value})


def test_traced_check_flags_bad_values():
    for model in (
        eqx.tree_at(lambda m: m.n, StressNonlinearCreep.wrap(BASE), -1.0),
        eqx.tree_at(lambda m: m.F_b, BeddingIn.wrap(BASE), 0.0),
        eqx.tree_at(lambda m: m.tau_k, SecondRetardation.wrap(BASE), -1.0),
    ):
        result = model.check(CABLE)
        assert result == jc.RESULTS.parameter_out_of_domain
    # and a bad base parameter is flagged through the wrapper
    bad_base = eqx.tree_at(lambda m: m.E2c, BASE, -1.0)
    assert SensorDrift.wrap(bad_base).check(CABLE) == (
        jc.RESULTS.parameter_out_of_domain
    )
    assert SensorDrift.wrap(BASE).check(CABLE) == jc.RESULTS.successful
    # WLF outside its domain (C2 + T - T_ref <= 0)
    wlf = TemperatureShiftWLF(BASE, c1=5.0, c2=10.0)
    cold = jc.Cable(length=0.3, temperature=273.15)
    assert wlf.check(cold) == jc.RESULTS.parameter_out_of_domain
