"""The site's generated parts, as an mkdocs hook (mkdocs.yml: `hooks`).

- `<!-- benchmark-results -->` in a page becomes one section per benchmark result in
  the repository: the JSON a benchmark script writes (`benchmarks/results/*.json`, the
  JSON that `--json-out` writes or that a script prints first), and the real records'
  outcomes (`tests/data/real/outcomes.json`, `benchmarks/real_records_before.json`).
  Every number on that page is read from those files when the site is built; none is
  kept by hand.
- `<!-- notebook-figures -->` becomes the figures the notebooks wrote beside
  themselves (`notebooks/*.png`), where they exist; the figures are copied into the
  site. Without them (a fresh clone) the page says how to make them.

`python scripts/docs_hooks.py` prints the benchmark section, for a look without mkdocs.
"""

from __future__ import annotations

import json
import math
import pathlib


ROOT = pathlib.Path(__file__).resolve().parent.parent
# Results kept elsewhere, with the title their section gets.
EXTRA_RESULTS = {
    "tests/data/real/outcomes.json": "Real records: the diagnosis's outcomes",
    "benchmarks/real_records_before.json": "Real records: the outcomes before the hardening of the start, noise and base",
}
# Scripts whose result lives elsewhere (EXTRA_RESULTS).
RECORDED_ELSEWHERE = {"real_records"}
FIGURE_DIR = "figures"
MAX_CELL = 90  # characters of a text cell shown (error messages can run to 500)


def _number(x: float) -> str:
    if isinstance(x, bool):
        return "yes" if x else "no"
    if isinstance(x, int):
        return str(x)
    if not math.isfinite(x):
        return str(x)
    if x == 0:
        return "0"
    if 1e-3 <= abs(x) < 1e6:
        return f"{x:.4g}"
    return f"{x:.3e}"


def cell(value) -> str:
    """One table cell: numbers with 4 significant digits, lists joined, text cut."""
    if value is None:
        return "-"
    if isinstance(value, (bool, int, float)):
        return _number(value)
    if isinstance(value, (list, tuple)):
        if all(not isinstance(v, (dict, list)) for v in value):
            text = ", ".join(cell(v) for v in value) or "-"
        else:
            text = json.dumps(value, separators=(",", ":"))
    elif isinstance(value, dict):
        text = ", ".join(f"{k}: {cell(v)}" for k, v in value.items())
    else:
        text = str(value)
    text = " ".join(text.split()).replace("|", "\\|")
    if len(text) > MAX_CELL:
        text = text[: MAX_CELL - 3] + "..."
    return text


def _is_rows(value) -> bool:
    return (
        isinstance(value, list)
        and bool(value)
        and all(isinstance(v, dict) for v in value)
    )


def rows_table(rows: list[dict]) -> list[str]:
    """A markdown table of a list of records, one column per key (in first-seen order)."""
    columns: list[str] = []
    for row in rows:
        columns += [k for k in row if k not in columns]
    lines = ["| " + " | ".join(columns) + " |", "|" + " --- |" * len(columns)]
    lines += [
        "| " + " | ".join(cell(row.get(c)) for c in columns) + " |" for row in rows
    ]
    return lines


def _scalars_table(items: list[tuple[str, object]]) -> list[str]:
    lines = ["| quantity | value |", "| --- | --- |"]
    return lines + [f"| {key} | {cell(value)} |" for key, value in items]


def render_body(data) -> list[str]:
    """The markdown of one benchmark's JSON: its scalars as one table, each list of
    records as a table, each nested mapping the same way under its key."""
    if _is_rows(data):
        return rows_table(data) + [""]
    if not isinstance(data, dict):
        return [cell(data), ""]
    lines: list[str] = []
    machine = data.get("machine")
    if isinstance(machine, dict):
        lines += ["Machine: " + cell(machine) + ".", ""]
    scalars = [
        (k, v)
        for k, v in data.items()
        if k != "machine" and not isinstance(v, dict) and not _is_rows(v)
    ]
    if scalars:
        lines += _scalars_table(scalars) + [""]
    for key, value in data.items():
        if key != "machine" and (_is_rows(value) or isinstance(value, dict)):
            lines += [f"**{key}**", ""] + render_body(value)
    return lines


def render_result(data, title: str, source: str) -> list[str]:
    """One benchmark's section: its title, where it comes from, its tables."""
    return [f"### {title}", "", f"From `{source}`.", ""] + render_body(data)


def load_results(root: pathlib.Path = ROOT) -> list[tuple[str, str, object]]:
    """(title, source path, parsed JSON) of every benchmark result in the repository."""
    found = []
    results = root / "benchmarks" / "results"
    for path in sorted(results.glob("*.json")) if results.is_dir() else []:
        found.append((f"`{path.stem}.py`", str(path.relative_to(root)), _read(path)))
    for name, title in EXTRA_RESULTS.items():
        path = root / name
        if path.is_file():
            found.append((title, name, _read(path)))
    return found


def _read(path: pathlib.Path):
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as error:
        raise ValueError(f"{path}: not a JSON benchmark result ({error})") from error


def benchmark_markdown(root: pathlib.Path = ROOT) -> str:
    """The generated benchmark section of the site: every recorded result, then the
    scripts that have none yet."""
    lines: list[str] = []
    for title, source, data in load_results(root):
        lines += render_result(data, title, source)
    recorded = {p.stem for p in (root / "benchmarks" / "results").glob("*.json")}
    recorded |= RECORDED_ELSEWHERE
    missing = sorted(
        f"`{p.name}`"
        for p in (root / "benchmarks").glob("*.py")
        if p.stem not in recorded
    )
    if missing:
        lines += ["### Not recorded yet", "", ", ".join(missing) + ".", ""]
    if not lines:
        return "No benchmark result is recorded in the repository yet.\n"
    return "\n".join(lines) + "\n"


def figures(root: pathlib.Path = ROOT) -> list[pathlib.Path]:
    return sorted((root / "notebooks").glob("*.png"))


def figures_markdown(page_uri: str = "", root: pathlib.Path = ROOT) -> str:
    """The figures, linked from the page at `page_uri` (relative to the docs folder)."""
    found = figures(root)
    up = "../" * page_uri.count("/")
    if not found:
        return (
            "No figure is here yet: the notebooks write their figures beside themselves "
            "when they run (`make test` runs them); then `make docs` shows them.\n"
        )
    lines = []
    for path in found:
        lines += [
            f"**{path.name}**",
            "",
            f"![{path.stem}]({up}{FIGURE_DIR}/{path.name})",
            "",
        ]
    return "\n".join(lines)


# mkdocs hooks -------------------------------------------------------------------------


def on_files(files, config):
    from mkdocs.structure.files import File

    for path in figures():
        files.append(
            File.generated(config, f"{FIGURE_DIR}/{path.name}", abs_src_path=str(path))
        )
    return files


def on_page_markdown(markdown, page, config, files):
    if "<!-- benchmark-results -->" in markdown:
        markdown = markdown.replace("<!-- benchmark-results -->", benchmark_markdown())
    if "<!-- notebook-figures -->" in markdown:
        markdown = markdown.replace(
            "<!-- notebook-figures -->", figures_markdown(page.file.src_uri)
        )
    return markdown


if __name__ == "__main__":
    print(benchmark_markdown())
