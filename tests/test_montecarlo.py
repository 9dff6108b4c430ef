"""Monte-Carlo: reproducibility, chunking, percentiles against NumPy, failed draws,
distributions, input errors, and sharding over 4 CPU devices (in a subprocess)."""

import json
import math
import os
import pathlib
import subprocess
import sys
import textwrap

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxcable as jc


ROOT = pathlib.Path(__file__).resolve().parent.parent
# Parameters pinned here (not the library defaults, which calibration may change).
MODEL = jc.IntegratedModel(
    E1c=2.2e9, beta=0.3, gamma=0.5, E1r=2.5e9, E2c=3.7e8, t_c=100.0, eta0=1.6e11,
    E2r=1.5e9, t_r1=60.0, E3r=6.0e8, lambda1=7.8e-3, lambda2=2.1e4,
)  # fmt: skip
SAMPLES = 40
TIME = np.linspace(0.0, 2 * 3600.0, SAMPLES)
# Two cables of a robot, each with its own logged force history.
FORCE = np.stack(
    [60 + 40 * np.sin(TIME / 900) ** 2, 30 + 50 * np.sin(TIME / 1500) ** 2]
)
LOADS = jc.ForceHistory(TIME, FORCE)
# No breaking strain: these parameters creep the cables far beyond a real rope's over
# 2 h, and these tests are about the statistics (tests/test_breaking_strain.py counts
# the draws that break).
UNBREAKABLE = math.inf
CABLES = jc.Cable(
    length=jnp.array([3.0, 5.0]), speed=3e-3 / 60, breaking_strain=UNBREAKABLE
)
NUM_DRAWS = 20  # not a multiple of the chunk: the last chunk is padded
CHUNK = 8


def _sampler(lambda2=(1.5e4, 2.5e4)):
    # One pytree structure for every test (one compilation each configuration).
    return jc.IndependentParameters(
        MODEL,
        {"E2c": jc.LogNormal(3.7e8, 0.1), "lambda2": jc.Uniform(*lambda2)},
    )


# The fields of jc.MonteCarlo among `_run`'s keywords.
_METHOD_FIELDS = (
    "key", "num_draws", "percentiles", "chunk_size", "method", "bins", "keep_draws",
    "devices",
)  # fmt: skip


def _run(**kwargs):
    args = dict(
        parameters=_sampler(),
        cables=CABLES,
        loads=LOADS,
        progress_meter=jc.NoProgressMeter(),
    )
    fields = dict(
        key=jax.random.key(0),
        num_draws=NUM_DRAWS,
        chunk_size=CHUNK,
        method="exact",
        keep_draws=True,
    )
    for name, value in kwargs.items():
        (fields if name in _METHOD_FIELDS else args)[name] = value
    return jc.monte_carlo(**args, method=jc.MonteCarlo(**fields))


@pytest.fixture(scope="module")
def exact():
    return _run()


def _reference(parameters, cables, loads, key, num_draws):
    """Every (draw, cable) simulated one by one with the public single-cable API."""
    out = np.full((num_draws, len(cables.length), loads.time.shape[-1]), np.nan)
    speeds = jnp.broadcast_to(cables.speed, cables.length.shape)
    for i in range(num_draws):
        model = parameters.draw(jax.random.fold_in(key, i))
        for j in range(len(cables.length)):
            cable = jc.Cable(
                length=cables.length[j],
                speed=speeds[j],
                breaking_strain=UNBREAKABLE,
            )
            traj = jc.simulate_force_history(
                model,
                cable,
                loads.time[j],
                loads.force[j],
                method=jc.Simulation(throw=False),
            )
            if traj.result == jc.RESULTS.successful:
                out[i, j] = np.asarray(traj.elongation)
    return out


def test_percentiles_match_numpy_percentile(exact):
    ref = _reference(_sampler(), CABLES, LOADS, jax.random.key(0), NUM_DRAWS)
    assert exact.method == "exact"
    np.testing.assert_allclose(exact.elongation, ref, rtol=1e-12, atol=0)
    expected = np.percentile(ref, exact.q, axis=0)
    np.testing.assert_allclose(exact.percentiles, expected, rtol=1e-12, atol=0)
    np.testing.assert_allclose(exact.mean, ref.mean(axis=0), rtol=1e-12)
    np.testing.assert_allclose(exact.std, ref.std(axis=0), rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(exact.min, ref.min(axis=0), rtol=1e-12)
    np.testing.assert_allclose(exact.max, ref.max(axis=0), rtol=1e-12)
    np.testing.assert_array_equal(exact.time, np.broadcast_to(TIME, (2, SAMPLES)))
    np.testing.assert_array_equal(exact.num_successful, [NUM_DRAWS, NUM_DRAWS])
    np.testing.assert_array_equal(exact.percentile(99.0), exact.percentiles[-1])
    # Spread is real: the draws differ.
    assert np.all(exact.std[:, -1] > 0)


def test_reproducible_with_seed(exact):
    again = _run()
    np.testing.assert_array_equal(again.percentiles, exact.percentiles)
    np.testing.assert_array_equal(again.elongation, exact.elongation)
    other = _run(key=jax.random.key(1))
    assert not np.allclose(other.percentiles[:, :, -1], exact.percentiles[:, :, -1])


def test_chunked_equals_unchunked(exact):
    whole = _run(chunk_size=NUM_DRAWS)
    np.testing.assert_allclose(whole.elongation, exact.elongation, rtol=1e-13)
    np.testing.assert_allclose(whole.percentiles, exact.percentiles, rtol=1e-13)
    np.testing.assert_allclose(whole.mean, exact.mean, rtol=1e-13)
    np.testing.assert_allclose(whole.std, exact.std, rtol=1e-10, atol=1e-16)


def test_histogram_percentiles_within_their_resolution(exact):
    hist = _run(method="histogram", keep_draws=False, bins=256)
    assert hist.method == "histogram" and hist.elongation is None
    err = np.abs(np.asarray(hist.percentiles) - np.asarray(exact.percentiles))
    assert np.all(err <= np.asarray(hist.resolution) * (1 + 1e-9) + 1e-15)
    # Bins of 2 x range(first chunk) / 256: ~1/100 of the spread here.
    spread = np.asarray(exact.max - exact.min)[None]
    assert np.all(np.asarray(hist.resolution) <= 0.02 * spread + 1e-12)
    # Moments are exact in both methods.
    np.testing.assert_allclose(hist.mean, exact.mean, rtol=1e-12)
    np.testing.assert_allclose(hist.std, exact.std, rtol=1e-9, atol=1e-15)


def test_failed_draws_are_counted_and_excluded():
    # Park Eq. 8: t_r2 = lambda1 (L0/v)^2 - lambda2 must be > 0. For the fast, short
    # cable (L0/v = 300 s) lambda1 (L0/v)^2 = 702 s, so about half of the draws of
    # lambda2 ~ U(0, 1400) s fail for it; the slow cable never fails.
    cables = jc.Cable(
        length=jnp.array([3.0, 0.3]),
        speed=jnp.array([5e-5, 1e-3]),
        breaking_strain=UNBREAKABLE,
    )
    key = jax.random.key(3)
    sampler = _sampler(lambda2=(0.0, 1400.0))
    res = _run(parameters=sampler, cables=cables, key=key)
    ref = _reference(sampler, cables, LOADS, key, NUM_DRAWS)
    ok = ~np.isnan(ref[:, :, 0])
    assert ok[:, 0].all() and 0 < ok[:, 1].sum() < NUM_DRAWS
    np.testing.assert_array_equal(res.num_successful, ok.sum(axis=0))
    counts = {k: np.asarray(v) for k, v in res.status_counts.items()}
    np.testing.assert_array_equal(
        counts["parameter_out_of_domain"], [0, NUM_DRAWS - ok[:, 1].sum()]
    )
    np.testing.assert_array_equal(sum(counts.values()), [NUM_DRAWS, NUM_DRAWS])
    # Excluded, never NaN: statistics over the successful draws only.
    assert np.all(np.isfinite(res.percentiles)) and np.all(np.isfinite(res.mean))
    expected = np.percentile(ref[ok[:, 1], 1], res.q, axis=0)
    np.testing.assert_allclose(res.percentiles[:, 1], expected, rtol=1e-12)
    np.testing.assert_allclose(res.mean[1], ref[ok[:, 1], 1].mean(0), rtol=1e-12)
    assert np.all(np.isnan(np.asarray(res.elongation)[~ok[:, 1], 1]))


def test_rate_test_with_correlated_parameters():
    # A fit's (model, names, covariance) triple; a rate-driven protocol whose sample
    # times are solved per draw.
    names = ("E2c", "t_c", "eta0")
    std = np.array([0.1 * 3.7e8, 0.1 * 100.0, 0.05 * 1.6e11])
    corr = np.array([[1.0, 0.5, 0.0], [0.5, 1.0, -0.3], [0.0, -0.3, 1.0]])
    sampler = jc.CorrelatedParameters.from_correlation(MODEL, names, std, corr)
    protocol = jc.Protocol.cycles(100.0, 1, samples_per_ramp=8)
    cables = jc.Cable(
        length=jnp.array([0.3, 0.5]),
        speed=jnp.array([5e-5, 1e-4]),
        breaking_strain=UNBREAKABLE,
    )
    key = jax.random.key(7)
    method = jc.MonteCarlo(
        key=key, num_draws=6, chunk_size=4, method="exact", keep_draws=True
    )
    res = jc.monte_carlo(
        sampler, cables, protocol, method, progress_meter=jc.NoProgressMeter()
    )
    elong = np.zeros((6, 2, protocol.num_samples))
    times = np.zeros_like(elong)
    for i in range(6):
        model = sampler.draw(jax.random.fold_in(key, i))
        for j in range(2):
            cable = jc.Cable(
                length=cables.length[j],
                speed=cables.speed[j],
                breaking_strain=UNBREAKABLE,
            )
            traj = jc.simulate_rate_test(model, cable, protocol)
            elong[i, j], times[i, j] = traj.elongation, traj.time
    np.testing.assert_allclose(res.elongation, elong, rtol=1e-10, atol=1e-15)
    np.testing.assert_allclose(res.time, times.mean(axis=0), rtol=1e-10)
    np.testing.assert_allclose(
        res.percentiles, np.percentile(elong, res.q, axis=0), rtol=1e-10, atol=1e-15
    )


def test_distributions_sample_correctly():
    key = jax.random.key(11)
    n = 200_000
    x = np.asarray(jc.Normal(2.0, 0.5).sample(key, (n,)))
    assert x.shape == (n,)
    assert abs(x.mean() - 2.0) < 0.01 and abs(x.std() - 0.5) < 0.01
    y = np.asarray(jc.LogNormal(3.7e8, 0.2).sample(key, (n,)))
    assert np.all(y > 0)
    assert abs(np.median(y) / 3.7e8 - 1) < 0.01 and abs(np.log(y).std() - 0.2) < 0.002
    u = np.asarray(jc.Uniform(-1.0, 3.0).sample(key, (n,)))
    assert u.min() >= -1.0 and u.max() < 3.0 and abs(u.mean() - 1.0) < 0.02
    assert abs(u.var() - 16 / 12) < 0.02


def test_correlated_parameters_reproduce_the_covariance():
    names = ("E2c", "beta", "lambda2")
    std = np.array([0.05 * 3.7e8, 0.02, 0.01 * 2.1e4])
    corr = np.array([[1.0, 0.6, -0.4], [0.6, 1.0, 0.1], [-0.4, 0.1, 1.0]])
    cov = np.outer(std, std) * corr
    keys = jax.random.split(jax.random.key(5), 100_000)
    # Linear space: exactly the given mean and covariance.
    lin = jc.CorrelatedParameters(MODEL, names, cov, log_space=())
    models = jax.vmap(lin.draw)(keys)
    draws = np.stack([np.asarray(getattr(models, n)) for n in names], axis=1)
    np.testing.assert_allclose(draws.mean(0), [3.7e8, 0.3, 2.1e4], rtol=2e-3)
    np.testing.assert_allclose(np.cov(draws.T), cov, rtol=0.03, atol=0.02 * std.max())
    np.testing.assert_allclose(np.corrcoef(draws.T), corr, atol=0.01)
    # Log space (the default for positive parameters): medians at the mean, the same
    # correlation of the logarithms, always positive.
    log = jc.CorrelatedParameters(MODEL, names, cov)
    assert log.log_space == (True, True, True)
    models = jax.vmap(log.draw)(keys)
    draws = np.stack([np.asarray(getattr(models, n)) for n in names], axis=1)
    assert np.all(draws > 0)
    np.testing.assert_allclose(np.median(draws, 0), [3.7e8, 0.3, 2.1e4], rtol=3e-3)
    np.testing.assert_allclose(np.corrcoef(np.log(draws).T), corr, atol=0.01)
    rel = np.log(draws).std(0)
    np.testing.assert_allclose(rel, std / np.array([3.7e8, 0.3, 2.1e4]), rtol=0.02)
    # Unlisted parameters keep the model's value.
    assert np.all(np.asarray(models.E1c) == float(MODEL.E1c))


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(num_draws=0), "num_draws"),
        (dict(num_draws=2.5), "num_draws"),
        (dict(chunk_size=0), "chunk_size"),
        (dict(key=0), "key"),
        (dict(key=jax.random.split(jax.random.key(0), 2)), "key"),
        (dict(percentiles=(50, 101)), "percentiles"),
        (dict(percentiles=()), "percentiles"),
        (dict(method="median"), "method"),
        (dict(bins=1, method="histogram", keep_draws=False), "bins"),
        (dict(method="histogram"), "keep_draws"),
        (dict(parameters=MODEL), "parameters"),
        (dict(cables=CABLES.length), "cables"),
        (dict(loads=FORCE), "loads"),
        (dict(loads=jc.ForceHistory(TIME, FORCE[:1].repeat(3, 0))), "loads"),
        (dict(loads=jc.ForceHistory(TIME[::-1], FORCE)), "time"),
        (dict(loads=jc.ForceHistory(TIME, -FORCE)), "force"),
        (dict(loads=jc.ForceHistory(TIME, FORCE + 5000)), "force"),
        (dict(devices=[]), "devices"),
        (dict(progress_meter="yes"), "progress_meter"),
    ],
)
def test_bad_inputs_raise(kwargs, match):
    # A count that is not an integer is a TypeError.
    with pytest.raises((ValueError, TypeError), match=match):
        _run(**kwargs)


def test_bad_distributions_and_samplers_raise():
    with pytest.raises(ValueError, match="sigma"):
        jc.LogNormal(1.0, -0.1)
    with pytest.raises(ValueError, match="median"):
        jc.LogNormal(0.0, 0.1)
    with pytest.raises(ValueError, match="std"):
        jc.Normal(0.0, -1.0)
    with pytest.raises(ValueError, match="low"):
        jc.Uniform(2.0, 1.0)
    with pytest.raises(ValueError, match="distributions"):
        jc.IndependentParameters(MODEL, {"E9": jc.Normal(1.0, 0.1)})
    with pytest.raises(ValueError, match="distributions"):
        jc.IndependentParameters(MODEL, {"E2c": 3.0})
    with pytest.raises(ValueError, match="names"):
        jc.CorrelatedParameters(MODEL, ("E2c", "nope"), np.eye(2))
    with pytest.raises(ValueError, match="covariance"):
        jc.CorrelatedParameters(MODEL, ("E2c", "t_c"), np.eye(3))
    with pytest.raises(ValueError, match="covariance"):
        jc.CorrelatedParameters(MODEL, ("E2c", "t_c"), [[1.0, 2.0], [2.0, 1.0]])
    with pytest.raises(ValueError, match="covariance"):
        jc.CorrelatedParameters(MODEL, ("E2c", "t_c"), [[1.0, 0.5], [0.0, 1.0]])
    with pytest.raises(ValueError, match="log_space"):
        jc.CorrelatedParameters(MODEL, ("E2c",), [[1.0]], log_space=("t_c",))


_SHARDED = textwrap.dedent(
    """
    import json, sys
    import jax, jax.numpy as jnp, numpy as np
    jax.config.update("jax_enable_x64", True)
    sys.path.insert(0, {root!r})
    from tests import test_montecarlo as t

    assert len(jax.devices()) == 4, jax.devices()
    out = {{"devices": len(jax.devices())}}
    for method in ("exact", "histogram"):
        r = t._run(method=method, keep_draws=method == "exact", bins=256)
        out[method] = dict(
            percentiles=np.asarray(r.percentiles).tolist(),
            resolution=np.asarray(r.resolution).tolist(),
            mean=np.asarray(r.mean).tolist(),
            std=np.asarray(r.std).tolist(),
            ok=np.asarray(r.num_successful).tolist(),
        )
    print(json.dumps(out))
    """
)


def test_sharded_over_four_devices_equals_single_device(exact):
    env = dict(os.environ)
    env["XLA_FLAGS"] = (
        env.get("XLA_FLAGS", "") + " --xla_force_host_platform_device_count=4"
    ).strip()
    env["JAX_PLATFORMS"] = "cpu"
    proc = subprocess.run(
        [sys.executable, "-c", _SHARDED.format(root=str(ROOT))],
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
        cwd=ROOT,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    sharded = json.loads(proc.stdout.strip().splitlines()[-1])
    assert sharded["devices"] == 4
    assert len(jax.devices()) == 1
    single = {
        "exact": exact,
        "histogram": _run(method="histogram", keep_draws=False, bins=256),
    }
    for method, res in single.items():
        got = sharded[method]
        np.testing.assert_allclose(got["percentiles"], res.percentiles, rtol=1e-12)
        np.testing.assert_allclose(got["resolution"], res.resolution, rtol=1e-12)
        np.testing.assert_allclose(got["mean"], res.mean, rtol=1e-12)
        np.testing.assert_allclose(got["std"], res.std, rtol=1e-9, atol=1e-15)
        np.testing.assert_array_equal(got["ok"], res.num_successful)
