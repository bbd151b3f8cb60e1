"""ctypes mirrors of the generated C structs (`<name>_info`, `<name>_workspace`).

They must follow templates/controller.h.in field by field; the loader checks the sizes against
the compiled library (`<name>_info_size`, `<name>_workspace_size`) before use.
"""

from __future__ import annotations

import ctypes

# Outputs of the generated qp_data, in the order the wrapper points `res` at them.
C_DATA_OUTPUTS = ("H", "f", "A_rowmajor", "bl", "bu", "tau0", "T", "ddq0", "Q", "s0", "S", "p0", "P")


def array_lengths(nx: int, na: int, nlevels: int, nref: int, nr: int, np_: int, nh: int) -> dict[str, int]:
    """Lengths of the structs' arrays (the header's `*_ALLOC`): at least 1, as C99 has no empty
    arrays. nr: joint/Cartesian bound rows; np_: rows of an over-constrained lowest level; nh:
    DAQP break points."""
    return {
        "nref": max(nref, 1), "nx": max(nx, 1), "na": max(na, 1), "nc": max(nx + na, 1), "nlevels": max(nlevels, 1),
        "nr": max(nr, 1), "np": max(np_, 1), "nh": max(nh, 1),
    }


def casadi_work_lengths(casadi_work: dict) -> dict[str, int]:
    """Lengths of the workspace's CasADi work vectors (`arg res iw w`) for the generated
    functions' `sz_*`; `res` holds at least qp_data's outputs."""
    return {
        "arg": max(casadi_work["sz_arg"], 1),
        "res": max(casadi_work["sz_res"], len(C_DATA_OUTPUTS)),
        "iw": max(casadi_work["sz_iw"], 1),
        "w": max(casadi_work["sz_w"], 1),
    }


def info_struct(nq: int, nlevels: int, nx: int, nr: int) -> type[ctypes.Structure]:
    class Info(ctypes.Structure):
        _fields_ = [
            ("ddq", ctypes.c_double * nq),
            ("scaling", ctypes.c_double * max(nlevels, 1)),
            ("x", ctypes.c_double * max(nx, 1)),
            ("nx", ctypes.c_int),
            ("status", ctypes.c_int),
            ("relaxed", ctypes.c_int * max(nr, 1)),
            ("relaxed_count", ctypes.c_int),
            ("solves", ctypes.c_int),
            ("iterations", ctypes.c_int),
            ("exitflag", ctypes.c_int),
        ]

    return Info


def workspace_struct(nq: int, nref: int, nx: int, na: int, nlevels: int, casadi_work: dict,
                     solver_bytes: int, nr: int, np_: int, nh: int) -> type[ctypes.Structure]:
    length = array_lengths(nx, na, nlevels, nref, nr, np_, nh)
    work = casadi_work_lengths(casadi_work)
    d, i = ctypes.c_double, ctypes.c_int
    nxa, nc = length["nx"], length["nc"]

    class Solver(ctypes.Union):
        _fields_ = [
            ("bytes", ctypes.c_ubyte * solver_bytes),
            ("align_double", ctypes.c_double),
            ("align_pointer", ctypes.c_void_p),
            ("align_long", ctypes.c_longlong),
        ]

    class Workspace(ctypes.Structure):
        _fields_ = [
            ("magic", ctypes.c_ulong),
            ("arg", ctypes.c_void_p * work["arg"]),
            ("res", ctypes.c_void_p * work["res"]),
            ("iw", ctypes.c_longlong * work["iw"]),
            ("w", d * work["w"]),
            ("H", d * (nxa * nxa)), ("f", d * nxa), ("A", d * (length["na"] * nxa)),
            ("bl", d * nc), ("bu", d * nc), ("sense", i * nc),
            ("tau0", d * nq), ("T", d * (nq * nxa)), ("ddq0", d * nq), ("Q", d * (nq * nxa)),
            ("s0", d * length["nlevels"]), ("S", d * (length["nlevels"] * nxa)), ("x", d * nxa),
            ("bl0", d * nc), ("bu0", d * nc), ("f0", d * nxa), ("bp", i * length["nh"]),
            ("p0", d * length["np"]), ("P", d * (length["np"] * nxa)), ("x_free", d * nxa),
            ("bl_free", d * nc), ("bu_free", d * nc),
            ("zeros", d * nq), ("last_q", d * nq), ("dq_finite", d * nq), ("fallback", d * nq),
            ("have_last_q", i),
            ("solver", Solver),
        ]

    return Workspace
