import os
import pathlib


# The command line keeps compiled programs in a per-user cache; the suite runs the
# command line in-process, where that would change jax.config for every later test.
# tests/test_cache.py checks the cache itself, in fresh interpreters.
os.environ["JAXCABLE_NO_CACHE"] = "1"

import jax  # noqa: E402
import pytest  # noqa: E402


jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_dtype_promotion", "standard")

ROOT = pathlib.Path(__file__).resolve().parent.parent
SHARED = pathlib.Path(os.environ.get("JAXCABLE_SHARED", ROOT.parent / "shared"))
DATA = SHARED / "data"


@pytest.fixture
def shared_data():
    """Path to ../shared/data, or skip when this clone has none (users' clones)."""
    if not DATA.is_dir():
        pytest.skip(f"shared data not found at {DATA} (only developers and CI have it)")
    return DATA
