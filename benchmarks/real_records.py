"""The real-data regression set: `jaxcable fit`, then `jaxcable diagnose --json`, on
every record of tests/data/real/records.json, as a user types them.

Each record runs through the command line's entry point (`jaxcable.cli.main`), `fit`
and `diagnose` in one fresh process per record (`--in-process`: all in this one), with
the options its entry states (`--full`: with the diagnosis's family check, which the
records skip for the suite's budget). Per record: the verdict, the named causes, the held-out RMSE of the final
model and of the base, their unit, the noise and where it came from (`noise_source`,
when the diagnosis reports one), the seconds `fit` and `diagnose` took together, and
the error: None, or the message the command printed when it refused (its last line on
stderr; the exit status is kept too).

Prints one line per record, then the JSON document; `--json-out FILE` writes it,
`--write-outcomes` writes it as tests/data/real/outcomes.json (what
tests/test_real_records.py asserts against), `--markdown FILE` writes the table of
docs/real_data.md from it (from a run, or with `--from-json FILE` from an earlier
document, without running anything).

    python benchmarks/real_records.py --write-outcomes --markdown docs/real_data.md
    python benchmarks/real_records.py --records silicone30a_bluehill_cycles
"""

import argparse
import contextlib
import io
import json
import math
import os
import pathlib
import platform
import subprocess
import sys
import tempfile
import time


ROOT = pathlib.Path(__file__).resolve().parent.parent
DATA = ROOT / "tests" / "data" / "real"
RECORDS = DATA / "records.json"
OUTCOMES = DATA / "outcomes.json"

# Verdicts from best to worst: a named cause (or nothing left to explain) is a
# diagnosis; 'partial' and 'unexplained' are not. A refusal ranks below them all.
VERDICT_RANK = {"named": 2, "none": 2, "partial": 1, "unexplained": 0}
REFUSED = -1


def verdict_rank(verdict):
    """The rank of a verdict (`VERDICT_RANK`; `REFUSED` for a refusal, None).

    **Arguments:**

    - `verdict`: a diagnosis' `verdict` string, or None when the commands refused.

    **Returns:** an int, higher is better.
    """
    if verdict is None:
        return REFUSED
    if verdict not in VERDICT_RANK:
        raise ValueError(f"`verdict`: {verdict!r} is not one of {sorted(VERDICT_RANK)}")
    return VERDICT_RANK[verdict]


def load_records(path=RECORDS):
    """The entries of records.json (a list of dicts)."""
    return json.loads(pathlib.Path(path).read_text(encoding="utf-8"))["records"]


def _run_cli(argv):
    """`jaxcable.cli.main(argv)` with stdout and stderr captured: (status, out, err)."""
    from jaxcable.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            status = main([str(a) for a in argv])
        except SystemExit as stop:  # argparse exits on a bad option
            status = stop.code if isinstance(stop.code, int) else 2
        except Exception as error:  # noqa: BLE001 - a crash is an outcome to record
            print(f"{type(error).__name__}: {error}", file=sys.stderr)
            status = 3
    return status, out.getvalue(), err.getvalue()


def _message(status, err):
    """The refusal's message: the last non-empty stderr line (the CLI prints the
    error last), or the status when stderr is empty."""
    lines = [line for line in err.splitlines() if line.strip()]
    message = lines[-1].strip() if lines else f"exit status {status}"
    return message.replace(f"{ROOT}/", "")


def _finite(x):
    return x if isinstance(x, (int, float)) and math.isfinite(x) else None


def record_command(record, command, out_file):
    """The argv of `jaxcable fit` or `jaxcable diagnose --json` for one record.

    **Arguments:**

    - `record`: an entry of records.json.
    - `command`: "fit" or "diagnose".
    - `out_file`: the PARAMS.json path of `fit --out` (unused by diagnose).

    **Returns:** a list of strings.
    """
    files = [str(DATA / f) for f in record["files"]]
    argv = [command, *files, *record.get("options", [])]
    if command == "fit":
        return [
            *argv,
            *record.get("fit_options", []),
            "--out",
            str(out_file),
            "--quiet",
        ]
    if command == "diagnose":
        return [*argv, *record.get("diagnose_options", []), "--json", "--quiet"]
    raise ValueError(f"`command`: {command!r} is not 'fit' or 'diagnose'")


def run_record(record):
    """Run `fit` then `diagnose --json` on one record; its outcome as a dict.

    **Arguments:**

    - `record`: an entry of records.json.

    **Returns:** a dict: record, source, licence, verdict, causes, heldout_rmse (the
    final model's), base_heldout_rmse, unit, noise, noise_source, seconds, status
    (the first non-zero exit status, else 0), error (None or the refusal's message)
    and command (the one that refused, else None).
    """
    outcome = {
        "record": record["id"],
        "source": record["source"],
        "licence": record["licence"],
        "verdict": None,
        "causes": [],
        "heldout_rmse": None,
        "base_heldout_rmse": None,
        "unit": None,
        "noise": None,
        "noise_source": None,
        "seconds": None,
        "status": 0,
        "error": None,
        "command": None,
    }
    start = time.perf_counter()
    with tempfile.TemporaryDirectory() as folder:
        params = pathlib.Path(folder) / "p.json"
        for command in ("fit", "diagnose"):
            argv = record_command(record, command, params)
            status, out, err = _run_cli(argv)
            if status != 0:
                outcome.update(
                    status=status,
                    error=_message(status, err),
                    command="jaxcable " + " ".join(_relative(a) for a in argv),
                )
                break
            if command == "diagnose":
                _read_diagnosis(outcome, out)
    outcome["seconds"] = round(time.perf_counter() - start, 1)
    return outcome


def run_apart(record, full=False):
    """[`run_record`][] in a fresh Python process, as a user runs the commands: a
    long process that compiles program after program can run out of the memory
    maps its compiled code takes (LLVM: "Unable to allocate section memory").

    **Arguments:**

    - `record`: an entry of records.json.
    - `full`: run the diagnosis with its family check (without the record's
        `--family never`).

    **Returns:** its outcome, as `run_record`'s.
    """
    with tempfile.TemporaryDirectory() as folder:
        out = pathlib.Path(folder) / "outcome.json"
        argv = [sys.executable, str(pathlib.Path(__file__).resolve())]
        argv += ["--records", record["id"], "--in-process", "--json-out", str(out)]
        argv += ["--full"] if full else []
        done = subprocess.run(argv, capture_output=True, text=True, check=False)
        if done.returncode != 0 or not out.exists():
            raise RuntimeError(
                f"{record['id']}: the benchmark's process failed "
                f"(exit {done.returncode}): {done.stderr[-2000:]}"
            )
        (outcome,) = json.loads(out.read_text(encoding="utf-8"))["outcomes"]
    return outcome


def without_family_switch(record):
    """`record` with its diagnosis's `--family never` removed (the default check)."""
    options = list(record.get("diagnose_options", []))
    while "--family" in options:
        i = options.index("--family")
        del options[i : i + 2]
    return {**record, "diagnose_options": options}


def _relative(arg):
    path = pathlib.Path(arg)
    if path.is_absolute() and ROOT in path.parents:
        return str(path.relative_to(ROOT))
    return "/tmp/p.json" if path.name == "p.json" else arg


def _read_diagnosis(outcome, out):
    report = json.loads(out)
    final = report.get("final_heldout_rmse", report.get("extended_heldout_rmse"))
    outcome.update(
        verdict=report.get("verdict"),
        causes=list(report.get("causes") or []),
        heldout_rmse=_finite(final),
        base_heldout_rmse=_finite(report.get("base_heldout_rmse")),
        unit=report.get("unit"),
        noise=_finite(report.get("noise")),
        noise_source=report.get("noise_source"),
    )


def _fmt(x, digits=4):
    return "-" if x is None else f"{x:.{digits}g}"


def line(outcome):
    """One line of the printed table for an outcome."""
    if outcome["error"] is not None:
        return f"{outcome['record']:<34} REFUSED ({outcome['seconds']} s): {outcome['error']}"
    causes = ",".join(outcome["causes"]) or "-"
    return (
        f"{outcome['record']:<34} {outcome['verdict']:<12} {causes:<28} held-out "
        f"{_fmt(outcome['heldout_rmse'])} (base {_fmt(outcome['base_heldout_rmse'])}) "
        f"{outcome['unit']}, noise {_fmt(outcome['noise'])} "
        f"({outcome['noise_source'] or 'not reported'}), {outcome['seconds']} s"
    )


def _short(outcome):
    """A verdict, or 'refused: ' and the start of the refusal."""
    if outcome["error"] is None:
        return outcome["verdict"]
    return "refused: " + outcome["error"][:160].replace("`", "'").replace("|", "/")


def markdown(document, before=None):
    """docs/real_data.md's generated table from a document of this script, with the
    verdict of each record in the document `before` (an earlier run: another
    version of the library) when given."""
    earlier = {o["record"]: o for o in (before or {}).get("outcomes", [])}
    rows = [
        "| record | source | licence | before | verdict | causes | held-out RMSE "
        "(base) | noise (source) | seconds |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for o in document["outcomes"]:
        was = _short(earlier[o["record"]]) if o["record"] in earlier else "-"
        if o["error"] is not None:
            verdict = _short(o)
            rmse = noise = causes = "-"
        else:
            verdict = o["verdict"]
            causes = ", ".join(o["causes"]) or "-"
            rmse = f"{_fmt(o['heldout_rmse'])} ({_fmt(o['base_heldout_rmse'])}) {o['unit']}"
            noise = f"{_fmt(o['noise'])} {o['unit']} ({o['noise_source'] or 'not reported'})"
        rows.append(
            f"| {o['record']} | {o['source']} | {o['licence']} | {was} | {verdict} "
            f"| {causes} "
            f"| {rmse} | {noise} | {o['seconds']} |"
        )
    return "\n".join(rows) + "\n"


BEGIN = "<!-- BEGIN GENERATED: benchmarks/real_records.py --markdown -->"
END = "<!-- END GENERATED -->"


def write_markdown(path, document, before=None):
    """Replace the generated block of `path` (between BEGIN and END) by the table;
    write a bare page when the file or its markers are missing."""
    path = pathlib.Path(path)
    block = f"{BEGIN}\n\n{markdown(document, before)}\n{END}"
    text = path.read_text(encoding="utf-8") if path.exists() else ""
    if BEGIN in text and END in text:
        head, rest = text.split(BEGIN, 1)
        text = head + block + rest.split(END, 1)[1]
    else:
        text = f"# Real-data regression set\n\n{block}\n"
    path.write_text(text, encoding="utf-8")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--records", help="comma-separated record ids (default: all)")
    parser.add_argument("--json-out", metavar="FILE", help="write the JSON document")
    parser.add_argument(
        "--write-outcomes",
        action="store_true",
        help=f"write {OUTCOMES.relative_to(ROOT)}",
    )
    parser.add_argument("--markdown", metavar="FILE", help="write the table into FILE")
    parser.add_argument(
        "--from-json", metavar="FILE", help="take the outcomes from FILE, run nothing"
    )
    parser.add_argument(
        "--before",
        metavar="FILE",
        help="a document of an earlier run (another version of the library): its "
        "verdicts in the table's 'before' column",
    )
    parser.add_argument(
        "--full",
        action="store_true",
        help="diagnose with the family check (drop the records' --family never, "
        "which keeps the suite's budget; several minutes a record)",
    )
    parser.add_argument(
        "--in-process",
        action="store_true",
        help="run the records in this process (by default each in its own)",
    )
    args = parser.parse_args(argv)

    if args.from_json:
        document = json.loads(pathlib.Path(args.from_json).read_text(encoding="utf-8"))
    else:
        os.environ.setdefault("JAXCABLE_NO_CACHE", "1")
        records = load_records()
        if args.records:
            wanted = set(args.records.split(","))
            unknown = wanted - {r["id"] for r in records}
            if unknown:
                parser.error(f"--records: unknown ids {sorted(unknown)}")
            records = [r for r in records if r["id"] in wanted]
        outcomes = []
        for record in records:
            if args.in_process:
                full = without_family_switch(record) if args.full else record
                outcomes.append(run_record(full))
            else:
                outcomes.append(run_apart(record, full=args.full))
            print(line(outcomes[-1]), flush=True)
        document = {
            "machine": {"python": platform.python_version(), "cpus": os.cpu_count()},
            "outcomes": outcomes,
        }
    text = json.dumps(document, indent=2)
    print(text)
    if args.json_out:
        pathlib.Path(args.json_out).write_text(text + "\n", encoding="utf-8")
    if args.write_outcomes:
        OUTCOMES.write_text(text + "\n", encoding="utf-8")
    if args.markdown:
        before = None
        if args.before:
            before = json.loads(pathlib.Path(args.before).read_text(encoding="utf-8"))
        write_markdown(args.markdown, document, before)
    return 0


if __name__ == "__main__":
    sys.exit(main())
