"""A test file's lines: its bytes decoded with the encoding given, else detected
(UTF-16 and UTF-32 by their byte-order mark, UTF-16 without one by its NUL bytes,
else UTF-8, GB18030 for Chinese testers' headers, Windows-1252 for Western European
ones, latin-1 for anything else), split at CR, LF and CRLF only."""

import re

from .testdata import where


# Tried in order when no encoding is given. utf-8-sig: spreadsheet programs prepend a
# byte-order mark. gb18030 (a superset of GBK): Chinese tensile testers' headers.
# latin-1 decodes any bytes, so a header in an unknown encoding never stops a file
# whose numbers are ASCII.
_ENCODINGS = ("utf-8-sig", "gb18030", "latin-1")


def _decode(raw: bytes) -> str:
    """`raw` decoded with the first of `_ENCODINGS` that decodes it."""
    for candidate in _ENCODINGS[:-1]:
        try:
            return _decode_as(raw, candidate)
        except UnicodeDecodeError:
            continue
    return raw.decode(_ENCODINGS[-1])


# The non-letters of Western European instrument exports (units, `Temp. (°C)`).
_LATIN_SYMBOLS = frozenset("°µ²³·±")


def _decode_as(raw: bytes, encoding: str) -> str:
    """`raw.decode(encoding)`, but for GB18030 text that is rather Windows-1252
    (`Prüfzeit`, `Einspannlänge` of a Zwick export decode as GB18030 too, to rare
    characters): then Windows-1252."""
    text = raw.decode(encoding)
    if encoding != "gb18030" or text.isascii():
        return text
    chinese = {ch for ch in text if not ch.isascii()}
    try:
        "".join(chinese).encode("gb2312")  # the common characters: Chinese it is
        return text
    except UnicodeEncodeError:
        pass
    try:
        latin = raw.decode("cp1252")
    except UnicodeDecodeError:
        return text
    if all(ch.isalpha() or ch in _LATIN_SYMBOLS for ch in set(latin) if ord(ch) > 127):
        return latin
    return text


# Byte-order marks of the wide encodings, UTF-32's first: its little-endian mark
# starts with UTF-16's.
_WIDE_BOMS = (
    (b"\xff\xfe\x00\x00", "utf-32-le"),
    (b"\x00\x00\xfe\xff", "utf-32-be"),
    (b"\xff\xfe", "utf-16-le"),
    (b"\xfe\xff", "utf-16-be"),
)


def _wide_encoding(raw: bytes) -> tuple[str, int] | None:
    """`(encoding, bom_length)` of a UTF-16 or UTF-32 file (Anton Paar RheoCompass
    and other Windows programs export UTF-16), or None for a byte-wise encoding.

    Without a byte-order mark, UTF-16 is told by its NUL bytes: the ASCII digits,
    separators and line ends of an export are a character and a NUL, so most bytes
    at odd offsets (little-endian) or at even ones (big-endian) are NUL and hardly
    any of the others; no byte-wise encoding writes NUL in text.
    """
    for bom, encoding in _WIDE_BOMS:
        if raw.startswith(bom):
            return encoding, len(bom)
    sample = raw[:4096]
    pairs = len(sample) // 2
    if pairs < 2:
        return None
    even = sample[0 : 2 * pairs : 2].count(0) / pairs
    odd = sample[1 : 2 * pairs : 2].count(0) / pairs
    if odd > 0.5 and even < 0.05:
        return "utf-16-le", 0
    if even > 0.5 and odd < 0.05:
        return "utf-16-be", 0
    return None


def _decode_wide(raw: bytes, encoding: str, bom: int, path) -> str:
    """`raw` (after its `bom` bytes) decoded as the detected `encoding`; a
    `ValueError` naming the file and line where it cannot be."""
    try:
        return raw[bom:].decode(encoding)
    except UnicodeDecodeError as e:
        before = raw[bom : bom + e.start].decode(encoding, errors="replace")
        how = "its byte-order mark" if bom else "its NUL bytes"
        raise ValueError(
            f"{where(path, before.count(chr(10)) + 1)}: read as {encoding} (by {how}) "
            f"but cannot be decoded ({e.reason} at byte {bom + e.start}); pass "
            "read_test its encoding."
        ) from None


def _read_text(path, encoding: str | None = None) -> str:
    """The file's text, decoded with `encoding`, else as UTF-16 or UTF-32 when its
    byte-order mark or NUL bytes say so, else with the first of `_ENCODINGS` that
    decodes it whole, else line by line."""
    with open(path, "rb") as f:
        raw = f.read()
    wide = _wide_encoding(raw) if encoding is None else None
    if wide is not None:
        return _decode_wide(raw, *wide, path)
    if encoding is None:
        for candidate in _ENCODINGS[:-1]:
            try:
                return _decode_as(raw, candidate)
            except UnicodeDecodeError:
                continue
        # Mixed encodings (a GBK header, a stray byte in a row): decoded whole as
        # latin-1, the header would turn to mojibake and its columns go unmatched;
        # line by line, the header keeps its encoding and the stray byte's row is
        # reported. Line ends are the same bytes in all of `_ENCODINGS`.
        return "".join(map(_decode, re.split(rb"(\r\n|\r|\n)", raw)))
    try:
        text = raw.decode(encoding)
    except LookupError:
        raise ValueError(f"{path}: unknown encoding {encoding!r}.") from None
    except UnicodeDecodeError as e:
        line = raw.count(b"\n", 0, e.start) + 1
        raise ValueError(
            f"{where(path, line)}: cannot be decoded as {encoding} ({e.reason} at "
            f"byte {e.start}); leave the encoding out to have it detected."
        ) from None
    return text.removeprefix("\ufeff")


def read_lines(path, encoding: str | None = None) -> list[str]:
    """The lines of the file, decoded (see `_read_text`), without line ends."""
    # Split on CR, LF and CRLF only: str.splitlines also splits on characters such as
    # U+0085, which a header decoded as latin-1 may hold, and would shift the line
    # numbers of error messages.
    lines = re.split(r"\r\n|\r|\n", _read_text(path, encoding))
    if lines and lines[-1] == "":
        lines.pop()
    return lines
