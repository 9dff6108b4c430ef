"""How a history's samples are solved: unrolled Newton steps first, the robust path
(loops, bracket, bisection) only where they did not converge, in one pass (a CPU's
default) or two (an accelerator's: no loop in the first, the robust pass for a
history that needs it, derivatives by replaying the roots). Each is checked against
the robust path from one Newton step (`ROBUST`)."""

import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxcable as jc
from jaxcable.internal import drives, newton, scan

from .helpers import finite_difference_grad


MODEL = jc.IntegratedModel()
CABLE = jc.Cable(length=0.3, speed=5e-3 / 60)
PROTOCOL = jc.Protocol.concatenate(
    jc.Protocol.cycles(100.0, 2, samples_per_ramp=60),
    jc.Protocol.rest(3600.0, samples=6),
    jc.Protocol.cycles(150.0, 1, samples_per_ramp=60),
)
ROBUST = jc.Newton(tol=1e-12, unrolled=1, two_pass=False)
TWO_PASS = jc.Newton(tol=1e-12, unrolled=3, two_pass=True)
TIME = np.linspace(0.0, 600.0, 240)
ELONGATION = 0.3 * 0.012 * np.sin(TIME / 120.0) ** 2


@functools.cache
def _robust_rate_test():
    return jc.simulate_rate_test(
        MODEL, CABLE, PROTOCOL, method=jc.Simulation(solver=ROBUST)
    )


def _peak_error(a, b):
    return float(np.max(np.abs(np.asarray(a) - np.asarray(b))) / np.max(np.abs(b)))


def _fast_pass(solver, model=MODEL, cable=CABLE, protocol=PROTOCOL):
    drive = drives.RateDrive(protocol, solver)
    return scan._pass(drive, model, cable, "fast", None)[0]


@pytest.mark.parametrize("solver", [None, TWO_PASS], ids=["default", "two_pass"])
def test_rate_test_equals_the_robust_path(solver):
    fast = jc.simulate_rate_test(
        MODEL, CABLE, PROTOCOL, method=jc.Simulation(solver=solver)
    )
    robust = _robust_rate_test()
    assert _peak_error(fast.elongation, robust.elongation) <= 1e-10
    assert _peak_error(fast.time, robust.time) <= 1e-10
    for a, b in zip(jax.tree.leaves(fast.parts), jax.tree.leaves(robust.parts)):
        assert float(np.max(np.abs(a - b))) <= 1e-10 * float(np.max(fast.strain))


def test_the_first_of_two_passes_solves_a_finely_sampled_history():
    # With 200 samples a ramp, no sample of this history (ramps from 0 N, a rest, a
    # reload past the old peak) needs the robust pass; with 60, the first samples
    # of a ramp from rest need a fourth Newton step.
    fine = jc.Protocol.concatenate(
        jc.Protocol.cycles(100.0, 2, samples_per_ramp=200),
        jc.Protocol.rest(3600.0, samples=6),
        jc.Protocol.cycles(150.0, 1, samples_per_ramp=200),
    )
    assert _fast_pass(TWO_PASS, protocol=fine).result == jc.RESULTS.successful
    assert _fast_pass(TWO_PASS).result == jc.RESULTS.newton_failed
    four = jc.Newton(tol=1e-12, unrolled=4, two_pass=True)
    assert _fast_pass(four).result == jc.RESULTS.successful


@pytest.mark.parametrize("solver", [None, TWO_PASS], ids=["default", "two_pass"])
def test_elongation_history_equals_the_robust_path(solver):
    fast = jc.simulate_elongation_history(
        MODEL, CABLE, TIME, ELONGATION, method=jc.Simulation(solver=solver)
    )
    robust = jc.simulate_elongation_history(
        MODEL, CABLE, TIME, ELONGATION, method=jc.Simulation(solver=ROBUST)
    )
    assert _peak_error(fast.force, robust.force) <= 1e-10


def test_a_history_the_first_pass_cannot_solve_is_solved_robustly():
    # One Newton step never converges to 1e-12 from the predictor: the first pass
    # fails, and the robust pass gives the robust path's answer, bit for bit.
    one_step = jc.Newton(tol=1e-12, unrolled=1, two_pass=True)
    assert _fast_pass(one_step).result == jc.RESULTS.newton_failed
    again = jc.simulate_rate_test(
        MODEL, CABLE, PROTOCOL, method=jc.Simulation(solver=one_step)
    )
    robust = _robust_rate_test()
    np.testing.assert_array_equal(again.elongation, robust.elongation)
    assert again.result == jc.RESULTS.successful


def test_a_batch_reruns_only_what_needs_it():
    # Under vmap, cables that need the robust pass get it and the others keep the
    # first pass's answer; every cable as when simulated alone.
    cables = jc.Cable(length=jnp.array([0.1, 0.3, 0.5]), speed=5e-3 / 60)
    cables = jax.tree.map(lambda x: jnp.broadcast_to(x, (3,)), cables)
    # One Newton step: every cable needs the robust pass.
    for solver in [jc.Newton(tol=1e-12, unrolled=1, two_pass=True)]:
        batch = jax.vmap(
            lambda c: jc.simulate_rate_test(
                MODEL, c, PROTOCOL, method=jc.Simulation(solver=solver)
            )
        )(cables)
        for i in range(3):
            one = jax.tree.map(lambda x: x[i], cables)
            alone = jc.simulate_rate_test(
                MODEL, one, PROTOCOL, method=jc.Simulation(solver=solver)
            )
            np.testing.assert_allclose(
                batch.elongation[i], alone.elongation, rtol=1e-12, atol=0
            )


@pytest.mark.parametrize("solver", [None, TWO_PASS], ids=["default", "two_pass"])
def test_failures_are_classified_as_by_the_robust_path(solver):
    # A force that creep keeps out of reach of a slow crosshead: no root.
    slow = jc.Cable(length=0.3, speed=1e-9)
    protocol = jc.Protocol.cycles(1900.0, 1, samples_per_ramp=20)
    fast = jc.simulate_rate_test(
        MODEL, slow, protocol, method=jc.Simulation(solver=solver, throw=False)
    )
    robust = jc.simulate_rate_test(
        MODEL, slow, protocol, method=jc.Simulation(solver=ROBUST, throw=False)
    )
    assert fast.result == robust.result
    assert fast.result != jc.RESULTS.successful


def test_gradients_in_two_passes_equal_the_robust_path_and_finite_differences():
    # The default's one pass is the robust path's derivative machinery, checked
    # against finite differences in test_jax_contract.py.
    solver = TWO_PASS

    def loss(model, solver):
        traj = jc.simulate_rate_test(
            model, CABLE, PROTOCOL, method=jc.Simulation(solver=solver)
        )
        return jnp.sum(traj.elongation**2) * 1e6

    fast = eqx.filter_grad(loss)(MODEL, solver)
    robust = eqx.filter_grad(loss)(MODEL, ROBUST)
    for name in ("E1c", "E2r", "t_e", "t_r1", "E3r"):
        np.testing.assert_allclose(
            getattr(fast, name), getattr(robust, name), rtol=1e-8, err_msg=name
        )
    fd = finite_difference_grad(
        lambda e: loss(eqx.tree_at(lambda m: m.E2r, MODEL, e), solver), MODEL.E2r
    )
    np.testing.assert_allclose(fast.E2r, fd, rtol=1e-5)


def test_the_first_pass_has_no_loop_and_no_branch_off_the_cpu(monkeypatch):
    # Off the CPU every loop or branch of a sample reads its predicate back to the
    # host: the first pass of a rate-driven test has none (its guess is a select),
    # and the robust pass is one loop over the whole history.
    monkeypatch.setattr(drives, "branches_are_cheap", lambda: False)
    monkeypatch.setattr(newton, "branches_are_cheap", lambda: False)
    drive = drives.RateDrive(PROTOCOL, drives.default_solver(jnp.float64))
    assert drive.two_pass
    jaxpr = str(
        jax.make_jaxpr(lambda m: scan._pass(drive, m, CABLE, "fast", None)[0])(MODEL)
    )
    assert "while[" not in jaxpr and "cond[" not in jaxpr
    whole = str(
        jax.make_jaxpr(lambda m: jc.simulate_rate_test(m, CABLE, PROTOCOL).strain)(
            MODEL
        )
    )
    assert whole.count("while[") > 0


@pytest.mark.parametrize("bad", [0, -1, 1.5, True])
def test_bad_unrolled(bad):
    # Not an integer: TypeError; below 1: ValueError.
    with pytest.raises((ValueError, TypeError), match="unrolled"):
        jc.Newton(tol=1e-12, unrolled=bad)


def test_bad_simulation_fields():
    with pytest.raises(ValueError, match="solver"):
        jc.Simulation(solver="newton")
    with pytest.raises(TypeError, match="throw"):
        jc.Simulation(throw="no")
    # A solver where the simulation's method belongs.
    with pytest.raises(TypeError, match="method"):
        jc.simulate_rate_test(MODEL, CABLE, PROTOCOL, method=jc.Newton(tol=1e-12))


def test_bad_two_pass():
    with pytest.raises(ValueError, match="two_pass"):
        jc.Newton(tol=1e-12, two_pass="yes")


def test_a_model_and_cable_of_two_dtypes_are_refused():
    cable32 = jc.Cable(length=jnp.float32(0.3), speed=jnp.float32(5e-3 / 60))
    with pytest.raises(ValueError, match="`model` has float64"):
        jc.simulate_rate_test(MODEL, cable32, PROTOCOL)
    with pytest.raises(ValueError, match="`model` has float64"):
        jc.simulate_elongation_history(MODEL, cable32, TIME, ELONGATION)
