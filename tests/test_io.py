import re

import numpy as np
import pytest

import jaxcable as jc


HISTORY = """\
# id: sk78-a
# material: Dyneema SK78
# length_mm: 300
# diameter_mm: 3.2
# rate_mm_per_min: 50
# temperature_C: 21.5
# operator: A. N. Other: shift 2
# a free comment without a key
time_s,force_N,elongation_mm,temperature_C,gauge_V
0,0,0,21.5,0.01
1.5,10,0.25,21.5,0.02

3,20.5,0.5,21.6,0.03
"""


def _write(tmp_path, text, name="history.csv"):
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def test_read_metadata_columns_and_units(tmp_path):
    path = _write(tmp_path, HISTORY)
    data = jc.read_csv(path)
    assert data.metadata == {
        "id": "sk78-a",
        "material": "Dyneema SK78",
        "length_mm": 300.0,
        "diameter_mm": 3.2,
        "rate_mm_per_min": 50.0,
        "temperature_C": 21.5,
        "operator": "A. N. Other: shift 2",
    }
    np.testing.assert_array_equal(data.time, [0.0, 1.5, 3.0])
    np.testing.assert_array_equal(data.force, [0.0, 10.0, 20.5])
    np.testing.assert_allclose(data.elongation, [0.0, 0.25e-3, 0.5e-3], rtol=1e-15)
    np.testing.assert_array_equal(data.temperature, [21.5, 21.5, 21.6])
    assert list(data.extra) == ["gauge_V"]
    np.testing.assert_array_equal(data.extra["gauge_V"], [0.01, 0.02, 0.03])
    # The blank line is skipped; line numbers stay those of the file.
    np.testing.assert_array_equal(data.lines, [10, 11, 13])
    assert data.source == str(path)
    assert data.num_samples == 3


def test_cable_in_si(tmp_path):
    cable = jc.read_csv(_write(tmp_path, HISTORY)).cable()
    assert isinstance(cable, jc.Cable)
    np.testing.assert_allclose(float(cable.length), 0.3)
    np.testing.assert_allclose(float(cable.diameter), 3.2e-3)
    np.testing.assert_allclose(float(cable.speed), 50e-3 / 60)


def test_cable_defaults_and_overrides(tmp_path):
    path = _write(tmp_path, "time_s,force_N\n0,0\n1,1\n")
    data = jc.read_csv(path, metadata={"length_mm": 100, "rate_mm_per_min": "6"})
    assert data.metadata == {"length_mm": 100.0, "rate_mm_per_min": 6.0}
    assert data.elongation is None and data.temperature is None and data.extra == {}
    cable = data.cable()
    np.testing.assert_allclose(float(cable.length), 0.1)
    np.testing.assert_allclose(float(cable.diameter), 3e-3)  # default 3 mm
    np.testing.assert_allclose(float(cable.speed), 6e-3 / 60)


def test_other_units_bom_crlf_and_quotes(tmp_path):
    text = '# length_mm: 300\r\ntime_min,force_kN,elongation_m\r\n0,0,0\r\n"0.5",0.1,0.002\r\n'
    path = tmp_path / "exported.csv"
    path.write_bytes(b"\xef\xbb\xbf" + text.encode())
    data = jc.read_csv(path)
    np.testing.assert_allclose(data.time, [0.0, 30.0])
    np.testing.assert_allclose(data.force, [0.0, 100.0])
    np.testing.assert_allclose(data.elongation, [0.0, 0.002])


def test_round_trip(tmp_path):
    rng = np.random.default_rng(0)
    n = 50
    data = jc.TestData(
        time=np.cumsum(rng.uniform(0.1, 2.0, n)),
        force=rng.uniform(0, 150, n),
        elongation=rng.uniform(0, 0.02, n),
        temperature=rng.uniform(15, 30, n),
        extra={"gauge_V": rng.normal(size=n), "cycle": np.arange(n) // 10},
        metadata={
            "id": "roundtrip",
            "length_mm": 300.0,
            "diameter_mm": 3.0,
            "rate_mm_per_min": 1 / 3,
            "note": "kept: as a string",
        },
    )
    path = tmp_path / "out.csv"
    jc.write_csv(path, data)
    assert path.read_text().splitlines()[5] == (
        "time_s,force_N,elongation_mm,temperature_C,gauge_V,cycle"
    )
    back = jc.read_csv(path)
    assert back.metadata == data.metadata
    np.testing.assert_array_equal(back.time, data.time)
    np.testing.assert_array_equal(back.force, data.force)
    np.testing.assert_array_equal(back.temperature, data.temperature)
    # m -> mm -> m costs at most an ulp or two.
    np.testing.assert_allclose(back.elongation, data.elongation, rtol=1e-15, atol=0)
    assert list(back.extra) == ["gauge_V", "cycle"]
    for name in data.extra:
        np.testing.assert_array_equal(back.extra[name], data.extra[name])
    # Written again, the file is unchanged.
    again = tmp_path / "again.csv"
    jc.write_csv(again, back)
    assert again.read_text() == path.read_text()


def test_write_without_elongation(tmp_path):
    data = jc.TestData(time=[0.0, 1.0], force=[0.0, 5.0], metadata={"length_mm": 100})
    path = tmp_path / "f.csv"
    jc.write_csv(path, data)
    assert path.read_text() == "# length_mm: 100\ntime_s,force_N\n0.0,0.0\n1.0,5.0\n"


def test_write_needs_length(tmp_path):
    data = jc.TestData(time=[0.0, 1.0], force=[0.0, 5.0])
    with pytest.raises(ValueError, match="length_mm"):
        jc.write_csv(tmp_path / "f.csv", data)


def test_testdata_checks_shapes():
    with pytest.raises(ValueError, match="differ in length"):
        jc.TestData(time=[0.0, 1.0], force=[0.0])
    with pytest.raises(ValueError, match="canonical column"):
        jc.TestData(time=[0.0], force=[0.0], extra={"force_N": [1.0]})


# (file contents, line, column or metadata key) of the first problem.
BAD_INPUTS = {
    "missing_column": ("# length_mm: 300\ntime_s,elongation_mm\n0,0\n", 2, "force_N"),
    "non_numeric": ("# length_mm: 300\ntime_s,force_N\n0,0\n1,12..5\n", 4, "force_N"),
    "empty_cell": ("# length_mm: 300\ntime_s,force_N\n0,0\n,3\n", 4, "time_s"),
    "nan": ("# length_mm: 300\ntime_s,force_N\n0,0\n1,nan\n", 4, "force_N"),
    "time_not_increasing": (
        "# length_mm: 300\ntime_s,force_N\n0,0\n2,1\n1,2\n",
        5,
        "time_s",
    ),
    "missing_length": ("# id: x\ntime_s,force_N\n0,0\n", 2, "length_mm"),
    "bad_length": ("# length_mm: -3\ntime_s,force_N\n0,0\n", 1, "length_mm"),
    "short_row": ("# length_mm: 300\ntime_s,force_N\n0,0\n1\n", 4, "force_N"),
}


@pytest.mark.parametrize("reader", [jc.read_csv, jc.read_test])
@pytest.mark.parametrize("case", list(BAD_INPUTS))
def test_bad_input_names_file_line_column(tmp_path, case, reader):
    text, line, column = BAD_INPUTS[case]
    path = _write(tmp_path, text, name=f"{case}.csv")
    with pytest.raises(ValueError) as info:
        reader(path)
    message = str(info.value)
    assert str(path) in message
    assert re.search(rf"\bline {line}\b", message), message
    assert f"'{column}'" in message
    assert "\n" not in message


def test_missing_length_can_be_given(tmp_path):
    text, _, _ = BAD_INPUTS["missing_length"]
    data = jc.read_csv(_write(tmp_path, text), metadata={"length_mm": 300})
    assert data.metadata["length_mm"] == 300.0


def test_read_test_reads_canonical_files_like_read_csv(tmp_path):
    path = _write(tmp_path, HISTORY)
    expected = jc.read_csv(path)
    data = jc.read_test(path)
    assert data.metadata == expected.metadata
    for name in ("time", "force", "elongation", "temperature", "lines"):
        np.testing.assert_array_equal(getattr(data, name), getattr(expected, name))
    assert list(data.extra) == ["gauge_V"]
    np.testing.assert_array_equal(data.extra["gauge_V"], expected.extra["gauge_V"])
    # Nothing to mask in a taut test; read_csv does not run the detection at all.
    assert data.mask.all() and data.force_raw is None
    assert data.slack_report is not None and data.slack_report.stretches == ()
    assert expected.slack_report is None and expected.mask.all()


def test_read_test_overrides_file_metadata(tmp_path):
    path = _write(tmp_path, HISTORY)
    data = jc.read_test(
        path,
        metadata={
            "length_mm": 100,
            "diameter_mm": 2,
            "rate_mm_per_min": 6,
            "temperature_C": 30,
            "material": "Dyneema SK99",
            "id": "other",
        },
    )
    assert data.metadata == {
        "id": "other",
        "material": "Dyneema SK99",
        "length_mm": 100.0,
        "diameter_mm": 2.0,
        "rate_mm_per_min": 6.0,
        "temperature_C": 30.0,
        "operator": "A. N. Other: shift 2",
    }
    cable = data.cable()
    np.testing.assert_allclose(float(cable.length), 0.1)
    np.testing.assert_allclose(float(cable.speed), 6e-3 / 60)
    with pytest.raises(ValueError, match=r"argument length_mm: must be positive"):
        jc.read_test(path, metadata={"length_mm": -1})


def test_testdata_mask_fields():
    assert jc.TestData.__test__ is False  # pytest must not collect it
    data = jc.TestData(time=[0.0, 1.0, 2.0], force=[0.0, 1.0, 2.0])
    np.testing.assert_array_equal(data.mask, [True, True, True])
    assert data.force_raw is None and data.slack_report is None
    masked = jc.TestData(time=[0.0, 1.0], force=[0.0, 1.0], mask=[1, 0])
    assert masked.mask.dtype == bool
    np.testing.assert_array_equal(masked.mask, [True, False])
    with pytest.raises(ValueError, match="mask"):
        jc.TestData(time=[0.0, 1.0], force=[0.0, 1.0], mask=[True])
    with pytest.raises(ValueError, match="differ in length"):
        jc.TestData(time=[0.0, 1.0], force=[0.0, 1.0], force_raw=[0.0])
