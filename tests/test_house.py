"""The layout of the package holds: small modules, folders that talk only through
their `__init__.py`, imports only downwards (docs/architecture.md)."""

import ast
import pathlib

import pytest


PACKAGE = pathlib.Path(__file__).resolve().parent.parent / "jaxcable"
MODULES = sorted(PACKAGE.rglob("*.py"))
MAX_LINES = 500

# Folders (and base modules) from the bottom layer up: a module may import only from
# its own layer or below.
LAYERS = [
    {
        "_arrays",
        "_cable",
        "_results",
        "_checks",
        "_progress",
        "_cache",
        "_cpu_loops",
        "_files",
        "_json",
    },
    {"_models"},
    {"_drive"},
    {"_io"},
    # The problem and method values sit beside the fit, which takes them.
    {"_fit", "_problem"},
    {"_diagnose", "_montecarlo", "_papers", "_uncertainty"},
    {"_report"},
    {"_cli", "cdpr", "cli", "papers", "states", "internal", "__init__", "__main__"},
]
LAYER = {name: i for i, names in enumerate(LAYERS) for name in names}


def _room(path: pathlib.Path) -> str:
    """The folder (or base module) of jaxcable a file belongs to."""
    parts = path.relative_to(PACKAGE).parts
    return parts[0] if len(parts) > 1 else parts[0].removesuffix(".py")


def _imports(path: pathlib.Path):
    """(target parts below jaxcable, imported names, line) of every relative import."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    here = path.relative_to(PACKAGE).parts[:-1]
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.level > 0:
            base = here[: len(here) - (node.level - 1)]
            target = base + tuple(node.module.split(".") if node.module else ())
            names = [a.name for a in node.names]
            if not node.module:
                # `from .. import _checks`: the names are modules.
                for name in names:
                    yield target + (name,), [], node.lineno
            else:
                yield target, names, node.lineno


def _rel(path):
    return str(path.relative_to(PACKAGE.parent))


@pytest.mark.parametrize("path", MODULES, ids=_rel)
def test_module_is_small(path):
    lines = len(path.read_text(encoding="utf-8").splitlines())
    assert lines <= MAX_LINES, f"{_rel(path)} has {lines} lines (at most {MAX_LINES})"


@pytest.mark.parametrize("path", MODULES, ids=_rel)
def test_folders_talk_through_their_init(path):
    room = _room(path)
    for target, names, line in _imports(path):
        other = target[0]
        if other == room:
            continue
        where = f"{_rel(path)}:{line}"
        # Another folder: only through its __init__ (one part), no private names.
        if (PACKAGE / other).is_dir():
            assert len(target) == 1, f"{where} imports {'.'.join(target)}"
        private = [n for n in names if n.startswith("_")]
        assert not private, f"{where} imports private {private} from {other}"
        assert LAYER[other] <= LAYER[room], f"{where}: {room} imports {other} (above)"


def test_analysis_never_imports_the_report():
    for path in MODULES:
        if _room(path) in ("_diagnose", "_montecarlo", "_papers", "_fit"):
            for target, _, line in _imports(path):
                assert target[0] != "_report", f"{_rel(path)}:{line}"


def test_no_pointer_outside_the_repository():
    for path in MODULES:
        text = path.read_text(encoding="utf-8")
        for needle in ("MODEL_NOTES", "../shared", "shared/papers"):
            assert needle not in text, f"{_rel(path)} points to {needle}"
