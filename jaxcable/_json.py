"""Numbers in JSON files: JSON has no NaN or infinity, so a non-finite number is
written as null and read back as NaN."""

import math

import numpy as np


def jsonable(x):
    """`x` with NumPy scalars as Python numbers and non-finite floats as None,
    through dicts, lists and tuples (a tuple becomes a list).

    **Arguments:**

    - `x`: a number, or a dict, list or tuple of them (other values pass through).

    **Returns:**

    The same structure, ready for `json.dumps`.
    """
    if isinstance(x, dict):
        return {k: jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable(v) for v in x]
    if isinstance(x, (bool, np.bool_)):
        return bool(x)
    if isinstance(x, (int, np.integer)):
        return int(x)
    if isinstance(x, (float, np.floating)):
        return float(x) if math.isfinite(x) else None
    return x


def from_json_number(x) -> float:
    """A number read from JSON as a float: NaN for null (the inverse of
    [`jsonable`][] for a float)."""
    return math.nan if x is None else float(x)
