"""The manual runs as written: every Python block of README.md and of the site's pages
(docs/), in order per page, one namespace per page; the site builds with
`mkdocs build --strict` (a broken cross-reference in a docstring fails it); every
public name has a place in the API reference; the benchmark tables come from JSON."""

import importlib
import json
import os
import pathlib
import re
import shutil
import subprocess
import sys
import types

import pytest

import jaxcable as jc


ROOT = pathlib.Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
PAGES = [ROOT / "README.md", *sorted(DOCS.rglob("*.md"))]
NORUN = "<!-- norun -->"
# A fence opens with ``` plus a language and closes with a bare ```.
FENCE = re.compile(r"^```([\w-]*)[^\n]*\n(.*?)^```[ \t]*$", re.S | re.M)
# The few blocks not run (a diagnosis or a posterior takes minutes) are marked with
# NORUN on the line above; this bound keeps them few.
MAX_NORUN = 6
# The public submodules whose names the API reference lists one by one.
SUBMODULES = ("states", "papers", "cdpr", "cli")
MKDOCS = shutil.which("mkdocs", path=str(pathlib.Path(sys.executable).parent))


def python_blocks(text: str) -> list[tuple[int, str, bool]]:
    """(line, code, runs) of every ```python block of a page, in order."""
    blocks = []
    for match in FENCE.finditer(text):
        if match.group(1) != "python":
            continue
        before = text[: match.start()].rstrip("\n").rsplit("\n", 1)[-1]
        line = text.count("\n", 0, match.start()) + 2
        blocks.append((line, match.group(2), before.strip() != NORUN))
    return blocks


def _relative(path: pathlib.Path) -> str:
    return str(path.relative_to(ROOT))


RUNNABLE = [
    p for p in PAGES if any(runs for _, _, runs in python_blocks(p.read_text()))
]


def test_blocks_are_found():
    readme = python_blocks((ROOT / "README.md").read_text())
    assert any(runs for _, _, runs in readme), "README.md has no Python block that runs"
    text = "x\n\n<!-- norun -->\n```python\nslow()\n```\n\n```python\nfast()\n```\n"
    assert [(code, runs) for _, code, runs in python_blocks(text)] == [
        ("slow()\n", False),
        ("fast()\n", True),
    ]


def test_few_blocks_are_not_run():
    skipped = [
        f"{_relative(page)}:{line}"
        for page in PAGES
        for line, _, runs in python_blocks(page.read_text())
        if not runs
    ]
    assert len(skipped) <= MAX_NORUN, f"too many blocks marked {NORUN}: {skipped}"


@pytest.mark.parametrize("page", RUNNABLE, ids=_relative)
def test_python_blocks_run(page, tmp_path, monkeypatch):
    # Files a block writes (reports, CSVs) go to a fresh folder.
    monkeypatch.chdir(tmp_path)
    namespace: dict = {"__name__": f"docs:{_relative(page)}"}
    for line, code, runs in python_blocks(page.read_text()):
        if not runs:
            continue
        try:
            exec(compile(code, f"{_relative(page)}:{line}", "exec"), namespace)
        except Exception as error:
            raise AssertionError(
                f"{_relative(page)}, the Python block at line {line} failed: "
                f"{type(error).__name__}: {error}"
            ) from error


def _api_text() -> str:
    return "\n".join(p.read_text() for p in sorted((DOCS / "api").glob("*.md")))


def _documented() -> set[str]:
    """The names the API reference renders under their public path: `::: NAME`, or an
    anchor `[](){#NAME}` above the rendering of the name's full path."""
    text = _api_text()
    rendered = re.findall(r"^::: (jaxcable(?:\.\w+)+)", text, re.M)
    anchored = re.findall(r"^\[\]\(\)\{#(jaxcable(?:\.\w+)+)\}", text, re.M)
    return set(rendered) | set(anchored)


def _public(module) -> set[str]:
    """The public names of a module, less the modules it imports."""
    names = getattr(module, "__all__", None) or dir(module)
    return {
        n
        for n in names
        if not n.startswith("_")
        and not isinstance(getattr(module, n), types.ModuleType)
    }


def test_every_public_name_is_in_the_api_reference():
    documented = _documented()
    missing = [
        f"jaxcable.{n}"
        for n in sorted(_public(jc))
        if f"jaxcable.{n}" not in documented
    ]
    for sub in SUBMODULES:
        module = importlib.import_module(f"jaxcable.{sub}")
        missing += [
            f"jaxcable.{sub}.{n}"
            for n in sorted(_public(module))
            if f"jaxcable.{sub}.{n}" not in documented
        ]
    assert not missing, f"not in docs/api/*.md (add a `::: NAME` line): {missing}"


def test_benchmark_tables_come_from_json(tmp_path):
    sys.path.insert(0, str(ROOT / "scripts"))
    try:
        hooks = importlib.import_module("docs_hooks")
    finally:
        sys.path.remove(str(ROOT / "scripts"))
    results = tmp_path / "benchmarks" / "results"
    results.mkdir(parents=True)
    document = {
        "machine": {"cpus": 2},
        "command": "python benchmarks/kernel.py",
        "rows": [{"batch": 1, "seconds": 0.012345678}, {"batch": 1024, "seconds": 3.5}],
    }
    (results / "kernel.json").write_text(json.dumps(document))
    for script in ("kernel.py", "fit.py"):
        (tmp_path / "benchmarks" / script).write_text("")
    page = hooks.benchmark_markdown(tmp_path)
    assert "### Not recorded yet\n\n`fit.py`.\n" in page
    assert "### `kernel.py`" in page
    assert "| batch | seconds |" in page
    assert "| 1 | 0.01235 |" in page and "| 1024 | 3.5 |" in page
    assert "| command | python benchmarks/kernel.py |" in page
    (results / "broken.json").write_text("{")
    with pytest.raises(ValueError, match="broken.json"):
        hooks.benchmark_markdown(tmp_path)


@pytest.mark.skipif(
    MKDOCS is None, reason="mkdocs is not installed (make test installs it)"
)
def test_site_builds_strict(tmp_path):
    done = subprocess.run(
        [MKDOCS, "build", "--strict", "--site-dir", str(tmp_path / "site")],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=600,
        env={**os.environ, "NO_MKDOCS_2_WARNING": "1"},
    )
    warnings = [
        line
        for line in done.stderr.splitlines()
        if "WARNING" in line or "ERROR" in line
    ]
    assert done.returncode == 0, "mkdocs build --strict failed:\n" + "\n".join(
        warnings or done.stderr.splitlines()[-20:]
    )
    assert (tmp_path / "site" / "api" / "fitting" / "index.html").is_file()


def test_no_public_path_renders_a_module_of_the_same_name():
    # `from .fit import fit` in a package makes griffe resolve `jaxcable.fit` to the
    # module fit.py, whose every helper the page would then show: such a name is
    # rendered by its full path under an anchor of its public path.
    clashes = []
    for path in re.findall(r"^::: (jaxcable(?:\.\w+)+)", _api_text(), re.M):
        parent, name = path.rsplit(".", 1)
        obj = getattr(importlib.import_module(parent), name, None)
        module = getattr(obj, "__module__", "") or ""
        if callable(obj) and module.split(".")[-1] == name and module != parent:
            clashes.append(path)
    assert not clashes, f"render these by their full path under an anchor: {clashes}"
