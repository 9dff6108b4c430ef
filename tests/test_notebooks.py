import os
import pathlib

import nbformat
import pytest
from nbclient import NotebookClient


NOTEBOOKS = sorted(
    (pathlib.Path(__file__).resolve().parent.parent / "notebooks").glob("*.ipynb")
)


def test_there_are_notebooks():
    assert NOTEBOOKS


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.name)
def test_committed_without_outputs(path):
    nb = nbformat.read(path, as_version=4)
    for cell in nb.cells:
        if cell.cell_type == "code":
            assert not cell.outputs and cell.execution_count is None, path.name


@pytest.mark.slow
@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.name)
def test_notebook_runs(path, jax_cache_env):
    nb = nbformat.read(path, as_version=4)
    # jupyter_client starts a kernel spec whose argv is "python" with this
    # interpreter (sys.executable), so the notebook runs in the venv under test.
    client = NotebookClient(
        nb,
        timeout=600,
        kernel_name="python3",
        resources={"metadata": {"path": str(path.parent)}},
    )
    # The kernel loads the kernels this run already compiled (tests/conftest.py).
    client.execute(env={**os.environ, **jax_cache_env})
