"""Gradients of long histories in bounded memory (checkpointed scan)."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxcable as jc


CABLE = jc.Cable(length=0.3, speed=3e-3 / 60)


def _history(n):
    t = jnp.linspace(0.0, 50.0 * n, n)
    f = 80.0 * jnp.sin(t / 3000.0) ** 2
    return t, f


def _loss(model, t, f, checkpoint):
    traj = jc.simulate_force_history(
        model, CABLE, t, f, method=jc.Simulation(checkpoint=checkpoint)
    )
    return jnp.mean(traj.elongation**2) * 1e6


@pytest.mark.parametrize("checkpoint", [7, 32, 1000])
def test_checkpointed_equals_plain(checkpoint):
    model = jc.IntegratedModel()
    t, f = _history(250)
    plain = jc.simulate_force_history(model, CABLE, t, f)
    ckpt = jc.simulate_force_history(
        model, CABLE, t, f, method=jc.Simulation(checkpoint=checkpoint)
    )
    np.testing.assert_allclose(ckpt.strain, plain.strain, rtol=1e-13)
    g0 = eqx.filter_grad(_loss)(model, t, f, None)
    g1 = eqx.filter_grad(_loss)(model, t, f, checkpoint)
    for a, b in zip(jax.tree_util.tree_leaves(g0), jax.tree_util.tree_leaves(g1)):
        np.testing.assert_allclose(a, b, rtol=1e-9)


def test_checkpointed_rate_test_equals_plain():
    model = jc.IntegratedModel()
    protocol = jc.Protocol.cycles(100.0, 2, 50)
    plain = jc.simulate_rate_test(model, CABLE, protocol)
    ckpt = jc.simulate_rate_test(
        model, CABLE, protocol, method=jc.Simulation(checkpoint=16)
    )
    np.testing.assert_allclose(ckpt.time, plain.time, rtol=1e-12)


def _grad_temp_bytes(n, checkpoint):
    model = jc.IntegratedModel()
    t, f = _history(n)
    grad = jax.jit(lambda m: eqx.filter_grad(lambda m: _loss(m, t, f, checkpoint))(m))
    compiled = grad.lower(model).compile()
    return compiled.memory_analysis().temp_size_in_bytes


def test_checkpointed_gradient_memory_is_bounded():
    n = 40_000
    plain = _grad_temp_bytes(n, None) / n
    ckpt = _grad_temp_bytes(n, 200) / n
    # The plain scan stores every sample's carry (each step is rematerialised in the
    # backward pass, so not its intermediates: ~15 float64 state variables, of which
    # XLA keeps at least 8 per sample); the
    # checkpointed one stores one carry per block and one block of intermediates, so
    # what is left per sample is the returned trajectory (8 float64 arrays) and its
    # cotangent.
    trajectory = 8 * 8
    assert ckpt < 2.5 * trajectory, (ckpt, plain)
    assert plain > ckpt + 8 * 8, (ckpt, plain)


def test_bad_checkpoint():
    t, f = _history(10)
    with pytest.raises(ValueError, match="checkpoint"):
        jc.simulate_force_history(
            jc.IntegratedModel(), CABLE, t, f, method=jc.Simulation(checkpoint=0)
        )
