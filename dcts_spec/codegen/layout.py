"""ctypes mirrors of the generated C structs (`<name>_info`, `<name>_workspace`).

They must follow templates/controller.h.in field by field; the loader checks the sizes against
the compiled library (`<name>_info_size`, `<name>_workspace_size`) before use.
"""

from __future__ import annotations

import ctypes

# Outputs of the generated qp_data, in the order the wrapper points `res` at them.
C_DATA_OUTPUTS = ("H", "f", "A_rowmajor", "bl", "bu", "tau0", "T", "ddq0", "Q", "s0", "S", "p0", "P", "excess",
                  "bound_shift")


def array_lengths(nx: int, na: int, nlevels: int, nref: int, nr: int, np_: int) -> dict[str, int]:
    """Lengths of the structs' arrays (the header's `*_ALLOC`): at least 1, as C99 has no empty
    arrays. nr: joint/Cartesian bound rows; np_: rows of an over-constrained lowest level. The
    relaxation has one slack per bound row: NX + NR variables and NA + NR rows."""
    return {
        "nref": max(nref, 1), "nx": max(nx, 1), "na": max(na, 1), "nc": max(nx + na, 1), "nlevels": max(nlevels, 1),
        "nr": max(nr, 1), "np": max(np_, 1),
        "nx2": max(nx + nr, 1), "na2": max(na + nr, 1), "nc2": max(nx + na + 2 * nr, 1),
        "chol": max(nx * nx, 1) if np_ else 1,
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


def daqp_problems(nx: int, na: int, nr: int) -> list[tuple[int, int, int]]:
    """(n, m, ms) of each DAQP state, in the order of controller.c.in's C_SOLVER_*: the QP and its
    stages (NX variables, NX simple bounds + NA rows), and with bounds (NR > 0) the relaxation
    (NX + NR variables and simple bounds, NA + NR rows). None for a closed form (NX = 0)."""
    if nx == 0:
        return []
    qp = (nx, nx + na, nx)
    return [qp, qp] + ([(nx + nr, nx + na + 2 * nr, nx + nr)] if nr else [])


def daqp_array_lengths(n: int, m: int, ms: int) -> tuple[int, int]:
    """(doubles, ints) that DAQP's setup_daqp allocates for a QP with n variables and m
    constraints, ms of them simple bounds, with no soft or binary constraint and no hierarchy
    (daqp/src/api.c: allocate_daqp_workspace(work, n, ns = 0), then allocate_daqp_ldp(work, n, m,
    ms, alloc_R = 1, alloc_v = 1)). controller.c.in hands out the same arrays from the workspace."""
    rows = m - ms
    doubles = (
        5 * (n + 1)  # lam, lam_star, D, xldl, zldl
        + (n + 1) * (n + 2) // 2  # L
        + 2 * n  # u (= x), xold
        + 3 * m  # scaling, dupper, dlower
        + n * rows  # M
        + (rows if m > ms else 0)  # Mu
        + (n + 1) * n // 2  # Rinv
        + n  # v
    )
    ints = (n + 1) + n + m  # WS, prox_mask, sense
    return doubles, ints


def daqp_storage(nx: int, na: int, nr: int) -> tuple[int, int]:
    """(doubles, ints) of every DAQP state's arrays together (see daqp_array_lengths)."""
    lengths = [daqp_array_lengths(*p) for p in daqp_problems(nx, na, nr)]
    return sum(d for d, _ in lengths), sum(i for _, i in lengths)


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
            ("optimal", ctypes.c_int),
            ("from_relaxation", ctypes.c_int),
        ]

    return Info


def workspace_fields(nq: int, nref: int, nx: int, na: int, nlevels: int, casadi_work: dict, nr: int,
                     np_: int, nparam: int = 0) -> list[tuple[str, str, int, str]]:
    """The workspace struct's fields before DAQP's storage: (name, C type, count, comment), for the
    generated header (`header_fields`) and its ctypes mirror (`workspace_struct`) alike. nparam:
    entries of the run-time parameter vector."""
    n = array_lengths(nx, na, nlevels, nref, nr, np_)
    work = casadi_work_lengths(casadi_work)
    nxa, nc, nx2 = n["nx"], n["nc"], n["nx2"]
    daqp_doubles, daqp_ints = daqp_storage(nx, na, nr)
    return [
        ("magic", "unsigned long", 0, "set by init"),
        ("self", "const void *", 0, "its own address, set by init: a copy (which points into the original) is not initialized"),
        ("arg", "const double *", work["arg"], "CasADi work vectors"),
        ("res", "double *", work["res"], ""),
        ("iw", "long long", work["iw"], ""),
        ("w", "double", work["w"], ""),
        ("H", "double", nxa * nxa, "QP data: min 1/2 x'Hx + f'x s.t. bl <= [x; A x] <= bu (A row-major)"),
        ("f", "double", nxa, ""),
        ("A", "double", n["na"] * nxa, ""),
        ("bl", "double", nc, ""),
        ("bu", "double", nc, ""),
        ("tau0", "double", nq, "tau = tau0 + T x, ddq = ddq0 + Q x, scaling = s0 + S x (column-major)"),
        ("T", "double", nq * nxa, ""),
        ("ddq0", "double", nq, ""),
        ("Q", "double", nq * nxa, ""),
        ("s0", "double", n["nlevels"], ""),
        ("S", "double", n["nlevels"] * nxa, ""),
        ("p0", "double", n["np"], "over-constrained lowest level: task acceleration p0 + P x"),
        ("P", "double", n["np"] * nxa, ""),
        ("excess", "double", n["nr"], "how far the state is beyond each bound's position or velocity limit"),
        ("bound_shift", "double", n["nr"], "each bound row's constant part: its value in rad/s^2 or m/s^2 is A x plus it"),
        ("x", "double", nxa, "the solution"),
        ("x_free", "double", nxa, "the solution without torque limits and bounds (p0 + P x)"),
        ("chol", "double", n["chol"], "its Cholesky factor"),
        ("lba", "double", n["na"], "the cascade: row bounds (widened when relaxed)"),
        ("row_size", "double", n["na"], "each row's largest |coefficient|"),
        ("data_size", "double", 0, "the largest |entry| of H and f, at least 1"),
        ("uba", "double", n["na"], ""),
        ("nominal", "double", nxa, "every level met"),
        ("lbx_w", "double", nxa, "variable bounds with the levels fixed so far"),
        ("ubx_w", "double", nxa, ""),
        ("lbx_f", "double", nxa, ""),
        ("ubx_f", "double", nxa, ""),
        ("lbx_n", "double", nxa, ""),
        ("ubx_n", "double", nxa, ""),
        ("weights", "double", nxa, "a stage's objective"),
        ("linear", "double", nxa, ""),
        ("xs", "double", nxa, ""),
        ("xb", "double", nxa, ""),
        ("witness", "double", nxa, ""),
        ("witness_f", "double", nxa, ""),
        ("face_lba", "double", n["na"], "a final QP's row bounds, kept while it runs on a face (ctl_on_face)"),
        ("face_uba", "double", n["na"], ""),
        ("face_rows", "int", n["na"], "the rows it holds as equalities"),
        ("held", "int", n["na"], "the rows held as equalities on scaled levels' optimal faces (ctl_hold_face)"),
        ("dropped", "int", n["na"], "the rows it found dependent (ctl_hold_rows)"),
        ("open_lba", "double", n["na"], "each row's bounds when not held"),
        ("open_uba", "double", n["na"], ""),
        ("reopen", "int", 0, "dropped rows keep their bounds (the cascade run again: ctl_solve)"),
        ("x_kept", "double", nxa, "the first run's answer and bends, while it runs again"),
        ("bent_kept", "int", n["nlevels"], ""),
        ("bent", "int", n["nlevels"], "by priority: bent in this solve"),
        ("hint_first", "int", 0, "where the last step gave way (Hint): the first priority not met, -1 none"),
        ("hint_bent", "int", n["nlevels"], "and the priorities it bent"),
        ("hint_steady", "int", 0, "and it is where the step before gave way too"),
        ("center", "double", nx2, "proximal steps"),
        ("direction", "double", nx2, ""),
        ("trial", "double", nx2, ""),
        ("previous", "double", nx2, ""),
        ("gradient", "double", nx2, "a stage's answer certified (ctl_stationary): the stage's gradient, the active rows"),
        ("kkt_rows", "double", nx2 * nx2, ""),
        ("kkt_gram", "double", nx2 * nx2, ""),
        ("kkt_mu", "double", nx2, ""),
        ("kkt_g", "double", nx2, ""),
        ("kkt_active", "int", nx2, ""),
        ("opt_count", "int", 0, "the lowest level's optimum (ctl_to_optimum): how many normals are active"),
        ("opt_index", "int", 2 * nc, "each one's row (or C_NA + free variable)"),
        ("opt_scale", "double", 2 * nc, "and sign / norm"),
        ("opt_mu", "double", 2 * nc, "Lawson-Hanson's coefficients"),
        ("opt_passive", "int", 2 * nc, ""),
        ("opt_passed", "int", 2 * nc, ""),
        ("opt_list", "int", nxa, "the passive ones, in order"),
        ("opt_z", "double", nxa, ""),
        ("opt_qr", "double", nxa * nxa, ""),
        ("opt_rhs", "double", nxa, ""),
        ("opt_g", "double", nxa, ""),
        ("opt_residual", "double", nxa, ""),
        ("opt_column", "double", nxa, ""),
        ("opt_face", "int", nxa, "Newton's step on the active face: its constraints, reflectors, basis"),
        ("opt_beta", "double", nxa, ""),
        ("opt_rdiag", "double", nxa, ""),
        ("opt_basis", "double", nxa * nxa, ""),
        ("opt_gram", "double", nxa * nxa, ""),
        ("opt_d", "double", nxa, "the step's direction, and the point it leads to"),
        ("opt_trial", "double", nxa, ""),
        ("lo", "double", nc, "DAQP's arrays of the QP (its H is the QP data's; f: theirs or finish_lowest's)"),
        ("hi", "double", nc, ""),
        ("sense", "int", nc, ""),
        ("lam_q", "double", nc, ""),
        ("xq", "double", nxa, ""),
        ("fq", "double", nxa, ""),
        ("Hq_free", "double", nxa * nxa, "the QP reduced to its free variables, and which they are (ctl_daqp)"),
        ("fq_free", "double", nxa, ""),
        ("Aq_free", "double", n["na"] * nxa, ""),
        ("free_q", "int", nxa, ""),
        ("constant_q", "int", n["na"], ""),
        ("row_scale_q", "double", n["na"], ""),
        ("Hd", "double", nxa * nxa, "DAQP's arrays of the cascade's stages (diagonal H, the same A)"),
        ("fd", "double", nxa, ""),
        ("lod", "double", nc, ""),
        ("hid", "double", nc, ""),
        ("sensed", "int", nc, ""),
        ("lam_d", "double", nc, ""),
        ("xd", "double", nxa, ""),
        ("Hd_free", "double", nxa * nxa, ""),
        ("fd_free", "double", nxa, ""),
        ("Ad_free", "double", n["na"] * nxa, ""),
        ("free_d", "int", nxa, ""),
        ("constant_d", "int", n["na"], ""),
        ("row_scale_d", "double", n["na"], ""),
        ("A2", "double", n["na2"] * nx2, "the relaxation: one slack per bound row"),
        ("lba2", "double", n["na2"], ""),
        ("uba2", "double", n["na2"], ""),
        ("row_size2", "double", n["na2"], ""),
        ("lbx2", "double", nx2, ""),
        ("ubx2", "double", nx2, ""),
        ("nominal2", "double", nx2, ""),
        ("weights2", "double", nx2, ""),
        ("linear2", "double", nx2, ""),
        ("xr", "double", nx2, ""),
        ("H2", "double", nx2 * nx2, ""),
        ("f2", "double", nx2, ""),
        ("lo2", "double", n["nc2"], ""),
        ("hi2", "double", n["nc2"], ""),
        ("sense2", "int", n["nc2"], ""),
        ("lam_2", "double", n["nc2"], ""),
        ("x2", "double", nx2, ""),
        ("H2_free", "double", nx2 * nx2, ""),
        ("f2_free", "double", nx2, ""),
        ("A2_free", "double", n["na2"] * nx2, ""),
        ("free_2", "int", nx2, ""),
        ("constant_2", "int", n["na2"], ""),
        ("row_scale_2", "double", n["na2"], ""),
        ("zeros", "double", nq, "fallback: the last finite q, the finite part of dq, the torque"),
        ("last_q", "double", nq, ""),
        ("dq_finite", "double", nq, ""),
        ("fallback", "double", nq, ""),
        ("rb_rotation", "double", 9 * nq, "the fallback's rigid-body dynamics: each joint's placement in its parent's"),
        ("rb_translation", "double", 3 * nq, ""),
        ("rb_velocity", "double", 6 * nq, "each body's velocity, acceleration, force (RNEA)"),
        ("rb_acceleration", "double", 6 * nq, ""),
        ("rb_force", "double", 6 * nq, ""),
        ("rb_subtree_mass", "double", nq, "each subtree's composite inertia (CRBA)"),
        ("rb_moment", "double", 3 * nq, ""),
        ("rb_composite", "double", 9 * nq, ""),
        ("rb_hold", "double", nq, "nu + g, M a_d, a_d"),
        ("rb_brake", "double", nq, ""),
        ("rb_decay", "double", nq, ""),
        ("have_last_q", "int", 0, ""),
        ("param_from", "double", max(nparam, 1), "run-time parameters: the ramp from one set to the last one taken"),
        ("param_to", "double", max(nparam, 1), ""),
        ("param_now", "double", max(nparam, 1), "the values of this step"),
        ("tau_limit", "double", nq, "|tau| <= this at this step (run-time torque limits within the compiled ones)"),
        ("ramp_step", "int", 0, "steps taken along the ramp"),
        ("refactor", "int", 3, "a DAQP state's H or A changed since it factored them"),
        ("nfree", "int", 3, "the free variables of each DAQP state's last QP"),
        ("answered", "int", 3, "each DAQP state's last QP solved, its answer holding every row (ctl_hold_face)"),
        ("sliver", "int", 0, "the bounds were relaxed this step: a failed QP is tried again with its rows widened"),
        ("daqp_real", "double", max(daqp_doubles, 1), "DAQP's arrays (factorizations, working sets) of every state: no heap"),
        ("daqp_int", "int", max(daqp_ints, 1), ""),
    ]


def header_fields(fields: list[tuple[str, str, int, str]]) -> str:
    """The fields as C declarations (count 0: a scalar)."""
    lines = []
    for name, ctype, count, comment in fields:
        if comment:
            lines.append(f"    /* {comment} */")
        pointer = ctype.endswith("*")
        decl = f"{ctype}{'' if pointer else ' '}{name}" + (f"[{count}]" if count else "")
        lines.append(f"    {decl};")
    return "\n".join(lines)


_CTYPES = {"double": ctypes.c_double, "int": ctypes.c_int, "long long": ctypes.c_longlong,
           "unsigned long": ctypes.c_ulong, "const double *": ctypes.c_void_p, "double *": ctypes.c_void_p,
           "const void *": ctypes.c_void_p}


def workspace_struct(fields: list[tuple[str, str, int, str]], solver_bytes: int) -> type[ctypes.Structure]:
    """The ctypes mirror of the generated workspace (fields from `workspace_fields`)."""

    class Solver(ctypes.Union):
        _fields_ = [
            ("bytes", ctypes.c_ubyte * solver_bytes),
            ("align_double", ctypes.c_double),
            ("align_pointer", ctypes.c_void_p),
            ("align_long", ctypes.c_longlong),
        ]

    class Workspace(ctypes.Structure):
        _fields_ = [(name, _CTYPES[ctype] * count if count else _CTYPES[ctype]) for name, ctype, count, _ in fields]
        _fields_ += [("solver", Solver)]

    return Workspace
