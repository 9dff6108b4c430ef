"""The validators of the command line's numeric options: argparse `type`s that refuse a
value in one line saying what is required."""

import argparse
import math
from collections.abc import Callable


def number(
    convert: type, noun: str, valid: Callable[[float], bool], requirement: str
) -> Callable[[str], int | float]:
    """An argparse `type`: `convert(text)`, refused unless `valid(value)`.

    **Arguments:**

    - `convert`: `int` or `float`.
    - `noun`: what `convert` parses, for the error ("an integer").
    - `valid`: whether a parsed value is acceptable.
    - `requirement`: what an acceptable value is, for the error ("must be at least 1").
    """

    def parse(text: str):
        # A value of thousands of digits is cut short: the error is one line.
        shown = text if len(text) <= 30 else f"{text[:20]}... ({len(text)} characters)"
        try:
            value = convert(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{shown!r} is not {noun}") from None
        if not valid(value):
            raise argparse.ArgumentTypeError(f"{shown} {requirement}")
        return value

    return parse


def at_least(low: int) -> Callable[[str], int]:
    """An argparse `type`: an integer >= `low`."""
    return number(int, "an integer", lambda v: v >= low, f"must be at least {low}")


positive_int = at_least(1)
non_negative_int = at_least(0)
# jax.random.key takes a 64-bit signed integer.
seed = number(
    int,
    "an integer",
    lambda v: -(2**63) <= v < 2**63,
    "is not a 64-bit integer (-2^63 to 2^63-1)",
)
# The demo simulates 10 cycles of 2 ramps: at most 10^6 samples, as a protocol file.
MAX_SAMPLES_PER_RAMP = 50_000
samples_per_ramp = number(
    int,
    "an integer",
    lambda v: 2 <= v <= MAX_SAMPLES_PER_RAMP,
    f"must be from 2 to {MAX_SAMPLES_PER_RAMP:,}",
)
positive_float = number(
    float,
    "a number",
    lambda v: math.isfinite(v) and v > 0,
    "must be a positive number",
)
# A breaking strain: positive, or `inf` for a material that does not break.
breaking_strain = number(
    float,
    "a number",
    lambda v: v > 0 and not math.isnan(v),
    "must be a positive number (or inf, for a material that does not break)",
)
