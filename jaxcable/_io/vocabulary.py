"""What tensile testers write, in one place: the words of their column headers and
the spellings of their units (read best-effort by `sniff.py`), and the labels and
units of their metadata lines and the words naming their control mode (read by
`preamble.py`). The canonical names these map to are in `units.py`.

Layouts known (each a header, maybe a units row, maybe metadata lines above it):

- Instron Bluehill: `Specimen properties : Length,"14.33000",mm`, `Test : Rate
    1,"5.00000",mm/min`, `Extension,Load,Tensile stress,Time,PIP count,Tenacity` over
    `(mm),(N),(MPa),(s),,(N/tex)`; Bluehill Universal `1,Time,Displacement,Force`
    over `,(s),(mm),(kN)`; WaveMatrix `Total Time (s),...,Position (mm),Force (kN)`.
- Walter+Bai (French): `S/No;C_1_Temps[s];C_1_Force[kN];C_1_Déplacement[mm]`.
- Zwick testXpert: `;`-separated with decimal commas, `Einspannlänge;100,0;mm`,
    `Standardkraft;Standardweg;Prüfzeit` (or `Standard force;Grip to grip
    separation;Test time`) over `N;mm;s`.
- MTS TestSuite: tab-separated `Time`, `Axial Displacement`/`Crosshead`, `Axial
    Force`/`Load` over `sec mm N` (or `s mm kN`).
- Shimadzu Trapezium: `Time,Force,Stroke` (試験時間, 試験力, ストローク) over `sec,N,mm`.
"""

from .units import COLUMNS


# Header words (lower case) for each quantity. A word of ASCII letters matches a
# whole word of the header cell (`load` in `Axial load`, not in `Download`); any
# other word matches anywhere in it (力 in 试验力, `prüfzeit`). A crosshead
# displacement is the cable's elongation when it starts at zero with the test, as
# tensile testers zero it; "strain" counts only in a length unit (Zwick writes the
# crosshead travel as `Strain` in mm): in % or mm/mm it is no elongation.
HEADER_WORDS = {
    "time": ("time", "zeit", "prüfzeit", "temps", "tiempo", "时间", "時間"),
    "force": (
        "force",
        "load",
        "kraft",
        "standardkraft",
        "prüfkraft",
        "力",
        "负荷",
        "負荷",
        "载荷",
        "荷重",
    ),
    "elongation": (
        "elongation",
        "extension",
        "displacement",
        "stroke",
        "crosshead",
        "position",  # Instron WaveMatrix's `Position (mm)`
        "deformation",
        "déplacement",  # French exports (Walter+Bai)
        "deplacement",
        "separation",  # Zwick's "Grip to grip separation"
        "strain",
        "traverse",
        "traversenweg",
        "weg",
        "standardweg",
        "位移",
        "伸长",
        "变形",
        "行程",
        "ストローク",
    ),
    "temperature": ("temperature", "temp", "temperatur", "温度"),
}
# Words of a stress column (read as the force, times the cross-section, where a file
# has no force column) and their units (lower case) -> factor to MPa; the units of a
# strain column (the elongation's words in these units: read as the elongation,
# times the length, where a file has no elongation column) -> factor to mm/mm.
STRESS_WORDS = ("stress", "spannung", "contrainte", "应力", "応力")
STRESS_UNITS = {
    "mpa": 1.0,
    "n/mm²": 1.0,
    "n/mm^2": 1.0,
    "n/mm2": 1.0,
    "kpa": 1e-3,
    "pa": 1e-6,
    "gpa": 1e3,
    "psi": 6.894757293168361e-3,
    "ksi": 6.894757293168361,
}
STRAIN_UNITS = {"mm/mm": 1.0, "in/in": 1.0, "m/m": 1.0, "%": 0.01}
# Canonical column name (`units.COLUMNS`) -> the spellings of its unit in a header
# or units row, lower case.
_WRITTEN_UNITS = {
    "time_s": ("s", "sec", "secs", "second", "seconds", "秒"),
    "time_ms": ("ms", "msec"),
    "time_min": ("min", "mins", "minute", "minutes", "分钟"),
    "time_h": ("h", "hr", "hrs", "hour", "hours", "小时"),
    "force_N": ("n",),
    "force_kN": ("kn",),
    "force_lbf": ("lbf", "lb"),
    "force_kgf": ("kgf",),
    "elongation_mm": ("mm",),
    "elongation_cm": ("cm",),
    "elongation_m": ("m",),
    "elongation_in": ("in", "inch"),
    "temperature_C": ("c", "°c", "℃", "degc", "deg c", "celsius"),
}
# (quantity, unit as written, lower case) -> canonical column name.
HEADER_UNITS = {
    (COLUMNS[name].quantity, unit): name
    for name, units in _WRITTEN_UNITS.items()
    for unit in units
}
# Units of the other columns instruments write (stress, strain, energy), lower case:
# a row of units under the header holds them too.
OTHER_UNITS = frozenset(
    (
        "mpa",
        "gpa",
        "kpa",
        "pa",
        "psi",
        "ksi",
        "n/mm²",
        "n/mm^2",
        "n/mm2",
        "%",
        "mm/mm",
        "in/in",
        "j",
        "nm",
        "n·m",
        "mm/min",
        "mm/s",
        "n/s",
        "kn/s",
        "hz",
        "v",
        "mm²",
        "mm^2",
        "-",
        "n/tex",
        "cn/tex",
        "m/m",
        "deg",
        "°",
        "n·m",
        "n.m",
    )
)
UNIT_SPELLINGS = frozenset(unit for _, unit in HEADER_UNITS) | OTHER_UNITS

# Metadata lines above the header: the label (lower case, after the last `:` of its
# first cell and without a trailing number, `Test : Rate 1` -> `rate`) -> the
# canonical key, most specific first: where several labels of one key are in a
# file, the first listed is used.
METADATA_LABELS = {
    "length_mm": (
        "free length",
        "specimen length",
        "length",
        "einspannlänge",
        "probenlänge",
        "länge",
        "grip to grip separation",
        "grip separation",
        "initial grip separation",
        "gauge length",
        "messlänge",
        "長さ",
        "长度",
    ),
    "diameter_mm": (
        "diameter",
        "specimen diameter",
        "durchmesser",
        "probendurchmesser",
        "直径",
    ),
    "rate_mm_per_min": (
        "rate",
        "test rate",
        "test speed",
        "crosshead speed",
        "speed",
        "prüfgeschwindigkeit",
        "geschwindigkeit",
        "試験速度",
        "速度",
    ),
}
# Labels of the metadata lines read as strings (`Specimen properties : Specimen
# label,"sample1"`), same rules as `METADATA_LABELS`.
STRING_LABELS = {
    "id": ("specimen label", "specimen id", "sample id", "probenkennung"),
}
# Unit as written (lower case) -> factor to the key's unit (mm, mm/min).
LENGTH_UNITS = {"mm": 1.0, "cm": 10.0, "m": 1000.0, "in": 25.4, "inch": 25.4}
RATE_UNITS = {
    "mm/min": 1.0,
    "mm/s": 60.0,
    "mm/sec": 60.0,
    "m/min": 1000.0,
    "m/s": 60_000.0,
    "in/min": 25.4,
    "in/s": 25.4 * 60,
}
METADATA_UNITS = {
    "length_mm": LENGTH_UNITS,
    "diameter_mm": LENGTH_UNITS,
    "rate_mm_per_min": RATE_UNITS,
}

# A line naming the control mode has one of CONTROL_MARKS and words of one mode's
# family (lower case; whole words, German compounds by prefix): `Control mode,
# Position`, `Extension control`, `Kraftregelung`.
CONTROL_MARKS = ("control", "regelung", "geregelt", "制御", "控制")
CONTROL_WORDS = {
    "elongation": (
        "extension",
        "displacement",
        "position",
        "stroke",
        "crosshead",
        "strain",
        "elongation",
        "weg",
        "lage",
        "traverse",
        "dehnung",
        "位移",
        "ストローク",
    ),
    "force": ("load", "force", "stress", "kraft", "荷重", "力"),
}
