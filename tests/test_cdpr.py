import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxcable as jc
from jaxcable import TerminationCompliance, cdpr
from jaxcable.internal import GRAVITY


ROBOT = cdpr.Robot()
# Jitted once: eager, every call would dispatch op by op.
tension_distribution = jax.jit(cdpr.tension_distribution)
forward_kinematics = jax.jit(cdpr.forward_kinematics)
POSES = [cdpr.HOME, cdpr.PICK, cdpr.PLACE, (1.2, -1.2, 0.8), (0.3, 0.2, 3.0)]


@pytest.mark.parametrize("position", POSES)
@pytest.mark.parametrize("mass", [20.0, 85.0])
def test_tension_distribution_is_balanced_taut_and_minimal(position, mass):
    x = jnp.asarray(position)
    t = tension_distribution(ROBOT, x, mass)
    A = ROBOT.directions(x)
    np.testing.assert_allclose(A @ t, [0.0, 0.0, mass * GRAVITY], atol=1e-9)
    assert np.all(np.asarray(t) >= float(ROBOT.min_tension) - 1e-9)
    # KKT of min |t|^2 / 2 s.t. A t = w, t >= t_min: t = max(t_min, A^T lambda), with
    # lambda the least-squares multiplier of the cables above t_min.
    free = np.asarray(t) > float(ROBOT.min_tension) + 1e-6
    lam = np.linalg.lstsq(np.asarray(A)[:, free].T, np.asarray(t)[free], rcond=None)[0]
    np.testing.assert_allclose(np.asarray(A).T[free] @ lam, np.asarray(t)[free])
    assert np.all(np.asarray(A).T[~free] @ lam <= float(ROBOT.min_tension) + 1e-6)


def test_tension_distribution_matches_a_generic_solver():
    scipy_optimize = pytest.importorskip("scipy.optimize")
    x = jnp.asarray((1.5, -1.4, 0.6))  # near a corner: two cables at t_min
    t = np.asarray(tension_distribution(ROBOT, x, 85.0))
    assert np.any(np.isclose(t, float(ROBOT.min_tension)))
    A = np.asarray(ROBOT.directions(x))
    w = np.array([0.0, 0.0, 85.0 * GRAVITY])
    res = scipy_optimize.minimize(
        lambda t: 0.5 * t @ t,
        np.full(8, 100.0),
        jac=lambda t: t,
        constraints=[{"type": "eq", "fun": lambda t: A @ t - w, "jac": lambda t: A}],
        bounds=[(float(ROBOT.min_tension), None)] * 8,
        method="SLSQP",
        options={"ftol": 1e-12, "maxiter": 500},
    )
    np.testing.assert_allclose(t, res.x, rtol=1e-5, atol=1e-4)


def test_tension_distribution_infeasible_is_nan():
    # Near an edge with a light load, t_min on every cable outweighs the load.
    t = tension_distribution(ROBOT, jnp.asarray((1.5, -1.4, 0.6)), 20.0)
    assert np.all(np.isnan(np.asarray(t)))


@pytest.mark.parametrize("position", POSES)
def test_forward_kinematics_inverts_inverse_kinematics(position):
    x = jnp.asarray(position)
    lengths = ROBOT.geometric_lengths(x)
    guess = x + jnp.array([0.05, -0.03, -0.08])
    np.testing.assert_allclose(forward_kinematics(ROBOT, lengths, guess), x, atol=1e-10)
    # Longer cables: the end-effector hangs lower.
    assert float(forward_kinematics(ROBOT, lengths + 0.01, x)[2]) < x[2]


def test_pick_and_place():
    sc = cdpr.pick_and_place(0.1, dt=0.5)
    t = np.asarray(sc.time)
    assert t[0] == 0.0 and t[-1] == pytest.approx(360.0) and np.all(np.diff(t) > 0)
    payload = np.asarray(sc.payload)
    assert payload.min() == 0.0 and payload.max() == 65.0
    assert set(np.unique(payload)) >= {0.0, 65.0, 30.0, 50.0}
    pos = np.asarray(sc.position)
    assert np.all(np.abs(pos[:, :2]) < 2.0) and np.all(
        (pos[:, 2] > 0) & (pos[:, 2] < 4)
    )
    np.testing.assert_allclose(pos[0], cdpr.HOME)
    # The payload is carried from the pick to the place, and only there.
    carrying = payload > 0
    assert np.all(np.linalg.norm(pos[carrying] - cdpr.HOME, axis=1) > 0.5)
    lengths = jax.vmap(ROBOT.free_lengths)(sc.position)
    assert 6.0 < float(lengths.min()) and float(lengths.max()) < 9.0  # Piao's range
    with pytest.raises(ValueError, match="`hours`"):
        cdpr.pick_and_place(-1.0)
    with pytest.raises(ValueError, match="`payloads`"):
        cdpr.pick_and_place(1.0, payloads=[10.0, -5.0])
    with pytest.raises(ValueError, match="pulleys"):
        cdpr.Robot(pulleys=np.zeros((3, 3)))


def test_real_cables_are_drawn_per_cable():
    real = cdpr.real_cables(jax.random.key(1))
    assert isinstance(real, TerminationCompliance)
    assert real.base.E2c.shape == (8,) and real.compliance.shape == (8,)
    assert len(np.unique(np.asarray(real.base.eta0))) == 8
    ratio = np.asarray(real.base.eta0) / float(cdpr.NOMINAL.eta0)
    assert np.all((ratio > 0.7) & (ratio < 1.4))
    np.testing.assert_array_equal(real.base.gamma, cdpr.NOMINAL.gamma)


SHORT = cdpr.pick_and_place(10 / 60)
REAL = cdpr.real_cables(jax.random.key(0))


def test_integrated_compensation_removes_80_percent_short():
    runs = {
        name: cdpr.simulate_robot(ROBOT, SHORT, REAL, model)
        for name, model in (("none", None), ("integrated", cdpr.NOMINAL))
    }
    rms = {k: float(r.rms_error()) for k, r in runs.items()}
    # The creep-induced error is all of the uncompensated error here (the elastic
    # part is < 10 % of it; the slow test checks against Hooke's law too).
    assert rms["integrated"] < 0.2 * rms["none"]
    none = runs["none"]
    # Without compensation the commands are the inverse kinematics and the cables
    # stretch: the end-effector hangs low.
    np.testing.assert_allclose(
        none.command, jax.vmap(ROBOT.free_lengths)(SHORT.position), rtol=1e-12
    )
    assert float(jnp.mean(none.error[:, 2])) < -0.01
    assert np.all(np.asarray(none.forces) >= float(ROBOT.min_tension) - 1e-9)
    assert float(jnp.max(none.forces)) < cdpr.BREAKING_LOAD / 10
    integrated = runs["integrated"]
    np.testing.assert_allclose(
        integrated.command,
        jax.vmap(ROBOT.free_lengths)(SHORT.position) - integrated.predicted,
        rtol=1e-12,
    )


# The scenario of the two gradient tests below: one length, so that the jitted loss
# and gradient (`cdpr.loss_and_grad`) compile once for both.
TRAIN = cdpr.pick_and_place(5 / 60)


@pytest.mark.slow
def test_closed_loop_gradient_matches_finite_differences():
    sc = TRAIN
    # `loss_and_grad` is `jax.value_and_grad(position_loss)`, jitted: the gradient
    # and the finite differences come from one compiled program (also the one
    # test_tune_gain_lowers_the_error uses), not a gradient and a loss compiled apart.
    _, grad = cdpr.loss_and_grad(1.0, ROBOT, sc, REAL, cdpr.NOMINAL)
    grad = float(grad)
    h = 1e-5

    def loss(gain):
        return cdpr.loss_and_grad(gain, ROBOT, sc, REAL, cdpr.NOMINAL)[0]

    fd = (float(loss(1.0 + h)) - float(loss(1.0 - h))) / (2 * h)
    assert grad != 0.0
    np.testing.assert_allclose(grad, fd, rtol=1e-6)

    # And with respect to a parameter of the controller's model (the dashpot).
    @eqx.filter_jit
    def loss_and_slope_eta0(log_scale, sc):
        def loss_eta0(log_scale):
            model = jc.IntegratedModel(eta0=cdpr.NOMINAL.eta0 * jnp.exp(log_scale))
            return cdpr.position_loss(1.0, ROBOT, sc, REAL, model)

        return jax.value_and_grad(loss_eta0)(log_scale)

    # The dashpot's share of the loss is tiny (a slope of ~3e-9): at h = 1e-5 the
    # rounding of the two losses (and of their Newton solves) is ~3e-6 of the
    # difference; at h = 1e-3 the step's own error is ~2e-7, at 1e-2 ~2e-5.
    h = 1e-3
    grad = float(loss_and_slope_eta0(jnp.asarray(0.0), sc)[1])
    plus = float(loss_and_slope_eta0(jnp.asarray(h), sc)[0])
    minus = float(loss_and_slope_eta0(jnp.asarray(-h), sc)[0])
    fd = (plus - minus) / (2 * h)
    np.testing.assert_allclose(grad, fd, rtol=1e-6)


@pytest.mark.slow
def test_tune_gain_lowers_the_error():
    sc = TRAIN
    gain, history = cdpr.tune_gain(ROBOT, sc, REAL, cdpr.NOMINAL, jnp.ones(8))
    assert gain.shape == (8,)
    assert history[-1]["rms_mm"] < 0.9 * history[0]["rms_mm"]
    assert np.all((np.asarray(gain) > 0.8) & (np.asarray(gain) < 1.25))
    # The Jacobian of the tuning is the forward-mode twin of the loss's gradient.
    r, J = cdpr.errors_and_jacobian(jnp.ones(8), ROBOT, sc, REAL, cdpr.NOMINAL)
    _, grad = cdpr.loss_and_grad(1.0, ROBOT, sc, REAL, cdpr.NOMINAL)
    T = sc.time.shape[0]
    np.testing.assert_allclose(2 * jnp.sum(J.T @ r) / T, grad, rtol=1e-8)


@pytest.mark.slow
def test_two_hour_scenario_table():
    # The README's numbers: 2 h of pick-and-place at 1 Hz.
    table = cdpr.compare(ROBOT, cdpr.pick_and_place(2.0), REAL)
    assert set(table) == {"none", "Hooke", "five-element (Piao, live)", "integrated"}
    assert cdpr.removed(table, "integrated", "none") >= 80.0
    assert cdpr.removed(table, "integrated", "Hooke") >= 80.0
    assert table["integrated"]["max_mm"] < table["none"]["max_mm"]


def test_closed_form_3x3_solve_matches_lapack():
    # The robot's Newton and Gauss-Newton steps solve 3 x 3 systems in closed form.
    from jaxcable.cdpr.robot import _solve3

    rng = np.random.default_rng(0)
    for _ in range(20):
        a = rng.standard_normal((3, 8))
        m = a @ a.T + 1e-3 * np.eye(3)
        b = rng.standard_normal(3)
        np.testing.assert_allclose(_solve3(m, b), np.linalg.solve(m, b), rtol=1e-10)
    # A general (non-symmetric) matrix too.
    m = rng.standard_normal((3, 3)) + 3 * np.eye(3)
    np.testing.assert_allclose(_solve3(m, b), np.linalg.solve(m, b), rtol=1e-10)


@pytest.mark.parametrize(
    "fields, error",
    [
        (dict(steps=-1), ValueError),
        (dict(steps=1.5), TypeError),
        (dict(ridge=-0.1), ValueError),
        (dict(ridge="big"), TypeError),
    ],
)
def test_gain_tuning_names_a_bad_field(fields, error):
    (name,) = fields
    with pytest.raises(error, match=f"`{name}`"):
        cdpr.GainTuning(**fields)
    with pytest.raises(TypeError, match="`method`"):
        cdpr.tune_gain(ROBOT, None, REAL, cdpr.NOMINAL, 1.0, method={"steps": 1})
