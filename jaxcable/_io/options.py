"""How [`jaxcable.read_test`][] reads a file ([`jaxcable.ReadOptions`][]), apart
from the facts about the test (`metadata`), which the file's `# key: value` block
also gives."""

import equinox as eqx

from .._checks import require_int
from .arguments import check_flag, check_optional_text, check_threshold
from .loadcell import check_force_sign


# The facts `read_test(..., metadata=...)` may give or replace, as the file's
# `# key: value` block names them.
METADATA_KEYS = (
    "length_mm",
    "diameter_mm",
    "rate_mm_per_min",
    "temperature_C",
    "material",
    "id",
    "breaking_strain",
)


class ReadOptions(eqx.Module):
    """How [`jaxcable.read_test`][] reads a file: its layout where detection is not
    wanted, and the corrections applied to the force.

    ```python
    options = jc.ReadOptions(detect_slack=False, force_sign=1)
    data = jc.read_test("run.csv", metadata={"length_mm": 300}, options=options)
    ```

    Change one field of a value with `dataclasses.replace(options, tare=False)`.

    **Fields:**

    - `skip_rows`: the number of lines before the first data row, counted from the
        top of the file (blank, metadata, preamble, header and unit lines alike);
        `None` (default) to detect it.
    - `encoding`: the file's encoding, or `None` (default) to detect it.
    - `delimiter`: the cell separator, or `None` (default) to detect it.
    - `detect_slack`: whether to detect and mask slack stretches (default `True`).
    - `slack_threshold_N`: the slack force threshold, N, or `None` (default) for
        the default rule (see [`jaxcable.mask_slack`][]).
    - `require_force`: whether the file must have a force column (default `True`);
        `False` reads a canonical elongation history (`time_s,elongation_mm`) with
        NaN forces, for an elongation-driven simulation (no slack detection then).
    - `force_sign`: `1` (the force as written), `-1` (flipped) or `"auto"`
        (default): flipped where the load cell reads tension as negative (the force
        mostly negative and growing in magnitude as the elongation grows from its
        start; a compression test is read as written). Rules in
        `jaxcable/_io/loadcell.py`; each correction is a note.
    - `tare`: whether a load cell's offset at rest (the force of the first samples,
        before the elongation moves, constant within the noise) is removed where
        it is clearly one: a reading below zero at rest, or one the test loads
        above and, back at the rest elongation, reads below, never reading zero.
        A preload is kept. Default `True`.
    - `frequency_hz`: the test frequency, Hz, of a file timed by a cycle count
        (`cycles` in `columns`); `None` (default) otherwise.

    **Raises:**

    `TypeError` or `ValueError` naming the field of a value of the wrong type or
    value (`encoding=5`, `skip_rows=-1`).
    """

    skip_rows: int | None = eqx.field(default=None, static=True)
    encoding: str | None = eqx.field(default=None, static=True)
    delimiter: str | None = eqx.field(default=None, static=True)
    detect_slack: bool = eqx.field(default=True, static=True)
    slack_threshold_N: float | None = eqx.field(default=None, static=True)
    require_force: bool = eqx.field(default=True, static=True)
    force_sign: int | str = eqx.field(default="auto", static=True)
    tare: bool = eqx.field(default=True, static=True)
    frequency_hz: float | None = eqx.field(default=None, static=True)

    def __check_init__(self):
        if self.skip_rows is not None:
            try:
                require_int("skip_rows", self.skip_rows, 0)
            except TypeError:
                raise TypeError(
                    f"`skip_rows` must be an integer or None, got {self.skip_rows!r}."
                ) from None
        check_optional_text(self.encoding, "encoding")
        if self.encoding is not None and not self.encoding.strip():
            raise ValueError("`encoding` must name an encoding, got ''.")
        check_optional_text(self.delimiter, "delimiter")
        check_flag(self.detect_slack, "detect_slack")
        check_threshold(self.slack_threshold_N, "slack_threshold_N")
        check_flag(self.require_force, "require_force")
        check_flag(self.tare, "tare")
        check_force_sign(self.force_sign)
        check_threshold(self.frequency_hz, "frequency_hz", positive=True)
