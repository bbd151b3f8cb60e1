"""Numbers as C source: exact literals of doubles."""

from __future__ import annotations

import numpy as np


def c_double(value: float) -> str:
    """An exact C99 literal of a double (hexadecimal floating constant)."""
    value = float(value)
    if np.isnan(value):  # (NAN and INFINITY are floats: -Wdouble-promotion)
        return "(double)NAN"
    if np.isinf(value):
        return "HUGE_VAL" if value > 0 else "-HUGE_VAL"
    return value.hex()


def c_array(values) -> str:
    return ", ".join(c_double(v) for v in np.asarray(values, dtype=float).ravel())


def c_rows(rows, separator: str = ", ") -> str:
    """The initializers of a 2-D C array, one braced row per entry of `rows`."""
    return separator.join("{" + c_array(row) + "}" for row in rows)
