import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxcable


# 3 mm Dyneema SK78 (Park), with no breaking strain: the baselines' formulas are
# checked at any strain (Burgers' dashpot creeps 0.4 in an hour at 120 N).
CABLE = jaxcable.Cable(length=0.3, breaking_strain=math.inf)
AREA = float(CABLE.area)

TIME = np.array([0.0, 2.0, 5.0, 20.0, 60.0, 61.0, 70.0, 150.0, 151.0, 400.0])
FORCE = np.array([30.0, 60.0, 100.0, 100.0, 100.0, 40.0, 0.0, 0.0, 80.0, 80.0])


def _simulate(model, time=TIME, force=FORCE):
    return jaxcable.simulate_force_history(model, CABLE, time, force)


# ----------------------------------------------------------------------------------
# Closed forms


def test_hooke_exact():
    model = jaxcable.HookeModel(E=2.0e9)
    traj = _simulate(model)
    np.testing.assert_allclose(traj.strain, FORCE / (2.0e9 * AREA), rtol=1e-15)
    np.testing.assert_allclose(
        traj.elongation, FORCE * 0.3 / (2.0e9 * AREA), rtol=1e-15
    )
    assert np.all(traj.creep == 0)


def test_burgers_constant_load_matches_park_eq3():
    model = jaxcable.BurgersModel(E1=2.2e9, eta0=1.6e11, E2=3.7e8, eta2=3.7e10)
    force = 120.0
    sigma = force / AREA
    time = np.array([0.0, 0.5, 3.0, 10.0, 40.0, 100.0, 250.0, 600.0, 1500.0, 4000.0])
    traj = _simulate(model, time, np.full_like(time, force))
    t_c = 3.7e10 / 3.7e8
    creep = sigma / 3.7e8 * (1 - np.exp(-time / t_c)) + sigma * time / 1.6e11
    np.testing.assert_allclose(traj.creep, creep, rtol=1e-12, atol=1e-18)
    np.testing.assert_allclose(traj.strain, sigma / 2.2e9 + creep, rtol=1e-12)


def test_burgers_ramp_is_exact():
    """F = k t: the exact hereditary integral (docs/model_notes.md, point 4), on a coarse grid."""
    model = jaxcable.BurgersModel(E1=2.2e9, eta0=1.6e11, E2=3.7e8, eta2=3.7e10)
    k = 0.5  # N/s
    time = np.array([0.0, 1.0, 5.0, 20.0, 50.0, 80.0, 100.0, 150.0, 200.0, 300.0])
    traj = _simulate(model, time, k * time)
    t_c = 100.0
    expected = (
        k * time / (2.2e9 * AREA)
        + k * (time - t_c * -np.expm1(-time / t_c)) / (3.7e8 * AREA)
        + k * time**2 / (2 * 1.6e11 * AREA)
    )
    np.testing.assert_allclose(traj.strain, expected, rtol=1e-12, atol=1e-18)
    # The paper's equivalent-force form (F t / 2)(1 - exp(-t/t_c)) underestimates it.
    approx = (k * time / 2) * -np.expm1(-time / t_c) / (3.7e8 * AREA)
    kv = traj.creep - k * time**2 / (2 * 1.6e11 * AREA)
    assert np.all(approx[1:] < kv[1:])


def test_burgers_unloading_leaves_dashpot_set():
    # A Kelvin-Voigt time of 100 s: its decay over the 80 s rest is measurable.
    model = jaxcable.BurgersModel(E1=2.2e9, eta0=1.6e11, E2=3.7e8, eta2=3.7e10)
    traj = _simulate(model)
    # Unloaded from t = 70 s (sample 6) to 150 s (sample 7): the dashpot strain stays
    # and the Kelvin-Voigt strain decays as exp(-80 / t_c).
    impulse = np.sum(0.5 * (FORCE[1:7] + FORCE[:6]) * np.diff(TIME[:7]))
    dashpot = impulse / (float(model.eta0) * AREA)
    decay = np.exp(-80.0 * float(model.E2 / model.eta2))
    np.testing.assert_allclose(
        traj.strain[7] - dashpot, (traj.strain[6] - dashpot) * decay, rtol=1e-12
    )


# ----------------------------------------------------------------------------------
# Bouc-Wen: rate-independent, closed loop, dissipative


def _cyclic(cycles=4, half=10, peak=150.0):
    up = np.linspace(0.0, peak, half + 1)
    cycle = np.concatenate([up[:-1], up[::-1][:-1]])
    force = np.concatenate([np.tile(cycle, cycles), [0.0]])
    return np.arange(force.size, dtype=float), force, 2 * half


def test_bouc_wen_virgin_loading_matches_closed_form():
    # n = 1, loading from zeta = 0: zeta = A/(beta+gamma) (1 - exp(-(beta+gamma) s/sy)).
    time, force, period = _cyclic()
    sigma = force[: period // 2 + 1] / AREA
    zeta = 1.0 * (1 - np.exp(-1.2 * sigma / 2.5e6))
    expected = sigma / 2.2e9 + 2e-3 * (1.2 * sigma / 2.5e6 - zeta)
    model = jaxcable.BoucWenModel(sigma_y=2.5e6, A=1.2, beta=0.7, gamma=0.5, n=1.0)
    strain = np.asarray(_simulate(model, time, force).strain)
    np.testing.assert_allclose(strain[: period // 2 + 1], expected, rtol=5e-4)


def test_bouc_wen_integration_is_second_order():
    # One sample from the virgin state to 2 sigma_y: doubling the substeps divides the
    # error of zeta by about 4.
    sigma = 5e6
    exact = 1 - np.exp(-sigma / 2.5e6)
    errors = []
    for substeps in (8, 16):
        model = jaxcable.BoucWenModel(sigma_y=2.5e6, substeps=substeps)
        state, _ = eqx.filter_jit(model.advance)(
            model.init(CABLE),
            CABLE,
            jnp.array(1.0),
            jnp.array(sigma * AREA),
            jnp.array(1, jnp.int32),
        )
        errors.append(abs(float(state.zeta) - exact))
    assert 3.5 < errors[0] / errors[1] < 4.5
    assert errors[0] < 1e-3


def test_bouc_wen_closed_loop_no_creep_and_dissipative():
    model = jaxcable.BoucWenModel(sigma_y=2.5e6)
    time, force, period = _cyclic()
    traj = _simulate(model, time, force)
    strain = np.asarray(traj.strain)
    cycles = [strain[k * period : (k + 1) * period + 1] for k in range(4)]
    # After the virgin cycle the loop closes: the same strain at the same force.
    assert np.max(np.abs(cycles[1] - cycles[0])) > 1e-4
    np.testing.assert_allclose(cycles[2], cycles[1], rtol=1e-6, atol=0)
    np.testing.assert_allclose(cycles[3], cycles[2], rtol=1e-12, atol=0)
    # Dissipated energy per cycle, J: positive and the same each closed cycle.
    elongation = np.asarray(traj.elongation)
    energy = []
    for k in range(4):
        f = force[k * period : (k + 1) * period + 1]
        x = elongation[k * period : (k + 1) * period + 1]
        energy.append(np.sum(0.5 * (f[1:] + f[:-1]) * np.diff(x)))
    assert all(e > 0 for e in energy)
    np.testing.assert_allclose(energy[3], energy[2], rtol=1e-10)
    # Rate-independent: the same force samples at other times give the same strain,
    # and a held force does not creep.
    slow = _simulate(model, time * 1e3 + 7.0, force)
    np.testing.assert_allclose(slow.strain, strain, rtol=1e-14)
    hold_time = np.array([0.0, 1.0, 10.0, 1e3, 1e5])
    held = _simulate(model, hold_time, np.array([0.0, 100.0, 100.0, 100.0, 100.0]))
    assert np.all(held.strain[2:] == held.strain[1])


def _bouc_wen_drift(model, amplitude, cycles=100):
    """Change of zeta over `cycles` oscillations 100 N -+ `amplitude` (N), after a
    virgin loading to 100 N and a push to 100 N + `amplitude`, through the driver
    (which computes the direction of each step)."""
    force = np.concatenate(
        [
            np.linspace(0.0, 100.0, 21),
            [100.0 + amplitude],
            np.tile([100.0 - amplitude, 100.0 + amplitude], cycles),
        ]
    )
    strain = _simulate(model, np.arange(force.size, dtype=float), force).strain
    # Same stress at both ends: the strain changes by -z_y times the change of zeta.
    return -float(strain[-1] - strain[21]) / float(model.z_y)


def test_bouc_wen_noise_within_the_band_traces_no_loop():
    """Regression (issue 10): sign(d sigma) from the step's direction made every noise
    blip a reversal, tracing a minor loop whose dissipation moved zeta in proportion
    to the blip: a drift with the total variation of the noise. Within the play band
    the loading weight is a function of the stress alone: the band does not move,
    and zeta comes back when the stress does, up to the ROS2 steps' error, of third
    order in the blip (not exactly reversible)."""
    model = jaxcable.BoucWenModel()
    band = float(model.band) * AREA  # N
    for amplitude, per_cycle in ((0.9 * band, 5e-6), (0.09 * band, 1e-8)):
        assert abs(_bouc_wen_drift(model, amplitude)) < 100 * per_cycle
    # Noise larger than the band traces genuine minor loops (the band moves by
    # 2 (amplitude - band) each half cycle): zeta changes at first order.
    assert abs(_bouc_wen_drift(model, 1.5 * band)) > 1e-2
    # A band far below the blips is the classical flag: a first-order drift even
    # for blips of 1e-3 band (1 mN).
    assert abs(_bouc_wen_drift(jaxcable.BoucWenModel(band=1e-3), 1e-3 * band)) > 1e-5


def test_bouc_wen_is_classical_2_band_past_a_reversal():
    """Once the stress has moved 2 band past a reversal the weight is the sign of the
    stress change: the step is the classical Bouc-Wen's (here: the same as with a
    band of 100 Pa, 7e-4 N, from the same zeta; the weight of a band much narrower
    than the stress's rounding, ~1e-9 Pa here, is itself rounded)."""
    model = jaxcable.BoucWenModel()
    band = float(model.band)
    advance = eqx.filter_jit(model.advance)
    state, one = model.init(CABLE), jnp.array(1, jnp.int32)
    for force in (50.0, 100.0, 100.0 - 2 * band * AREA):
        state, _ = advance(state, CABLE, jnp.array(1.0), jnp.array(force), one)
    # w = 0 at the bottom of the band.
    np.testing.assert_allclose(state.centre, state.stress + band, rtol=1e-15)
    classical = jaxcable.BoucWenModel(band=100.0)
    twin = eqx.tree_at(lambda s: s.centre, state, state.stress + 100.0)
    for force in (60.0, 30.0, 0.0):
        state, parts = advance(state, CABLE, jnp.array(1.0), jnp.array(force), one)
        twin, twin_parts = eqx.filter_jit(classical.advance)(
            twin, CABLE, jnp.array(1.0), jnp.array(force), one
        )
        np.testing.assert_allclose(parts.instantaneous, twin_parts.instantaneous)
        np.testing.assert_allclose(state.zeta, twin.zeta, rtol=1e-11)


def test_bouc_wen_ignores_direction():
    model = jaxcable.BoucWenModel()
    state = model.init(CABLE)
    steps = [
        model.advance(state, CABLE, jnp.array(1.0), jnp.array(80.0), jnp.array(d))
        for d in (1, -1, 0)
    ]
    for other in steps[1:]:
        assert jax.tree.all(jax.tree.map(lambda a, b: a == b, steps[0], other))


# ----------------------------------------------------------------------------------
# Parameter validation

BAD = [0.0, -1.0, np.nan, np.inf]


@pytest.mark.parametrize(
    "cls, name",
    [(jaxcable.HookeModel, "E")]
    + [(jaxcable.BurgersModel, n) for n in ("E1", "eta0", "E2", "eta2")]
    + [
        (jaxcable.BoucWenModel, n) for n in ("E", "sigma_y", "z_y", "A", "beta", "band")
    ],
)
@pytest.mark.parametrize("bad", BAD)
def test_bad_parameter_raises(cls, name, bad):
    with pytest.raises(ValueError, match=name):
        cls(**{name: bad})


@pytest.mark.parametrize(
    "kwargs, name",
    [
        (dict(gamma=np.nan), "gamma"),
        (dict(gamma=0.7, beta=0.6), "gamma"),
        (dict(gamma=-0.7, beta=0.6), "gamma"),
        (dict(n=0.5), "n"),
        (dict(n=np.inf), "n"),
        (dict(z_y=1.0), "z_y"),
        (dict(substeps=0), "substeps"),
    ],
)
def test_bouc_wen_bad_shape_parameters(kwargs, name):
    with pytest.raises(ValueError, match=f"BoucWenModel.{name}`"):
        jaxcable.BoucWenModel(**kwargs)


def test_traced_bad_parameters_are_flagged():
    check = jax.jit(lambda v: jaxcable.BoucWenModel(gamma=v).check(CABLE))
    assert check(0.4) == jaxcable.RESULTS.successful
    assert check(0.9) == jaxcable.RESULTS.parameter_out_of_domain
    check = jax.jit(lambda v: jaxcable.BoucWenModel(band=v).check(CABLE))
    assert check(1e5) == jaxcable.RESULTS.successful
    assert check(0.0) == jaxcable.RESULTS.parameter_out_of_domain
    check = jax.jit(lambda v: jaxcable.BurgersModel(eta0=v).check(CABLE))
    assert check(-1.0) == jaxcable.RESULTS.parameter_out_of_domain
    check = jax.jit(lambda v: jaxcable.HookeModel(E=v).check(CABLE))
    assert check(jnp.nan) == jaxcable.RESULTS.parameter_out_of_domain


# ----------------------------------------------------------------------------------
# Gradients against finite differences; vmap over parameter sets against a loop

MODELS = {
    "hooke": (jaxcable.HookeModel(E=2.0e9), ("E",)),
    "burgers": (
        jaxcable.BurgersModel(E1=2.2e9, eta0=1.6e11, E2=3.7e8, eta2=3.7e10),
        ("E1", "eta0", "E2", "eta2"),
    ),
    "bouc_wen": (
        jaxcable.BoucWenModel(sigma_y=5e6, z_y=2e-3, A=1.1, beta=0.6, gamma=0.3, n=1.5),
        ("E", "sigma_y", "z_y", "A", "beta", "gamma", "n"),
    ),
}


def _loss_of_strain(strain):
    return jnp.sum((strain * 1e3) ** 2)


@pytest.mark.parametrize("key", MODELS)
def test_gradient_fd_and_vmap(key):
    model, names = MODELS[key]
    grad = eqx.filter_grad(lambda m: _loss_of_strain(_simulate(m).strain))(model)

    # All central-difference perturbations as one vmapped batch of parameter sets.
    rel = 1e-6
    perturbed = []
    for name in names:
        p = getattr(model, name)
        for sign in (1, -1):
            v = jnp.asarray(p * (1 + sign * rel))
            perturbed.append(eqx.tree_at(lambda m: getattr(m, name), model, v))
    batch = jax.tree.map(lambda *xs: jnp.stack(xs), *perturbed)
    strains = jax.vmap(lambda m: _simulate(m).strain)(batch)
    losses = np.asarray(jax.vmap(_loss_of_strain)(strains))
    for i, name in enumerate(names):
        p = float(getattr(model, name))
        fd = (losses[2 * i] - losses[2 * i + 1]) / (2 * rel * p)
        g = float(getattr(grad, name))
        # Compare d loss / d log p.
        np.testing.assert_allclose(g * p, fd * p, rtol=2e-6, atol=1e-9, err_msg=name)

    # vmap over parameter sets equals a Python loop.
    for i in (0, len(perturbed) - 1):
        single = _simulate(perturbed[i]).strain
        np.testing.assert_allclose(strains[i], single, rtol=1e-14, atol=0)
