"""The validators of the command line's numeric options: argparse `type`s that refuse a
value in one line saying what is required. The bounds are checked by the library's
one check of a count or a number (`jaxcable._checks`), as every Python boundary
checks them; only the wording is the command line's."""

import argparse
from collections.abc import Callable
from typing import TypeVar

from .. import _checks


_N = TypeVar("_N", int, float)


def _parser(
    convert: Callable[[str], _N],
    noun: str,
    check: Callable[[_N], object],
    requirement: str,
) -> Callable[[str], _N]:
    """An argparse `type`: `convert(text)`, refused unless `check(value)` passes.

    **Arguments:**

    - `convert`: `int` or `float`.
    - `noun`: what `convert` parses, for the error ("an integer").
    - `check`: raises `ValueError` for a value out of bounds.
    - `requirement`: what an acceptable value is, for the error ("must be at least 1").
    """

    def parse(text: str) -> _N:
        # A value of thousands of digits is cut short: the error is one line.
        shown = text if len(text) <= 30 else f"{text[:20]}... ({len(text)} characters)"
        try:
            value = convert(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{shown!r} is not {noun}") from None
        try:
            check(value)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{shown} {requirement}") from None
        return value

    return parse


def integer(
    requirement: str, low: int | None = None, high: int | None = None
) -> Callable[[str], int]:
    """An argparse `type`: an integer from `low` to `high` (None: unbounded); out
    of bounds, an error saying `requirement`."""
    return _parser(
        int, "an integer", lambda v: _checks.require_int("", v, low, high), requirement
    )


def real(
    requirement: str,
    low: float | None = None,
    high: float | None = None,
    *,
    above: bool = False,
) -> Callable[[str], float]:
    """An argparse `type`: a finite number from `low` (above it, with `above`) to
    `high` (None: unbounded); out of bounds, an error saying `requirement`."""

    def check(v):
        _checks.require_number("", v, low, strict=above)
        _checks.require_number("", v, high=high)

    return _parser(float, "a number", check, requirement)


def at_least(low: int) -> Callable[[str], int]:
    """An argparse `type`: an integer >= `low`."""
    return integer(f"must be at least {low}", low)


positive_int = at_least(1)
non_negative_int = at_least(0)
# jax.random.key takes a 64-bit signed integer.
seed = integer("is not a 64-bit integer (-2^63 to 2^63-1)", -(2**63), 2**63 - 1)
# The demo simulates 10 cycles of 2 ramps: at most 10^6 samples, as a protocol file.
MAX_SAMPLES_PER_RAMP = 50_000
samples_per_ramp = integer(
    f"must be from 2 to {MAX_SAMPLES_PER_RAMP:,}", 2, MAX_SAMPLES_PER_RAMP
)
positive_float = real("must be a positive number", 0.0, above=True)
fraction = real("must be in (0, 1]", 0.0, 1.0, above=True)


def _breaking(v: float) -> None:
    # Positive, or `inf` for a material that does not break (which the finite check
    # of a number refuses).
    if v != float("inf"):
        _checks.require_number("", v, 0.0, strict=True)


breaking_strain = _parser(
    float,
    "a number",
    _breaking,
    "must be a positive number (or inf, for a material that does not break)",
)
