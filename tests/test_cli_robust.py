"""The command line against hostile input: every bad input exits 2 with one line naming
the file (and place) or the option, no output replaces an input, every file is
written atomically and a replaced one is said in the command's log (stdout).

Every case is refused before anything is simulated or fitted (fast), except the
two that replace an output, which simulate a short force history with Hooke's law.
"""

import json
import os

import numpy as np
import pytest

import jaxcable as jc
from jaxcable.cli import main


_GOOD_PROTOCOL = {
    "length_mm": 300,
    "segments": [{"cycles": 1, "force_max_N": 50, "samples_per_ramp": 5}],
}
_HUGE_INT = "1" + "0" * 400


def _protocol(**changes) -> dict:
    doc = json.loads(json.dumps(_GOOD_PROTOCOL))
    for key, value in changes.items():
        if key == "segment":
            doc["segments"][0].update(value)
        else:
            doc[key] = value
    return doc


def _one_error_line(err: str) -> str:
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("jaxcable: error: "), err
    assert "Traceback" not in err
    return lines[0]


def _data_file(path, rows: int = 12):
    time = np.linspace(0.0, 60.0, rows)
    jc.write_csv(
        path,
        jc.TestData(
            time=time,
            force=np.linspace(0.0, 50.0, rows),
            elongation=np.linspace(0.0, 1e-3, rows),
            metadata={"id": "d", "length_mm": 300.0},
        ),
    )
    return path


def _history_file(path):
    time = np.linspace(0.0, 60.0, 7)
    jc.write_csv(
        path,
        jc.TestData(
            time=time, force=np.linspace(0.0, 30.0, 7), metadata={"length_mm": 300.0}
        ),
    )
    return path


def _refused(argv, capsys, *names) -> str:
    status = main([str(a) for a in argv])
    message = _one_error_line(capsys.readouterr().err)
    assert status == 2, message
    for name in names:
        assert str(name) in message, message
    return message


# (protocol text, what the one line must say besides the file)
_BAD_PROTOCOLS = {
    "float_beyond_range": (
        '{"length_mm": 1e999, "segments": [{"ramp_to_N": 10}]}',
        "line 1, column 15",
    ),
    "integer_literal_10_400": (
        '{"length_mm": 300,\n "segments": [{"cycles": ' + _HUGE_INT + "}]}",
        "line 2, column 26",
    ),
    "nan_literal": ('{"length_mm": NaN, "segments": []}', "line 1, column 15"),
    "cycles_1e9": (
        json.dumps(_protocol(segment={"cycles": 1e9})),
        "segments[0].cycles",
    ),
    "cycles_over_limit": (
        json.dumps(_protocol(segment={"cycles": 200_000, "samples_per_ramp": 1})),
        "segments[0].cycles",
    ),
    "samples_per_ramp_absurd": (
        json.dumps(_protocol(segment={"samples_per_ramp": 10**12})),
        "segments[0].samples_per_ramp",
    ),
    "total_samples_over_limit": (
        json.dumps(_protocol(segment={"cycles": 10, "samples_per_ramp": 60_000})),
        "segments[0].cycles",
    ),
    "diameter_1e200": (json.dumps(_protocol(diameter_mm=1e200)), "diameter_mm"),
    "length_below_range": (json.dumps(_protocol(length_mm=1e-9)), "length_mm"),
    "rate_above_range": (
        json.dumps(_protocol(rate_mm_per_min=1e30)),
        "rate_mm_per_min",
    ),
    "stress_above_fibres": (
        json.dumps(_protocol(diameter_mm=0.01, segment={"force_max_N": 1000})),
        "segments[0].force_max_N",
    ),
    "hold_too_short": (
        json.dumps(
            _protocol(segments=[{"ramp_to_N": 10}, {"hold_s": 1e-300, "samples": 3}])
        ),
        "segments[1].hold_s",
    ),
    "rest_too_long": (
        json.dumps(_protocol(segments=[{"rest_h": 1e12}])),
        "segments[0].rest_h",
    ),
    "ramp_too_fine": (
        json.dumps(_protocol(segments=[{"ramp_to_N": 1e-300}])),
        "segments[0].ramp_to_N",
    ),
    "huge_string": (
        json.dumps(_protocol(segments=[{"ramp_to_N": "x" * 100_000}])),
        "segments[0].ramp_to_N",
    ),
}


@pytest.mark.parametrize("case", list(_BAD_PROTOCOLS))
def test_bad_protocol_one_located_line(tmp_path, capsys, case):
    text, place = _BAD_PROTOCOLS[case]
    src = tmp_path / f"{case}.json"
    src.write_text(text)
    out = tmp_path / "out.csv"
    message = _refused(["simulate", src, "--out", out], capsys, src, place)
    assert len(message) < 400
    assert not out.exists()


def test_latin1_protocol_located(tmp_path, capsys):
    src = tmp_path / "latin1.json"
    src.write_bytes('{"length_mm": 300,\n "id": "caf\xe9"}'.encode("latin-1"))
    _refused(["simulate", src, "--out", tmp_path / "o.csv"], capsys, src, "line 2")


_BAD_PARAMS = {
    "plain_integer_10_400": ('{"E1c": ' + _HUGE_INT + "}", "line 1, column 9"),
    "plain_1e999": ('{"E1c": 1e999}', "line 1, column 9"),
    "fit_model_not_a_string": (
        json.dumps({"format": "jaxcable-params", "model": 5, "parameters": {}}),
        "model",
    ),
    "fit_parameters_a_list": (
        json.dumps(
            {"format": "jaxcable-params", "model": "HookeModel", "parameters": [1]}
        ),
        "parameters",
    ),
    "fit_static_a_number": (
        json.dumps(
            {
                "format": "jaxcable-params",
                "model": "HookeModel",
                "parameters": {},
                "static": 3,
            }
        ),
        "static",
    ),
    "fit_base_model_a_list": (
        json.dumps(
            {
                "format": "jaxcable-params",
                "model": "Hereditary",
                "parameters": {},
                "base": {"model": []},
            }
        ),
        "base.model",
    ),
    "fit_parameter_integer_10_400": (
        '{"format": "jaxcable-params", "model": "HookeModel", "parameters": '
        '{"E": ' + _HUGE_INT + "}}",
        "column",
    ),
}


@pytest.mark.parametrize("command", ["simulate", "fit", "diagnose"])
@pytest.mark.parametrize("case", list(_BAD_PARAMS))
def test_bad_params_one_located_line(tmp_path, capsys, case, command):
    text, place = _BAD_PARAMS[case]
    params = tmp_path / "params.json"
    params.write_text(text)
    if command == "simulate":
        src = tmp_path / "p.json"
        src.write_text(json.dumps(_GOOD_PROTOCOL))
        argv = ["simulate", src, "--out", tmp_path / "o.csv"]
    else:
        argv = [command, _data_file(tmp_path / "d.csv")]
        argv += ["--out", tmp_path / "o.json"] if command == "fit" else []
    _refused([*argv, "--params", params], capsys, params, place)


def test_cell_over_csv_field_limit(tmp_path, capsys):
    src = tmp_path / "big.csv"
    src.write_text(
        "# length_mm: 300\ntime_s,force_N,elongation_mm\n"
        f'"{"1" * 140_000}",1,2\n1,2,3\n'
    )
    message = _refused(["fit", src, "--out", tmp_path / "p.json"], capsys, src)
    assert len(message) < 400


@pytest.mark.parametrize(
    "argv, option",
    [
        (["fit", "D", "--seed", str(2**64), "--out", "p.json"], "--seed"),
        (["diagnose", "D", "--seed", str(-(2**70))], "--seed"),
        (["fit", "D", "--seed", "1" * 5000, "--out", "p.json"], "--seed"),
        (["demo", "--samples-per-ramp", str(10**14)], "--samples-per-ramp"),
        (["demo", "--samples-per-ramp", "1"], "--samples-per-ramp"),
        (["fit", "D", "--starts", "1" * 5000, "--out", "p.json"], "--starts"),
    ],
)
def test_absurd_numeric_options(tmp_path, capsys, argv, option):
    data = str(_data_file(tmp_path / "d.csv"))
    message = _refused([data if a == "D" else a for a in argv], capsys, option)
    assert len(message) < 300


def test_output_equal_to_input_is_refused(tmp_path, capsys):
    data = _data_file(tmp_path / "d.csv")
    before = data.read_bytes()
    # fit --out onto its data (also through another spelling of the same path).
    _refused(["fit", data, "--out", data], capsys, "--out", data)
    other = tmp_path / "sub" / ".." / "d.csv"
    _refused(["fit", data, "--out", other], capsys, "--out")
    link = tmp_path / "link.csv"
    os.symlink(data, link)
    _refused(["fit", data, "--out", link], capsys, "--out", link)
    # simulate --out onto its history, its protocol or its --params.
    history = _history_file(tmp_path / "h.csv")
    _refused(["simulate", history, "--out", history], capsys, "--out")
    protocol = tmp_path / "p.json"
    protocol.write_text(json.dumps(_GOOD_PROTOCOL))
    _refused(["simulate", protocol, "--out", protocol], capsys, "--out")
    params = tmp_path / "start.json"
    params.write_text("{}")
    argv = ["simulate", protocol, "--params", params, "--out", params]
    _refused(argv, capsys, "--out", params)
    # fit/diagnose --report onto an input; fit --out onto its own report.
    table = _data_file(tmp_path / "rmse.csv")
    _refused(
        ["fit", table, "--out", tmp_path / "p.json", "--report", tmp_path],
        capsys,
        "--report",
    )
    # A report folder that holds the inputs, none of them named as a report file:
    # written beside them (the inputs are checked unchanged below).
    argv = ["diagnose", data, "--report", tmp_path, "--params", params, "--quiet"]
    assert main([str(a) for a in argv]) == 0
    capsys.readouterr()
    (tmp_path / "summary.md").write_text("{}")
    argv = ["diagnose", data, "--report", tmp_path, "--params", tmp_path / "summary.md"]
    _refused(argv, capsys, "--report")
    (tmp_path / "r").mkdir()
    argv = ["fit", data, "--out", tmp_path / "r" / "rmse.csv"]
    _refused([*argv, "--report", tmp_path / "r"], capsys, "--report")
    # demo --out onto its --data folder, where a data file has an output's name.
    folder = tmp_path / "data"
    folder.mkdir()
    _data_file(folder / "params.json.csv")
    _data_file(folder / "rate_3mm_per_min.csv")
    _refused(["demo", "--data", folder, "--out", folder], capsys, "--out")
    # An output that is a folder.
    _refused(["fit", data, "--out", tmp_path], capsys, "--out")
    assert data.read_bytes() == before
    assert protocol.read_text() == json.dumps(_GOOD_PROTOCOL)
    assert params.read_text() == "{}"


def test_replaced_output_said_and_written_atomically(tmp_path, capsys, monkeypatch):
    history = _history_file(tmp_path / "h.csv")
    out = tmp_path / "out.csv"
    argv = ["simulate", str(history), "--model", "hooke", "--out", str(out)]
    assert main(argv) == 0
    first = capsys.readouterr()
    assert first.err == "" and "replacing" not in first.out
    assert main(argv) == 0
    second = capsys.readouterr()
    assert second.err == ""
    assert second.out.startswith(f"replacing {out} (--out)\nwrote {out} ")
    written = out.read_bytes()

    # A write cut short (here: the rename fails) leaves the old file, no temporary
    # file, and one line naming the option and the file.
    def fail(*args):
        raise OSError(28, "No space left on device", str(args[0]))

    monkeypatch.setattr(os, "replace", fail)
    assert main(argv) == 2
    message = _one_error_line(capsys.readouterr().err)
    assert message.endswith(f"--out {out}: cannot write: No space left on device.")
    assert out.read_bytes() == written
    assert sorted(p.name for p in tmp_path.iterdir()) == ["h.csv", "out.csv"]


def test_library_writers_are_atomic(tmp_path, monkeypatch):
    # FitResult.to_json and Diagnosis.to_json write through the atomic writer: a
    # failed write leaves the old file as it was.
    from jaxcable._diagnose import diagnosis as diagnose_result
    from jaxcable._fit import result as fit_result

    assert fit_result.write_text_atomic is diagnose_result.write_text_atomic
    target = tmp_path / "PARAMS.json"
    target.write_text("old")

    def fail(*args):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "replace", fail)
    with pytest.raises(OSError):
        fit_result.write_text_atomic(target, "new")
    assert target.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["PARAMS.json"]
