import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxcable as jc
from jaxcable import LiveFiveElement, controller_init, controller_step
from jaxcable.states import ControllerState

from .helpers import tree_allclose


LENGTHS = np.array([6.5, 7.2, 8.3])
RATE = 2.8e-3


def _cables(lengths=LENGTHS):
    lengths = jnp.asarray(lengths)
    return jc.Cable(lengths, 6e-3, speed=lengths * RATE, breaking_load=8000.0)


def _cable(i):
    return jc.Cable(LENGTHS[i], 6e-3, speed=LENGTHS[i] * RATE, breaking_load=8000.0)


def _history(samples=40):
    # Three different force histories: loading, holds, unloading, reloading.
    t = np.linspace(0.0, 600.0, samples)
    base = np.array([120.0, 200.0, 60.0])
    f = base[:, None] * (1.0 + 0.6 * np.sin(t / 60.0 + np.arange(3)[:, None]))
    f[:, 0] = 0.0
    return t, f  # (T,), (n, T)


@eqx.filter_jit
def _loop(model, cables, t, forces, per_cable):
    state = controller_init(model, cables, t[0], per_cable=per_cable)

    def body(state, x):
        ti, fi = x
        return controller_step(model, cables, state, ti, fi)

    return jax.lax.scan(body, state, (t, forces.T))


def _run(model, t, f, *, per_cable=False, cables=None):
    cables = _cables() if cables is None else cables
    return _loop(model, cables, jnp.asarray(t), jnp.asarray(f), per_cable)


_step = eqx.filter_jit(controller_step)


MODELS = [
    jc.IntegratedModel(),
    jc.HookeModel(),
    pytest.param(jc.FiveElementModel(), marks=pytest.mark.slow),
    pytest.param(jc.BurgersModel(), marks=pytest.mark.slow),
    pytest.param(
        jc.TerminationCompliance(jc.IntegratedModel(), 2e-5), marks=pytest.mark.slow
    ),
]


@pytest.mark.parametrize(
    "model",
    MODELS,
    ids=["integrated", "hooke", "five_element", "burgers", "termination"],
)
def test_scan_matches_simulate_force_history(model):
    t, f = _history()
    _, elongation = _run(model, t, f)
    for i in range(3):
        traj = jc.simulate_force_history(model, _cable(i), t, f[i])
        np.testing.assert_allclose(
            elongation[:, i], traj.elongation, rtol=1e-12, atol=1e-15
        )


@pytest.mark.slow  # the robot example's fast test runs a per-cable model too
def test_per_cable_parameters():
    t, f = _history()
    E2c = jnp.array([3.0e8, 3.8e8, 4.5e8])
    models = jax.vmap(lambda e: jc.IntegratedModel(E2c=e))(E2c)
    _, elongation = _run(models, t, f, per_cable=True)
    for i in range(3):
        traj = jc.simulate_force_history(
            jc.IntegratedModel(E2c=E2c[i]), _cable(i), t, f[i]
        )
        np.testing.assert_allclose(elongation[:, i], traj.elongation, rtol=1e-12)


def test_jit_matches_eager_and_vmap():
    cables = _cables()
    forces = jnp.array([100.0, 150.0, 50.0])
    # jit against eager (op by op; Hooke's law keeps that cheap).
    hooke = jc.HookeModel()
    state = controller_init(hooke, cables)
    eager = controller_step(hooke, cables, state, 2.0, forces)
    jitted = jax.jit(lambda s, t, f: controller_step(hooke, cables, s, t, f))(
        state, 2.0, forces
    )
    assert tree_allclose(eager, jitted)
    # vmap over two robots (two force sets) equals a loop over them.
    model = jc.FiveElementModel()
    state = controller_init(model, cables)
    step = jax.jit(lambda f: controller_step(model, cables, state, 2.0, f))
    forces2 = jnp.stack([forces, 2.0 * forces])
    batched = jax.jit(jax.vmap(step))(forces2)
    for k in range(2):
        one = step(forces2[k])
        assert tree_allclose(jax.tree_util.tree_map(lambda x: x[k], batched), one)


def test_state_properties_and_lengths_change():
    model = jc.IntegratedModel()
    state = controller_init(model, _cables())
    assert isinstance(state, ControllerState) and state.num_cables == 3
    forces = jnp.array([100.0, 150.0, 50.0])
    state, e1 = _step(model, _cables(), state, 1.0, forces)
    np.testing.assert_allclose(state.forces, forces)
    assert float(state.time) == 1.0
    assert bool(jnp.all(state.result == jc.RESULTS.successful))
    np.testing.assert_allclose(e1, state.strain * LENGTHS)
    # The strain is the state; the elongation scales with the current length (the
    # speed too, so that the strain rate, and Park's t_r2, stay the same).
    _, e2 = _step(model, _cables(LENGTHS), state, 3.0, forces)
    _, e3 = _step(model, _cables(2 * LENGTHS), state, 3.0, forces)
    np.testing.assert_allclose(e3, 2 * e2, rtol=1e-12)


def test_grad_matches_finite_differences():
    t, f = _history(20)

    def loss(E2c, forces):
        model = jc.IntegratedModel(E2c=E2c)
        _, elongation = _run(model, t, forces)
        return jnp.sum(elongation[-5:] ** 2)

    E2c = jnp.asarray(3.8e8)
    gE, gf = jax.grad(loss, argnums=(0, 1))(E2c, jnp.asarray(f))
    h = 1e-6 * float(E2c)
    fd = (loss(E2c + h, f) - loss(E2c - h, f)) / (2 * h)
    np.testing.assert_allclose(gE, fd, rtol=1e-6)
    i, k = 1, 15
    df = np.zeros_like(f)
    df[i, k] = 1e-4
    fd = (loss(E2c, f + df) - loss(E2c, f - df)) / 2e-4
    np.testing.assert_allclose(gf[i, k], fd, rtol=1e-5)


def test_live_five_element_equals_piao_preset_at_constant_load():
    t = np.linspace(0.0, 300.0, 31)
    force = np.full_like(t, 250.0)
    force[0] = 0.0
    force[1:] = 250.0
    live = LiveFiveElement()
    fixed = jc.piao_five_element(250.0 / 9.80665, LENGTHS[0])
    a = jc.simulate_force_history(live, _cable(0), t, force)
    b = jc.simulate_force_history(fixed, _cable(0), t, force)
    np.testing.assert_allclose(a.elongation, b.elongation, rtol=1e-12, atol=1e-15)
    m = live.model_at(jnp.asarray(250.0), jnp.asarray(7.0))
    np.testing.assert_allclose(m.E_L1, jc.PIAO_TABLE3(250.0 / 9.80665, 7.0))


def test_live_five_element_follows_payload_and_length():
    # The surface rises with payload and falls with length (PIAO_TABLE3's reading).
    live = LiveFiveElement()
    e = lambda f, length: float(live.model_at(jnp.asarray(f), jnp.asarray(length)).E_L1)
    assert e(400.0, 7.0) > e(200.0, 7.0)
    assert e(400.0, 8.0) < e(400.0, 6.0)
    t, f = _history()
    _, elongation = _run(live, t, f)
    assert np.all(np.isfinite(elongation)) and np.all(elongation >= 0)


def test_runtime_failure_raises_or_is_flagged():
    model = jc.IntegratedModel()
    cables = _cables()
    state = controller_init(model, cables)
    step = jax.jit(
        lambda s, f, throw: controller_step(model, cables, s, 1.0, f, throw=throw),
        static_argnums=2,
    )
    bad = jnp.array([100.0, -5.0, 50.0])  # traced: not caught at the boundary
    with pytest.raises(Exception, match="non-negative|negative"):
        jax.block_until_ready(step(state, bad, True))
    new, _ = step(state, bad, False)
    assert list(np.asarray(new.result == jc.RESULTS.successful)) == [True, False, True]


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(forces=[1.0, 2.0]), "`forces`"),
        (dict(forces=[1.0, -2.0, 3.0]), "`forces`"),
        (dict(forces=[1.0, np.nan, 3.0]), "`forces`"),
        (dict(forces=[1.0, 9000.0, 3.0]), "`forces`"),
        (dict(time=-1.0), "`time`"),
        (dict(time=np.nan), "`time`"),
        (dict(time=[1.0, 2.0]), "`time`"),
        (dict(cables=jc.Cable(jnp.ones((2, 3)))), "`cables`"),
        (dict(cables=jc.Cable(jnp.ones(3), jnp.full(2, 6e-3))), "`cables`"),
        (dict(cables=jc.Cable(jnp.ones(4))), "`state`"),
        (dict(model="integrated"), "`model`"),
        (dict(state=(1, 2)), "`state`"),
        (dict(per_cable=True), "`model"),
    ],
)
def test_bad_inputs_raise_value_error(kwargs, match):
    model = jc.IntegratedModel()
    state = controller_init(model, _cables())
    state, _ = controller_step(model, _cables(), state, 0.0, jnp.zeros(3))
    args = dict(
        model=model,
        cables=_cables(),
        state=state,
        time=1.0,
        forces=[1.0, 2.0, 3.0],
        per_cable=False,
    )
    args.update(kwargs)
    if args.pop("per_cable"):
        # A state of one parameter set per cable, stepped with a shared model.
        stacked = jax.tree_util.tree_map(lambda x: jnp.stack([x] * 3), model)
        args["state"] = controller_init(stacked, _cables(), per_cable=True)
    with pytest.raises(ValueError, match=match):
        controller_step(**args)


def test_init_bad_inputs():
    with pytest.raises(ValueError, match="`cables`"):
        controller_init(jc.IntegratedModel(), jc.Cable(7.0))
    with pytest.raises(ValueError, match="`time`"):
        controller_init(jc.IntegratedModel(), _cables(), np.inf)
    with pytest.raises(ValueError, match="LiveFiveElement.gravity"):
        LiveFiveElement(gravity=-1.0)


def test_no_retrace_for_repeated_calls():
    model = jc.IntegratedModel()
    cables = _cables()
    traces = []

    @jax.jit
    def step(state, t, f):
        traces.append(1)
        return controller_step(model, cables, state, t, f)

    state = controller_init(model, cables)
    for k in range(5):
        state, _ = step(state, float(k), jnp.full(3, 10.0 * k))
    assert len(traces) == 1
    assert all(eqx.is_array(p) and p.nbytes <= 512 for p in state.packed)
