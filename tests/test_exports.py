"""Real tester exports as labs saved them (`tests/data/exports/`, sources and
licences in its README.md): each reads without `columns`, its time, force and
elongation equal to its own columns (parsed here independently) in SI, its metadata
read, its control mode detected. Then the layouts they taught the reader: a units row
with empty cells and units such as (N/tex), a stress column without a force column,
a comment line right under the header, and the keyword arguments checked."""

import csv
import json
import pathlib

import numpy as np
import pytest

import jaxcable as jc
from jaxcable.cli import main
from jaxcable.internal import resolve_control


EXPORTS = pathlib.Path(__file__).parent / "data" / "exports"
IN, LBF, KN = 0.0254, 4.4482216152605, 1e3

# file, separator, first data line (1-based), (column, factor to SI) of time, force,
# elongation, the length_mm given where the file has none, the metadata read from
# the file, the control detected (None: the detection says it cannot tell).
CORPUS = [
    *(
        (
            f"TensileDataAnalysis/Specimen_RawData_{k}.csv",
            ",",
            7,
            ((0, 1.0), (2, LBF), (1, IN)),
            50.0,
            {"id": f"orgn_80_NA_2_wblk_3ptbnd_run{k}"},
            "elongation",
        )
        for k in range(1, 6)
    ),
    (
        "bluer/vero_clear_ccyclic_Specimen_RawData_6.csv",
        ",",
        6,
        ((0, 1.0), (2, 1.0), (1, 1e-3)),
        20.0,
        {"id": "22L.3"},
        "elongation",
    ),
    (
        "instron_data_processing/silicone_30a_Test1.steps.tracking.csv",
        ",",
        2,
        ((0, 1.0), (8, KN), (7, 1e-3)),
        30.0,
        {},
        None,
    ),
    (
        "instron_data_processing/silicone_10a_Test7.steps.tracking.csv",
        ",",
        2,
        ((0, 1.0), (8, KN), (7, 1e-3)),
        30.0,
        {},
        # Read with its tension's sign flipped (as the load cell writes it
        # negative), the strip's position is seen to be the one held and ramped.
        "elongation",
    ),
    (
        "instron_data_processing/silicone_30a_20251029_145648_1.csv",
        ",",
        3,
        ((1, 1.0), (3, KN), (2, 1e-3)),
        30.0,
        {},
        "elongation",
    ),
    (
        "tensile_test_analyzer/Exemple_Shimadzu_Tract_L100_D2.csv",
        ",",
        4,
        ((0, 1.0), (1, 1.0), (2, 1e-3)),
        100.0,
        {},
        "elongation",
    ),
    (
        "tensile_test_analyzer/Exemple_WB100kN_Tract_L100_D2.csv",
        ";",
        2,
        ((1, 1.0), (2, KN), (9, 1e-3)),
        100.0,
        {},
        "elongation",
    ),
    (
        "tensile_test_analyzer/Exemple_WB100kN_2_Tract_L100_D2.csv",
        ";",
        2,
        ((1, 1.0), (2, KN), (4, 1e-3)),
        100.0,
        {},
        "elongation",
    ),
    (
        "tensile_test_analyzer/Exemple_WB100kN_Mod_Young.csv",
        ";",
        2,
        ((1, 1.0), (2, KN), (9, 1e-3)),
        100.0,
        {},
        "elongation",
    ),
]


def _own_columns(path, sep, first, spec):
    """The file's time, force and elongation in SI, by the csv module."""
    text = path.read_bytes().decode("latin-1")
    rows = list(csv.reader(text.splitlines()[first - 1 :], delimiter=sep))
    return [
        np.array([float(row[column]) for row in rows if row]) * factor
        for column, factor in spec
    ]


def test_the_corpus_is_whole():
    """Every file listed, every file here listed; at least 12 from 4 sources."""
    here = {str(p.relative_to(EXPORTS)) for p in EXPORTS.glob("*/*.csv")}
    assert here == {row[0] for row in CORPUS}
    assert len(here) >= 12 and len({name.split("/")[0] for name in here}) >= 4
    readme = (EXPORTS / "README.md").read_text(encoding="utf-8")
    for name in here:
        assert name in readme


@pytest.mark.parametrize("row", CORPUS, ids=[row[0].split("/")[-1] for row in CORPUS])
def test_export_reads_as_it_comes(row):
    name, sep, first, spec, length_mm, metadata, control = row
    path = EXPORTS / name
    # The columns as written: no correction of the load cell's sign or offset.
    data = jc.read_test(
        path,
        metadata={"length_mm": length_mm},
        options=jc.ReadOptions(detect_slack=False, force_sign=1, tare=False),
    )
    time, force, elongation = _own_columns(path, sep, first, spec)
    np.testing.assert_allclose(data.time, time, rtol=1e-12, atol=0)
    np.testing.assert_allclose(data.force, force, rtol=1e-12, atol=1e-300)
    np.testing.assert_allclose(data.elongation, elongation, rtol=1e-12, atol=1e-300)
    assert data.lines[0] == first
    for key, value in metadata.items():
        assert data.metadata[key] == value
    detected = resolve_control(
        jc.read_test(path, metadata={"length_mm": length_mm}), None
    )
    if control is None:
        assert "ambiguous" in detected.reason
    else:
        assert detected.control == control and detected.detected


def _bluehill_relaxation(stress_only=False):
    """An Instron Bluehill stress-relaxation export laid out as the tendon fascicle
    files of a public data set (not redistributable, so written here): ramp at
    5 mm/min to 5 % strain, hold."""
    length, area = 14.33, np.pi * 0.399**2 / 4
    t = np.arange(0.0, 60.0, 0.5)
    e = np.minimum(t * 5 / 60, 0.05 * length)
    ramp = t * 5 / 60 < 0.05 * length
    # A toe region, then relaxation; the load cell's noise.
    decay = 24 + 16 * np.exp(-(t - 8.6) / 9)
    f = np.where(ramp, 40 * (e / (0.05 * length)) ** 1.6, decay)
    f = f + np.random.default_rng(0).normal(0, 0.02, t.size)
    lines = [
        'Specimen properties : Specimen label,"sample1"',
        'Specimen properties : Diameter,"0.39900",mm',
        'Specimen properties : Length,"14.33000",mm',
        'Test : Rate 1,"5.00000",mm/min',
        'Test : Start of hold value,"0.05000",mm/mm',
        'Test : Delta,"180.00000",s',
        "",
    ]
    if stress_only:
        lines += ["Time,Tensile stress,Tensile strain (Extension)", "(s),(MPa),(%)"]
        rows = zip(t, f / area, 100 * e / length)
    else:
        lines += [
            "Extension,Load,Tensile stress,Time,PIP count,Tenacity,Tensile extension,"
            "Tensile strain (Extension)",
            "(mm),(N),(MPa),(s),,(N/tex),(mm),(mm/mm)",
        ]
        rows = (
            (x, y, y / area, z, 0, y / 9, x, x / length) for z, x, y in zip(t, e, f)
        )
    for row in rows:
        lines.append(",".join(f'"{v:.5f}"' for v in row))
    return "\r\n".join(lines) + "\r\n", t, np.round(e, 5), f


def test_bluehill_units_row_is_not_the_header(tmp_path):
    text, t, e, f = _bluehill_relaxation()
    path = tmp_path / "Specimen_RawData_1.csv"
    path.write_bytes(text.encode())
    data = jc.read_test(path, options=jc.ReadOptions(detect_slack=False))
    np.testing.assert_allclose(data.time, t)
    np.testing.assert_allclose(data.elongation, e * 1e-3, rtol=1e-12)
    np.testing.assert_allclose(data.force, f, atol=5e-6)
    assert data.metadata == {
        "id": "sample1",
        "diameter_mm": 0.399,
        "length_mm": 14.33,
        "rate_mm_per_min": 5.0,
    }
    # The columns not read, in one line: none of them a second elongation.
    (note,) = data.notes
    assert "'Tensile stress (MPa)'" in note and "'Tensile extension'" in note
    assert "'Tenacity (N/tex)'" in note and "'PIP count'" in note
    assert resolve_control(data, None).control == "elongation"


def test_stress_without_force(tmp_path):
    text, t, e, f = _bluehill_relaxation(stress_only=True)
    path = tmp_path / "stress.csv"
    path.write_bytes(text.encode())
    data = jc.read_test(path, options=jc.ReadOptions(detect_slack=False))
    np.testing.assert_allclose(data.force, f, rtol=1e-5, atol=1e-4)
    np.testing.assert_allclose(data.elongation, e * 1e-3, rtol=1e-4, atol=1e-9)
    path.write_bytes(text.replace("Diameter", "Width").encode())
    with pytest.raises(ValueError) as error:
        jc.read_test(path)
    message = str(error.value)
    assert "\n" not in message and "'Tensile stress (MPa)'" in message
    assert "metadata={'diameter_mm'" in message and "--diameter-mm" in message
    given = jc.read_test(
        path,
        metadata={"diameter_mm": 0.399},
        options=jc.ReadOptions(detect_slack=False),
    )
    np.testing.assert_allclose(given.force, data.force)


@pytest.mark.parametrize(
    "head",
    [
        "Time (s),Load (N),Extension (mm)\n# note\n",
        "Time,Load,Extension\n# note\n(s),(N),(mm)\n",
        "Time,Load,Extension\n(s),(N),(mm)\n# note\n\n",
        "# length_mm: 10\ntime_s,force_N,elongation_mm\n# note\n",
    ],
)
def test_comment_under_the_header_skips_no_row(tmp_path, head):
    path = tmp_path / "comment.csv"
    path.write_text(head + "0,0,0\n1,2,0.1\n2,4,0.2\n3,6,0.3\n")
    data = jc.read_test(
        path, metadata={"length_mm": 10}, options=jc.ReadOptions(detect_slack=False)
    )
    np.testing.assert_array_equal(data.time, [0, 1, 2, 3])
    np.testing.assert_array_equal(data.force, [0, 2, 4, 6])


@pytest.mark.parametrize(
    "call, argument",
    [
        (lambda p: jc.read_test(p, options=jc.ReadOptions(encoding=5)), "encoding"),
        (lambda p: jc.read_test(p, options=jc.ReadOptions(encoding="")), "encoding"),
        (lambda p: jc.read_test(p, options=jc.ReadOptions(delimiter=4)), "delimiter"),
        (lambda p: jc.read_test(p, columns=3), "columns"),
        (lambda p: jc.read_test(p, columns=[]), "columns"),
        (lambda p: jc.read_test(p, options=jc.ReadOptions(skip_rows="2")), "skip_rows"),
        (lambda p: jc.read_test(p, options=jc.ReadOptions(skip_rows=-1)), "skip_rows"),
        (lambda p: jc.read_test(p, metadata={"length_mm": [1]}), "length_mm"),
        (lambda p: jc.read_test(p, metadata={"length_mm": -1}), "length_mm"),
        (lambda p: jc.read_test(p, metadata={"material": 3}), "material"),
        (
            lambda p: jc.read_test(p, options=jc.ReadOptions(detect_slack="no")),
            "detect_slack",
        ),
        (
            lambda p: jc.read_test(p, options=jc.ReadOptions(slack_threshold_N="1")),
            "slack_threshold_N",
        ),
        (
            lambda p: jc.read_test(
                p, options=jc.ReadOptions(slack_threshold_N=float("nan"))
            ),
            "threshold_N",
        ),
        (lambda p: jc.read_test(3), "path"),
        (lambda p: jc.read_test(p, metadata={"lenght_mm": 10}), "metadata"),
        (lambda p: jc.read_test(p, metadata=[("length_mm", 10)]), "metadata"),
        (lambda p: jc.read_test(p, options={"tare": False}), "options"),
        (lambda p: jc.ReadOptions(tare="no"), "tare"),
        (lambda p: jc.ReadOptions(frequency_hz=0.0), "frequency_hz"),
        (lambda p: jc.ReadOptions(force_sign=2), "force_sign"),
        (lambda p: jc.read_csv(p, metadata={"length_mm": "x"}), "length_mm"),
        (lambda p: jc.read_csv(p, metadata=300), "metadata"),
        (lambda p: jc.read_csv(None), "path"),
        (lambda p: jc.write_csv(p, "data"), "data"),
        (lambda p: jc.write_csv(3, jc.read_test(p)), "path"),
        (lambda p: jc.mask_slack(jc.read_test(p), threshold_N=-2), "threshold_N"),
        (lambda p: jc.mask_slack(p), "data"),
    ],
)
def test_bad_keyword_arguments_are_named(tmp_path, call, argument):
    path = tmp_path / "ok.csv"
    path.write_text("# length_mm: 10\ntime_s,force_N\n0,0\n1,1\n2,2\n")
    with pytest.raises((TypeError, ValueError)) as error:
        call(path)
    assert argument in str(error.value)


@pytest.mark.xdist_group("exports_cli")
def test_cli_fit_and_simulate_a_bluehill_export(tmp_path, capsys):
    """Without --columns or --drive: elongation control detected, fitted on the
    force, `simulate --params` filling in force_N."""
    text, t, e, f = _bluehill_relaxation()
    path = tmp_path / "Specimen_RawData_1.csv"
    path.write_bytes(text.encode())
    params = tmp_path / "params.json"
    args = ["fit", str(path), "--model", "burgers", "--out", str(params)]
    assert main([*args, "--starts", "1", "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "drive: detected elongation control" in out
    assert "    columns not read: 'Tensile stress (MPa)'" in out
    assert json.loads(params.read_text())
    simulated = tmp_path / "sim.csv"
    args = ["simulate", str(path), "--model", "burgers", "--params", str(params)]
    assert main([*args, "--out", str(simulated)]) == 0
    assert "force_N simulated" in capsys.readouterr().out
    back = jc.read_csv(simulated)
    assert back.metadata["control"] == "elongation"
    assert np.all(np.isfinite(back.force)) and np.ptp(back.force) > 1.0
    np.testing.assert_allclose(back.elongation, e * 1e-3, rtol=1e-12)
