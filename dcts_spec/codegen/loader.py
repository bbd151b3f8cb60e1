"""Load a built bundle with ctypes: the same `step` API and `StepResult` as the Python runtime."""

from __future__ import annotations

import ctypes
import json
from pathlib import Path

import numpy as np

from ..controller import STATUS_INVALID_OUTPUT, StepResult
from ..tasks import ReferenceInput
from .bundle import CodegenError
from .layout import info_struct, workspace_struct

_DOUBLE_P = ctypes.POINTER(ctypes.c_double)


class CompiledController:
    """The generated C controller, loaded from a bundle directory (or its manifest).

    `step(q, dq, tau_ext=None, ref=None)` returns a StepResult like `Controller.step`; the C
    workspace keeps the same history the Python runtime keeps (the last finite q) plus the
    QP solver's warm start.
    """

    def __init__(self, directory: str | Path):
        self.directory = Path(directory)
        try:
            self.manifest = json.loads((self.directory / "manifest.json").read_text())
        except (OSError, ValueError) as exc:
            raise CodegenError(f"{self.directory} holds no readable manifest.json: {exc}") from None
        m = self.manifest
        self.name: str = m["name"]
        self.formulation: str = m["formulation"]
        self.n: int = m["nq"]
        self.nx: int = m["nx"]
        self.na: int = m["na"]
        self.ref_size: int = m["nref"]
        self.priorities: list[int] = list(m["priorities"])
        self.tau_max = np.array(m["tau_max"], dtype=float)
        self.fallback_damping = np.array(m["fallback_damping"], dtype=float)
        self.spec_sha256: str = m["spec_sha256"]
        self.variables: list[str] = list(m["variables"])
        library = self.directory / m["library"]
        if not library.is_file():
            raise CodegenError(f"{library} not found: build the bundle first (make)")
        self.library_path = library
        self._lib = ctypes.CDLL(str(library))
        self._bind()
        levels = len(self.priorities)
        self._Info = info_struct(self.n, levels, self.nx)
        workspace = workspace_struct(self.n, self.ref_size, self.nx, self.na, levels, m["casadi_work"],
                                     m["solver_storage_bytes"], m.get("relaxable_rows", 0))
        self.workspace_bytes = int(self._lib_fn("workspace_size")())
        if self.workspace_bytes != ctypes.sizeof(workspace) or self._lib_fn("info_size")() != ctypes.sizeof(self._Info):
            raise CodegenError(f"{library}: struct sizes differ from the manifest's (stale build?)")
        # 8-byte aligned storage for the workspace, owned by Python.
        self._storage = np.zeros(self.workspace_bytes // 8 + 1, dtype=np.float64)
        self._ws = ctypes.c_void_p(self._storage.ctypes.data)
        self._info = self._Info()
        self._tau = np.zeros(self.n)
        self._zeros = np.zeros(self.n)
        self._empty_ref = np.zeros(1)
        if self._init(self._ws) != 0:
            raise CodegenError(f"{self.name}_init failed (out of memory?)")
        self._open = True

    def _lib_fn(self, suffix: str):
        return getattr(self._lib, f"{self.name}_{suffix}")

    def _bind(self) -> None:
        self._init = self._lib_fn("init")
        self._init.argtypes, self._init.restype = [ctypes.c_void_p], ctypes.c_int
        self._release = self._lib_fn("release")
        self._release.argtypes, self._release.restype = [ctypes.c_void_p], None
        self._reset = self._lib_fn("reset")
        self._reset.argtypes, self._reset.restype = [ctypes.c_void_p], None
        self._set_warm = self._lib_fn("set_warm_start")
        self._set_warm.argtypes, self._set_warm.restype = [ctypes.c_void_p, ctypes.c_int], None
        self._step = self._lib_fn("step")
        self._step.argtypes = [ctypes.c_void_p, _DOUBLE_P, _DOUBLE_P, _DOUBLE_P, _DOUBLE_P, _DOUBLE_P, ctypes.c_void_p]
        self._step.restype = ctypes.c_int
        self._lib_fn("workspace_size").restype = ctypes.c_size_t
        self._lib_fn("info_size").restype = ctypes.c_size_t
        self._status_name = self._lib_fn("status_name")
        self._status_name.argtypes, self._status_name.restype = [ctypes.c_int], ctypes.c_char_p

    # -- same surface as Controller --------------------------------------------------------------

    @property
    def ref_layout(self) -> list[ReferenceInput]:
        return [
            ReferenceInput(r["task"], r["field"], r["offset"], r["size"], r["unit"], tuple(r["components"]))
            for r in self.manifest["ref_layout"]
        ]

    def status_name(self, status: int) -> str:
        return self._status_name(status).decode()

    def _inputs(self, q, dq, tau_ext, ref) -> tuple[np.ndarray, ...]:
        q = np.ascontiguousarray(q, dtype=float).reshape(-1)
        dq = np.ascontiguousarray(dq, dtype=float).reshape(-1)
        tau_ext = self._zeros if tau_ext is None else np.ascontiguousarray(tau_ext, dtype=float).reshape(-1)
        if ref is None:
            if self.ref_size:
                raise ValueError(f"this controller takes a reference vector of {self.ref_size} values (see ref_layout)")
            ref = self._empty_ref
        else:
            ref = np.ascontiguousarray(ref, dtype=float).reshape(-1)
            if ref.size != self.ref_size:
                raise ValueError(f"ref must have {self.ref_size} values, got {ref.size}")
            if not ref.size:
                ref = self._empty_ref
        for name, value in (("q", q), ("dq", dq), ("tau_ext", tau_ext)):
            if value.size != self.n:
                raise ValueError(f"{name} must have {self.n} values, got {value.size}")
        return q, dq, tau_ext, ref

    def step(self, q, dq, tau_ext=None, ref=None) -> StepResult:
        """One control step of the C code: τ, commanded q̈, scalings, status and the QP solution."""
        if not self._open:
            raise RuntimeError("the controller was closed")
        q, dq, tau_ext, ref = self._inputs(q, dq, tau_ext, ref)
        tau = np.empty(self.n)
        status = self._step(self._ws, q.ctypes.data_as(_DOUBLE_P), dq.ctypes.data_as(_DOUBLE_P),
                            tau_ext.ctypes.data_as(_DOUBLE_P), ref.ctypes.data_as(_DOUBLE_P),
                            tau.ctypes.data_as(_DOUBLE_P), ctypes.byref(self._info))
        info = self._info
        levels = len(self.priorities)
        ddq = np.array(info.ddq[: self.n])
        scaling = np.array(info.scaling[:levels])
        x = np.array(info.x[: info.nx]) if (status >= 0 or status == STATUS_INVALID_OUTPUT) else np.zeros(0)
        return StepResult(tau, ddq, scaling, int(status), x)

    def last_info(self) -> dict:
        """Solver statistics of the last step: solves, DAQP iterations and exit flag."""
        return {"solves": self._info.solves, "iterations": self._info.iterations, "exitflag": self._info.exitflag}

    def reset(self) -> None:
        """Forget the history (last finite q, warm start)."""
        self._reset(self._ws)

    def set_warm_start(self, on: bool) -> None:
        self._set_warm(self._ws, int(bool(on)))

    def close(self) -> None:
        if getattr(self, "_open", False):
            self._release(self._ws)
            self._open = False

    def __del__(self):
        try:
            self.close()
        except Exception:  # pragma: no cover - interpreter shutdown
            pass

    def __enter__(self) -> "CompiledController":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"CompiledController({self.name!r}, {self.formulation}, n={self.n}, nx={self.nx}, na={self.na})"


def load_bundle(directory: str | Path) -> CompiledController:
    return CompiledController(directory)
