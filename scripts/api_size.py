"""How much a newcomer must hold in their head: the public functions' parameter
counts, the function bodies over 80 lines, the modules over 500 lines, and the test
files that import private modules.

    python scripts/api_size.py [--json]

Counts every parameter of every public function and public method of a public class
(`self` excluded) in `jaxcable`, `jaxcable.cdpr`, `jaxcable.states` and
`jaxcable.papers`; a body is counted without its docstring.
"""

import ast
import inspect
import json
import pathlib
import sys


ROOT = pathlib.Path(__file__).resolve().parent.parent


def _parameters():
    import jaxcable
    from jaxcable import cdpr, papers, states

    rows = []
    for prefix, module in (("jc", jaxcable), ("cdpr", cdpr), ("states", states)):
        rows += _module_rows(prefix, module)
    rows += _module_rows("papers", papers)
    return sorted(rows, reverse=True)


def _module_rows(prefix, module):
    rows = []
    for name in dir(module):
        obj = getattr(module, name)
        if name.startswith("_"):
            continue
        if inspect.isfunction(obj):
            rows.append((len(inspect.signature(obj).parameters), f"{prefix}.{name}"))
        elif inspect.isclass(obj) and obj.__module__.startswith("jaxcable"):
            for method, f in vars(obj).items():
                if inspect.isfunction(f) and not method.startswith("_"):
                    count = len(inspect.signature(f).parameters) - 1
                    rows.append((count, f"{prefix}.{name}.{method}"))
    return rows


def _body_lines(node) -> int:
    body = node.body
    first = body[0] if body else None
    if isinstance(first, ast.Expr) and isinstance(
        getattr(first, "value", None), ast.Constant
    ):
        body = body[1:]
    return body[-1].end_lineno - body[0].lineno + 1 if body else 0


def _long_functions():
    rows = []
    for path in sorted((ROOT / "jaxcable").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = _body_lines(node)
                if n > 80:
                    rows.append((n, f"{path.relative_to(ROOT)}:{node.name}"))
    return rows


def main(argv):
    modules = sorted((ROOT / "jaxcable").rglob("*.py"))
    lines = {p: len(p.read_text(encoding="utf-8").splitlines()) for p in modules}
    private = [
        p.name
        for p in sorted((ROOT / "tests").glob("*.py"))
        if "jaxcable._" in p.read_text(encoding="utf-8")
    ]
    parameters = _parameters()
    report = {
        "most_parameters": parameters[:5],
        "over_6_parameters": [r for r in parameters if r[0] > 6],
        "bodies_over_80_lines": _long_functions(),
        "modules": len(modules),
        "lines": sum(lines.values()),
        "modules_over_500_lines": [
            str(p.relative_to(ROOT)) for p, n in lines.items() if n > 500
        ],
        "test_files_importing_private": private,
        "readme_lines": len(
            (ROOT / "README.md").read_text(encoding="utf-8").splitlines()
        ),
    }
    if "--json" in argv:
        print(json.dumps(report, indent=1))
        return
    for key, value in report.items():
        print(f"{key}: {value}")


if __name__ == "__main__":
    main(sys.argv[1:])
