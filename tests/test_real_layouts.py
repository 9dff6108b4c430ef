"""The layouts of the real records in `tests/data/real/` that the readers learnt from
(reading only, no fits): a load cell that reads tension as negative (sign flipped),
one not zeroed before the test (tared), a fatigue record timed by its cycle count
and logged in bursts (one sample per burst, t = N / f), a header found by its names
above a data row that carries a label, a stretch ratio and a stress in kPa; and
each rule not applied where it must not be: a compression test, a preloaded creep
test, a creep record at its mean load, a zeroed load cell; an Anton Paar RheoCompass
export (UTF-16, tabs, decimal commas, a status text column)."""

import csv
import json
import math
import pathlib

import numpy as np
import pytest

import jaxcable as jc
from jaxcable.internal import cli_data, cli_parser


DATA = pathlib.Path(__file__).parent / "data"
REAL = DATA / "real"
WAVEMATRIX = REAL / "instron_data_processing"
CCF = REAL / "CCFatiguePlatform"
LIU = CCF / "Liu_2020-09_FA_measure_010.csv"
LIU_COLUMNS = (
    "Machine_N_cycles=cycles,Machine_Displacement=elongation_mm,Machine_Load=force_kN"
)
AUTO = dict(force_sign="auto", tare=True)  # the default
# As written: no correction of the load cell.
RAW = dict(force_sign=1, tare=False)


def _columns(path, *names, encoding="utf-8-sig"):
    """The named columns of a CSV file with a header line, by the csv module (empty
    cells as NaN)."""
    with open(path, encoding=encoding, newline="") as f:
        rows = list(csv.reader(f))
    header = rows[0]
    return [
        np.array([float(r[header.index(n)] or "nan") for r in rows[1:] if r])
        for n in names
    ]


def _wavematrix(name, length_mm):
    path = WAVEMATRIX / name
    raw = jc.read_test(
        path,
        metadata={"length_mm": length_mm},
        options=jc.ReadOptions(detect_slack=False, **RAW),
    )
    auto = jc.read_test(
        path,
        metadata={"length_mm": length_mm},
        options=jc.ReadOptions(detect_slack=False, **AUTO),
    )
    return path, raw, auto


def test_wavematrix_tension_read_negative_is_flipped():
    """Silicone: 98 % of the readings below zero, growing in magnitude with the
    position: read flipped; its 18 N at rest is a load (the cell reads zero when
    the strip is slack), kept."""
    path, raw, auto = _wavematrix("silicone_10a_Test7.steps.tracking.csv", 57)
    (force_kN,) = _columns(path, "Force (kN)")
    np.testing.assert_allclose(raw.force, 1e3 * force_kN, rtol=1e-12)
    np.testing.assert_allclose(auto.force, -1e3 * force_kN, rtol=1e-12)
    assert any("sign flipped" in note for note in auto.notes)
    assert any("is kept" in note and "zeroed" in note for note in auto.notes)
    assert not any("tared" in note for note in auto.notes)
    # As the command line reads it: the tension is fitted, not masked as slack.
    masked = jc.read_test(
        path, metadata={"length_mm": 57}, options=jc.ReadOptions(**AUTO)
    )
    assert np.mean(masked.mask) > 0.9 and np.max(masked.force) > 40.0


def test_wavematrix_offset_at_rest_is_tared():
    """Latex glove: flipped, then its 18.8 N at rest, which the test loads above and
    unloads below without the cell ever reading zero, removed."""
    path, raw, auto = _wavematrix("latex_glove_Test6.steps.tracking.csv", 79)
    (force_kN,) = _columns(path, "Force (kN)")
    # A constant removed from the flipped force: the reading at rest (the first
    # ten samples, before the position moves), within its noise.
    shift = -1e3 * force_kN - auto.force
    assert np.ptp(shift) < 1e-9
    rest = shift[0]
    assert rest == pytest.approx(-1e3 * np.median(force_kN[:10]), abs=0.1)
    assert 18.0 < rest < 19.5
    (note,) = [n for n in auto.notes if "tared" in n]
    assert f"{-rest:+.4g} N" in note and "--no-tare" in note
    untared = jc.read_test(
        path,
        metadata={"length_mm": 79},
        options=jc.ReadOptions(detect_slack=False, tare=False, force_sign="auto"),
    )
    np.testing.assert_allclose(untared.force, -1e3 * force_kN, rtol=1e-12)
    # Without the corrections the command line masked every sample.
    assert not np.any(
        jc.read_test(
            path, metadata={"length_mm": 79}, options=jc.ReadOptions(**RAW)
        ).mask
    )
    assert np.mean(jc.read_test(path, metadata={"length_mm": 79}).mask) > 0.3


def test_compression_test_is_read_as_written():
    """Force and elongation both going negative (a lattice crushed): no flip, no
    tare, no note about the load cell."""
    path = DATA / "exports" / "bluer" / "vero_clear_ccyclic_Specimen_RawData_6.csv"
    raw = jc.read_test(
        path,
        metadata={"length_mm": 20},
        options=jc.ReadOptions(detect_slack=False, **RAW),
    )
    auto = jc.read_test(
        path,
        metadata={"length_mm": 20},
        options=jc.ReadOptions(detect_slack=False, **AUTO),
    )
    assert np.mean(raw.force < 0) > 0.9
    np.testing.assert_array_equal(auto.force, raw.force)
    assert auto.notes == raw.notes


def _history(path, t, f, e):
    lines = ["# length_mm: 100", "time_s,force_N,elongation_mm"]
    lines += [f"{a:.17g},{b:.17g},{c:.17g}" for a, b, c in zip(t, f, e)]
    path.write_text("\n".join(lines) + "\n")
    return path


def _creep(preload, unload_to, offset=0.0, seed=0):
    """A creep test: a rest at `preload` N (elongation still), a step to 100 N held
    with creep, an unloading to `unload_to` N; forces plus `offset`, noise 0.02 N."""
    t = np.arange(0.0, 60.0, 0.5)
    f = np.where(t < 5, preload, np.where(t < 40, 100.0, unload_to))
    e = np.where(t < 5, 0.0, 1.0 + 0.01 * np.sqrt(np.maximum(t - 5, 0)))
    e = np.where(t < 40, e, 0.3)
    noise = np.random.default_rng(seed).normal(0.0, 0.02, t.size)
    return t, f + offset + noise, e


@pytest.mark.parametrize("unload_to", [10.0, 0.0, 5.0])
def test_preload_is_never_tared(tmp_path, unload_to):
    """A rest at a 10 N preload is kept, whether the test comes back to it, goes
    to zero, or recovers at 5 N (at a larger elongation than at rest)."""
    t, f, e = _creep(10.0, unload_to)
    path = _history(tmp_path / "creep.csv", t, f, e)
    data = jc.read_test(path, options=jc.ReadOptions(detect_slack=False, **AUTO))
    written = jc.read_test(path, options=jc.ReadOptions(detect_slack=False))
    np.testing.assert_array_equal(data.force, written.force)
    (note,) = data.notes
    assert "is kept as a load the test starts with" in note


def test_offsets_are_tared(tmp_path):
    """A cell that reads -5 N at rest (a cable at rest cannot push) and one that
    reads 20 N at rest, then 16-30 N in cycles back to the rest elongation (the
    latex glove's pattern): both tared by their rest reading."""
    t, f, e = _creep(0.0, 0.0, offset=-5.0)
    path = _history(tmp_path / "negative.csv", t, f, e)
    data = jc.read_test(path, options=jc.ReadOptions(detect_slack=False, **AUTO))
    np.testing.assert_allclose(data.force, f + 5.0, atol=0.05)
    assert "tared" in data.notes[0] and "cannot push" in data.notes[0]
    t = np.arange(0.0, 40.0, 0.25)
    e = np.where(t < 5, 0.0, 0.5 - 0.5 * np.cos(2 * np.pi * (t - 5) / 5))
    noise = np.random.default_rng(1).normal(0.0, 0.02, t.size)
    # The first loading from the rest reading, the later cycles 4 N lower.
    f = np.where(t < 7.5, 20.0 + 14.0 * e, 16.0 + 14.0 * e) + noise
    path = _history(tmp_path / "positive.csv", t, f, e)
    data = jc.read_test(path, options=jc.ReadOptions(detect_slack=False, **AUTO))
    offset = np.median(f[t < 5])
    np.testing.assert_allclose(data.force, f - offset, atol=1e-12)
    assert "tared" in data.notes[0] and "rest elongation" in data.notes[0]


def test_zeroed_load_cell_is_left_alone(tmp_path):
    t, f, e = _creep(0.0, 0.0)
    path = _history(tmp_path / "zeroed.csv", t, f, e)
    data = jc.read_test(path, options=jc.ReadOptions(detect_slack=False, **AUTO))
    np.testing.assert_array_equal(data.force, f)
    assert data.notes == ()


def test_fatigue_header_is_line_one():
    """Without columns, the error names line 1 (the header), not the first data row,
    which carries the specimen's name; its columns without units are listed."""
    with pytest.raises(ValueError) as error:
        jc.read_test(LIU, metadata={"length_mm": 64})
    message = str(error.value)
    assert f"{LIU}, line 1:" in message
    assert "'Machine_Load' (force, no unit)" in message


def test_fatigue_time_from_cycles():
    """Named by their header names with a cycle count and 4.2 Hz: one sample per
    burst (a run of one count), its mean force and elongation, at t = N / f; the
    first data row (with the specimen's name) read."""
    data = jc.read_test(
        LIU,
        columns=LIU_COLUMNS,
        metadata={"length_mm": 64},
        options=jc.ReadOptions(frequency_hz=4.2, detect_slack=False, **RAW),
    )
    n, disp, load = _columns(
        LIU, "Machine_N_cycles", "Machine_Displacement", "Machine_Load"
    )
    counts, first = np.unique(n, return_index=True)
    assert data.num_samples == counts.size and data.num_samples < n.size / 10
    np.testing.assert_allclose(data.time, counts / 4.2, rtol=1e-12)
    sizes = np.diff(np.append(first, n.size))
    np.testing.assert_allclose(
        data.force, 1e3 * np.add.reduceat(load, first) / sizes, rtol=1e-9
    )
    np.testing.assert_allclose(
        data.elongation, 1e-3 * np.add.reduceat(disp, first) / sizes, rtol=1e-9
    )
    assert data.lines[0] == 2
    (note,) = data.notes
    assert "4.2 Hz" in note and "bursts" in note and "cyclic part" in note
    # The mean load is held (a creep record): never tared.
    assert jc.read_test(
        LIU,
        columns=LIU_COLUMNS,
        metadata={"length_mm": 64},
        options=jc.ReadOptions(frequency_hz=4.2, **AUTO),
    ).force == pytest.approx(data.force)
    with pytest.raises(ValueError, match="frequency"):
        jc.read_test(LIU, columns=LIU_COLUMNS, metadata={"length_mm": 64})


def test_titin_stretch_ratio_and_stress():
    path = REAL / "TitinViscoelasticity" / "AvgRelaxed_10s.csv"
    diameter = 10.0
    data = jc.read_test(
        path,
        columns="time_s,stretch_ratio,stress_kPa,-",
        metadata={"length_mm": 2.0, "diameter_mm": diameter},
        options=jc.ReadOptions(detect_slack=False),
    )
    time, stretch, stress = _columns(path, "Time", "L", "F")
    area_mm2 = math.pi * diameter**2 / 4
    np.testing.assert_allclose(data.time, time, rtol=1e-12)
    np.testing.assert_allclose(data.elongation, (stretch - 1) * 2e-3, atol=1e-15)
    np.testing.assert_allclose(data.force, stress * 1e-3 * area_mm2, rtol=1e-12)
    assert len(data.notes) == 2


def test_command_line_options_reach_the_reader():
    """`--force-sign +1` and `--no-tare` read the latex glove as written; the
    defaults correct it, and the notes say so."""
    path = str(WAVEMATRIX / "latex_glove_Test6.steps.tracking.csv")
    parser = cli_parser.build_parser()
    common = ["fit", path, "--length-mm", "79", "--out", "p.json"]
    default = cli_data.read_data(path, cli_data.data_options(parser.parse_args(common)))
    written = cli_data.read_data(
        path,
        cli_data.data_options(
            parser.parse_args([*common, "--force-sign", "+1", "--no-tare"])
        ),
    )
    assert any("tared" in n for n in default.notes)
    assert not any("tared" in n or "flipped" in n for n in written.notes)
    assert np.max(default.force) > 5.0 and not np.any(written.mask)
    args = parser.parse_args(
        [
            "fit",
            str(LIU),
            "--length-mm",
            "64",
            "--columns",
            LIU_COLUMNS,
            "--frequency-hz",
            "4.2",
            "--out",
            "p.json",
        ]
    )
    assert cli_data.read_data(str(LIU), cli_data.data_options(args)).num_samples == 62


PYRHEO = REAL / "pyRheo"
RHEO_TEXT = (
    "Test:\tHC1\r\nResult:\tStep strain\r\n"
    "Point No.\tTime\tShear Strain\tShear Stress\tTemperature\tStatus\r\n"
    "\t\t\t\t\t\r\n\t[s]\t[%]\t[Pa]\t[°C]\t\r\n"
    "1\t0,010\t0,019\t7,922\t20,00\tDy_auto\r\n"
    "2\t0,021\t0,0499\t-1,2326\t20,00\tDy_auto\r\n"
    "3\t0,031\t0,0773\t-2,3138\t20,01\tDy_auto\r\n"
)


def test_rheocompass_export_reads_with_its_record_options():
    """The RheoCompass export (UTF-16 with a byte-order mark, CRLF, tabs, decimal
    commas, a `Status` column of text) read with the options of its record: the
    strain in % as the elongation of a 1 mm cable, the stress in Pa as the force
    on a 1 m^2 section; the status column not read, as the notes say."""
    (record,) = [
        r
        for r in json.loads((REAL / "records.json").read_text())["records"]
        if r["id"] == "cnf_hydrogel_step_strain_relaxation"
    ]
    path = str(REAL / record["files"][0])
    args = cli_parser.build_parser().parse_args(
        ["fit", path, *record["options"], "--out", "p"]
    )
    data = cli_data.read_data(path, cli_data.data_options(args))
    text = pathlib.Path(path).read_bytes().decode("utf-16")
    rows = [line.split("\t") for line in text.splitlines()]
    rows = [r for r in rows if r[0].strip().isdigit()]
    time, strain, stress = (
        np.array([float(r[i].replace(",", ".")) for r in rows]) for i in (1, 2, 3)
    )
    area_m2 = math.pi * 1.12838**2 / 4
    assert data.num_samples == len(rows) == 264
    np.testing.assert_allclose(data.time, time, rtol=1e-12)
    np.testing.assert_allclose(data.elongation, strain / 100 * 1e-3, rtol=1e-12)
    # The ringing step's negative stresses are clipped to 0 by the slack detection.
    np.testing.assert_allclose(data.force, np.maximum(stress, 0) * area_m2, rtol=1e-12)
    assert data.column_names["force"] == "Shear Stress"
    assert any("'Status' (text: 'Dy_auto')" in note for note in data.notes)


@pytest.mark.parametrize("encoding", ["utf-16", "utf-16-be", "utf-32"])
def test_wide_encodings_read_like_utf8(tmp_path, encoding):
    """UTF-16 and UTF-32 with a byte-order mark, and UTF-16 without one (`utf-16-be`
    writes none), read like the same text in UTF-8 (the header's `°C` too)."""
    twin, wide = tmp_path / "utf8.txt", tmp_path / "wide.txt"
    twin.write_bytes(RHEO_TEXT.encode("utf-8"))
    wide.write_bytes(RHEO_TEXT.encode(encoding))
    options = dict(
        metadata={"length_mm": 1.0, "diameter_mm": 10.0},
        options=jc.ReadOptions(detect_slack=False),
    )
    a, b = jc.read_test(twin, **options), jc.read_test(wide, **options)
    np.testing.assert_allclose(a.temperature, [20.0, 20.0, 20.01])
    for name in ("time", "elongation", "force", "temperature"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert a.notes == b.notes and a.column_names == b.column_names


def test_text_column_not_read_but_a_word_in_a_read_column_refused(tmp_path):
    """A column of text in every data row is not read (named in the notes); a word
    in a column that is read is refused, naming the file, line and column."""
    path = tmp_path / "status.csv"
    path.write_text(RHEO_TEXT.replace(",", "."), encoding="utf-8")
    data = jc.read_test(
        path,
        metadata={"length_mm": 1.0, "diameter_mm": 10.0},
        options=jc.ReadOptions(detect_slack=False),
    )
    np.testing.assert_allclose(data.time, [0.010, 0.021, 0.031])
    assert data.lines.tolist() == [6, 7, 8]
    (note,) = data.notes
    assert "'Status' (text: 'Dy_auto')" in note and "'Point No.'" in note
    path.write_text(
        RHEO_TEXT.replace(",", ".").replace("-1.2326", "n.a."), encoding="utf-8"
    )
    with pytest.raises(ValueError) as error:
        jc.read_test(path, metadata={"length_mm": 1.0, "diameter_mm": 10.0})
    message = str(error.value)
    assert f"{path}, line 7, column 4 " in message and "'n.a.'" in message
