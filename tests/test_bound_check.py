"""The check that makes status "ok" a guarantee (solve/bound_check.py), and where rounding decides it."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from dcts_spec.solve import check_bounds, marginal_rows

DATA = Path(__file__).parent / "data"


def test_a_status_rounding_decides_is_marginal_in_both_runtimes_answers():
    """A 15-joint dual arm (two xArm7 on a waist, found from outside) under a heavy load: its left
    wrist's free acceleration, 7,650 rad/s², puts the QP's bound of its 20 rad/s² acceleration limit
    at 7,630, which the cascade resolves to 7.6e-4 rad/s² (1e-7 of it), where the check allows 2e-5.
    The Python runtime's answer crossed the limit by 3.3e-4 rad/s² ("limits relaxed"), the C
    runtime's held it to 1e-10 ("ok"), their torques 1.4e-6 Nm apart: the golden test failed on it.
    Both answers find that row, and the other rows at their bounds, marginal."""
    saved = np.load(DATA / "status_decided_by_rounding.npz")
    rows = range(*saved["rows"])
    data = (saved["A"], saved["lba"], saved["uba"])
    python, c = (check_bounds(rows, *data, saved[x], saved["shift"]) for x in ("x_python", "x_c"))
    assert python.violated == [5] and c.holds
    for x in ("x_python", "x_c"):
        assert marginal_rows(rows, *data, saved[x], saved["shift"])[5]


def test_a_row_at_its_bound_is_decided_where_the_qp_resolves_it_finer_than_the_check():
    """The same row at its bound (and 1e-4 beyond, and 1e-3 inside) with a QP bound of the size of
    its own (no large constant part): rounding decides nothing."""
    rows, A, shift = range(0, 1), np.array([[1.0]]), np.array([-30.0])
    lba, uba = np.array([10.0]), np.array([50.0])  # (the bound −20 ≤ a ≤ 20 rad/s², a = x − 30)
    for value, crossed in ((10.0, False), (10.0 - 1e-4, True), (10.0 + 1e-3, False)):
        x = np.array([value])
        assert check_bounds(rows, A, lba, uba, x, shift).violated == ([0] if crossed else [])
        assert not marginal_rows(rows, A, lba, uba, x, shift).any()
    # with the heavy load's constant part, a row at its bound is marginal, one well inside is not
    big = np.array([-7650.0])
    assert marginal_rows(rows, A, lba + 7620.0, uba + 7620.0, np.array([7630.0]), big).all()
    assert not marginal_rows(rows, A, lba + 7620.0, uba + 7620.0, np.array([7631.0]), big).any()
