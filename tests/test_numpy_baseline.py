"""The NumPy baseline of benchmarks/ (what jaxcable is timed against) computes the same
numbers as the kernel: float64, rtol 1e-8, on a multi-cycle protocol with a rest."""

import importlib.util
import pathlib

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxcable as jc


_PATH = (
    pathlib.Path(__file__).resolve().parent.parent / "benchmarks" / "numpy_baseline.py"
)
_spec = importlib.util.spec_from_file_location("numpy_baseline", _PATH)
numpy_baseline = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(numpy_baseline)

PROTOCOL = jc.Protocol.concatenate(
    jc.Protocol.cycles(100.0, 3, samples_per_ramp=40, hold=30.0),
    jc.Protocol.rest(3600.0, samples=10),
    jc.Protocol.cycles(150.0, 2, samples_per_ramp=40, force_min=20.0, start=False),
)
LENGTHS = np.array([0.1, 0.3, 0.5])
SPEEDS = np.array([3e-3, 5e-3, 10e-3]) / 60
PINNED = jc.IntegratedModel(
    E1c=2.2e9, beta=0.3, gamma=0.5, E1r=2.5e9, E2c=3.7e9, t_c=100.0, eta0=1e15,
    E2r=2.5e9, t_r1=60.0, E3r=2.0e9, lambda1=7.8e-3, lambda2=2.1e4, t_e=5.0,
    strain_a=4e7 / 2.2e9,
)  # fmt: skip


@pytest.mark.parametrize(
    "model", [jc.IntegratedModel(), PINNED], ids=["default", "pinned"]
)
def test_numpy_baseline_matches_kernel(model):
    arrays = {
        k: np.asarray(getattr(PROTOCOL, k))
        for k in ("force", "direction", "duration", "mask")
    }
    params = numpy_baseline.default_parameters(model)
    ref = numpy_baseline.simulate_rate_test_numpy(params, LENGTHS, SPEEDS, arrays)
    assert ref["converged"].all()
    # The other Cable fields keep their defaults, broadcast to the batch.
    cables = jax.tree_util.tree_map(
        lambda x: jnp.broadcast_to(x, (3,)),
        jc.Cable(length=jnp.asarray(LENGTHS), speed=jnp.asarray(SPEEDS)),
    )
    traj = jax.vmap(lambda c: jc.simulate_rate_test(model, c, PROTOCOL))(cables)
    assert traj.elongation.dtype == jnp.float64
    np.testing.assert_allclose(ref["time"], traj.time, rtol=1e-8, atol=1e-9)
    np.testing.assert_allclose(ref["strain"], traj.strain, rtol=1e-8, atol=1e-14)
    np.testing.assert_allclose(
        ref["elongation"], traj.elongation, rtol=1e-8, atol=1e-14
    )
    # The protocol exercises every branch: reversals, a hold, recovery during the rest.
    assert np.ptp(np.asarray(traj.parts.recovery_long)) > 0
    assert np.ptp(np.asarray(traj.parts.recovery_short)) > 0


def test_numpy_baseline_flags_out_of_domain_parameters():
    params = numpy_baseline.default_parameters(PINNED)
    params["lambda2"] = 1e12  # t_r2 = lambda1 (L0/v)^2 - lambda2 < 0 (Park Eq. 8)
    arrays = (PROTOCOL.force, PROTOCOL.direction, PROTOCOL.duration)
    ref = numpy_baseline.simulate_rate_test_numpy(params, LENGTHS, SPEEDS, arrays)
    assert not ref["converged"].any()
