import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxcable
from jaxcable.internal import kelvin_voigt_step

from .helpers import asymmetric_five_element, floats


FIELDS = (
    "E_L1",
    "E_L2",
    "E_L3",
    "eta_L2",
    "eta_L3",
    "E_UL1",
    "E_UL2",
    "E_UL3",
    "eta_UL2",
    "eta_UL3",
)

CABLE = jaxcable.Cable(length=7.4, diameter=6e-3, breaking_load=20000.0)

# Distinct, compliant parameters (seconds-scale retardation times) so that every term
# of Eq. 1-3 is visible in the strain.
LINEAR = dict(E_L1=2.0e10, E_L2=9.5e9, E_L3=5.0e10, eta_L2=1.0e10, eta_L3=1.0e12)


def _linear_model(**overrides):
    """Equal loading and unloading parameters: the linear five-element solid."""
    params = dict(LINEAR)
    params.update(overrides)
    unloading = {k.replace("_L", "_UL"): v for k, v in params.items()}
    return jaxcable.FiveElementModel(**params, **unloading)


def _compliance(model, t):
    """Creep compliance J(t) of Piao Eq. 1 (loading parameters), 1/Pa."""
    m = floats(model)
    return (
        1 / m.E_L1
        + (1 - np.exp(-m.E_L2 * t / m.eta_L2)) / m.E_L2
        + (1 - np.exp(-m.E_L3 * t / m.eta_L3)) / m.E_L3
    )


def _ramp_integral(model, t, start, end):
    """int_start^end J(t - s) ds for t >= end (the response to a unit stress rate)."""
    model = floats(model)
    out = (end - start) / model.E_L1
    for E, eta in ((model.E_L2, model.eta_L2), (model.E_L3, model.eta_L3)):
        tau = eta / E
        out = (
            out
            + (
                (end - start)
                - tau * (np.exp(-(t - end) / tau) - np.exp(-(t - start) / tau))
            )
            / E
        )
    return out


def test_constant_load_matches_piao_eq1():
    model = asymmetric_five_element()
    force = 600.0
    sigma = force / float(CABLE.area)
    # A coarse, irregular grid: the update is exact, so the grid does not matter.
    time = np.array([0.0, 0.3, 1.0, 2.5, 5.0, 10.0, 50.0, 120.0, 300.0, 1000.0])
    traj = jaxcable.simulate_force_history(
        model, CABLE, time, np.full_like(time, force)
    )
    expected = sigma * _compliance(model, time)
    np.testing.assert_allclose(traj.strain, expected, rtol=1e-12, atol=0)
    np.testing.assert_allclose(traj.instantaneous, sigma / 2.0e10, rtol=1e-14)
    np.testing.assert_allclose(
        traj.creep, expected - sigma / 2.0e10, rtol=1e-11, atol=1e-18
    )
    assert np.all(traj.recovery_short == 0) and np.all(traj.recovery_long == 0)


def test_load_ramp_unload_matches_superposition():
    """Piao Eq. 2-3 (L = UL): a load step, a hold, an unloading ramp, a rest."""
    model = _linear_model()
    f0, t_r, t_2 = 500.0, 20.0, 26.0
    sigma0 = f0 / float(CABLE.area)
    time = np.concatenate([[0.0, 7.0], np.linspace(t_r, t_2, 4), [27, 30, 60, 500]])
    force = np.interp(time, [0.0, t_r, t_2, 1e9], [f0, f0, 0.0, 0.0])
    traj = jaxcable.simulate_force_history(model, CABLE, time, force)

    rate = sigma0 / (t_2 - t_r)
    expected = []
    for t in time:
        eps = sigma0 * _compliance(model, t)
        if t > t_r:
            eps -= rate * _ramp_integral(model, t, t_r, min(t, t_2))
        expected.append(eps)
    np.testing.assert_allclose(traj.strain, expected, rtol=1e-10, atol=1e-16)
    # The linear solid recovers fully: nothing but a decaying tail is left.
    assert traj.strain[-1] < 1e-3 * traj.strain[t_r == time].item()
    assert np.all(traj.parts.recovery_short[time > t_r] > 0)
    np.testing.assert_allclose(traj.parts.total, traj.strain, rtol=1e-14, atol=1e-20)


def test_instant_unload_matches_piao_eq3():
    """Piao Eq. 3 as printed (the t_2 -> t_r limit), for t >= t_r."""
    model = _linear_model()
    p = floats(model)
    f0, t_r = 500.0, 12.0
    sigma0 = f0 / float(CABLE.area)
    step = eqx.filter_jit(jaxcable.step)
    state = jaxcable.init_state(model, CABLE)
    # Array inputs, so that the compiled step is reused.
    x = jnp.asarray
    state, _ = step(model, CABLE, state, x(0.0), x(f0))
    state, _ = step(model, CABLE, state, x(t_r), x(f0))
    # dt = 0: the load is removed instantly at t_r.
    state, _ = step(model, CABLE, state, x(t_r), x(0.0))
    for t in (t_r, 13.0, 20.0, 100.0):
        state, parts = step(model, CABLE, state, x(t), x(0.0))
        expected = 0.0
        for E, eta in ((p.E_UL2, p.eta_UL2), (p.E_UL3, p.eta_UL3)):
            expected += sigma0 / E * np.expm1(E * t_r / eta) * np.exp(-E * t / eta)
        np.testing.assert_allclose(parts.total, expected, rtol=1e-10)
        np.testing.assert_allclose(parts.instantaneous, 0.0, atol=1e-20)


def test_branch_families_use_their_own_parameters():
    """Distinct sets: the loading family keeps its L kernel, the removed stress is
    superposed with the UL kernel, and the strain is bounded below by 0
    (max(Eq. 2-3 + D(t), 0), docs/model_notes.md point 10)."""
    model = asymmetric_five_element()
    p = floats(model)
    f0, t_r = 500.0, 5.0
    sigma0 = f0 / float(CABLE.area)
    time = np.array([0.0, 1.0, t_r, t_r + 1e-9, 5.5, 6.0, 8.0, 15.0, 40.0, 100.0])
    force = np.where(time <= t_r, f0, 0.0)
    traj = jaxcable.simulate_force_history(model, CABLE, time, force)
    after = time - t_r - 1e-9
    # An unloading step of 1 ns is a step.
    loading = sigma0 * _compliance(model, time)
    unloading = np.where(
        time > t_r,
        sigma0
        * (
            1 / p.E_UL1
            + -np.expm1(-p.E_UL2 * after / p.eta_UL2) / p.E_UL2
            + -np.expm1(-p.E_UL3 * after / p.eta_UL3) / p.E_UL3
        ),
        0.0,
    )
    # This UL set is softer than the L set: unbounded, the cable would end 1.6e-3
    # shorter than new; the bound stops it at 0.
    assert np.min(loading - unloading) < -1.5e-3
    np.testing.assert_allclose(
        traj.strain, np.maximum(loading - unloading, 0.0), rtol=1e-7, atol=1e-15
    )
    bounded = unloading > loading
    assert bounded.sum() == 4 and not bounded[:6].any()
    # Each unloading term is scaled by the same share s = min(1, added / removed).
    share = np.where(bounded, loading / np.where(bounded, unloading, 1.0), 1.0)
    np.testing.assert_allclose(
        traj.instantaneous,
        sigma0 * (1 / p.E_L1 - share * (time > t_r) / p.E_UL1),
        rtol=1e-7,
    )
    np.testing.assert_allclose(
        traj.recovery_short,
        share
        * sigma0
        / p.E_UL2
        * -np.expm1(-p.E_UL2 * np.maximum(after, 0) / p.eta_UL2),
        rtol=1e-7,
        atol=1e-12,  # the 1 ns unloading ramp is a ramp, not a step
    )


def test_direction_is_ignored():
    """No state depends on the sign of a force change: the drivers' `direction`
    (+1, -1, 0) does not change the step."""
    model = asymmetric_five_element()
    advance = eqx.filter_jit(model.advance)
    state = model.init(CABLE)
    one = jnp.array(1, jnp.int32)
    state, _ = advance(state, CABLE, jnp.array(0.0), jnp.array(500.0), one)
    state, _ = advance(state, CABLE, jnp.array(1.0), jnp.array(300.0), -one)
    steps = [
        advance(state, CABLE, jnp.array(1.0), jnp.array(350.0), d * one)
        for d in (1, -1, 0)
    ]
    for other in steps[1:]:
        assert jax.tree.all(jax.tree.map(lambda a, b: a == b, steps[0], other))


def test_reload_below_the_maximum_takes_the_recovery_back():
    """Reloading below the largest stress so far drives the unloading family back
    towards 0 (recovery taken back with the UL kernel); only a stress above the
    previous maximum loads the L family again. (The old reading added every upward
    increment to the L family: sigma_L = 500 + 150 here, 500 + 150 + 150 after the
    last step.)"""
    model = asymmetric_five_element()
    advance = eqx.filter_jit(model.advance)
    state = model.init(CABLE)
    area = float(CABLE.area)
    x, one = jnp.asarray, jnp.array(1, jnp.int32)
    expected = [(500.0, 0.0), (500.0, -200.0), (500.0, -50.0), (650.0, 0.0)]
    for force, (sigma_L, sigma_UL) in zip((500.0, 300.0, 450.0, 650.0), expected):
        state, parts = advance(state, CABLE, x(1.0), x(force), one)
        np.testing.assert_allclose(state.sigma_L * area, sigma_L, rtol=1e-14)
        np.testing.assert_allclose(state.sigma_UL * area, sigma_UL, atol=1e-9)
        p = floats(model)
        np.testing.assert_allclose(
            parts.instantaneous,
            (sigma_L / p.E_L1 + sigma_UL / p.E_UL1) / area,
            rtol=1e-13,
        )


def test_step_past_the_maximum_is_exact():
    """A step that passes the previous maximum mid-step is advanced exactly (split at
    the kink of the running maximum): the same strain as with a sample at the kink."""
    model = asymmetric_five_element()
    # Load to 500 N, unload to 200 N, then a coarse reload to 800 N (passing 500 N at
    # 1/2 of the step), against the same history with a sample at 500 N.
    time = np.array([0.0, 2.0, 4.0, 6.0, 8.0])
    force = np.array([0.0, 500.0, 200.0, 800.0, 800.0])
    fine_time = np.array([0.0, 2.0, 4.0, 5.0, 6.0, 8.0])
    fine_force = np.array([0.0, 500.0, 200.0, 500.0, 800.0, 800.0])
    coarse = jaxcable.simulate_force_history(model, CABLE, time, force)
    fine = jaxcable.simulate_force_history(model, CABLE, fine_time, fine_force)
    keep = np.array([0, 1, 2, 4, 5])
    np.testing.assert_allclose(coarse.strain, fine.strain[keep], rtol=1e-12)
    np.testing.assert_allclose(
        coarse.parts.recovery_short, fine.parts.recovery_short[keep], rtol=1e-12
    )


def test_noise_does_not_accumulate_in_sigma_L():
    """Regression (issue 10): with the branch flag every up/down noise blip added its
    up-step to sigma_L, so sigma_L grew with the total variation of the noise."""
    model = asymmetric_five_element()
    n = 200
    time = np.arange(n + 1.0)
    noise = 1e-3 * (-1.0) ** np.arange(n + 1)
    force = np.concatenate([[0.0], np.full(n, 500.0)]) + np.r_[0.0, noise[1:]]
    noisy = jaxcable.simulate_force_history(model, CABLE, time, force)
    clean = jaxcable.simulate_force_history(
        model, CABLE, time, np.r_[0.0, np.full(n, 500.0)]
    )
    p = floats(model)
    compliance = sum(1 / getattr(p, k) for k in FIELDS if k.startswith("E_L")) + 2 * (
        sum(1 / getattr(p, k) for k in FIELDS if k.startswith("E_UL"))
    )
    bound = 1e-3 / float(CABLE.area) * compliance
    assert np.max(np.abs(noisy.strain - clean.strain)) <= bound


def test_kelvin_voigt_step_limits():
    q0, s0, s1, E, eta = 1e-3, 2e7, 3e7, 9.5e9, 1e10
    tau = eta / E
    # Around the series/closed-form switch (h / tau = 0.1), and a long step.
    h = jnp.array([0.1 * tau * (1 - 1e-12), 0.1 * tau * (1 + 1e-12), 0.7])

    @jax.jit
    def run():
        kv = kelvin_voigt_step
        value, rate = jax.jvp(lambda h_: kv(q0, s0, s1, h_, E, eta), (0.0,), (1.0,))
        grads = jax.grad(kv, argnums=(0, 1, 2, 3, 4, 5))(q0, s0, s1, 0.0, E, eta)
        return value, rate, grads, kv(q0, s0, s1, h, E, eta)

    value, rate, grads, (below, above, q_07) = run()
    # h = 0 leaves the element where it was; the first-order growth is the mean
    # stress of the ramp: q1 = q0 + h ((s0 + s1) / 2 - E q0) / eta + O(h^2).
    assert value == q0
    np.testing.assert_allclose(rate, ((s0 + s1) / 2 - E * q0) / eta, rtol=1e-12)
    assert all(np.isfinite(g) for g in grads)
    np.testing.assert_allclose(below, above, rtol=1e-12)
    # Against the convolution q(h) = a q0 + (1/eta) int_0^h exp(-(h-t)/tau) s(t) dt
    # by the trapezoid rule on a fine grid.
    t = np.linspace(0.0, 0.7, 400001)
    integrand = np.exp(-(0.7 - t) / tau) * (s0 + (s1 - s0) * t / 0.7)
    q = np.exp(-0.7 / tau) * q0 + np.trapezoid(integrand, t) / eta
    np.testing.assert_allclose(q_07, q, rtol=1e-10)


@pytest.mark.parametrize("name", FIELDS)
@pytest.mark.parametrize("bad", [0.0, -1.0e9, np.nan, np.inf])
def test_bad_parameter_raises(name, bad):
    with pytest.raises(ValueError, match=name):
        jaxcable.FiveElementModel(**{name: bad})


def test_traced_bad_parameter_is_flagged():
    @jax.jit
    def result(E):
        return jaxcable.FiveElementModel(E_UL3=E).check(CABLE)

    assert result(5e10) == jaxcable.RESULTS.successful
    assert result(-1.0) == jaxcable.RESULTS.parameter_out_of_domain


HISTORY_T = np.array([0.0, 0.5, 2.0, 6.0, 6.5, 7.0, 9.0, 15.0, 15.5, 25.0])
HISTORY_F = np.array(
    [200.0, 400.0, 400.0, 400.0, 250.0, 100.0, 100.0, 100.0, 300.0, 300]
)


def _loss_of_strain(strain):
    return jnp.sum((strain * 1e3) ** 2)


def _strain(model):
    return jaxcable.simulate_force_history(model, CABLE, HISTORY_T, HISTORY_F).strain


def test_gradient_fd_and_vmap():
    model = asymmetric_five_element()
    grad = eqx.filter_grad(lambda m: _loss_of_strain(_strain(m)))(model)
    # All central-difference perturbations as one vmapped batch of parameter sets.
    rel = 1e-6
    perturbed = []
    for name in FIELDS:
        p = getattr(model, name)
        for sign in (1, -1):
            v = jnp.asarray(p * (1 + sign * rel))
            perturbed.append(eqx.tree_at(lambda m: getattr(m, name), model, v))
    batch = jax.tree.map(lambda *xs: jnp.stack(xs), *perturbed)
    strains = jax.vmap(_strain)(batch)
    losses = np.asarray(jax.vmap(_loss_of_strain)(strains))
    for i, name in enumerate(FIELDS):
        p = float(getattr(model, name))
        fd = (losses[2 * i] - losses[2 * i + 1]) / (2 * rel * p)
        g = float(getattr(grad, name))
        # Compare d loss / d log p.
        np.testing.assert_allclose(g * p, fd * p, rtol=1e-6, atol=1e-9, err_msg=name)
    # vmap over parameter sets equals a Python loop.
    for i in (0, 7, len(perturbed) - 1):
        np.testing.assert_allclose(strains[i], _strain(perturbed[i]), rtol=1e-14)


# ----------------------------------------------------------------------------------
# Parameter surface (Piao Eq. 5, Table 3)


def test_surface_trend_matches_text():
    """E_L1 rises with payload and falls with cable length (Piao Section 3.3)."""
    surface = jaxcable.PIAO_TABLE3
    mass, length = np.meshgrid(np.linspace(10, 110, 41), np.linspace(5.4, 8.4, 13))
    mass, length = jnp.asarray(mass.ravel()), jnp.asarray(length.ravel())
    slopes = jax.jit(
        jax.vmap(jax.grad(lambda s, m, ln: s(m, ln), argnums=(1, 2)), (None, 0, 0))
    )
    d_mass, d_length = slopes(surface, mass, length)
    assert jnp.all(d_mass > 0)
    assert jnp.all(d_length < 0)
    assert jnp.all(surface(mass, length) > 0)
    # As printed (mass as the first variable) it rises with length instead: the reason
    # for the swapped reading.
    printed = jaxcable.ParameterSurface(surface.coefficients, first="mass")
    _, d_length_printed = slopes(printed, mass, length)
    assert jnp.mean(d_length_printed > 0) > 0.5


def test_surface_span_against_fibre_modulus():
    """Table 3's parameter and unit did not survive (docs/model_notes.md point 12):
    over Piao's range (10-100 kg, 5.4-8.4 m) the preset's reading spans 3.7e12 to
    6.1e14 Pa (31-6100 x the UHMWPE fibre modulus, 100-120 GPa), the printed order
    1.3e12 to 5.4e12 Pa: no spring of this rope in either reading."""
    mass, length = np.meshgrid(np.linspace(10, 100, 91), np.linspace(5.4, 8.4, 31))
    printed = jaxcable.ParameterSurface(jaxcable.PIAO_TABLE3.coefficients, first="mass")
    for surface, (low, high) in (
        (jaxcable.PIAO_TABLE3, (3.722e12, 6.061e14)),
        (printed, (1.320e12, 5.420e12)),
    ):
        values = np.asarray(surface(mass, length))
        np.testing.assert_allclose([values.min(), values.max()], [low, high], rtol=1e-3)
        assert values.min() > 10 * 120e9
    # The default E_L1 (65 kg, 7.4 m) is about 2000 x the fibre modulus.
    default = float(jaxcable.PIAO_TABLE3(65.0, 7.4))
    assert default / 120e9 > 1800 and default / 100e9 < 2200


def test_surface_polynomial_order():
    c = np.arange(1.0, 10.0)
    m, ln = 3.0, 5.0
    mass_first = jaxcable.ParameterSurface(c)(m, ln)
    expected = (
        c[0]
        + c[1] * m
        + c[2] * ln
        + c[3] * m**2
        + c[4] * m * ln
        + c[5] * ln**2
        + c[6] * m**3
        + c[7] * m**2 * ln
        + c[8] * m * ln**2
    )
    np.testing.assert_allclose(mass_first, expected, rtol=1e-14)
    swapped = jaxcable.ParameterSurface(c, first="length")(ln, m)
    np.testing.assert_allclose(swapped, expected, rtol=1e-14)


def _table3_numpy(m, ln):
    """Piao Eq. 5 with x = length, y = mass (the reading of PIAO_TABLE3)."""
    p = [2.803e12, -1.993e11, -7.127e11, 2.543e9, 5.164e10, 8.817e10, -2.286e7]
    p += [5.996e7, -4.337e9]
    x, y = ln, m
    return (p[0] + p[1] * x + p[2] * y + p[3] * x**2 + p[4] * x * y + p[5] * y**2) + (
        p[6] * x**3 + p[7] * x**2 * y + p[8] * x * y**2
    )


def test_surface_jit_vmap_grad():
    surface = jaxcable.PIAO_TABLE3
    mass = np.array([20.0, 40.0, 65.0])
    length = np.array([5.4, 7.4, 8.4])
    expected = _table3_numpy(mass, length)

    @jax.jit
    def run(s, m, ln):
        # vmap over points, grad in mass and length, and in the coefficients.
        values = jax.vmap(s)(m, ln)
        slopes = jax.vmap(jax.grad(s, argnums=(0, 1)))(m, ln)
        d_coefficients = jax.grad(lambda s_: s_(m[-1], ln[-1]))(s).coefficients
        return values, slopes, d_coefficients

    values, (d_mass, d_length), d_coefficients = run(surface, mass, length)
    np.testing.assert_allclose(values, expected, rtol=1e-13)
    fd_mass = _table3_numpy(mass + 1e-4, length) - _table3_numpy(mass - 1e-4, length)
    fd_length = _table3_numpy(mass, length + 1e-5) - _table3_numpy(mass, length - 1e-5)
    np.testing.assert_allclose(d_mass, fd_mass / 2e-4, rtol=1e-6)
    np.testing.assert_allclose(d_length, fd_length / 2e-5, rtol=1e-5)
    # d P / d p30 = x^3 = length^3 in this reading.
    np.testing.assert_allclose(d_coefficients[6], 8.4**3, rtol=1e-14)


def test_surface_bad_arguments():
    with pytest.raises(ValueError, match="coefficients"):
        jaxcable.ParameterSurface(np.ones(8))
    with pytest.raises(ValueError, match="coefficients"):
        jaxcable.ParameterSurface(np.full(9, np.nan))
    with pytest.raises(ValueError, match="first"):
        jaxcable.ParameterSurface(np.ones(9), first="payload")
    with pytest.raises(ValueError, match="length_m"):
        jaxcable.piao_five_element(50.0, -1.0)
    with pytest.raises(ValueError, match="mass_kg"):
        jaxcable.piao_five_element(np.nan, 7.4)
    # Far outside the fitted domain the surface turns negative: caught, named.
    with pytest.raises(ValueError, match="E_L1"):
        jaxcable.piao_five_element(50.0, 40.0)


def test_default_e_l1_is_the_surface_at_max_payload():
    np.testing.assert_allclose(
        jaxcable.FiveElementModel().E_L1, jaxcable.PIAO_TABLE3(65.0, 7.4), rtol=0.02
    )


def test_piao_five_element_traceable_and_monotone_in_payload():
    cable = jaxcable.Cable(length=7.4, diameter=6e-3, breaking_load=20000.0)
    time = jnp.array([0.0, 1.0, 10.0, 100.0])

    def strain(mass, length):
        model = jaxcable.piao_five_element(mass, length)
        force = jnp.full(time.shape, mass * 9.81)
        return jaxcable.simulate_force_history(model, cable, time, force).strain

    def strain_and_sensitivity(mass, length):
        def f(m, l_):
            s = strain(m, l_)
            return s, s

        jac, s = jax.jacfwd(f, argnums=(0, 1), has_aux=True)(mass, length)
        return s, jac

    run = jax.jit(jax.vmap(strain_and_sensitivity))
    masses = jnp.array([10.0, 30.0, 65.0, 100.0])
    lengths = jnp.full(4, 7.4)
    batched, (d_mass, d_length) = run(masses, lengths)
    model = jaxcable.piao_five_element(65.0, 7.4)
    assert model.E_L1 == model.E_UL1
    np.testing.assert_allclose(model.E_L1, _table3_numpy(65.0, 7.4), rtol=1e-13)
    # Piao Eq. 1 for each payload (linear model, constant load from t = 0).
    sigma = np.asarray(masses)[:, None] * 9.81 / float(cable.area)
    E1 = _table3_numpy(np.asarray(masses), 7.4)[:, None]
    t = np.asarray(time)
    expected = sigma * (
        1 / E1
        + -np.expm1(-9.5e9 * t / 1e10) / 9.5e9
        + -np.expm1(-5e10 * t / 1e13) / 5e10
    )
    np.testing.assert_allclose(batched, expected, rtol=1e-12)
    # The elongation rises with payload once the Kelvin-Voigt elements respond.
    assert jnp.all(jnp.diff(batched[:, 1:], axis=0) > 0)
    # Differentiable in payload and length (a controller's sensitivity).
    fd_mass = (run(masses + 1e-3, lengths)[0] - run(masses - 1e-3, lengths)[0]) / 2e-3
    fd_length = (run(masses, lengths + 1e-4)[0] - run(masses, lengths - 1e-4)[0]) / 2e-4
    np.testing.assert_allclose(d_mass, fd_mass, rtol=1e-6)
    np.testing.assert_allclose(d_length, fd_length, rtol=1e-5, atol=1e-15)
    assert jnp.all(d_mass[:, 1:] > 0)
