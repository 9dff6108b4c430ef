import os
import pathlib

import jax
import pytest


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
