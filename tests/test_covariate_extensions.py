"""The extensions driven by a recorded covariate (`jc.COVARIATE_EXTENSIONS`): each is
its base at the null value, matches its closed form, has finite-difference
gradients, refuses bad parameters, and a fit through `covariate=` recovers it."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxcable as jc

from .helpers import finite_difference_grad, humidity_history


BASE = jc.BurgersModel(E1=2e9, eta0=2e13, E2=6e9, eta2=6e10)
LENGTH_MM = 300.0
# An effect of each of about 1e-3 of strain over the humidity swings below.
SIZES = {"covariate_strain": 3e-5, "mechano_sorptive": 6e-13, "covariate_shift": 0.02}


def _history(seed: int, samples: int = 120):
    return humidity_history(seed, samples)


def _raw(seeds=(0, 1, 2)):
    out = []
    for s in seeds:
        time, force, humidity = _history(s)
        out.append(
            jc.TestData(
                time=time,
                force=force,
                elongation=np.zeros_like(time),
                extra={"humidity": humidity},
                # No breaking strain: the shifted time of the gradient test's target
                # creeps this dashpot past the rope's.
                metadata={
                    "length_mm": LENGTH_MM,
                    "control": "force",
                    "id": f"t{s}",
                    "breaking_strain": float("inf"),
                },
            )
        )
    return out


PADDED = jc.pad_tests(_raw(), drive="force", covariate="humidity")


def _elongation(model, padded=PADDED):
    """The model's elongation (m) at every sample, driven by the recorded force and
    covariate (the fit's own simulation: `jc.residuals` of zero data)."""
    params, static = eqx.partition(model, eqx.is_inexact_array)
    return np.asarray(jc.residuals(params, static, padded))


def _model(ext_id, size=None):
    cls = jc.COVARIATE_EXTENSIONS[ext_id]
    model = cls.wrap(BASE)
    value = SIZES[ext_id] if size is None else size
    return eqx.tree_at(lambda m: getattr(m, cls.SIZE_FIELD), model, jnp.asarray(value))


@pytest.mark.parametrize("ext_id", list(jc.COVARIATE_EXTENSIONS))
def test_null_value_is_the_base_exactly(ext_id):
    cls = jc.COVARIATE_EXTENSIONS[ext_id]
    assert ext_id not in jc.EXTENSIONS  # not a candidate of the plain catalogue
    np.testing.assert_array_equal(
        _elongation(cls.switched_off(BASE)), _elongation(BASE)
    )
    # And the effect is there at its size.
    assert np.max(np.abs(_elongation(_model(ext_id)) - _elongation(BASE))) > 1e-4


def test_covariate_strain_is_alpha_times_the_change_since_the_start():
    alpha = SIZES["covariate_strain"]
    added = _elongation(_model("covariate_strain")) - _elongation(BASE)
    for i, t in enumerate(_raw()):
        h = np.asarray(t.extra["humidity"])
        expected = alpha * (h - h[0]) * LENGTH_MM * 1e-3
        np.testing.assert_allclose(added[i, : len(h)], expected, atol=1e-15)


def test_mechano_sorptive_is_the_discovered_term_of_its_form():
    m = SIZES["mechano_sorptive"]
    term = jc.DiscoveredTerm(BASE, theta0=m, terms=("sigma_c_abs_rate",))
    np.testing.assert_allclose(
        _elongation(_model("mechano_sorptive")), _elongation(term), rtol=1e-12
    )


def test_covariate_shift_at_a_constant_covariate_is_the_base_on_scaled_time():
    # log10 a = -k (c - c_ref) = -log10 2: every process twice as fast, i.e. the
    # base on time stretched by 2 (force-driven: no crosshead speed involved).
    time, force, _ = _history(0)
    k = 0.5
    c = np.log10(2.0) / k
    cable = jc.Cable(length=0.3, covariate=c)
    model = jc.CovariateShift(BASE, k=k, c_ref=0.0)
    shifted = jc.simulate_force_history(model, cable, time, force).elongation
    stretched = jc.simulate_force_history(BASE, cable, 2 * time, force).elongation
    np.testing.assert_allclose(shifted, stretched, rtol=1e-10)
    # No covariate set (read as 0 = c_ref): the base.
    plain = jc.Cable(length=0.3)
    np.testing.assert_array_equal(
        jc.simulate_force_history(model, plain, time, force).elongation,
        jc.simulate_force_history(BASE, plain, time, force).elongation,
    )


@pytest.mark.parametrize("ext_id", list(jc.COVARIATE_EXTENSIONS))
def test_gradient_matches_finite_differences_and_vmaps(ext_id):
    cls = jc.COVARIATE_EXTENSIONS[ext_id]
    target = _elongation(_model(ext_id, 1.3 * SIZES[ext_id]))
    start = _model(ext_id, 0.7 * SIZES[ext_id])

    def loss(model):
        p, s = eqx.partition(model, eqx.is_inexact_array)
        r = jc.residuals(p, s, PADDED) - target
        return jnp.sum(r**2)

    grad = eqx.filter_jit(eqx.filter_grad(loss))(start)
    fd = finite_difference_grad(loss, start)
    for name in (cls.SIZE_FIELD, "base.E1", "base.eta0"):
        pick = (lambda n: lambda m: eval("m." + n))(name)  # noqa: S307
        g, f = float(pick(grad)), float(pick(fd))
        assert abs(g - f) <= 1e-4 * abs(f) + 1e-30, (name, g, f)
    # vmap over the size: each as computed alone.
    sizes = jnp.array([0.0, SIZES[ext_id]])
    batch = jax.jit(
        jax.vmap(
            lambda v: loss(eqx.tree_at(lambda m: getattr(m, cls.SIZE_FIELD), start, v))
        )
    )(sizes)
    np.testing.assert_allclose(batch[1], loss(_model(ext_id)), rtol=1e-10)


@pytest.mark.parametrize("ext_id", list(jc.COVARIATE_EXTENSIONS))
def test_bad_parameters_are_refused(ext_id):
    cls = jc.COVARIATE_EXTENSIONS[ext_id]
    with pytest.raises(ValueError, match=cls.__name__ + ".*" + cls.SIZE_FIELD):
        cls(BASE, **{cls.SIZE_FIELD: np.nan})
    # Traced, the domain check flags it instead of a silent NaN.
    bad = jax.jit(
        lambda v: eqx.tree_at(
            lambda m: getattr(m, cls.SIZE_FIELD), _model(ext_id), v
        ).check(jc.Cable(length=0.3, covariate=50.0))
    )(jnp.inf)
    assert bad == jc.RESULTS.parameter_out_of_domain


def test_a_fit_through_the_covariate_column_recovers_the_shift():
    true = _model("covariate_shift")
    clean = _elongation(true)
    rng = np.random.default_rng(5)
    tests = []
    for t, e in zip(_raw(), clean):
        n = len(t.time)
        noisy = e[:n] + 2e-6 * rng.normal(size=n)
        tests.append(
            jc.TestData(t.time, t.force, noisy, extra=t.extra, metadata=t.metadata)
        )
    start = _model("covariate_shift", 0.005)
    problem = jc.Problem(start, tests, fit=["k", "base.E1"], covariate="humidity")
    result = jc.fit(problem, jc.LeastSquares(multistart=1))
    k = result.names.index("k")
    assert abs(result.values[k] - SIZES["covariate_shift"]) <= 3 * result.stderr[k]
    assert result.stderr[k] < 0.1 * SIZES["covariate_shift"]
