"""The persistent compilation cache: the command line fills it, a second process
loads from it, `jaxcable cache --clear` empties it, and nothing is cached unless
asked for (the library leaves jax.config alone)."""

import os
import pathlib
import subprocess
import sys

import jax
import numpy as np
import pytest

import jaxcable as jc
from jaxcable._cache import cache_size
from jaxcable.cli import main


def _run(code: str, env: dict) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-c", code],
        env={**os.environ, **env},
        capture_output=True,
        text=True,
        timeout=300,
    )


def _cli_env(tmp_path, **extra):
    env = {"JAXCABLE_CACHE_DIR": str(tmp_path / "cache"), "JAXCABLE_NO_CACHE": ""}
    return {**env, **extra}


_SIMULATE = """
import sys
from jaxcable.cli import main
sys.exit(main(["simulate", {protocol!r}, "--out", {out!r}]))
"""


@pytest.fixture
def protocol(tmp_path):
    path = tmp_path / "protocol.json"
    path.write_text(
        '{"length_mm": 300, "segments": [{"cycles": 1, "force_max_N": 50, '
        '"samples_per_ramp": 20}]}',
        encoding="utf-8",
    )
    return str(path)


def test_cli_fills_the_cache_and_a_second_process_reuses_it(tmp_path, protocol):
    env = _cli_env(tmp_path)
    code = _SIMULATE.format(protocol=protocol, out=str(tmp_path / "a.csv"))
    first = _run(code, env)
    assert first.returncode == 0, first.stderr
    files, size = cache_size(tmp_path / "cache")
    assert files > 0 and size > 0
    second = _run(code, env)
    assert second.returncode == 0, second.stderr
    # The second run wrote no new program: every one was found in the cache.
    assert cache_size(tmp_path / "cache")[0] == files


def test_no_cache_switch_and_clear(tmp_path, protocol, capsys):
    env = _cli_env(tmp_path, JAXCABLE_NO_CACHE="1")
    code = _SIMULATE.format(protocol=protocol, out=str(tmp_path / "a.csv"))
    assert _run(code, env).returncode == 0
    assert cache_size(tmp_path / "cache") == (0, 0)

    cache = tmp_path / "cache"
    cache.mkdir()
    (cache / "jit_f-0123-cache").write_bytes(b"x" * 10)
    assert jc.clear_compilation_cache(cache) == 10
    assert not cache.exists()
    # A folder that is not a cache is refused, and nothing in it deleted.
    other = tmp_path / "notes"
    other.mkdir()
    (other / "thesis.tex").write_text("precious", encoding="utf-8")
    with pytest.raises(ValueError, match="not a compilation-cache entry"):
        jc.clear_compilation_cache(other)
    assert (other / "thesis.tex").exists()


def test_cache_command_reports_and_clears(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("JAXCABLE_CACHE_DIR", str(tmp_path / "c"))
    (tmp_path / "c").mkdir()
    (tmp_path / "c" / "jit_g-abc-cache").write_bytes(b"y" * 2000)
    assert main(["cache"]) == 0
    out = capsys.readouterr().out
    assert str(tmp_path / "c") in out and "1 files" in out
    assert main(["cache", "--clear"]) == 0
    assert not (tmp_path / "c").exists()


def test_importing_jaxcable_leaves_the_cache_off(tmp_path):
    done = _run(
        "import jax, jaxcable; print(jax.config.jax_compilation_cache_dir)",
        {"JAXCABLE_CACHE_DIR": str(tmp_path), "JAX_COMPILATION_CACHE_DIR": ""},
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() in ("None", "")
    # In this process too: the only cache is the run's own (tests/conftest.py); the
    # command line, run in-process with its cache turned off, left it as it was.
    suite = os.environ.get("JAXCABLE_TEST_JAX_CACHE", "off")
    expected = None if suite == "off" else suite
    assert (jax.config.jax_compilation_cache_dir or None) == expected


_FIT = """
import sys
from jaxcable.cli import main
sys.exit(main({argv!r}))
"""


def _fit_argv(out):
    data = sorted(
        str(p) for p in (pathlib.Path(jc.__file__).parent / "data").glob("*.csv")
    )
    return [
        # Hooke: the thinned files join samples across 24 h rests, over which a
        # dashpot at its default viscosity creeps past the rope's breaking strain.
        "fit", *data[:2], "--model", "hooke", "--every", "20", "--starts", "2",
        "--max-steps", "30", "--out", str(out), "--quiet",
    ]  # fmt: skip


def test_warm_fit_loads_the_exported_kernel_and_writes_the_same_params(tmp_path):
    """A second process loads the fit kernel exported by the first (no tracing), and
    its PARAMS.json is byte for byte the first's and the uncached library fit's."""
    pytest.importorskip("flatbuffers")
    # A short fit (30 steps): converged or not (exit status 1), PARAMS.json is
    # written, and it is the program's output that is compared.
    env = _cli_env(tmp_path)
    exported = tmp_path / "cache" / "exported"
    cold = _run(_FIT.format(argv=_fit_argv(tmp_path / "cold.json")), env)
    assert cold.returncode in (0, 1), cold.stderr
    programs = sorted(exported.glob("fit-*-cache"))
    assert len(programs) == 1
    written = programs[0].stat().st_mtime_ns
    warm = _run(_FIT.format(argv=_fit_argv(tmp_path / "warm.json")), env)
    assert warm.returncode in (0, 1), warm.stderr
    # Read, not exported again.
    assert sorted(exported.glob("fit-*-cache")) == programs
    assert programs[0].stat().st_mtime_ns == written
    cold_json = (tmp_path / "cold.json").read_text(encoding="utf-8")
    assert (tmp_path / "warm.json").read_text(encoding="utf-8") == cold_json
    # The library's own kernel (no cache at all), in a fresh process too.
    off = _cli_env(
        tmp_path, JAXCABLE_NO_CACHE="1", JAXCABLE_CACHE_DIR=str(tmp_path / "n")
    )
    plain = _run(_FIT.format(argv=_fit_argv(tmp_path / "plain.json")), off)
    assert plain.returncode in (0, 1), plain.stderr
    assert not (tmp_path / "n").exists()
    assert (tmp_path / "plain.json").read_text(encoding="utf-8") == cold_json


@pytest.mark.filterwarnings("ignore::jaxcable.IdentifiabilityWarning")
def test_cached_kernels_in_process_match_the_library_fit(tmp_path):
    """The exported program, written then read back, gives the library fit's result
    bit for bit; a damaged file is exported again."""
    pytest.importorskip("flatbuffers")
    from jaxcable._cli.data import _thin
    from jaxcable._fit import cached_fit_kernels

    data = sorted((pathlib.Path(jc.__file__).parent / "data").glob("*.csv"))[:2]
    with jax.enable_x64(True):
        tests = [jc.read_test(p) for p in data]
        tests = [_thin(t, 20) for t in tests]
        method = jc.LeastSquares(multistart=2, max_steps=30)
        # A stiff dashpot: the thinned tests join samples across 24 h rests, over
        # which the default one creeps past the rope's breaking strain.
        problem = jc.Problem(jc.BurgersModel(eta0=1e14), tests)
        plain = jc.fit(problem, method, throw=False)
        results = []
        for damage in (False, False, True):
            for p in (tmp_path / "x").glob("fit-*-cache"):
                if damage:
                    p.write_bytes(b"not a program")
            with cached_fit_kernels(tmp_path / "x"):
                results.append(jc.fit(problem, method, throw=False))
    assert len(list((tmp_path / "x").glob("fit-*-cache"))) == 1
    for r in results:
        for name in ("values", "stderr", "start_losses", "rmse_mm"):
            np.testing.assert_array_equal(getattr(r, name), getattr(plain, name))
        assert r.loss == plain.loss and r.num_steps == plain.num_steps


def test_no_cache_switch_turns_exported_kernels_off_and_clear_takes_them(
    tmp_path, monkeypatch
):
    from jaxcable._cache import exported_programs_dir

    monkeypatch.setenv("JAXCABLE_CACHE_DIR", str(tmp_path / "c"))
    monkeypatch.setenv("JAXCABLE_NO_CACHE", "1")
    assert exported_programs_dir() is None
    monkeypatch.setenv("JAXCABLE_NO_CACHE", "")
    assert exported_programs_dir() == tmp_path / "c" / "exported"
    (tmp_path / "c" / "exported").mkdir(parents=True)
    (tmp_path / "c" / "exported" / "fit-0123-cache").write_bytes(b"z" * 5)
    assert main(["cache", "--clear"]) == 0
    assert not (tmp_path / "c").exists()
