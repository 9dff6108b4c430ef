import atexit
import os
import pathlib
import shutil
import subprocess
import sys
import tempfile


# The command line keeps compiled programs in a per-user cache; the suite runs the
# command line in-process, where that would change jax.config for every later test.
# tests/test_cache.py checks the cache itself, in fresh interpreters.
os.environ["JAXCABLE_NO_CACHE"] = "1"

# One compilation cache for the whole run, in a fresh folder: many tests (and the
# xdist workers, and the notebooks' kernels) compile the same kernels, and loading a
# program from disk takes a fraction of compiling it again. The first process of the
# run (plain pytest, or xdist's controller) makes the folder and deletes it at exit;
# the workers it starts inherit the variable. A fresh folder per run, so that a run
# never depends on what an earlier one left. JAXCABLE_TEST_JAX_CACHE=off turns it off.
TEST_CACHE_ENV = "JAXCABLE_TEST_JAX_CACHE"
if TEST_CACHE_ENV not in os.environ:
    _folder = tempfile.mkdtemp(prefix="jaxcable-test-cache-")
    os.environ[TEST_CACHE_ENV] = _folder
    atexit.register(shutil.rmtree, _folder, ignore_errors=True)
TEST_CACHE = (
    None
    if os.environ[TEST_CACHE_ENV] == "off"
    else pathlib.Path(os.environ[TEST_CACHE_ENV])
)

# XLA's CPU backend compiles each fusion through its MLIR fusion emitters by default.
# The suite compiles about 1300 programs and runs most of them a few times on small
# problems, so compilation is a large part of its cost (about 37 % of the cores' time
# with the default emitters); XLA's older LLVM IR emitters compile the same programs
# about 40 % faster, every test passing either way. They run large batches slower (a
# 1024-cable forward 3x), which is why the library leaves XLA's defaults alone and
# only the suite, its notebooks' kernels and its subprocesses switch. The first
# process of the run checks that this jaxlib knows the flag (XLA aborts on an unknown
# one) and the workers inherit its choice. With the same switch the suite compiles
# at XLA's backend optimisation level 0 (LLVM's passes off): about 15 % less time for
# the compile-bound test files (tests/test_fit.py, test_diagnose_drive.py,
# test_jax_contract.py), every test passing either way. JAXCABLE_TEST_XLA_EMITTERS=default keeps
# XLA's defaults for both (`make test-xla-default`).
TEST_EMITTERS_ENV = "JAXCABLE_TEST_XLA_EMITTERS"
LEGACY_EMITTERS = (
    "--xla_cpu_use_fusion_emitters=false --xla_backend_optimization_level=0"
)


def _with_flag(flags: str, flag: str) -> str:
    return f"{flags} {flag}".strip()


def _jaxlib_accepts(flag: str) -> bool:
    env = {**os.environ, "XLA_FLAGS": _with_flag(os.environ.get("XLA_FLAGS", ""), flag)}
    env["JAX_PLATFORMS"] = "cpu"
    probe = "import jax, jax.numpy as jnp; jnp.zeros(()).block_until_ready()"
    try:
        done = subprocess.run(
            [sys.executable, "-c", probe], env=env, capture_output=True, timeout=120
        )
    except subprocess.TimeoutExpired:
        return False
    return done.returncode == 0


_flags = os.environ.get("XLA_FLAGS", "")
if TEST_EMITTERS_ENV not in os.environ:
    _legacy = "use_fusion_emitters" not in _flags and _jaxlib_accepts(LEGACY_EMITTERS)
    os.environ[TEST_EMITTERS_ENV] = "legacy" if _legacy else "default"
if os.environ[TEST_EMITTERS_ENV] == "legacy" and LEGACY_EMITTERS not in _flags:
    os.environ["XLA_FLAGS"] = _with_flag(_flags, LEGACY_EMITTERS)

import jax  # noqa: E402
import pytest  # noqa: E402


jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_dtype_promotion", "standard")
if TEST_CACHE is not None:
    jax.config.update("jax_compilation_cache_dir", str(TEST_CACHE))
    # Every program: the suite's many small kernels add up.
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)

# The scans' loops compiled as single CPU kernels, as `import jaxcable` sets them up
# (before the first computation; the workers, notebooks' kernels and subprocesses
# inherit XLA_FLAGS). tests/test_cpu_loops.py checks that XLA's default gives the
# same results. JAXCABLE_TEST_LOOP_KERNELS=off keeps XLA's default
# (`make test-xla-default`), through jaxcable's own switch.
if os.environ.get("JAXCABLE_TEST_LOOP_KERNELS", "on") == "off":
    os.environ["JAXCABLE_NO_LOOP_KERNELS"] = "1"

import jaxcable  # noqa: E402, F401  (sets up the loop kernels before any computation)


ROOT = pathlib.Path(__file__).resolve().parent.parent
SHARED = pathlib.Path(os.environ.get("JAXCABLE_SHARED", ROOT.parent / "shared"))
DATA = SHARED / "data"


@pytest.fixture(scope="session")
def jax_cache_env() -> dict[str, str]:
    """Environment variables that point a child interpreter (a notebook's kernel) at
    the run's compilation cache; empty when the cache is off."""
    if TEST_CACHE is None:
        return {}
    return {
        "JAX_COMPILATION_CACHE_DIR": str(TEST_CACHE),
        "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS": "0",
    }


@pytest.fixture
def shared_data():
    """Path to ../shared/data, or skip when this clone has none (users' clones)."""
    if not DATA.is_dir():
        pytest.skip(f"shared data not found at {DATA} (only developers and CI have it)")
    return DATA


# `make test` runs the suite in two xdist workers (--dist loadgroup), each taking one
# group at a time in this order: the longest groups first (the longest-processing-
# time rule), so that neither worker is left with a long one at the end while the
# other idles. A group is a file (its module-scoped fixtures and compiled kernels stay
# in one process), except for the tests of OWN_GROUP, each its own group: every
# notebook (each runs in its own kernel anyway), the calibration (in its own
# interpreter, tests/test_papers.py) and the demo, so that they start early without
# the rest of their file. Seconds on the 2-core machine, from `--durations=0` of a
# whole run (two workers); update the list when a group grows slow. Groups not listed
# (a few seconds each) come last, in the files' order.
#
# The demo comes first: it fits and diagnoses the bundled data set as 02_fit.ipynb
# and 03_diagnose.ipynb do, and the notebooks then load those programs from the run's
# compilation cache instead of compiling them again; then the groups by length.
NOTEBOOK_RUNS = "tests/test_notebooks.py::test_notebook_runs["
DEMO = "tests/test_cli.py::test_demo_bundled_data"
OWN_GROUP = (
    NOTEBOOK_RUNS,
    "tests/test_papers.py::test_calibrate_runs_and_does_not_worsen",
    DEMO,
)
SLOW_FIRST = (
    DEMO,  # 30 s
    # Before test_papers.py, whose `report` fixture loads the program it compiles.
    "tests/test_papers.py::test_calibrate_runs_and_does_not_worsen",  # 45 s
    # After the demo, on the same worker (a worker is handed its next group while it
    # still has up to two tests to run, so the other takes the calibration).
    f"{NOTEBOOK_RUNS}03_diagnose.ipynb]",  # 91 s
    "tests/test_diagnose.py",  # 78 s
    "tests/test_real_records.py",  # 150-250 s, every real record fitted and diagnosed
    "tests/test_tts_reference.py",  # 50-90 s
    "tests/test_family.py",  # 65 s
    "tests/test_commands_agree.py",  # 57 s
    "tests/test_start_scaling.py",  # about 35 s
    "tests/test_hardening_candidate.py",  # about 25 s
    f"{NOTEBOOK_RUNS}06_uncertainty.ipynb]",  # 50-140 s
    "tests/test_jax_contract.py",  # 54 s
    "tests/test_two_pass.py",  # 52 s
    "tests/test_discover.py",  # 44 s
    "tests/test_diagnose_drive.py",  # 43 s
    "tests/test_drive.py",  # 41 s
    "tests/test_rounds.py",  # 38 s
    "tests/test_fit.py",  # 38 s
    "tests/test_docs.py",  # 40 s, every page's examples and the strict site build
    "tests/test_problem.py",  # about 30 s
    "tests/test_cli.py",  # 37 s
    f"{NOTEBOOK_RUNS}02_fit.ipynb]",  # 35 s
    "tests/test_cdpr.py",  # 31 s
    "tests/test_distributed.py",  # 31 s, three processes
    f"{NOTEBOOK_RUNS}05_cdpr.ipynb]",  # 28 s
    "tests/test_integrated.py",  # 27 s
    "tests/test_posterior.py",  # about 25 s
    "tests/test_design.py",  # about 22 s
    "tests/test_cache.py",  # 26 s
    "tests/test_extensions.py",  # 25 s
    "tests/test_rate_solver.py",  # 25 s
    "tests/test_montecarlo.py",  # 25 s
    "tests/test_papers.py",  # 24 s
    "tests/test_long_histories.py",  # 22 s
    "tests/test_shared_kernel.py",  # 21 s
    "tests/test_errors.py",  # 20 s
    f"{NOTEBOOK_RUNS}07_self_calibration.ipynb]",  # 20 s
    f"{NOTEBOOK_RUNS}01_papers.ipynb]",  # 19 s
    "tests/test_controller.py",  # 17 s
    "tests/test_cpu_loops.py",  # 16 s, one fresh interpreter
    "tests/test_covariate_extensions.py",  # 15 s
    "tests/test_fit_each.py",  # 15 s
    "tests/test_hidden_effects.py",  # 11 s
    "tests/test_round_trip.py",  # 10 s
    "tests/test_continuity_models.py",  # 10 s
    "tests/test_five_element.py",  # 9 s
    "tests/test_baselines.py",  # 7 s
    "tests/test_breaking_strain.py",  # 7 s
    "tests/test_cli_robust.py",  # 7 s
    "tests/test_physics.py",  # 6 s
    "tests/test_registry.py",  # 6 s
    "tests/test_exports.py",  # 6 s
    "tests/test_noise_floor.py",  # 15 s
)


def _rank(item: pytest.Item) -> int:
    for rank, prefix in enumerate(SLOW_FIRST):
        if item.nodeid.startswith(prefix):
            return rank
    return len(SLOW_FIRST)


def pytest_report_header(config):
    return (
        f"XLA CPU emitters: {os.environ[TEST_EMITTERS_ENV]}, loop kernels "
        f"{os.environ.get('JAXCABLE_TEST_LOOP_KERNELS', 'on')} "
        f"(XLA_FLAGS={os.environ.get('XLA_FLAGS', '')!r})"
    )


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items):
    # tryfirst: xdist reads the xdist_group marks in its own hook of the same name.
    for item in items:
        group = item.nodeid.split("::")[0]
        if item.nodeid.startswith(OWN_GROUP):
            group = item.nodeid
        item.add_marker(pytest.mark.xdist_group(group))
    items.sort(key=_rank)  # stable: within a group, the file's order
