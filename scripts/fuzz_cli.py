"""Bad invocations of `jaxcable simulate`, `fit` and `diagnose`, run in-process through
`jaxcable._cli.main`, counted: tracebacks (an exception out of `main`), exit statuses
other than 2, and stderr other than exactly one line `jaxcable: error: ...` naming the
file or the option at fault; and runs over the time limit.

    python scripts/fuzz_cli.py [--json-only] [--limit-s 20]

Prints a table of the failing cases (none, when all is well) and the counts as JSON on
the last line; exits 1 when any count is not 0.
"""

import argparse
import contextlib
import io
import json
import os
import pathlib
import signal
import sys
import tempfile
import time
import traceback


_HUGE_INT = "1" + "0" * 400
_GOOD_PROTOCOL = {
    "length_mm": 300,
    "segments": [{"cycles": 1, "force_max_N": 50, "samples_per_ramp": 5}],
}
_CSV_HEADER = "# length_mm: 300\ntime_s,force_N,elongation_mm\n"
_CSV_ROWS = "".join(f"{t},{5 * t},{0.01 * t}\n" for t in range(12))


def _protocol_cases() -> dict[str, tuple[str | bytes, str]]:
    """name -> (the protocol file's content, a word the error line must hold)."""

    def doc(**changes) -> str:
        d = json.loads(json.dumps(_GOOD_PROTOCOL))
        for key, value in changes.items():
            if key == "segment":
                d["segments"][0] = value
            elif value is None:
                d.pop(key)
            else:
                d[key] = value
        return json.dumps(d)

    raw = lambda text: text  # noqa: E731
    cases = {
        "empty_file": (raw(""), "line 1"),
        "not_json": (raw("length_mm = 300"), "line 1"),
        "truncated": (raw('{"length_mm": 300, "segments": [{"ramp'), "line 1"),
        "a_list": (raw("[1, 2]"), "JSON object"),
        "a_string": (raw('"hello"'), "JSON object"),
        "bom": (raw("\ufeff" + json.dumps(_GOOD_PROTOCOL)), "line 1"),
        "latin1": ('{"id": "caf\xe9", "length_mm": 300}'.encode("latin-1"), "line 1"),
        "binary": (bytes(range(256)), "line"),
        "nested_deep": (raw("[" * 100_000 + "]" * 100_000), "nested"),
        "nan": (raw('{"length_mm": NaN, "segments": []}'), "line 1"),
        "infinity": (raw('{"length_mm": Infinity, "segments": []}'), "line 1"),
        "float_1e999": (raw('{"length_mm": 1e999, "segments": []}'), "line 1"),
        "int_10_400": (raw('{"length_mm": ' + _HUGE_INT + "}"), "line 1"),
        "int_5000_digits": (raw('{"length_mm": 1' + "0" * 5000 + "}"), "line 1"),
        "length_missing": (doc(length_mm=None), "length_mm"),
        "length_string": (doc(length_mm="300"), "length_mm"),
        "length_bool": (doc(length_mm=True), "length_mm"),
        "length_null": (raw('{"length_mm": null, "segments": []}'), "length_mm"),
        "length_negative": (doc(length_mm=-300), "length_mm"),
        "length_zero": (doc(length_mm=0), "length_mm"),
        "length_tiny": (doc(length_mm=1e-300), "length_mm"),
        "length_1e300": (doc(length_mm=1e300), "length_mm"),
        "diameter_1e200": (doc(diameter_mm=1e200), "diameter_mm"),
        "diameter_tiny": (doc(diameter_mm=1e-12), "diameter_mm"),
        "rate_zero": (doc(rate_mm_per_min=0), "rate_mm_per_min"),
        "rate_1e30": (doc(rate_mm_per_min=1e30), "rate_mm_per_min"),
        "rate_list": (doc(rate_mm_per_min=[3]), "rate_mm_per_min"),
        "id_number": (doc(id=5), "id"),
        "unknown_key": (doc(lenght_mm=300), "lenght_mm"),
        "segments_missing": (doc(segments=None), "segments"),
        "segments_empty": (doc(segments=[]), "segments"),
        "segments_object": (doc(segments={"ramp_to_N": 5}), "segments"),
        "segment_number": (doc(segment=5), "segments[0]"),
        "segment_no_kind": (doc(segment={"samples": 5}), "segments[0]"),
        "segment_two_kinds": (
            doc(segment={"ramp_to_N": 5, "rest_s": 5}),
            "segments[0]",
        ),
        "segment_unknown_key": (
            doc(segment={"ramp_to_N": 5, "sample": 5}),
            "segments[0].sample",
        ),
        "cycles_1e9": (doc(segment={"cycles": 1e9, "force_max_N": 50}), "cycles"),
        "cycles_200k": (
            doc(segment={"cycles": 200_000, "force_max_N": 50, "samples_per_ramp": 1}),
            "cycles",
        ),
        "cycles_zero": (doc(segment={"cycles": 0, "force_max_N": 50}), "cycles"),
        "cycles_fraction": (doc(segment={"cycles": 1.5, "force_max_N": 50}), "cycles"),
        "cycles_int_10_400": (
            raw('{"length_mm": 300, "segments": [{"cycles": ' + _HUGE_INT + "}]}"),
            "line 1",
        ),
        "spr_1e12": (
            doc(segment={"cycles": 1, "force_max_N": 50, "samples_per_ramp": 10**12}),
            "samples_per_ramp",
        ),
        "spr_total_too_many": (
            doc(segment={"cycles": 20, "force_max_N": 50, "samples_per_ramp": 30_000}),
            "cycles",
        ),
        "force_over_breaking": (
            doc(segment={"cycles": 1, "force_max_N": 1e6}),
            "force_max_N",
        ),
        "force_negative": (doc(segment={"ramp_to_N": -5}), "ramp_to_N"),
        "force_min_above_max": (
            doc(segment={"cycles": 1, "force_max_N": 50, "force_min_N": 60}),
            "force_min_N",
        ),
        "stress_over_fibres": (
            doc(diameter_mm=0.01, segment={"ramp_to_N": 1000}),
            "ramp_to_N",
        ),
        "ramp_too_fine": (doc(segment={"ramp_to_N": 1e-300}), "ramp_to_N"),
        "ramp_samples_1e9": (
            doc(segment={"ramp_to_N": 50, "samples": 10**9}),
            "samples",
        ),
        "hold_tiny": (
            doc(segments=[{"ramp_to_N": 5}, {"hold_s": 1e-300}]),
            "segments[1].hold_s",
        ),
        "hold_1e300": (
            doc(segments=[{"ramp_to_N": 5}, {"hold_s": 1e300}]),
            "segments[1].hold_s",
        ),
        "hold_wrong_force": (
            doc(segments=[{"ramp_to_N": 5}, {"hold_s": 5, "force_N": 7}]),
            "force_N",
        ),
        "rest_h_1e12": (doc(segment={"rest_h": 1e12}), "rest_h"),
        "rest_under_load": (doc(segments=[{"ramp_to_N": 5}, {"rest_s": 5}]), "rest_s"),
        "peak_hold_negative": (
            doc(segment={"cycles": 1, "force_max_N": 50, "peak_hold_s": -1}),
            "peak_hold_s",
        ),
        "huge_string_value": (doc(segment={"ramp_to_N": "x" * 100_000}), "ramp_to_N"),
    }
    return cases


def _params_cases() -> dict[str, tuple[str, str]]:
    """name -> (the --params file's content, a word the error line must hold)."""
    fit = {"format": "jaxcable-params", "model": "HookeModel", "parameters": {}}

    def pj(**changes) -> str:
        return json.dumps({**fit, **changes})

    return {
        "params_not_json": ("{E1c: 5}", "line 1"),
        "params_a_list": ("[1, 2]", "params"),
        "params_unknown_name": ('{"E9": 5}', "E9"),
        "params_string_value": ('{"E1c": "big"}', "E1c"),
        "params_null_value": ('{"E1c": null}', "E1c"),
        "params_negative": ('{"E1c": -5}', "params"),
        "params_int_10_400": ('{"E1c": ' + _HUGE_INT + "}", "line 1"),
        "params_1e999": ('{"E1c": 1e999}', "line 1"),
        "params_nan": ('{"E1c": NaN}', "line 1"),
        "params_empty_file": ("", "line 1"),
        "fit_model_number": (pj(model=5), "model"),
        "fit_model_list": (pj(model=["HookeModel"]), "model"),
        "fit_model_unknown": (pj(model="NoSuchModel"), "NoSuchModel"),
        "fit_parameters_list": (pj(parameters=[1, 2]), "parameters"),
        "fit_parameters_string": (pj(parameters="E=1"), "parameters"),
        "fit_static_number": (pj(static=3), "static"),
        "fit_base_model_list": (pj(model="Hereditary", base={"model": []}), "model"),
        "fit_parameter_int_10_400": (
            '{"format": "jaxcable-params", "model": "HookeModel", "parameters": '
            '{"E": ' + _HUGE_INT + "}}",
            "line 1",
        ),
        "fit_truncated": (pj()[:40], "line 1"),
    }


def _csv_cases() -> dict[str, tuple[str | bytes, str]]:
    """name -> (a data file's content, a word the error line must hold)."""
    return {
        "csv_empty": ("", "csv"),
        "csv_header_only": (_CSV_HEADER, "csv"),
        "csv_binary": (bytes(range(256)) * 4, "csv"),
        "csv_cell_over_128k": (_CSV_HEADER + '"' + "1" * 140_000 + '",1,2\n', "csv"),
        "csv_unclosed_quote": (_CSV_HEADER + '"1,2,3\n' + _CSV_ROWS, "csv"),
        "csv_text_cell": (_CSV_HEADER + _CSV_ROWS + "12,x,3\n", "csv"),
        "csv_nan": (_CSV_HEADER + _CSV_ROWS + "12,nan,3\n", "csv"),
        "csv_time_backwards": (_CSV_HEADER + _CSV_ROWS + "5,1,1\n", "csv"),
        "csv_no_length": ("time_s,force_N,elongation_mm\n" + _CSV_ROWS, "csv"),
        "csv_length_text": (
            "# length_mm: abc\ntime_s,force_N,elongation_mm\n" + _CSV_ROWS,
            "csv",
        ),
        "csv_length_1e999": (
            "# length_mm: 1e999\ntime_s,force_N,elongation_mm\n" + _CSV_ROWS,
            "csv",
        ),
        "csv_number_1e999": (_CSV_HEADER + _CSV_ROWS + "12,1e999,3\n", "csv"),
        "csv_no_elongation": (
            "# length_mm: 300\ntime_s,force_N\n0,0\n1,1\n2,2\n",
            "csv",
        ),
        "csv_short_row": (_CSV_HEADER + _CSV_ROWS + "12,1\n", "csv"),
    }


def _invocations(folder: pathlib.Path) -> list[tuple[str, list[str], str]]:
    """(name, argv, a word the error line must hold) of every bad invocation."""

    def write(name: str, content) -> str:
        path = folder / name
        if isinstance(content, bytes):
            path.write_bytes(content)
        else:
            path.write_text(content, encoding="utf-8")
        return str(path)

    good_protocol = write("good.json", json.dumps(_GOOD_PROTOCOL))
    data = write("data.csv", _CSV_HEADER + _CSV_ROWS)
    out_csv, out_json = str(folder / "out.csv"), str(folder / "out.json")
    cases = []
    for name, (content, word) in _protocol_cases().items():
        path = write(f"{name}.json", content)
        cases.append((f"simulate/{name}", ["simulate", path, "--out", out_csv], word))
    for name, (content, word) in _params_cases().items():
        params = write(f"{name}.json", content)
        cases.append(
            (
                f"simulate/{name}",
                ["simulate", good_protocol, "--params", params, "--out", out_csv],
                word,
            )
        )
        command = "fit" if len(cases) % 2 else "diagnose"
        argv = [command, data, "--params", params]
        argv += ["--out", out_json] if command == "fit" else []
        cases.append((f"{command}/{name}", argv, word))
    for name, (content, word) in _csv_cases().items():
        path = write(f"{name}.csv", content)
        cases.append((f"fit/{name}", ["fit", path, "--out", out_json], word))
        cases.append((f"diagnose/{name}", ["diagnose", path], word))
        if name != "csv_no_elongation":  # a force history has no elongation
            cases.append(
                (f"simulate/{name}", ["simulate", path, "--out", out_csv], word)
            )
    options = [
        ("fit/seed_2^64", ["fit", data, "--seed", str(2**64)], "--seed"),
        ("fit/seed_text", ["fit", data, "--seed", "x"], "--seed"),
        ("diagnose/seed_-2^70", ["diagnose", data, "--seed", str(-(2**70))], "--seed"),
        ("fit/seed_5000_digits", ["fit", data, "--seed", "9" * 5000], "--seed"),
        ("fit/starts_0", ["fit", data, "--starts", "0"], "--starts"),
        ("fit/starts_huge", ["fit", data, "--starts", "9" * 5000], "--starts"),
        ("fit/every_-1", ["fit", data, "--every", "-1"], "--every"),
        ("fit/max_steps_x", ["fit", data, "--max-steps", "x"], "--max-steps"),
        ("fit/length_inf", ["fit", data, "--length-mm", "inf"], "--length-mm"),
        ("fit/length_nan", ["fit", data, "--length-mm", "nan"], "--length-mm"),
        (
            "fit/diameter_1e999",
            ["fit", data, "--diameter-mm", "1e999"],
            "--diameter-mm",
        ),
        ("fit/skip_rows_-1", ["fit", data, "--skip-rows", "-1"], "--skip-rows"),
        ("fit/fit_unknown", ["fit", data, "--fit", "nope"], "--fit"),
        ("fit/fit_empty_name", ["fit", data, "--fit", "E1c,,beta"], "--fit"),
        ("fit/per_test_unknown", ["fit", data, "--per-test", "nope"], "--per-test"),
        ("fit/model_unknown", ["fit", data, "--model", "nope"], "--model"),
        (
            "fit/columns_bad",
            ["fit", data, "--columns", "time_fortnight,x"],
            "columns",
        ),
        ("fit/no_out", ["fit", data], "--out"),
        ("fit/out_is_data", ["fit", data, "--out", data], "--out"),
        ("fit/out_is_folder", ["fit", data, "--out", str(folder)], "--out"),
        (
            "fit/out_missing_folder",
            ["fit", data, "--out", str(folder / "no" / "p.json")],
            "--out",
        ),
        (
            "fit/report_onto_input",
            [
                "fit",
                write("rmse.csv", _CSV_HEADER + _CSV_ROWS),
                "--report",
                str(folder),
            ],
            "--report",
        ),
        ("diagnose/folds_0", ["diagnose", data, "--folds", "0"], "--folds"),
        ("diagnose/holdout_-1", ["diagnose", data, "--holdout", "-1"], "--holdout"),
        ("diagnose/split_bad", ["diagnose", data, "--split", "nope"], "--split"),
        (
            "diagnose/report_is_a_file",
            ["diagnose", data, "--report", data],
            "--report",
        ),
        ("diagnose/no_data", ["diagnose"], "DATA.csv"),
        ("diagnose/json_missing_file", ["diagnose", "nope.csv", "--json"], "nope.csv"),
        (
            "diagnose/json_candidates_x",
            ["diagnose", data, "--json", "--report", data],
            "--report",
        ),
        ("diagnose/missing_file", ["diagnose", str(folder / "nope.csv")], "nope.csv"),
        ("diagnose/a_folder", ["diagnose", str(folder)], str(folder)),
        ("simulate/no_out", ["simulate", good_protocol], "--out"),
        (
            "simulate/out_is_input",
            ["simulate", good_protocol, "--out", good_protocol],
            "--out",
        ),
        (
            "simulate/out_is_params",
            ["simulate", good_protocol, "--params", data, "--out", data],
            "--out",
        ),
        (
            "simulate/missing_file",
            ["simulate", str(folder / "no.json"), "--out", out_csv],
            "no.json",
        ),
        (
            "simulate/model_unknown",
            ["simulate", good_protocol, "--model", "x", "--out", out_csv],
            "--model",
        ),
        (
            "simulate/test_without_per_test",
            [
                "simulate",
                good_protocol,
                "--test",
                "7",
                "--params",
                "nope.json",
                "--out",
                out_csv,
            ],
            "nope.json",
        ),
    ]
    for name, argv, word in options:
        if argv[0] == "fit" and "--out" not in argv and name != "fit/no_out":
            argv = [*argv, "--out", out_json]
        cases.append((name, argv, word))
    return cases


class _Timeout(Exception):
    pass


def _on_alarm(signum, frame):
    raise _Timeout()


def run(limit_s: float) -> tuple[dict, list]:
    """Run every invocation; (counts, failing cases as table rows)."""
    os.environ.setdefault("JAXCABLE_NO_CACHE", "1")
    from jaxcable._cli import main

    signal.signal(signal.SIGALRM, _on_alarm)
    counts = {
        "invocations": 0,
        "tracebacks": 0,
        "exit_not_2": 0,
        "stderr_not_one_located_line": 0,
        "over_time_limit": 0,
    }
    failures = []
    with tempfile.TemporaryDirectory(prefix="fuzz_cli.") as tmp:
        folder = pathlib.Path(tmp)
        for name, argv, word in _invocations(folder):
            counts["invocations"] += 1
            before = {p: p.read_bytes() for p in folder.iterdir() if p.is_file()}
            out, err = io.StringIO(), io.StringIO()
            start = time.perf_counter()
            signal.setitimer(signal.ITIMER_REAL, limit_s)
            status, problem = None, ""
            try:
                with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
                    status = main(argv)
            except _Timeout:
                counts["over_time_limit"] += 1
                problem = f"over {limit_s:g} s"
            except BaseException as e:  # noqa: BLE001 - counting them is the point
                counts["tracebacks"] += 1
                problem = "".join(traceback.format_exception_only(e)).strip()
            finally:
                signal.setitimer(signal.ITIMER_REAL, 0)
            seconds = time.perf_counter() - start
            lines = err.getvalue().splitlines()
            if not problem and status != 2:
                counts["exit_not_2"] += 1
                problem = f"exit {status}"
            if not problem and not (
                len(lines) == 1
                and lines[0].startswith("jaxcable: error: ")
                and word in lines[0]
                and "Traceback" not in lines[0]
            ):
                counts["stderr_not_one_located_line"] += 1
                problem = f"stderr {lines!r} (wanted one line naming {word!r})"
            # No input may have been changed by a refused run.
            for path, content in before.items():
                if path.read_bytes() != content:
                    problem += f"; changed {path.name}"
            for stray in ("out.csv", "out.json"):
                (folder / stray).unlink(missing_ok=True)
            if problem:
                failures.append((name, status, f"{seconds:.2f}", problem[:160]))
    return counts, failures


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--limit-s", type=float, default=20.0, help="time limit a case")
    parser.add_argument(
        "--json-only", action="store_true", help="print the counts only"
    )
    args = parser.parse_args()
    counts, failures = run(args.limit_s)
    if not args.json_only:
        print(f"{'case':<40} {'exit':>4} {'s':>6}  problem")
        for name, status, seconds, problem in failures:
            print(f"{name:<40} {status!s:>4} {seconds:>6}  {problem}")
        print(f"{len(failures)} of {counts['invocations']} invocations failed.")
    print(json.dumps(counts))
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
