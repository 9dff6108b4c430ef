"""One force history, one answer (issue 10, item 5): every entry point that drives a
model with a time-stamped force history gives the same elongations for the same noisy
history, and none of them takes an input conditioning option the others lack."""

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jaxcable as jc
from jaxcable.cli import main
from jaxcable.internal import heldout_rmse, model_elongations


# Issue 10's history: 0 -> 100 N in 300 s, hold 2 h, unload to 2 N in 300 s, rest 2 h,
# 400 samples, with 0.2 % of the peak force as zero-mean load-cell noise (clipped at
# 0). A 300 mm cable, the default IntegratedModel.
_PEAK = 100.0
_NOISE = 0.002 * _PEAK


def _history():
    time = np.concatenate(
        [
            np.linspace(0.0, 300.0, 61),
            300.0 + np.linspace(0.0, 7200.0, 141)[1:],
            7500.0 + np.linspace(0.0, 300.0, 61)[1:],
            7800.0 + np.linspace(0.0, 7200.0, 141)[1:],
        ]
    )
    force = np.interp(time, [0.0, 300.0, 7500.0, 7800.0, 15000.0], [0, 100, 100, 2, 2])
    rng = np.random.default_rng(10)
    noisy = np.clip(force + _NOISE * rng.standard_normal(time.size), 0.0, None)
    noisy[0] = 0.0
    test = jc.TestData(
        time=time,
        force=noisy,
        elongation=np.zeros_like(time),
        metadata={"id": "entry-points", "length_mm": 300.0, "control": "force"},
    )
    return test


class _Nominal(jc.AbstractParameterSampler):
    """Every draw is the given model (a Monte-Carlo at the nominal parameters)."""

    model: jc.AbstractCableModel

    def draw(self, key):
        return self.model


def _close(name, actual, expected):
    np.testing.assert_allclose(
        np.asarray(actual),
        np.asarray(expected),
        rtol=1e-10,
        atol=1e-15,
        err_msg=f"{name} differs from simulate_force_history",
    )


def test_every_entry_point_gives_the_same_elongations(tmp_path):
    model = jc.IntegratedModel()
    test = _history()
    cable = test.cable()
    time, force = jnp.asarray(test.time), jnp.asarray(test.force)
    n = test.num_samples
    assert 300 <= n <= 500

    # 1. simulate_force_history.
    reference = np.asarray(
        jc.simulate_force_history(model, cable, time, force).elongation
    )
    assert reference.shape == (n,) and np.all(np.isfinite(reference))
    assert np.max(reference) > 1e-3  # a loaded 300 mm cable, not a trivial history

    # 2. A user's own lax.scan of `step`.
    @jax.jit
    def user_scan(time, force):
        def body(state, x):
            state, parts = jc.step(model, cable, state, *x)
            return state, parts.total * cable.length

        _, e = jax.lax.scan(body, jc.init_state(model, cable, time[0]), (time, force))
        return e

    _close("lax.scan of step", user_scan(time, force), reference)

    # 3. controller_step over the history (one cable of the set).
    cables = eqx.tree_at(lambda c: c.length, cable, jnp.reshape(cable.length, (1,)))

    @jax.jit
    def controller(time, force):
        def body(state, x):
            t, f = x
            return jc.controller_step(model, cables, state, t, f[None])

        state = jc.controller_init(model, cables, time[0])
        _, e = jax.lax.scan(body, state, (time, force))
        return e[:, 0]

    _close("controller_step", controller(time, force), reference)

    # 4. The fit's path (`residuals`, through `model_elongations`, which `fit`,
    # `diagnose` and the reports use).
    (fitted,) = model_elongations(model, [test])
    _close("the fit's residuals", fitted, reference)
    # diagnose's own defaults (it used to pick a data-derived tolerance): the model
    # that made the data predicts its held-out part exactly.
    exact = dataclasses.replace(test, elongation=reference)
    assert heldout_rmse(model, [exact]) < 1e-10 * 1e3 * np.max(reference)

    # 5. monte_carlo over a ForceHistory, one draw at the nominal parameters.
    mc = jc.monte_carlo(
        _Nominal(model),
        cable,
        jc.ForceHistory(time, force),
        progress_meter=jc.NoProgressMeter(),
        method=jc.MonteCarlo(
            key=jax.random.key(0), num_draws=1, method="exact", keep_draws=True
        ),
    )
    assert mc.elongation.shape == (1, 1, n)
    _close("monte_carlo", mc.elongation[0, 0], reference)

    # 6. The command line: `jaxcable simulate HISTORY.csv`.
    src, out = tmp_path / "history.csv", tmp_path / "out.csv"
    jc.write_csv(src, test)
    assert main(["simulate", str(src), "--model", "integrated", "--out", str(out)]) == 0
    _close("jaxcable simulate", jc.read_csv(out).elongation, reference)


@pytest.mark.parametrize(
    "call",
    [
        lambda m, c, t, f: jc.simulate_force_history(m, c, t, f, reversal_tolerance=1),
        lambda m, c, t, f: jc.step(
            m, c, jc.init_state(m, c), 1.0, 1.0, reversal_tolerance=1
        ),
    ],
    ids=["simulate_force_history", "step"],
)
def test_reversal_tolerance_is_gone(call):
    # Regression (issue 10): a threshold only some entry points applied made the
    # library give two answers for one history.
    model, cable = jc.IntegratedModel(), jc.Cable(0.3)
    with pytest.raises(TypeError, match="reversal_tolerance"):
        call(model, cable, jnp.array([0.0, 1.0]), jnp.array([0.0, 1.0]))


@pytest.mark.parametrize("command", ["simulate", "fit", "diagnose"])
def test_cli_refuses_reversal_tolerance(tmp_path, capsys, command):
    src = tmp_path / "history.csv"
    jc.write_csv(src, _history())
    argv = [command, str(src), "--reversal-tolerance-N", "0.5"]
    argv += ["--out", str(tmp_path / "out.json")] if command != "diagnose" else []
    assert main(argv) == 2
    assert "unrecognized arguments: --reversal-tolerance-N" in capsys.readouterr().err
