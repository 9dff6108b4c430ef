"""Raw tensile-tester exports: `jaxcable.read_test` and slack detection.

Synthetic files are written to tmp_path; the real VHB 4910 exports are read from
../shared/data and never copied here.
"""

import re

import numpy as np
import pytest

import jaxcable as jc


VHB_COLUMNS = "time_s,elongation_mm,force_N"


def _vhb_like_rows():
    """A VHB-like load-unload cycle at 4 mm/s to 20 mm, 10 Hz: taut loading, taut
    unloading down to a residual 5 mm, then slack (force -0.01 N) back to 0 mm."""
    t = np.round(np.arange(101) * 0.1, 10)
    x = np.where(t <= 5, 4 * t, 40 - 4 * t)
    loading = 0.1 * x
    unloading = np.where(x >= 5, 0.1 * (x - 5) * 4 / 3, -0.01)
    f = np.where(t <= 5, loading, unloading)
    return t, x, f


def _write_vhb_like(path, rows=None, encoding="gbk"):
    """The VHB export format: blank first line, GBK header, units row, quoted
    numbers, CRLF."""
    t, x, f = _vhb_like_rows() if rows is None else rows
    body = "".join(f'"{a:.4f}","{b:.4f}","{c:.4f}"\r\n' for a, b, c in zip(t, x, f))
    text = "\r\n时间,位移,力\r\n(s),(mm),(N)\r\n" + body + "\r\n"
    path.write_bytes(text.encode(encoding))
    return path


def _error(path, line, column, **kwargs) -> str:
    """The message of the ValueError `read_test(path, **kwargs)` raises, checked to
    name the file, the line and the column on one line."""
    with pytest.raises(ValueError) as info:
        jc.read_test(path, **kwargs)
    message = str(info.value)
    assert str(path) in message, message
    if line is not None:
        assert re.search(rf"\bline {line}\b", message), message
    if column is not None:
        assert f"'{column}'" in message, message
    assert "\n" not in message
    return message


# ----------------------------------------------------------------------------------
# Formats


def test_vhb_like_export_with_columns(tmp_path):
    path = _write_vhb_like(tmp_path / "vhb.csv")
    data = jc.read_test(path, columns=VHB_COLUMNS, metadata={"length_mm": 80})
    t, x, f = _vhb_like_rows()
    np.testing.assert_allclose(data.time, t, atol=1e-12)
    np.testing.assert_allclose(data.elongation, np.round(x, 4) * 1e-3, atol=1e-15)
    np.testing.assert_allclose(data.force_raw, np.round(f, 4), atol=1e-12)
    # Line 1 blank, 2 header, 3 units: the first sample is line 4.
    np.testing.assert_array_equal(data.lines, np.arange(4, 4 + t.size))
    assert data.metadata == {"length_mm": 80.0}
    assert data.source == str(path)


def test_vhb_like_export_best_effort_header(tmp_path):
    # 时间 (time), 位移 (displacement), 力 (force) over the units row (s),(mm),(N).
    path = _write_vhb_like(tmp_path / "vhb.csv")
    by_header = jc.read_test(path, metadata={"length_mm": 80})
    by_columns = jc.read_test(path, columns=VHB_COLUMNS, metadata={"length_mm": 80})
    for name in ("time", "force", "elongation", "lines", "mask"):
        np.testing.assert_array_equal(
            getattr(by_header, name), getattr(by_columns, name)
        )


@pytest.mark.parametrize("encoding", ["utf-8", "utf-8-sig", "gb18030", "latin-1"])
def test_header_encodings(tmp_path, encoding):
    header = "Zeit (s);Kraft (kN);Weg (mm);Bemerkung (äöü)"
    text = f"{header}\n0;0;0;1\n1;0,5;2,5;2\n"
    path = tmp_path / "de.csv"
    path.write_bytes(text.encode(encoding))
    data = jc.read_test(path, metadata={"length_mm": 300})
    np.testing.assert_allclose(data.time, [0.0, 1.0])
    np.testing.assert_allclose(data.force, [0.0, 500.0])  # kN, decimal comma
    np.testing.assert_allclose(data.elongation, [0.0, 2.5e-3])
    assert data.extra == {}  # the unmatched column is ignored


def test_gbk_header_never_crashes_utf8_reading(tmp_path):
    # A GBK header read as UTF-8 fails; given explicitly, that is an error with the
    # line, and without it the encoding is detected.
    path = _write_vhb_like(tmp_path / "vhb.csv")
    message = _error(
        path,
        2,
        None,
        columns=VHB_COLUMNS,
        metadata={"length_mm": 80},
        options=jc.ReadOptions(encoding="utf-8"),
    )
    assert "utf-8" in message
    assert (
        jc.read_test(path, columns=VHB_COLUMNS, metadata={"length_mm": 80}).num_samples
        == 101
    )


@pytest.mark.parametrize(
    ("sep", "decimal"),
    [(",", "."), (";", "."), (";", ","), ("\t", "."), ("\t", ",")],
    ids=["comma", "semicolon", "semicolon-decimal-comma", "tab", "tab-decimal-comma"],
)
def test_separators(tmp_path, sep, decimal):
    rows = [(0, 0, 0), (0.5, 1.25, 0.1), (1.0, 2.5, 0.2)]
    lines = ["# length_mm: 250", sep.join(["time_s", "force_N", "elongation_mm"])]
    lines += [sep.join(str(v).replace(".", decimal) for v in row) for row in rows]
    path = tmp_path / "sep.csv"
    path.write_text("\r\n".join(lines) + "\r\n", encoding="utf-8")
    data = jc.read_test(path)
    np.testing.assert_allclose(data.time, [0.0, 0.5, 1.0])
    np.testing.assert_allclose(data.force, [0.0, 1.25, 2.5])
    np.testing.assert_allclose(data.elongation, [0.0, 0.1e-3, 0.2e-3])
    assert data.metadata == {"length_mm": 250.0}
    assert jc.read_test(path, options=jc.ReadOptions(delimiter=sep)).num_samples == 3


def test_columns_with_ignored_columns_and_units(tmp_path):
    text = (
        "idx,t,state,F,dl,T\n"
        '1,0,"OK, settled",0,0,20.5\n'
        "2,0.5,OK,0.1,0.001,20.6\n"
        "3,1.0,ok,0.2,0.002,20.7,\n"  # a trailing separator
    )
    path = tmp_path / "raw.csv"
    path.write_text(text, encoding="utf-8")
    data = jc.read_test(
        path,
        columns="-,time_min,-,force_kN,elongation_m,temperature_C",
        metadata={"length_mm": 300},
    )
    np.testing.assert_allclose(data.time, [0.0, 30.0, 60.0])
    np.testing.assert_allclose(data.force, [0.0, 100.0, 200.0])
    np.testing.assert_allclose(data.elongation, [0.0, 0.001, 0.002])
    np.testing.assert_allclose(data.temperature, [20.5, 20.6, 20.7])
    np.testing.assert_array_equal(data.lines, [2, 3, 4])
    assert data.extra == {}
    # A sequence of names works as well as a string.
    same = jc.read_test(
        path,
        columns=["-", "time_min", "-", "force_kN", "elongation_m", "-"],
        metadata={"length_mm": 1},
    )
    np.testing.assert_array_equal(same.force, data.force)


@pytest.mark.parametrize(
    ("token", "to_s"),
    [("time_s", 1.0), ("time_ms", 1e-3), ("time_min", 60.0), ("time_h", 3600.0)],
)
def test_time_units(tmp_path, token, to_s):
    path = tmp_path / "t.csv"
    path.write_text("0,0\n2,1\n4,2\n", encoding="utf-8")
    data = jc.read_test(path, columns=f"{token},force_N", metadata={"length_mm": 100})
    np.testing.assert_allclose(data.time, np.array([0, 2, 4]) * to_s)


PREAMBLE = (
    "Test report\n"
    "Operator: A. N. Other\n"
    "\n"
    "Sample;VHB 4910\n"
    "Time (s);Standard force (N);Crosshead (mm)\n"
    "0;0;0\n"
    "1;0.5;1\n"
    "2;1.0;2\n"
)


def test_skip_rows_detected_and_given(tmp_path):
    path = tmp_path / "preamble.csv"
    path.write_text(PREAMBLE, encoding="utf-8")
    detected = jc.read_test(path, metadata={"length_mm": 100})
    np.testing.assert_array_equal(detected.lines, [6, 7, 8])
    np.testing.assert_allclose(detected.force, [0.0, 0.5, 1.0])
    np.testing.assert_allclose(detected.elongation, [0.0, 1e-3, 2e-3])
    given = jc.read_test(
        path, metadata={"length_mm": 100}, options=jc.ReadOptions(skip_rows=5)
    )
    np.testing.assert_array_equal(given.lines, detected.lines)
    np.testing.assert_array_equal(given.force, detected.force)
    spec = jc.read_test(
        path,
        columns="time_s,force_N,elongation_mm",
        metadata={"length_mm": 100},
        options=jc.ReadOptions(skip_rows=5),
    )
    np.testing.assert_array_equal(spec.elongation, detected.elongation)
    # One row too few skipped: the header is read as data, and that is said where.
    _error(
        path,
        5,
        "time_s",
        columns="time_s,force_N,-",
        metadata={"length_mm": 1},
        options=jc.ReadOptions(skip_rows=4),
    )
    _error(
        path,
        None,
        None,
        metadata={"length_mm": 1},
        options=jc.ReadOptions(skip_rows=99),
    )


def test_units_row_under_plain_header(tmp_path):
    path = tmp_path / "units.csv"
    path.write_text("Time,Load,Extension\ns,kN,mm\n0,0,0\n1,0.002,0.5\n")
    data = jc.read_test(path, metadata={"length_mm": 100})
    np.testing.assert_allclose(data.force, [0.0, 2.0])
    np.testing.assert_allclose(data.elongation, [0.0, 0.5e-3])


# ----------------------------------------------------------------------------------
# Bad input: file, line and column in one line


def test_unknown_header_asks_for_columns(tmp_path):
    path = tmp_path / "anon.csv"
    path.write_text("a,b,c\n0,0,0\n1,1,1\n")
    message = _error(path, 1, None, metadata={"length_mm": 1})
    assert "--columns" in message and "time_s,elongation_mm,force_N" in message
    # A header with a time but no force column says so.
    path.write_bytes("\r\n时间,位移\r\n(s),(mm)\r\n0,0\r\n1,1\r\n".encode("gbk"))
    message = _error(path, 2, None, metadata={"length_mm": 1})
    assert "no force column" in message and "--columns" in message
    # No header at all.
    path.write_text("0,0\n1,1\n")
    assert "--columns" in _error(path, 1, None, metadata={"length_mm": 1})


def _vhb_with(tmp_path, line_index, cells):
    """The VHB-like file with data row `line_index` (0-based) replaced."""
    t, x, f = _vhb_like_rows()
    path = _write_vhb_like(tmp_path / "bad.csv")
    lines = path.read_bytes().split(b"\r\n")
    lines[3 + line_index] = ",".join(f'"{c}"' for c in cells).encode()
    path.write_bytes(b"\r\n".join(lines))
    return path


@pytest.mark.parametrize(
    ("cells", "column", "what"),
    [
        (["0.5000", "abc", "0.2"], "2 'elongation_mm'", "'abc' is not a number"),
        (["0.5000", "2.0000", "NaN"], "3 'force_N'", "not a finite number"),
        (["0.5000", "2.0000", ""], "3 'force_N'", "empty cell"),
        (["0.5000", "2.0000"], "3 'force_N'", "missing cell"),
        (["0.4000", "2.0000", "0.2"], "1 'time_s'", "a repeated time stamp"),
        (["0.3000", "2.0000", "0.2"], "1 'time_s'", "time goes back"),
    ],
    ids=["non-numeric", "nan", "empty", "missing-cell", "repeated-time", "time-back"],
)
def test_bad_cells_name_file_line_column(tmp_path, cells, column, what):
    # Row 5 (line 9) follows t = 0.4 at line 8.
    path = _vhb_with(tmp_path, 5, cells)
    message = _error(path, 9, None, columns=VHB_COLUMNS, metadata={"length_mm": 80})
    assert f"column {column}" in message and what in message, message


def test_other_bad_inputs(tmp_path):
    path = _write_vhb_like(tmp_path / "vhb.csv")
    message = _error(
        path, None, None, columns="time_s,elongation_mm", metadata={"length_mm": 80}
    )
    assert "no force column" in message
    message = _error(
        path, None, None, columns="time_s,stretch,force_N", metadata={"length_mm": 80}
    )
    assert "'stretch' is not a column name" in message and "time_min" in message
    message = _error(
        path, None, None, columns="time_s,force_kN,force_N", metadata={"length_mm": 80}
    )
    assert "second force column" in message
    message = _error(
        path, 4, None, columns="time_s,force_N", metadata={"length_mm": 80}
    )
    assert "3 cells but columns names 2 columns" in message
    message = _error(path, None, "length_mm", columns=VHB_COLUMNS)
    assert "--length-mm" in message
    _error(path, None, None, columns=VHB_COLUMNS, metadata={"length_mm": 0})


# ----------------------------------------------------------------------------------
# Slack


def test_slack_end_of_unloading_is_masked_and_clipped(tmp_path):
    path = _write_vhb_like(tmp_path / "vhb.csv")
    data = jc.read_test(path, columns=VHB_COLUMNS, metadata={"length_mm": 80})
    report = data.slack_report
    # Threshold: 0.5 % of the 2 N peak (the synthetic force has no noise).
    assert report.threshold == pytest.approx(0.01)
    assert report.noise == pytest.approx(0.0, abs=1e-9)
    assert len(report.stretches) == 1
    (stretch,) = report.stretches
    # x < 5 mm from t = 8.8 s (sample 88, line 92) to the end (t = 10 s, line 104).
    assert (stretch.start, stretch.stop) == (88, 101)
    assert stretch.lines == (92, 104)
    assert stretch.time == pytest.approx((8.8, 10.0))
    assert stretch.elongation == pytest.approx((4.8e-3, 0.0))
    assert stretch.min_force == pytest.approx(-0.01)
    expected = np.ones(101, dtype=bool)
    expected[88:] = False
    np.testing.assert_array_equal(data.mask, expected)
    assert report.masked == 13 and report.clipped == 13 and report.negative == 0
    # The fitted force is clipped to 0; the measured force is kept.
    assert np.all(data.force >= 0)
    np.testing.assert_array_equal(data.force[88:], 0.0)
    np.testing.assert_allclose(data.force_raw[88:], -0.01)
    np.testing.assert_array_equal(data.force[:88], data.force_raw[:88])
    text = str(report)
    assert "1 slack stretch: lines 92-104" in text and "13 samples masked" in text
    # Detection off: the file as it is.
    raw = jc.read_test(
        path,
        columns=VHB_COLUMNS,
        metadata={"length_mm": 80},
        options=jc.ReadOptions(detect_slack=False),
    )
    assert raw.mask.all() and raw.slack_report is None and raw.force_raw is None
    np.testing.assert_array_equal(raw.force, data.force_raw)
    # mask_slack on it (or again on its result) gives the same.
    for source in (raw, data):
        again = jc.mask_slack(source)
        np.testing.assert_array_equal(again.mask, data.mask)
        np.testing.assert_array_equal(again.force, data.force)
        np.testing.assert_array_equal(again.force_raw, data.force_raw)


def test_slack_start_and_threshold_override():
    # Crosshead at 1 mm/s: 3 mm of slack (force noise about 0), then taut.
    t = np.arange(200) * 0.1
    x = t * 1e-3
    noise = 0.002 * np.random.default_rng(0).standard_normal(t.size)
    f = np.where(x < 3e-3, 0.0, 50.0 * (x - 3e-3) / 17e-3) + noise
    data = jc.mask_slack(jc.TestData(time=t, force=f, elongation=x))
    (stretch,) = data.slack_report.stretches
    assert stretch.start == 0 and stretch.lines is None
    assert 29 <= stretch.stop <= 32  # 3 mm at 0.1 mm per sample
    assert not data.mask[: stretch.stop].any() and data.mask[stretch.stop :].all()
    assert data.slack_report.speed == pytest.approx(1e-3)
    # The rule's threshold: 0.5 % of the peak force, above 3 x the noise here.
    assert data.slack_report.threshold == pytest.approx(0.005 * f.max())
    assert data.slack_report.noise == pytest.approx(0.002, rel=0.3)
    # A threshold above every force masks the moving test entirely.
    everything = jc.mask_slack(
        jc.TestData(time=t, force=f, elongation=x), threshold_N=100
    )
    assert not everything.mask.any()


def test_not_slack_valleys_rests_and_noise():
    # Taut cycles through zero force and a rest at zero force where the elongation
    # recovers slowly: to be fitted, nothing masked. Crosshead 3 mm/min.
    ramp = np.linspace(0.0, 100.0, 201)
    f_cycles = np.concatenate([ramp, ramp[-2::-1], ramp[1:], ramp[-2::-1]])
    e_cycles = 2e-3 * f_cycles / 100 + 1e-4 * np.arange(f_cycles.size) / f_cycles.size
    t_cycles = np.concatenate([[0.0], np.cumsum(np.abs(np.diff(e_cycles)) / 5e-5)])
    t_rest = t_cycles[-1] + np.geomspace(10, 86400, 24)
    e_rest = e_cycles[-1] * (0.5 + 0.5 * np.exp(-(t_rest - t_cycles[-1]) / 3600))
    data = jc.TestData(
        time=np.concatenate([t_cycles, t_rest]),
        force=np.concatenate([f_cycles, np.zeros(24)]),
        elongation=np.concatenate([e_cycles, e_rest]),
        metadata={"length_mm": 300.0, "rate_mm_per_min": 3.0},
    )
    result = jc.mask_slack(data)
    assert result.slack_report.stretches == () and result.mask.all()
    assert result.slack_report.speed == pytest.approx(5e-5)
    # Without the metadata the speed is estimated, with the same result.
    data.metadata.pop("rate_mm_per_min")
    assert jc.mask_slack(data).mask.all()

    # A lone reading below minus the threshold (a cable cannot push) is masked too;
    # a small negative reading inside the noise is only clipped.
    f = np.concatenate([ramp, ramp[-2::-1]])
    f[100] = -5.0
    f[-1] = -0.1
    e = 1e-5 * np.abs(f)
    result = jc.mask_slack(jc.TestData(time=np.arange(f.size), force=f, elongation=e))
    assert result.slack_report.negative == 1 and result.slack_report.clipped == 2
    assert np.flatnonzero(~result.mask).tolist() == [100]
    assert result.force[100] == 0 and result.force[-1] == 0


def test_force_without_elongation_only_masks_negative_readings():
    f = np.array([0.0, 10.0, -3.0, 10.0, -0.01, 0.0])
    data = jc.mask_slack(jc.TestData(time=np.arange(6.0), force=f))
    assert np.flatnonzero(~data.mask).tolist() == [2]
    assert data.slack_report.speed is None and data.slack_report.clipped == 2


# ----------------------------------------------------------------------------------
# The real exports (../shared/data/vhb4910), never copied into the repository

# Peak displacement, mm, from the file name's stretch: (stretch - 1) x 80 mm. One
# file's name is wrong: 0d05_2d5_2 peaks at 80 mm (stretch 2.0), not 120.
_PEAK_MISNAMED = {"0d05_2d5_2.csv": 80.0}


def _stretch(stem: str) -> float:
    """The peak stretch of a file name: RATE_STRETCH[_k] or STRETCH, `1d5` = 1.5."""
    parts = stem.split("_")
    return float((parts[1] if len(parts) > 1 else parts[0]).replace("d", "."))


def _data_lines(path) -> int:
    """Rows of numbers, counted independently of the loader."""
    return sum(
        1
        for line in path.read_bytes().splitlines()
        if line and line[:1] in b'"0123456789'
    )


def test_vhb4910_loading_unloading(shared_data):
    files = sorted((shared_data / "vhb4910" / "loading-unloading").glob("*.csv"))
    assert len(files) == 16
    for path in files:
        data = jc.read_test(path, columns=VHB_COLUMNS, metadata={"length_mm": 80})
        n = data.num_samples
        assert n == _data_lines(path) and n > 1000, path.name
        for name in ("time", "force", "elongation", "mask", "lines", "force_raw"):
            assert getattr(data, name).shape == (n,), (path.name, name)
        assert np.all(np.diff(data.time) > 0)
        assert data.elongation.min() > -0.01e-3
        peak = _PEAK_MISNAMED.get(path.name, (_stretch(path.stem) - 1) * 80)
        assert data.elongation.max() * 1e3 == pytest.approx(peak, abs=0.5), path.name
        # One slack stretch: the end of unloading, the force below the threshold
        # (and partly negative) while the crosshead returns the last 10-35 % of
        # the way to 0.
        report = data.slack_report
        assert len(report.stretches) == 1, (path.name, str(report))
        (stretch,) = report.stretches
        assert stretch.stop == n
        top = int(np.argmax(data.elongation))
        assert stretch.start > top
        assert 0.1 < stretch.elongation[0] / data.elongation.max() < 0.35, path.name
        assert stretch.elongation[1] < 0.01e-3
        assert stretch.min_force < 0
        assert np.all(data.force_raw[stretch.start :] < report.threshold)
        assert report.masked == stretch.num_samples and report.negative == 0
        assert not data.mask[stretch.start :].any() and data.mask[: stretch.start].all()
        assert np.all(data.force >= 0)
        assert report.threshold == pytest.approx(0.005 * data.force.max(), rel=0.3)


def test_vhb4910_relaxation(shared_data):
    files = sorted((shared_data / "vhb4910" / "relaxation").glob("*.csv"))
    assert len(files) == 8
    for path in files:
        data = jc.read_test(path, columns=VHB_COLUMNS, metadata={"length_mm": 80})
        n = data.num_samples
        assert n == _data_lines(path) and n > 30000, path.name
        assert data.time.shape == data.elongation.shape == data.mask.shape == (n,)
        assert np.all(np.diff(data.time) > 0) and data.time[-1] > 1800
        # Held at (stretch - 1) x 80 mm after a small overshoot; never slack.
        hold = (_stretch(path.stem) - 1) * 80
        assert data.elongation[-1] * 1e3 == pytest.approx(hold, abs=0.01)
        assert data.slack_report.stretches == () and data.mask.all(), path.name
        assert np.all(data.force >= 0)


@pytest.mark.parametrize(
    "name",
    ["loading-unloading/0d05_1d5_1.csv", "relaxation/3d0.csv"],
    ids=["gbk-quoted", "utf8-plain"],
)
def test_vhb4910_header_read_without_columns(shared_data, name):
    # The GBK header 时间,位移,力 (time, displacement, force) over (s),(mm),(N) is
    # matched without `columns`; relaxation/3d0 is UTF-8, unquoted, 20 Hz.
    path = shared_data / "vhb4910" / name
    by_header = jc.read_test(path, metadata={"length_mm": 80})
    by_columns = jc.read_test(path, columns=VHB_COLUMNS, metadata={"length_mm": 80})
    for field in ("time", "force", "elongation", "mask"):
        np.testing.assert_array_equal(
            getattr(by_header, field), getattr(by_columns, field)
        )
