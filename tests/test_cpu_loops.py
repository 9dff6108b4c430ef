"""`jaxcable.enable_cpu_loop_kernels`: XLA's option that compiles small while loops as
single CPU kernels, which the command line and this suite turn on."""

import json
import os
import subprocess
import sys

import jax.numpy as jnp
import numpy as np
import pytest

import jaxcable as jc
from jaxcable.internal import (
    DEFAULT_LOOP_KERNEL_BYTES,
    NO_LOOP_KERNELS_ENV,
    loop_kernels_disabled,
    with_loop_kernel_option,
)


_OPTION = "xla_cpu_small_while_loop_byte_threshold"


@pytest.mark.parametrize(
    "flags, expected",
    [
        ("", f"--xla_backend_extra_options={_OPTION}=64"),
        (
            "--xla_cpu_use_fusion_emitters=false",
            f"--xla_cpu_use_fusion_emitters=false "
            f"--xla_backend_extra_options={_OPTION}=64",
        ),
        # Merged into an extra-options flag already there (a second one would
        # replace it).
        (
            "--xla_backend_extra_options=xla_cpu_disable_loop_unrolling",
            f"--xla_backend_extra_options=xla_cpu_disable_loop_unrolling,{_OPTION}=64",
        ),
        # The caller's own threshold is kept.
        (
            f"--xla_backend_extra_options={_OPTION}=5",
            f"--xla_backend_extra_options={_OPTION}=5",
        ),
    ],
)
def test_the_flag_is_added_once_and_merged(flags, expected):
    assert with_loop_kernel_option(flags, 64) == expected


@pytest.mark.parametrize("bad", [0, -1, 1.5, True, "1024", None])
def test_bad_threshold_names_the_argument(bad):
    error = (
        ValueError if isinstance(bad, int) and not isinstance(bad, bool) else TypeError
    )
    with pytest.raises(error, match="byte_threshold"):
        jc.enable_cpu_loop_kernels(bad)


def test_after_the_first_computation_it_says_so():
    jnp.zeros(()).block_until_ready()
    before = os.environ.get("XLA_FLAGS")
    with pytest.raises(RuntimeError, match="before the first computation"):
        jc.enable_cpu_loop_kernels()
    assert os.environ.get("XLA_FLAGS") == before


def test_the_command_line_switch(monkeypatch):
    for value, disabled in [("", False), ("0", False), ("1", True), ("yes", True)]:
        monkeypatch.setenv(NO_LOOP_KERNELS_ENV, value)
        assert loop_kernels_disabled() is disabled


# One script, run in a fresh interpreter with XLA's defaults (no XLA_FLAGS): does
# importing jaxcable start JAX's backend, and the float64 results of the three drives
# and a gradient, which this process (with the loop kernels, tests/conftest.py)
# computes again.
_SCRIPT = r"""
import json
import jax
jax.config.update("jax_enable_x64", True)
import numpy as np
import jaxcable as jc
from jax._src import xla_bridge
import os
started_by_import = xla_bridge.backends_are_initialized()
flags = os.environ.get("XLA_FLAGS")
from tests.test_cpu_loops import drives
print(json.dumps(dict(started_by_import=started_by_import, flags=flags, **drives())))
"""


def drives() -> dict:
    """The float64 results of the three drives and a gradient, as lists."""
    import jax

    model = jc.IntegratedModel()
    protocol = jc.Protocol.cycles(100.0, 2, samples_per_ramp=60, start=False)
    cable = jc.Cable(length=0.3, speed=5e-3 / 60)
    rate = jc.simulate_rate_test(model, cable, protocol)
    elong = jc.simulate_elongation_history(model, cable, rate.time, rate.elongation)
    force = jc.simulate_force_history(model, cable, rate.time, rate.force)

    def loss(E1c):
        m = jc.IntegratedModel(E1c=E1c)
        return jnp.sum(jc.simulate_rate_test(m, cable, protocol).elongation ** 2)

    grad = jax.grad(loss)(jnp.asarray(model.E1c))
    return dict(
        rate=np.asarray(rate.elongation).tolist(),
        time=np.asarray(rate.time).tolist(),
        elong=np.asarray(elong.force).tolist(),
        force=np.asarray(force.elongation).tolist(),
        grad=float(grad),
    )


def _fresh_env(**extra: str) -> dict[str, str]:
    """This process's environment without XLA_FLAGS and jaxcable's switch, with the
    project on the path, plus `extra`."""
    env = {
        k: v
        for k, v in os.environ.items()
        if k not in ("XLA_FLAGS", NO_LOOP_KERNELS_ENV)
    }
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [root, env.get("PYTHONPATH")]))
    return {**env, **extra}


@pytest.fixture(scope="module")
def default():
    # XLA's default: no XLA_FLAGS, and jaxcable's import told to leave them.
    env = _fresh_env(**{NO_LOOP_KERNELS_ENV: "1"})
    done = subprocess.run(
        [sys.executable, "-c", _SCRIPT],
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_importing_jaxcable_computes_nothing(default):
    # Otherwise XLA_FLAGS set after `import jaxcable` would be ignored.
    assert default["started_by_import"] is False
    # ... and with the switch set, it leaves XLA's flags alone.
    assert default["flags"] is None


def test_the_suite_runs_with_the_default_threshold():
    if os.environ.get("JAXCABLE_TEST_LOOP_KERNELS", "on") == "off":
        pytest.skip("the loop kernels are off (`make test-xla-default`)")
    assert f"{_OPTION}=16777216" in os.environ["XLA_FLAGS"]
    assert with_loop_kernel_option("", DEFAULT_LOOP_KERNEL_BYTES) == (
        f"--xla_backend_extra_options={_OPTION}=16777216"
    )


def test_loop_kernels_give_xla_defaults_results(default):
    # XLA's default (no XLA_FLAGS at all) against this process's compilation (the
    # loop kernels, and the suite's emitters): the same float64 computation, compiled
    # differently, so equal to rounding.
    loops = drives()
    for key in ("time", "rate", "elong", "force"):
        a, b = np.asarray(default[key]), np.asarray(loops[key])
        assert a.shape == b.shape and np.all(np.isfinite(b))
        np.testing.assert_allclose(b, a, rtol=0, atol=1e-12 * np.max(np.abs(a)))
    np.testing.assert_allclose(loops["grad"], default["grad"], rtol=1e-10)


# What `import jaxcable` does to XLA_FLAGS in a fresh interpreter: the flags after the
# import, whether the backend then runs (a computation), and the warnings raised.
_IMPORT = r"""
import json, os, sys, warnings
warnings.simplefilter("always")
with warnings.catch_warnings(record=True) as caught:
    if sys.argv[1] == "late":
        import jax.numpy as jnp
        jnp.zeros(()).block_until_ready()
    import jaxcable as jc
    flags = os.environ.get("XLA_FLAGS")
    if sys.argv[1] == "replace":
        jc.enable_cpu_loop_kernels(4096)
    import jax.numpy as jnp
    float(jnp.ones(3).sum())
print(json.dumps(dict(
    flags=flags,
    replaced=os.environ.get("XLA_FLAGS"),
    warnings=[type(w.message).__name__ for w in caught],
    late=[str(w.message) for w in caught if issubclass(w.category, jc.LoopKernelWarning)],
)))
"""


def _import_in_fresh_process(case: str = "early", **env: str) -> dict:
    done = subprocess.run(
        [sys.executable, "-c", _IMPORT, case],
        env=_fresh_env(**env),
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


_OTHERS = "--xla_cpu_use_fusion_emitters=false --xla_backend_extra_options=xla_cpu_disable_loop_unrolling"


@pytest.mark.parametrize(
    "env, expected",
    [
        # A user's first import: the default threshold, and nothing else.
        ({}, f"--xla_backend_extra_options={_OPTION}=16777216"),
        # Other flags, and other extra options, are kept; the threshold merged in.
        (
            {"XLA_FLAGS": _OTHERS},
            "--xla_cpu_use_fusion_emitters=false --xla_backend_extra_options="
            f"xla_cpu_disable_loop_unrolling,{_OPTION}=16777216",
        ),
        # A threshold of the user's own is theirs.
        (
            {"XLA_FLAGS": f"--xla_backend_extra_options={_OPTION}=4096"},
            f"--xla_backend_extra_options={_OPTION}=4096",
        ),
        # The switch: XLA's flags untouched.
        ({NO_LOOP_KERNELS_ENV: "1", "XLA_FLAGS": _OTHERS}, _OTHERS),
        ({NO_LOOP_KERNELS_ENV: "1"}, None),
    ],
)
def test_importing_jaxcable_enables_the_loop_kernels(env, expected):
    out = _import_in_fresh_process(**env)
    assert out["flags"] == expected
    assert out["warnings"] == []


def test_importing_jaxcable_too_late_warns_once():
    out = _import_in_fresh_process("late")
    assert out["flags"] is None
    assert len(out["late"]) == 1 and "first computation" in out["late"][0]
    # With the switch, no warning.
    assert _import_in_fresh_process("late", **{NO_LOOP_KERNELS_ENV: "1"})["late"] == []


def test_a_call_of_the_users_replaces_the_imports_default():
    out = _import_in_fresh_process(
        "replace", XLA_FLAGS="--xla_cpu_use_fusion_emitters=false"
    )
    assert out["replaced"] == (
        "--xla_cpu_use_fusion_emitters=false "
        f"--xla_backend_extra_options={_OPTION}=4096"
    )
    # A threshold the user set before the import stays theirs, even then.
    mine = f"--xla_backend_extra_options={_OPTION}=7"
    assert _import_in_fresh_process("replace", XLA_FLAGS=mine)["replaced"] == mine
