"""The Numba peer baseline of benchmarks/ (benchmarks/peer_numba.py, what jaxcable is
timed against) computes the same elongations as jaxcable: float64, within 1e-12 of
each cable's peak. Numba is a benchmark-only dependency: skipped without it."""

import importlib.util
import pathlib

import numpy as np
import pytest


pytest.importorskip(
    "numba", reason="numba is a benchmark-only dependency (pip install -e .[bench])"
)

_PATH = pathlib.Path(__file__).resolve().parent.parent / "benchmarks" / "peer_numba.py"
_spec = importlib.util.spec_from_file_location("peer_numba", _PATH)
peer_numba = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(peer_numba)


def test_peer_numba_matches_jaxcable():
    # One serial kernel (compiled once, in a few seconds); 2 cables x 200 samples.
    check = peer_numba.check_agreement(200, 2, parallel=False)
    assert check["successful_jaxcable"] == check["successful_numba"] == 2
    assert check["agreement"] <= 1e-12


def test_peer_numba_flags_out_of_domain_parameters():
    _, arrays, lengths, speeds, params = peer_numba.problem(200, 2)
    params = np.array(params)
    params[peer_numba.PARAMETERS.index("lambda2")] = 1e12  # t_r2 < 0 (Park Eq. 8)
    out = peer_numba.simulate_rate_test_numba(
        params, lengths, speeds, arrays, parallel=False
    )
    assert (out["status"] == peer_numba.STATUS.index("out_of_domain")).all()
    assert np.isnan(out["elongation"]).all()


def test_peer_numba_matches_jaxcable_through_holds_rests_and_fallback():
    # Holds, a rest, padding, hardening (beta > 0) and, with one Newton step, the
    # bracket search and bisection: the same elongations (where bisection ends a
    # solve, its root is only known to the tolerance, 1e-12 of the strain, and the
    # differences add up over the samples).
    import jax

    import jaxcable as jc

    protocol = jc.Protocol.concatenate(
        jc.Protocol.cycles(100.0, 2, samples_per_ramp=20, hold=30.0),
        jc.Protocol.rest(3600.0, samples=5),
        jc.Protocol.cycles(150.0, 1, samples_per_ramp=20, force_min=20.0, start=False),
    ).pad(130)
    arrays = {
        k: np.asarray(getattr(protocol, k))
        for k in ("force", "direction", "duration", "mask")
    }
    lengths, speeds = np.array([0.1, 0.5]), np.array([3e-3, 10e-3]) / 60
    params = dict(zip(peer_numba.PARAMETERS, peer_numba.problem(2, 1)[-1]))
    params.update(beta=0.3, gamma=0.5, t_r1=60.0)
    params = np.array([params[k] for k in peer_numba.PARAMETERS])
    model, cables = peer_numba.jaxcable_inputs(params, lengths, speeds)
    for max_steps, agree in ((32, 1e-12), (1, 1e-10)):
        solver = jc.Newton(tol=1e-12, max_steps=max_steps)
        traj = jax.vmap(
            lambda c: jc.simulate_rate_test(
                model, c, protocol, method=jc.Simulation(solver=solver, throw=False)
            )
        )(cables)
        out = peer_numba.simulate_rate_test_numba(
            params, lengths, speeds, arrays, max_steps=max_steps, parallel=False
        )
        assert (traj.result == jc.RESULTS.successful).all()
        assert (out["status"] == 0).all()
        assert peer_numba.agreement(traj.elongation, out["elongation"]) <= agree
