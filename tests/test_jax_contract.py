"""The JAX contract: one scan, no retracing, vmap/jit equivalence, gradients, float32."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxcable as jc

from .helpers import finite_difference_grad, leaf_names, tree_allclose


CABLE = jc.Cable(length=0.3, speed=3e-3 / 60)
# A faster crosshead keeps every force level of these contract tests reachable.
FAST = jc.Cable(length=0.3, speed=10e-3 / 60)
PROTOCOL = jc.Protocol.concatenate(
    jc.Protocol.cycles(100.0, 2, samples_per_ramp=20),
    jc.Protocol.rest(3600.0, samples=4),
)


def _batch_cable(lengths, speeds):
    # Every other field keeps its default, broadcast to the batch (whatever the
    # fields of Cable are).
    n = len(lengths)
    cable = jc.Cable(length=jnp.asarray(lengths), speed=jnp.asarray(speeds))
    return jax.tree_util.tree_map(lambda x: jnp.broadcast_to(x, (n,)), cable)


def _traced_once(passes: int = 1) -> jc.IntegratedModel:
    # The kernel calls the model's `init` once per pass of a history in one trace
    # (the initial state): a rate-driven test has two passes (fixed Newton steps,
    # then the robust solve where needed), a force history one. An `init` that may
    # be traced only that often makes any retrace of the kernel raise.
    init = eqx.debug.assert_max_traces(jc.IntegratedModel.init, max_traces=passes)

    class TracedOnce(jc.IntegratedModel):
        def init(self, cable):
            return init(self, cable)

    return TracedOnce()


def test_repeated_call_does_not_retrace():
    other_cable = jc.Cable(length=0.1, speed=3e-3 / 60)
    t = np.linspace(0, 100, 30)
    model = _traced_once(passes=2)
    other_model = eqx.tree_at(lambda m: m.E2c, model, 2 * model.E2c)
    jc.simulate_rate_test(model, CABLE, PROTOCOL)
    jc.simulate_rate_test(other_model, other_cable, PROTOCOL)
    model = _traced_once()
    other_model = eqx.tree_at(lambda m: m.E2c, model, 2 * model.E2c)
    jc.simulate_force_history(model, CABLE, t, 50 * np.sin(t / 20) ** 2)
    jc.simulate_force_history(other_model, other_cable, t, 60 * np.sin(t / 30) ** 2)


def test_default_and_fitted_values_share_one_program():
    # A fit gives strongly typed arrays (from its float parameter vector); a model or
    # cable built from Python numbers must hold the same types, or `jit` compiles
    # every kernel once for the defaults and again for fitted values
    # (jaxcable/_arrays.py).
    model = _traced_once(passes=2)
    fitted = eqx.tree_at(lambda m: m.E2c, model, jnp.asarray(np.asarray(model.E2c)))
    assert fitted.E2c.dtype == model.E2c.dtype
    jc.simulate_rate_test(model, CABLE, PROTOCOL)
    cable = jc.Cable(length=jnp.asarray(np.asarray(0.1)), speed=CABLE.speed)
    jc.simulate_rate_test(fitted, cable, PROTOCOL)
    from jaxcable.internal import CLASSES_BY_NAME

    for cls in CLASSES_BY_NAME.values():
        try:
            built = cls()
        except TypeError:  # an extension needs the model it wraps
            built = cls(jc.IntegratedModel())
        for leaf in jax.tree_util.tree_leaves(built):
            assert not (eqx.is_array(leaf) and getattr(leaf, "weak_type", False)), (
                cls.__name__
            )


def test_one_scan_per_simulation():
    # Each pass of a history is one lax.scan (over blocks of samples, each a scan):
    # no Python loop over samples unrolled in the jaxpr (its size and its scans do
    # not grow with the number of samples).
    model = jc.IntegratedModel()

    def size(n):
        protocol = jc.Protocol.cycles(100.0, 1, samples_per_ramp=n)
        jaxpr = jax.make_jaxpr(
            lambda m: (
                jc.simulate_rate_test(
                    m, CABLE, protocol, method=jc.Simulation(throw=False)
                ).strain
            )
        )(model)
        return str(jaxpr).count("scan["), len(jaxpr.jaxpr.eqns)

    # A history of over 512 samples is a scan of blocks, each a scan; a shorter
    # one a flat scan.
    (scans_a, len_a), (scans_b, len_b) = size(300), size(1200)
    # A scan of blocks per pass: two passes on an accelerator (fixed Newton steps;
    # the robust solve where needed), one on a CPU.
    passes = 2 if jc.Newton(tol=1e-12).in_two_passes else 1
    assert scans_a == scans_b == 2 * passes
    short, _ = size(10)
    assert short == passes
    assert len_a == len_b


def test_vmap_over_lengths_and_rates_matches_loop():
    model = jc.IntegratedModel()
    lengths, speeds = [0.1, 0.3, 0.5], [3e-3 / 60, 10e-3 / 60, 6e-3 / 60]
    batched = jax.vmap(lambda c: jc.simulate_rate_test(model, c, PROTOCOL))(
        _batch_cable(lengths, speeds)
    )
    for i, (length, speed) in enumerate(zip(lengths, speeds)):
        one = jc.simulate_rate_test(
            model, jc.Cable(length=length, speed=speed), PROTOCOL
        )
        np.testing.assert_allclose(batched.elongation[i], one.elongation, rtol=1e-9)
        np.testing.assert_allclose(batched.time[i], one.time, rtol=1e-9)


def test_vmap_over_parameter_sets_matches_loop():
    base = jc.IntegratedModel()
    models = [
        eqx.tree_at(lambda m: (m.E2c, m.eta0), base, (base.E2c * s, base.eta0 * s))
        for s in (0.9, 1.0, 2.0)
    ]
    stacked = jax.tree_util.tree_map(lambda *xs: jnp.stack(xs), *models)
    batched = jax.vmap(lambda m: jc.simulate_rate_test(m, FAST, PROTOCOL))(stacked)
    for i, m in enumerate(models):
        one = jc.simulate_rate_test(m, FAST, PROTOCOL)
        np.testing.assert_allclose(batched.strain[i], one.strain, rtol=1e-9)


def test_vmap_over_padded_force_histories():
    model = jc.IntegratedModel()
    t_long = np.linspace(0, 600, 40)
    t_short = np.linspace(0, 300, 25)
    f_long = 80 * np.sin(t_long / 200) ** 2
    f_short = 120 * np.sin(t_short / 100) ** 2
    n = len(t_long)
    pad = n - len(t_short)
    time = np.stack(
        [t_long, np.concatenate([t_short, t_short[-1] + 1 + np.arange(pad)])]
    )
    force = np.stack([f_long, np.concatenate([f_short, np.full(pad, f_short[-1])])])
    mask = np.stack([np.ones(n, bool), np.arange(n) < len(t_short)])
    batched = jax.vmap(
        lambda t, f, m: jc.simulate_force_history(model, CABLE, t, f, mask=m)
    )(time, force, mask)
    short = jc.simulate_force_history(model, CABLE, t_short, f_short)
    long = jc.simulate_force_history(model, CABLE, t_long, f_long)
    np.testing.assert_allclose(batched.strain[0], long.strain, rtol=1e-12)
    np.testing.assert_allclose(
        batched.strain[1, : len(t_short)], short.strain, rtol=1e-12
    )
    # Padding repeats the last valid sample.
    np.testing.assert_allclose(
        batched.strain[1, len(t_short) :], short.strain[-1], rtol=1e-12
    )


def test_vmap_over_padded_protocols():
    model = jc.IntegratedModel()
    a = jc.Protocol.cycles(100.0, 2, samples_per_ramp=20)
    b = jc.Protocol.cycles(150.0, 1, samples_per_ramp=20)
    stacked = jax.tree_util.tree_map(
        lambda x, y: jnp.stack([x, y]), a, b.pad(a.num_samples)
    )
    batched = jax.vmap(lambda p: jc.simulate_rate_test(model, FAST, p))(stacked)
    one = jc.simulate_rate_test(model, FAST, b)
    np.testing.assert_allclose(
        batched.strain[1, : b.num_samples], one.strain, rtol=1e-10
    )
    assert not bool(batched.mask[1, -1])


def test_jit_matches_eager_and_step_matches_scan():
    model = jc.IntegratedModel()
    t = np.linspace(0, 900, 50)
    f = 100 * np.abs(np.sin(t / 150))
    eager = jc.simulate_force_history(model, CABLE, t, f)
    jitted = jax.jit(lambda m, t, f: jc.simulate_force_history(m, CABLE, t, f))(
        model, t, f
    )
    assert tree_allclose(eager, jitted)

    def user_scan(model, t, f):
        state = jc.init_state(model, CABLE, t[0])

        def body(state, x):
            state, parts = jc.step(model, CABLE, state, *x)
            return state, parts.total

        return jax.lax.scan(body, state, (jnp.asarray(t), jnp.asarray(f)))[1]

    np.testing.assert_allclose(
        jax.jit(user_scan)(model, t, f), eager.strain, rtol=1e-12
    )


def _rate_loss(model):
    traj = jc.simulate_rate_test(model, CABLE, PROTOCOL)
    return jnp.sum(traj.elongation**2) * 1e4


def _force_loss(model):
    t = jnp.linspace(0.0, 2000.0, 30)
    f = 100 * jnp.abs(jnp.sin(t / 400))
    traj = jc.simulate_force_history(model, CABLE, t, f)
    return jnp.sum(traj.elongation**2) * 1e4


def _elongation_loss(model):
    t = jnp.linspace(0.0, 600.0, 25)
    x = 4e-3 * jnp.sin(t / 400)
    traj = jc.simulate_elongation_history(model, CABLE, t, x)
    return jnp.sum(traj.force**2) * 1e-4


@pytest.mark.parametrize("loss", [_rate_loss, _force_loss, _elongation_loss])
def test_grad_matches_finite_differences(loss):
    # With hardening (beta > 0; the default has none), so that its gradient is checked
    # too and a finite difference of beta stays in its domain.
    model = jc.IntegratedModel(beta=0.05, gamma=2.0)
    # Jitted whole: eagerly, every one of the 24 finite-difference evaluations (and
    # the gradient) would trace the driver again; jitted, one compilation serves
    # them all. The functions differentiated are the same.
    grad = eqx.filter_jit(eqx.filter_grad(loss))(model)
    fd = finite_difference_grad(eqx.filter_jit(loss), model)
    names = leaf_names(model)
    values = [
        float(x)
        for x in jax.tree_util.tree_leaves(eqx.filter(model, eqx.is_inexact_array))
    ]
    # Compare sensitivities to a relative change of each parameter (g * p): the
    # parameters span 1e-3..1e11, so the raw gradients span many decades.
    g = [float(x) * v for x, v in zip(jax.tree_util.tree_leaves(grad), values)]
    d = [float(x) * v for x, v in zip(jax.tree_util.tree_leaves(fd), values)]
    scale = max(abs(x) for x in d)
    for name, a, b in zip(names, g, d):
        assert abs(a - b) <= 1e-4 * abs(b) + 1e-7 * scale, (name, a, b)


def test_grad_with_respect_to_cable_length_and_speed():
    model = jc.IntegratedModel()

    def loss(length, speed):
        cable = jc.Cable(length=length, speed=speed)
        return jnp.sum(jc.simulate_rate_test(model, cable, PROTOCOL).elongation) * 1e3

    g = jax.grad(loss, argnums=(0, 1))(0.3, 5e-5)
    h = 1e-7
    fd_l = (loss(0.3 + h, 5e-5) - loss(0.3 - h, 5e-5)) / (2 * h)
    fd_v = (loss(0.3, 5e-5 * (1 + 1e-6)) - loss(0.3, 5e-5 * (1 - 1e-6))) / (2 * 5e-11)
    np.testing.assert_allclose(g[0], fd_l, rtol=1e-4)
    np.testing.assert_allclose(g[1], fd_v, rtol=1e-4)


def test_float32_matches_float64():
    # Documented tolerance: float32 elongations agree with float64 to 1e-4 relative.
    model64 = jc.IntegratedModel()
    model32 = jax.tree_util.tree_map(lambda x: jnp.asarray(x, jnp.float32), model64)
    cable32 = jax.tree_util.tree_map(lambda x: jnp.asarray(x, jnp.float32), CABLE)
    protocol = jc.Protocol.cycles(100.0, 3, samples_per_ramp=200)
    t64 = jc.simulate_rate_test(model64, CABLE, protocol)
    t32 = jc.simulate_rate_test(model32, cable32, protocol)
    assert t32.elongation.dtype == jnp.float32
    scale = float(jnp.max(jnp.abs(t64.elongation)))
    np.testing.assert_allclose(t32.elongation, t64.elongation, atol=1e-4 * scale)
    np.testing.assert_allclose(t32.time, t64.time, rtol=1e-4, atol=1e-3)
    assert t32.result == jc.RESULTS.successful
