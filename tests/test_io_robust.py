"""The reader never drops or changes a row without saying so: typos in the first rows,
unit conversions, metadata, slow header cells, atomic writes, and a fuzz test over
generated malformed files (the generator of `scripts/fuzz_io.py`)."""

import importlib.util
import pathlib
import re
import time

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

import jaxcable as jc
from jaxcable.internal import io_csv as csv_module


def _error(path, line, column=None, **kwargs) -> str:
    """The one-line message of the ValueError `read_test(path, **kwargs)` raises,
    checked to name the file, the line and the column."""
    with pytest.raises(ValueError) as info:
        jc.read_test(path, **kwargs)
    message = str(info.value)
    assert str(path) in message and "\n" not in message, message
    if line is not None:
        assert re.search(rf"\bline {line}\b", message), message
    if column is not None:
        assert f"'{column}'" in message, message
    return message


def _write(tmp_path, text, name="t.csv", encoding="utf-8"):
    path = tmp_path / name
    path.write_bytes(text.encode(encoding) if isinstance(text, str) else text)
    return path


# ----------------------------------------------------------------------------------
# Rows under a header are data


@pytest.mark.parametrize(
    ("row", "column"),
    [
        ("0,0,N/A", "elongation_mm"),
        ("O.5,0,0", "time_s"),
        ("0,,0,0", None),  # a stray separator
        ("0", "force_N"),  # a one-cell row
        ("0,0,1_0", "elongation_mm"),  # float() would read 10
        ("End of test", None),
    ],
)
@pytest.mark.parametrize("place", ["first", "second", "last"])
def test_typo_under_canonical_header_is_an_error(tmp_path, row, column, place):
    good = ["1,0.5,0.1", "2,1.0,0.2", "3,1.5,0.3"]
    rows = {
        "first": [row, *good],
        "second": [good[0], row, *good[1:]],
        "last": [*good, row],
    }[place]
    line = 3 + rows.index(row)
    text = "# length_mm: 100\ntime_s,force_N,elongation_mm\n" + "\n".join(rows)
    path = _write(tmp_path, text + "\n")
    _error(path, line, column)


def test_typo_under_matched_header_and_units_row_is_an_error(tmp_path):
    text = "Test report\nTime,Load,Extension\n(s),(N),(mm)\n0,0,N/A\n1,1,1\n2,2,2\n"
    _error(_write(tmp_path, text), 4, "elongation_mm", metadata={"length_mm": 100})
    text = "Zeit (s);Kraft (N)\n\nO,5;0\n1;1\n2;2\n"
    _error(_write(tmp_path, text), 3, "time_s", metadata={"length_mm": 100})


def test_blank_comment_and_units_rows_under_the_header_are_not_data(tmp_path):
    text = "# length_mm: 100\ntime_s,force_N\n\n# zeroed\ns,N\n0,0\n1,1\n"
    data = jc.read_test(_write(tmp_path, text))
    np.testing.assert_array_equal(data.lines, [6, 7])
    np.testing.assert_array_equal(data.time, [0.0, 1.0])


def test_typo_above_first_row_without_header_is_an_error(tmp_path):
    kwargs = {"columns": "time_s,force_N,elongation_mm", "metadata": {"length_mm": 100}}
    for first, column in [
        ("0,0,N/A", "elongation_mm"),
        ("O.5,0,0", "time_s"),
        ("0,0,abc", "elongation_mm"),
        ("0.5", "force_N"),
        ("N/A,N/A,N/A", "time_s"),
        ("nan,-,n/a", "time_s"),
    ]:
        path = _write(tmp_path, f"Test report\n{first}\n\n1,1,1\n2,2,2\n")
        _error(path, 2, column, **kwargs)
    # Preamble (no digits, or words) above the data is still skipped.
    path = _write(tmp_path, "Test report\nSample VHB 4910\nt,F,x\n1,1,1\n2,2,2\n")
    np.testing.assert_array_equal(jc.read_test(path, **kwargs).lines, [4, 5])


# ----------------------------------------------------------------------------------
# Unit conversions and values out of range


def test_conversion_to_si_is_checked(tmp_path):
    head = "# length_mm: 100\n"
    path = _write(tmp_path, head + "time_h,force_N\n0,0\n1e306,1\n")
    assert "out of range" in _error(path, 4, "time_h")
    path = _write(tmp_path, head + "time_s,force_kN\n0,0\n1,1e306\n")
    assert "out of range" in _error(path, 4, "force_kN")
    # 1e-320 and 1.2e-320 ms differ, but are the same number of seconds.
    path = _write(tmp_path, head + "time_ms,force_N\n1e-320,0\n1.2e-320,1\n")
    message = _error(path, 4, "time_ms")
    assert "repeated time stamp after the conversion from time_ms" in message
    # Large but finite values read exactly.
    path = _write(tmp_path, head + "time_s,force_N\n0,-1e300\n1,1e300\n")
    data = jc.read_test(path, options=jc.ReadOptions(detect_slack=False))
    np.testing.assert_array_equal(data.force, [-1e300, 1e300])


# ----------------------------------------------------------------------------------
# Metadata


@pytest.mark.parametrize(
    ("line", "what"),
    [
        ("# breaking_load_N: abc", "'abc' is not a number"),
        ("# breaking_load_N: -5", "must be positive"),
        ("# rate_mm_per_min: inf", "not a finite number"),
        ("# temperature_C: -300", "must be above -273.15"),
        ("# diameter_mm: 5e-324", "too small"),
    ],
)
def test_metadata_validated_when_read(tmp_path, line, what):
    path = _write(tmp_path, f"# length_mm: 100\n{line}\ntime_s,force_N\n0,0\n1,1\n")
    for reader in (jc.read_test, jc.read_csv):
        with pytest.raises(ValueError) as info:
            reader(path)
        message = str(info.value)
        assert f"{path}, line 2, metadata '{line[2:].split(':')[0]}'" in message
        assert what in message, message


def test_breaking_load_read_as_number(tmp_path):
    text = "# length_mm: 100\n# breaking_load_N: 2500\ntime_s,force_N\n0,0\n1,1\n"
    data = jc.read_test(_write(tmp_path, text))
    assert data.metadata["breaking_load_N"] == 2500.0
    assert float(data.cable().breaking_load) == 2500.0
    # A TestData built in code with bad metadata says which key, and where from.
    bad = jc.TestData(
        time=[0.0, 1.0],
        force=[0.0, 1.0],
        metadata={"length_mm": 100, "breaking_load_N": "abc"},
        source="made.csv",
    )
    with pytest.raises(ValueError, match="made.csv, metadata 'breaking_load_N'"):
        bad.cable()


# ----------------------------------------------------------------------------------
# Header cells and long cells


@pytest.mark.parametrize("spaces", [1_500, 20_000])
def test_header_cell_with_an_open_bracket_is_read_fast(tmp_path, spaces):
    # The split of `Name (unit)` backtracked in cubic time on such a cell (20 s for
    # 1,500 spaces).
    cell = "Remark (" + " " * spaces + "x"
    for header in (f"Time (s),Force (N),{cell}", f"Time (s),{cell},Force (N)"):
        path = _write(tmp_path, f"{header}\n0,0,1\n1,1,2\n")
        start = time.perf_counter()
        try:
            jc.read_test(path, metadata={"length_mm": 100})
        except ValueError as e:
            assert str(path) in str(e)
        assert time.perf_counter() - start < 1.0


def test_quoted_cell_over_csv_limit(tmp_path):
    remark = "x" * 200_000
    text = f'0,0,"{remark}"\n1,1,"ok, fine"\n'
    path = _write(tmp_path, text)
    data = jc.read_test(path, columns="time_s,force_N,-", metadata={"length_mm": 100})
    np.testing.assert_array_equal(data.force, [0.0, 1.0])
    path = _write(tmp_path, f'time_s,force_N\n0,"{"1" * 200_000}"\n1,1\n')
    assert "not a finite number" in _error(
        path, 2, "force_N", metadata={"length_mm": 100}
    )


def test_stray_byte_of_another_encoding_is_reported_on_its_line(tmp_path):
    # A GBK header over a row with a byte no encoding of the file decodes: the
    # header still reads (line by line), and the row is an error.
    text = "时间,力,位移\n(s),(N),(mm)\n0,0,0\n1,1,1\n".encode("gbk")
    text = text.replace(b"1,1,1", b"1,1\xb5\xff,1")
    _error(_write(tmp_path, text), 4, "force_N", metadata={"length_mm": 100})


# ----------------------------------------------------------------------------------
# Atomic write


def test_write_csv_is_atomic(tmp_path, monkeypatch):
    data = jc.TestData(time=[0.0, 1.0], force=[0.0, 2.0], metadata={"length_mm": 100})
    path = tmp_path / "out.csv"
    path.write_text("old content\n")
    jc.write_csv(path, data)
    np.testing.assert_array_equal(jc.read_csv(path).force, data.force)
    assert [p.name for p in tmp_path.iterdir()] == ["out.csv"]
    before = path.read_bytes()

    def failing_open(file, *args, **kwargs):
        f = open(file, *args, **kwargs)  # noqa: SIM115 (closed below)
        f.write("time_s,for")
        f.close()
        raise OSError("disk full")

    monkeypatch.setattr(csv_module, "open", failing_open, raising=False)
    with pytest.raises(OSError, match="disk full"):
        jc.write_csv(path, data)
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["out.csv"]


# ----------------------------------------------------------------------------------
# Fuzz: generated malformed files


def _fuzz_module():
    path = pathlib.Path(__file__).resolve().parent.parent / "scripts" / "fuzz_io.py"
    spec = importlib.util.spec_from_file_location("fuzz_io", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


FUZZ = _fuzz_module()


@settings(
    deadline=None,
    max_examples=300,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
@given(rng=st.randoms(use_true_random=False))
def test_fuzz_read_test(tmp_path, rng):
    # read_test returns exactly the file's data rows (none dropped, added or
    # changed) or raises a ValueError naming the file; never another exception,
    # never more than 2 s.
    case = FUZZ.make_case(rng)
    path = tmp_path / "fuzz.csv"
    path.write_bytes(case.text)
    outcome, seconds, detail = FUZZ.check(case, path, jc.read_test)
    assert outcome not in ("silently_wrong", "crash"), (case.what, detail)
    assert seconds < 2.0, case.what
