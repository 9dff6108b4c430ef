"""The per-sample Newton solve of rate-driven tests (Park Eq. 5-6)."""

import numpy as np

import jaxcable as jc


CABLE = jc.Cable(length=0.3, speed=3e-3 / 60)


def test_unloading_with_fast_recovery_converges():
    # Regression: with a stiff spring and a fast unloading element the residual
    # first falls (recovery outruns the crosshead) and then rises through zero; plain
    # Newton from the instantaneous guess ran away to dt = 0 and reported failure.
    model = jc.FiveElementModel(E_L1=3e10, E_UL1=3e10)
    traj = jc.simulate_rate_test(model, CABLE, jc.Protocol.cycles(100.0, 2, 100))
    assert traj.result == jc.RESULTS.successful
    # Kinematics hold on every ramp sample: |d strain| = (v / L0) dt.
    ramp = np.asarray(jc.Protocol.cycles(100.0, 2, 100).direction) != 0
    d_strain = np.abs(np.diff(np.asarray(traj.strain)))[ramp[1:]]
    d_time = np.diff(np.asarray(traj.time))[ramp[1:]]
    np.testing.assert_allclose(
        d_strain, CABLE.strain_rate * d_time, rtol=1e-8, atol=1e-14
    )


def test_every_model_runs_a_rate_test():
    protocol = jc.Protocol.concatenate(
        jc.Protocol.cycles(50.0, 2, 40), jc.Protocol.rest(600.0, samples=5)
    )
    fast = jc.Cable(length=0.3, speed=10e-3 / 60)
    for model in (
        jc.IntegratedModel(),
        # Piao's default spring is practically rigid (E_L1 from the Table 3 surface):
        # a crosshead-driven test of it is a stiff problem; use a compliant spring.
        jc.FiveElementModel(E_L1=3e10, E_UL1=3e10),
        jc.BurgersModel(),
        jc.HookeModel(),
        jc.BoucWenModel(),
    ):
        traj = jc.simulate_rate_test(model, fast, protocol)
        assert traj.result == jc.RESULTS.successful, type(model).__name__
        assert np.all(np.diff(np.asarray(traj.time)) >= 0)


def test_unloading_with_strong_short_recovery_converges():
    # Regression: the relative residual was scaled by |crosshead strain(dt)| + floor,
    # which depends on dt. With a strong, fast short-term recovery (small E2r, short
    # t_r1) the unloading residual is far below zero past its turning point, and the
    # scale's slope term flipped the residual's slope there: the solver took the
    # iterate for one before the turning point, grew it past the end of the ramp and
    # reported `newton_failed`. The scale is now fixed per sample.
    model = jc.IntegratedModel(E2r=5e8, t_r1=2.0)
    cable = jc.Cable(length=0.3, speed=10e-3 / 60)
    protocol = jc.Protocol.cycles(100.0, 2, 50)
    traj = jc.simulate_rate_test(
        model, cable, protocol, method=jc.Simulation(throw=False)
    )
    assert traj.result == jc.RESULTS.successful
    # The recovery is strong: it takes a sizeable share of the peak strain.
    assert np.max(traj.parts.recovery_short) > 0.05 * np.max(traj.strain)
    # Kinematics hold on every ramp sample: |d strain| = (v / L0) dt.
    ramp = np.asarray(protocol.direction) != 0
    d_strain = np.abs(np.diff(np.asarray(traj.strain)))[ramp[1:]]
    d_time = np.diff(np.asarray(traj.time))[ramp[1:]]
    np.testing.assert_allclose(
        d_strain, cable.strain_rate * d_time, rtol=1e-8, atol=1e-14
    )


def _tanh_root(tol, guess, c, active=None):
    """`root_scalar` on fn(y, c) = tanh(4 (y - c)): a root at y = c along a rising
    tanh, flat far from it, so that Newton's steps (at most 3) overshoot from far
    away; c < 0 puts the root below `lower` (no root)."""
    import jax.numpy as jnp

    from jaxcable import Newton
    from jaxcable.internal import newton

    return newton.root_scalar(
        lambda y, c: jnp.tanh(4.0 * (y - c)),
        Newton(tol=tol, max_steps=3),
        guess,
        c,
        jnp.zeros_like(guess),
        slope_sign=jnp.ones_like(guess),
        growth=jnp.asarray(1e-3),
        active=active,
    )


def test_fallback_lanes_under_vmap_match_single_solves():
    # The bracket search and the bisection share one loop in which each lane goes
    # through its own phases: under vmap, a lane that Newton's method solves, one it
    # fails on that has a root (search, then bisection), one without a root and an
    # inactive one must each get what they get alone.
    import jax
    import jax.numpy as jnp

    def solve(guess, c, active):
        r = _tanh_root(1e-6, guess, c, active)
        return r.value, r.converged, r.no_root

    guess = jnp.array([1.01, 30.0, 0.5, 30.0])
    c = jnp.array([1.0, 7.0, -1.0, 7.0])
    active = jnp.array([True, True, True, False])
    batched = jax.vmap(solve)(guess, c, active)
    for i in range(4):
        single = solve(guess[i], c[i], active[i])
        for b, s in zip(batched, single):
            np.testing.assert_array_equal(np.asarray(b[i]), np.asarray(s))
    value, converged, no_root = (np.asarray(x) for x in batched)
    assert converged[:2].all() and not converged[2:].any()
    np.testing.assert_allclose(value[:2], [1.0, 7.0], atol=1e-5)
    assert no_root[2] and not no_root[[0, 1, 3]].any()


def test_root_derivative_is_implicit_on_newton_and_bisected_lanes():
    # The root's derivative comes from the implicit function theorem with the slope
    # the solve evaluated (Newton's lanes) or, for a root found by bisection, which
    # evaluates no slopes, the slope at the root: here the root is y = c, so
    # dy/dc = 1 exactly on every lane that has a root, in forward and reverse mode,
    # alone and under vmap.
    import jax
    import jax.numpy as jnp

    def root(c, guess):
        return _tanh_root(1e-10, guess, c).value

    # Newton converges from 1.01; from 30 it overshoots and bisection finishes.
    c = jnp.array([1.0, 7.0])
    guess = jnp.array([1.01, 30.0])

    @jax.jit
    def derivatives(c, guess):
        batched = lambda c: jax.vmap(root)(c, guess)
        return (
            batched(c),
            jax.jacfwd(batched)(c),
            jax.jacrev(batched)(c),
            # One lane alone: the bisected one, and the guess of the other.
            jax.grad(root)(c[1], guess[1]),
            jax.grad(root, argnums=1)(c[0], guess[0]),
        )

    value, forward, reverse, alone, by_guess = derivatives(c, guess)
    np.testing.assert_allclose(value, c, atol=1e-9)
    np.testing.assert_allclose(forward, np.eye(2), atol=1e-8)
    np.testing.assert_allclose(reverse, np.eye(2), atol=1e-8)
    np.testing.assert_allclose(alone, 1.0, rtol=1e-8)
    # The guess does not move the root.
    assert by_guess == 0.0


def test_state_at_the_root_is_the_model_at_the_solved_times():
    # The rate and elongation drives take the model's state after a sample from the
    # solve's last evaluation, moved to the root to first order
    # (`root_derivatives.aux_at_root`), instead of running the model once more. The
    # same model driven by the solved (time, force) history must give the same
    # strain split at every sample, to ~tol^2: here, float64, 1e-12 of the peak.
    # Two model classes (each compiles three simulations): Park's, also with a
    # strong fast recovery, and the five-element model.
    protocol = jc.Protocol.concatenate(
        jc.Protocol.cycles(80.0, 2, 40), jc.Protocol.rest(600.0, samples=5)
    )
    for model in (
        jc.IntegratedModel(),
        jc.IntegratedModel(E2r=5e8, t_r1=2.0),
        jc.FiveElementModel(E_L1=3e10, E_UL1=3e10),
    ):
        name = type(model).__name__
        rate = jc.simulate_rate_test(model, CABLE, protocol)
        assert rate.result == jc.RESULTS.successful, name
        again = jc.simulate_force_history(model, CABLE, rate.time, rate.force)
        peak = float(np.max(np.abs(rate.strain)))
        for field in ("instantaneous", "creep", "recovery_short", "recovery_long"):
            np.testing.assert_allclose(
                getattr(again.parts, field),
                getattr(rate.parts, field),
                rtol=0,
                atol=1e-12 * peak,
                err_msg=f"{name} {field}",
            )
        # The elongation drive solves the force of each sample of the same history.
        elong = jc.simulate_elongation_history(model, CABLE, rate.time, rate.elongation)
        assert elong.result == jc.RESULTS.successful, name
        forward = jc.simulate_force_history(model, CABLE, elong.time, elong.force)
        np.testing.assert_allclose(
            forward.strain, elong.strain, rtol=0, atol=1e-12 * peak, err_msg=name
        )
