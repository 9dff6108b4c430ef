"""`jaxcable.StreamingLeastSquares`: the fit of a long record from normal equations
accumulated sample by sample (memory independent of the record's length)."""

import jax.numpy as jnp
import numpy as np
import pytest

import jaxcable as jc


NAMES = ("E1", "eta0", "E2", "eta2")
TRUTH = jc.BurgersModel(E1=2.4e9, eta0=5e15, E2=7e8, eta2=2.0e10)


def _record(samples: int, seed: int = 1, control: str = "force") -> jc.TestData:
    """A robot-like force record (two periods of load change, 2 Hz sampling) on a
    2 m cable, its elongation from TRUTH with 1 um of noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(samples) * 0.5
    f = 40 + 20 * np.sin(2 * np.pi * t / 300.0) + 10 * np.sin(2 * np.pi * t / 37.0)
    f[0] = 0.0
    cable = jc.Cable(length=2.0)
    e = jc.simulate_force_history(TRUTH, cable, jnp.asarray(t), jnp.asarray(f))
    noisy = np.asarray(e.elongation) + 1e-6 * rng.standard_normal(samples)
    meta = {"length_mm": 2000.0, "diameter_mm": 3.0, "control": control}
    return jc.TestData(time=t, force=f, elongation=noisy, metadata=meta)


@pytest.fixture(scope="module")
def record():
    # Longer than one block of the streaming scan (4096 samples): the blocks and the
    # padding of the last one are exercised.
    return _record(5000)


def test_the_same_fit_as_in_memory(record):
    problem = jc.Problem(jc.BurgersModel(), [record], fit=NAMES)
    memory = jc.fit(problem, jc.LeastSquares(multistart=1))
    stream = jc.fit(problem, jc.StreamingLeastSquares())
    assert stream.result == jc.RESULTS.successful and stream.names == memory.names
    values, reference = np.asarray(stream.values), np.asarray(memory.values)
    # Within a hundredth of a standard error (the in-memory solver stops at its own
    # tolerance), and the uncertainties alike.
    assert np.all(np.abs(values - reference) <= 0.01 * np.asarray(memory.stderr))
    np.testing.assert_allclose(stream.stderr, memory.stderr, rtol=1e-3)
    np.testing.assert_allclose(stream.loss, memory.loss, rtol=1e-8)
    np.testing.assert_array_equal(stream.num_samples, memory.num_samples)
    # And near the truth: the fit is of the data, not of the start.
    assert abs(values[0] / TRUTH.E1 - 1) < 1e-3


def test_bad_problems_and_fields_are_named(record):
    driven = _record(200, control="elongation")
    with pytest.raises(ValueError, match="force-driven"):
        jc.fit(
            jc.Problem(jc.BurgersModel(), [driven], fit=NAMES),
            jc.StreamingLeastSquares(),
        )
    with pytest.raises(ValueError, match="per_test"):
        jc.fit(
            jc.Problem(
                jc.BurgersModel(), [record, record], fit=NAMES, per_test=("E1",)
            ),
            jc.StreamingLeastSquares(),
        )
    with pytest.raises(ValueError, match="max_steps"):
        jc.StreamingLeastSquares(max_steps=0)
    with pytest.raises(ValueError, match="rtol"):
        jc.StreamingLeastSquares(rtol=-1.0)
    with pytest.raises(TypeError, match="method"):
        jc.fit(jc.Problem(jc.BurgersModel(), [record], fit=NAMES), "streaming")  # pyright: ignore[reportArgumentType]
