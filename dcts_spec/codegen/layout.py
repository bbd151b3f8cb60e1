"""ctypes mirrors of the generated C structs (`<name>_info`, `<name>_workspace`).

They must follow templates/controller.h.in field by field; the loader checks the sizes against
the compiled library (`<name>_info_size`, `<name>_workspace_size`) before use.
"""

from __future__ import annotations

import ctypes

# Outputs of the generated qp_data, in the order the wrapper points `res` at them.
C_DATA_OUTPUTS = ("H", "f", "A_rowmajor", "bl", "bu", "tau0", "T", "ddq0", "Q", "s0", "S")


def array_lengths(nx: int, na: int, nlevels: int, nref: int, nr: int) -> dict[str, int]:
    """Lengths of the structs' arrays (the header's `*_ALLOC`): at least 1, as C99 has no empty
    arrays. The relaxed QP has NX + NR variables and NA + NR rows; without relaxable rows its
    arrays are placeholders of length 1."""
    return {
        "nref": max(nref, 1), "nx": max(nx, 1), "na": max(na, 1), "nc": max(nx + na, 1), "nlevels": max(nlevels, 1),
        "nx2": nx + nr if nr else 1, "na2": na + nr if nr else 1, "nc2": nx + na + 2 * nr if nr else 1,
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


def _qp_fields(suffix: str, nx: int, na: int, nc: int) -> list[tuple[str, type]]:
    """H, f, A, bl, bu and sense of one QP (the QP, or with suffix "2" the relaxed QP)."""
    return [
        (f"H{suffix}", ctypes.c_double * (nx * nx)),
        (f"f{suffix}", ctypes.c_double * nx),
        (f"A{suffix}", ctypes.c_double * (na * nx)),
        (f"bl{suffix}", ctypes.c_double * nc),
        (f"bu{suffix}", ctypes.c_double * nc),
        (f"sense{suffix}", ctypes.c_int * nc),
    ]


def workspace_struct(nq: int, nref: int, nx: int, na: int, nlevels: int, casadi_work: dict,
                     solver_bytes: int, nr: int = 0) -> type[ctypes.Structure]:
    length = array_lengths(nx, na, nlevels, nref, nr)
    work = casadi_work_lengths(casadi_work)

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
            ("w", ctypes.c_double * work["w"]),
            *_qp_fields("", length["nx"], length["na"], length["nc"]),
            ("tau0", ctypes.c_double * nq),
            ("T", ctypes.c_double * (nq * length["nx"])),
            ("ddq0", ctypes.c_double * nq),
            ("Q", ctypes.c_double * (nq * length["nx"])),
            ("s0", ctypes.c_double * length["nlevels"]),
            ("S", ctypes.c_double * (length["nlevels"] * length["nx"])),
            ("x", ctypes.c_double * length["nx"]),
            *_qp_fields("2", length["nx2"], length["na2"], length["nc2"]),
            ("x2", ctypes.c_double * length["nx2"]),
            ("zeros", ctypes.c_double * nq),
            ("last_q", ctypes.c_double * nq),
            ("gravity", ctypes.c_double * nq),
            ("have_last_q", ctypes.c_int),
            ("warm_start", ctypes.c_int),
            ("n_warm", ctypes.c_int),
            ("warm", ctypes.c_int * length["nc"]),
            ("solver", Solver),
        ]

    return Workspace
