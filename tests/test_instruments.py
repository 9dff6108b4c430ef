"""Tester exports as instruments write them (Instron Bluehill, Zwick testXpert, MTS
TestSuite, Shimadzu Trapezium): metadata block, header and units row read without
`columns`; an unknown layout refused in one located line; the caller's values win
over the file's, with a warning where they differ. Every file is written here."""

import warnings

import numpy as np
import pytest

import jaxcable as jc
from jaxcable.internal import cli_data


# time s, elongation mm, force N: the rows every layout below writes, in its units.
ROWS = np.array(
    [[0.0, 0.0, 0.0], [1.5, 0.125, 2.5], [3.0, 0.25, 5.25], [4.5, 0.375, 8.0]]
)


def _write(tmp_path, name, text, newline="\n", encoding="utf-8"):
    path = tmp_path / name
    path.write_bytes(text.replace("\n", newline).encode(encoding))
    return path


def _check_rows(data):
    """`data` holds `ROWS`, in SI."""
    np.testing.assert_allclose(data.time, ROWS[:, 0], rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(data.elongation, ROWS[:, 1] * 1e-3, rtol=1e-12)
    np.testing.assert_allclose(data.force, ROWS[:, 2], rtol=1e-12, atol=1e-12)


def _bluehill(length="14.33000,mm", rate="5.00000,mm/min", control=None):
    """A Bluehill export: the metadata in another order than usual, other lines."""
    value, unit = length.split(",")
    rate_value, rate_unit = rate.split(",")
    lines = [
        '"Results Table 1"',
        f'Test : Rate 1,"{rate_value}",{rate_unit}',
        "Sample : Operator,Jane",
        f'Specimen properties : Length,"{value}",{unit}',
        'Specimen properties : Diameter,"0.50000",mm',
    ]
    if control is not None:
        lines.append(control)
    lines += ["", "Extension,Load,Tensile stress,Time", "(mm),(N),(MPa),(s)"]
    for t, e, f in ROWS:
        lines.append(f'"{e:.5f}","{f:.5f}","{f / 0.196:.5f}","{t:.5f}"')
    return "\n".join(lines) + "\n"


def test_bluehill(tmp_path):
    path = _write(tmp_path, "bluehill.csv", _bluehill(), newline="\r\n")
    data = jc.read_test(path, options=jc.ReadOptions(detect_slack=False))
    _check_rows(data)
    assert data.metadata["length_mm"] == 14.33
    assert data.metadata["diameter_mm"] == 0.5
    assert data.metadata["rate_mm_per_min"] == 5.0
    assert "control" not in data.metadata  # the file does not say
    assert data.extra == {}  # the stress column is not read
    assert data.lines[0] == 9


@pytest.mark.parametrize(
    "length, rate, length_mm, rate_mm_per_min",
    [
        ("1.433,cm", "0.08333,mm/s", 14.33, 4.9998),
        ("0.5642,in", "0.2,in/min", 14.33068, 5.08),
        ("0.01433,m", "0.0001,m/s", 14.33, 6.0),
        ("14.33,(mm)", "0.005,m/min", 14.33, 5.0),
    ],
)
def test_bluehill_metadata_units(tmp_path, length, rate, length_mm, rate_mm_per_min):
    path = _write(tmp_path, "units.csv", _bluehill(length, rate))
    data = jc.read_test(path)
    assert data.metadata["length_mm"] == pytest.approx(length_mm, rel=1e-12)
    assert data.metadata["rate_mm_per_min"] == pytest.approx(rate_mm_per_min)


@pytest.mark.parametrize(
    "line, control",
    [
        ('Test : Control mode,"Extension",', "elongation"),
        ("Test : Position control,,", "elongation"),
        ("Method : Displacement control", "elongation"),
        ('Test : Control mode,"Load",', "force"),
        ("Test : Force control,,", "force"),
        ("Test : Load control then position control", None),  # both: not stated
        ("Test : Load cell,1 kN", None),  # no control mode
    ],
)
def test_control_mode(tmp_path, line, control):
    path = _write(tmp_path, "control.csv", _bluehill(control=line))
    assert jc.read_test(path).metadata.get("control") == control


def test_metadata_without_known_unit_is_located(tmp_path):
    path = _write(tmp_path, "nounit.csv", _bluehill(length="14.33,ft"))
    with pytest.raises(ValueError) as error:
        jc.read_test(path)
    message = str(error.value)
    assert "\n" not in message
    assert f"{path}, line 4" in message and "'ft' unknown" in message
    assert "--length-mm" in message
    # Given by the caller, the file's length is not needed.
    assert (
        jc.read_test(path, metadata={"length_mm": 14.33}).metadata["length_mm"] == 14.33
    )


def test_zwick_german_decimal_comma(tmp_path):
    text = (
        "Prüfprotokoll;Kunde: Muster\n"
        "Einspannlänge;100,0;mm\n"
        "Durchmesser;3,0;mm\n"
        "Prüfgeschwindigkeit;0,5;mm/s\n"
        "Regelung;Wegregelung\n"
        "\n"
        "Standardkraft;Standardweg;Prüfzeit;Dehnung\n"
        "kN;mm;s;%\n"
    )
    for t, e, f in ROWS:
        text += f"{f / 1e3:.6f};{e:.4f};{t:.2f};{e:.4f}\n".replace(".", ",")
    # testXpert writes Windows-1252, as read by the latin-1 fallback.
    path = _write(tmp_path, "zwick.csv", text, newline="\r\n", encoding="cp1252")
    data = jc.read_test(path)
    _check_rows(data)
    assert data.metadata == {
        "length_mm": 100.0,
        "diameter_mm": 3.0,
        "rate_mm_per_min": 30.0,
        "control": "elongation",
    }


def test_zwick_english(tmp_path):
    text = (
        '"Gauge length";"250";"mm"\n'
        '"Test speed";"10";"mm/min"\n'
        '"Control mode";"Force control"\n'
        '"Standard force";"Grip to grip separation";"Test time"\n'
        '"N";"mm";"min"\n'
    )
    for t, e, f in ROWS:
        text += f'"{f:.3f}";"{e:.4f}";"{t / 60:.10f}"\n'.replace(".", ",")
    data = jc.read_test(_write(tmp_path, "zwick_en.csv", text))
    np.testing.assert_allclose(data.time, ROWS[:, 0], atol=1e-8)
    np.testing.assert_allclose(data.force, ROWS[:, 2])
    assert data.metadata["length_mm"] == 250.0
    assert data.metadata["rate_mm_per_min"] == 10.0
    assert data.metadata["control"] == "force"


@pytest.mark.parametrize(
    "names, units, to",
    [
        ("Time\tAxial Displacement\tAxial Force", "sec\tmm\tN", (1.0, 1.0, 1.0)),
        ("Time\tCrosshead\tLoad", "s\tmm\tkN", (1.0, 1.0, 1e3)),
        ("Time\tCrosshead\tLoad", "s\tin\tlbf", (1.0, 25.4, 4.4482216152605)),
        ("Time\tAxial Displacement\tAxial Force", "ms\tm\tkgf", (1e-3, 1e3, 9.80665)),
    ],
)
def test_mts_testsuite(tmp_path, names, units, to):
    time_to_s, elongation_to_mm, force_to_n = to
    text = "Specimen 1\nSpecimen Length:\t80\tmm\n\n" + names + "\n" + units + "\n"
    for t, e, f in ROWS:
        text += f"{t / time_to_s}\t{e / elongation_to_mm}\t{f / force_to_n}\n"
    data = jc.read_test(_write(tmp_path, "mts.txt", text))
    _check_rows(data)
    assert data.metadata["length_mm"] == 80.0


@pytest.mark.parametrize("encoding", ["utf-8", "shift_jis"])
def test_shimadzu_trapezium(tmp_path, encoding):
    names = "Time,Force,Stroke" if encoding == "utf-8" else "試験時間,試験力,ストローク"
    text = "Test speed: 3 mm/min\n" + names + "\n" + "sec,N,mm\n"
    for t, e, f in ROWS:
        text += f"{t},{f},{e}\n"
    path = _write(tmp_path, "shimadzu.csv", text, encoding=encoding)
    if encoding != "utf-8":
        # Shift-JIS is not among the encodings detected: the caller names it.
        data = jc.read_test(
            path, metadata={"length_mm": 100}, options=jc.ReadOptions(encoding=encoding)
        )
    else:
        data = jc.read_test(path, metadata={"length_mm": 100})
    _check_rows(data)
    assert data.metadata["rate_mm_per_min"] == 3.0


def test_unknown_layout_one_located_line(tmp_path):
    text = "Specimen 1\nZeitpunkt,Kanal 2,Kraft\n(s),(mm),(lb·ft)\n0,0,0\n1,1,1\n"
    path = _write(tmp_path, "unknown.csv", text)
    with pytest.raises(ValueError) as error:
        jc.read_test(path, metadata={"length_mm": 1})
    message = str(error.value)
    assert "\n" not in message
    assert message.startswith(f"{path}, line 2:")
    for found in ("'Zeitpunkt' (not recognised)", "'Kanal 2' (not recognised)"):
        assert found in message
    assert "'Kraft' (force, unit 'lb·ft' unknown)" in message
    assert "columns=" in message and "--columns" in message
    # Two force columns: the header is refused, with a columns value to start from.
    text = "Time,Load,Force\ns,N,kN\n0,0,0\n1,1,1\n"
    path = _write(tmp_path, "two.csv", text)
    with pytest.raises(ValueError, match="two force columns") as error:
        jc.read_test(path, metadata={"length_mm": 1})
    assert "perhaps columns='time_s,force_N,force_kN'" in str(error.value)


def test_caller_values_win_with_a_warning(tmp_path):
    path = _write(tmp_path, "bluehill.csv", _bluehill())
    with pytest.warns(jc.MetadataConflictWarning) as caught:
        data = jc.read_test(path, metadata={"length_mm": 20, "rate_mm_per_min": 5.0})
    assert data.metadata["length_mm"] == 20.0
    assert len(caught) == 1  # the rate agrees
    message = str(caught[0].message)
    assert f"{path}, line 4" in message
    assert "length_mm=20 given" in message and "14.33" in message
    assert "the given value is used" in message
    # Within rounding (a value of the file read in inches included): no warning.
    path = _write(tmp_path, "inches.csv", _bluehill(length="0.5,in"))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert (
            jc.read_test(path, metadata={"length_mm": 12.7}).metadata["length_mm"]
            == 12.7
        )
        jc.read_test(path, metadata={"length_mm": 12.7001, "diameter_mm": 0.5})
    # The canonical `# key: value` block too.
    text = "# length_mm: 300\n# material: SK78\ntime_s,force_N\n0,0\n1,1\n"
    path = _write(tmp_path, "canonical.csv", text)
    with pytest.warns(jc.MetadataConflictWarning, match="line 2: material='SK99'"):
        data = jc.read_test(path, metadata={"material": "SK99"})
    assert data.metadata["material"] == "SK99"


def test_cli_prints_the_warning_as_one_line(tmp_path, capsys):
    path = _write(tmp_path, "bluehill.csv", _bluehill(), newline="\r\n")
    options = cli_data.Reading(
        metadata={"length_mm": 20.0}, options=jc.ReadOptions(detect_slack=False)
    )
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # printed, not raised
        (data,) = cli_data.read_tests([path], options, 1, jc.NoProgressMeter())
    assert data.metadata["length_mm"] == 20.0
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert err.startswith(f"jaxcable: warning: {path}, line 4: length_mm=20 given")


def test_of_two_columns_of_one_quantity_the_plainer_is_read(tmp_path):
    """`Extension` rather than `Tensile extension`, `Total Time` rather than `Cycle
    Elapsed Time`; the others named in the one-line note."""
    text = (
        "Cycle Elapsed Time (s),Total Time (s),Tensile extension (mm),Extension (mm),"
        "Load (N)\n"
    )
    for t, e, f in ROWS:
        text += f"{t + 100},{t},{e * 2},{e},{f}\n"
    data = jc.read_test(_write(tmp_path, "two.csv", text), metadata={"length_mm": 10})
    _check_rows(data)
    assert data.notes == (
        "columns not read: 'Cycle Elapsed Time (s)', 'Tensile extension (mm)'",
    )
