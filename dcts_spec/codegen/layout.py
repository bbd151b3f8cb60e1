"""ctypes mirrors of the generated C structs (`<name>_info`, `<name>_workspace`).

They must follow templates/controller.h.in field by field; the loader checks the sizes against
the compiled library (`<name>_info_size`, `<name>_workspace_size`) before use.
"""

from __future__ import annotations

import ctypes


def info_struct(nq: int, nlevels: int, nx: int) -> type[ctypes.Structure]:
    class Info(ctypes.Structure):
        _fields_ = [
            ("ddq", ctypes.c_double * nq),
            ("scaling", ctypes.c_double * max(nlevels, 1)),
            ("x", ctypes.c_double * max(nx, 1)),
            ("nx", ctypes.c_int),
            ("status", ctypes.c_int),
            ("solves", ctypes.c_int),
            ("iterations", ctypes.c_int),
            ("exitflag", ctypes.c_int),
        ]

    return Info


def workspace_struct(nq: int, nref: int, nx: int, na: int, nlevels: int, casadi_work: dict,
                     solver_bytes: int, nr: int = 0) -> type[ctypes.Structure]:
    nx1, na1, nc1, nl1 = max(nx, 1), max(na, 1), max(nx + na, 1), max(nlevels, 1)
    nx2, na2, nc2 = (nx + nr, na + nr, nx + na + 2 * nr) if nr else (1, 1, 1)

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
            ("arg", ctypes.c_void_p * max(casadi_work["sz_arg"], 1)),
            ("res", ctypes.c_void_p * max(casadi_work["sz_res"], 11)),
            ("iw", ctypes.c_longlong * max(casadi_work["sz_iw"], 1)),
            ("w", ctypes.c_double * max(casadi_work["sz_w"], 1)),
            ("H", ctypes.c_double * (nx1 * nx1)),
            ("f", ctypes.c_double * nx1),
            ("A", ctypes.c_double * (na1 * nx1)),
            ("bl", ctypes.c_double * nc1),
            ("bu", ctypes.c_double * nc1),
            ("sense", ctypes.c_int * nc1),
            ("tau0", ctypes.c_double * nq),
            ("T", ctypes.c_double * (nq * nx1)),
            ("ddq0", ctypes.c_double * nq),
            ("Q", ctypes.c_double * (nq * nx1)),
            ("s0", ctypes.c_double * nl1),
            ("S", ctypes.c_double * (nl1 * nx1)),
            ("x", ctypes.c_double * nx1),
            ("H2", ctypes.c_double * (nx2 * nx2)),
            ("f2", ctypes.c_double * nx2),
            ("A2", ctypes.c_double * (na2 * nx2)),
            ("bl2", ctypes.c_double * nc2),
            ("bu2", ctypes.c_double * nc2),
            ("sense2", ctypes.c_int * nc2),
            ("x2", ctypes.c_double * nx2),
            ("zeros", ctypes.c_double * nq),
            ("last_q", ctypes.c_double * nq),
            ("gravity", ctypes.c_double * nq),
            ("have_last_q", ctypes.c_int),
            ("warm_start", ctypes.c_int),
            ("n_warm", ctypes.c_int),
            ("warm", ctypes.c_int * nc1),
            ("solver", Solver),
        ]

    return Workspace
