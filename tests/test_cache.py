"""The persistent compilation cache: the command line fills it, a second process
loads from it, `jaxcable cache --clear` empties it, and nothing is cached unless
asked for (the library leaves jax.config alone)."""

import os
import subprocess
import sys

import jax
import pytest

import jaxcable as jc
from jaxcable._cache import cache_size
from jaxcable._cli import main


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
from jaxcable._cli import main
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
