"""Load a built bundle with ctypes: the same `step` API and `StepResult` as the Python runtime."""

from __future__ import annotations

import ctypes
import json
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np

from ..controller import STATUS_INVALID_OUTPUT, STATUS_LIMITS_RELAXED, StepResult
from ..formulations.parameters import ParameterError, ParameterLayout
from ..tasks import ReferenceInput
from .bundle import CodegenError
from .layout import info_struct, workspace_fields, workspace_struct


class CompiledController:
    """The generated C controller, loaded from a bundle directory (or its manifest).

    `step(q, dq, tau_ext=None, ref=None)` returns a StepResult like `Controller.step` (fresh
    arrays, never views of internal buffers); `step_into` is the allocation-free variant for
    loops that keep their own arrays (the simulation). The C workspace keeps the same history
    the Python runtime keeps (the last finite q). One
    controller must not be stepped from several threads at once (neither may the C workspace).

    Per step, the inputs are copied into buffers allocated once (their addresses are passed to
    C as prepared `c_void_p` arguments), and the outputs are read from numpy views of those
    buffers and of the C `info` struct: no ctypes conversion work beyond the call itself.
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
        # The robot model it was generated for (bundles from before the model record: the spec's).
        self.model_sha256: str | None = m.get("model_sha256")
        self.model_modified: bool = bool((m.get("model") or {}).get("modified", False))
        self.variables: list[str] = list(m["variables"])
        library = self.directory / m["library"]
        if not library.is_file():
            raise CodegenError(f"{library} not found: build the bundle first (make)")
        self._lib = _load_copy(library)
        self._bind()
        levels = len(self.priorities)
        self.bound_names: list[str] = list(m["bound_names"])
        self._Info = info_struct(self.n, levels, self.nx, len(self.bound_names))
        self.param_layout = ParameterLayout.from_dict(m.get("param_layout"), self.n)
        self.param_size = self.param_layout.size
        fields = workspace_fields(self.n, self.ref_size, self.nx, self.na, levels, m["casadi_work"],
                                  len(self.bound_names), m["least_squares_rows"], self.param_size)
        workspace = workspace_struct(fields, m["solver_storage_bytes"])
        self.workspace_bytes = int(self._lib_fn("workspace_size")())
        if self.workspace_bytes != ctypes.sizeof(workspace) or self._lib_fn("info_size")() != ctypes.sizeof(self._Info):
            raise CodegenError(f"{library}: struct sizes differ from the manifest's (stale build?)")
        # 8-byte aligned storage for the workspace, owned by Python.
        self._storage = np.zeros(self.workspace_bytes // 8 + 1, dtype=np.float64)
        self._ws = ctypes.c_void_p(self._storage.ctypes.data)
        self._info = self._Info()
        self._prepare_buffers()
        if self._init(self._ws) != 0:
            raise CodegenError(f"{self.name}_init failed: DAQP could not be set up in the workspace (stale build?)")
        self._open = True

    def _prepare_buffers(self) -> None:
        """Input and output buffers, allocated once, and the call's arguments pointing at them."""
        n, levels = self.n, len(self.priorities)
        self._shape = (n,)
        self._ref_shape = (self.ref_size,)
        self._q, self._dq, self._tau_ext, self._tau = (np.zeros(n) for _ in range(4))
        self._ref = np.zeros(max(self.ref_size, 1))
        self._ref_in = self._ref[: self.ref_size]  # what a reference is copied into
        # Views of the info struct's arrays (they share its memory; the views keep it alive).
        self._ddq_out = np.ctypeslib.as_array(self._info.ddq)[:n]
        self._scaling_out = np.ctypeslib.as_array(self._info.scaling)[:levels]
        self._x_out = np.ctypeslib.as_array(self._info.x)

        def address(array: np.ndarray) -> ctypes.c_void_p:
            return ctypes.c_void_p(array.ctypes.data)

        info = ctypes.c_void_p(ctypes.addressof(self._info))
        head = (self._ws, address(self._q), address(self._dq))
        tail = (address(self._ref), address(self._tau), info)
        self._args = (*head, address(self._tau_ext), *tail)
        self._args_no_tau_ext = (*head, ctypes.c_void_p(None), *tail)  # NULL: zero external torque

    def _lib_fn(self, suffix: str):
        return getattr(self._lib, f"{self.name}_{suffix}")

    def _bind(self) -> None:
        self._init = self._lib_fn("init")
        self._init.argtypes, self._init.restype = [ctypes.c_void_p], ctypes.c_int
        self._release = self._lib_fn("release")
        self._release.argtypes, self._release.restype = [ctypes.c_void_p], None
        self._reset = self._lib_fn("reset")
        self._reset.argtypes, self._reset.restype = [ctypes.c_void_p], None
        self._step = self._lib_fn("step")
        # Every argument is a pointer prepared once (see _prepare_buffers).
        self._step.argtypes = [ctypes.c_void_p] * 7
        self._step.restype = ctypes.c_int
        self._lib_fn("workspace_size").restype = ctypes.c_size_t
        self._lib_fn("info_size").restype = ctypes.c_size_t
        self._status_name = self._lib_fn("status_name")
        self._status_name.argtypes, self._status_name.restype = [ctypes.c_int], ctypes.c_char_p
        self._set_params = self._lib_fn("set_params")
        self._set_params.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.POINTER(ctypes.c_int)]
        self._set_params.restype = ctypes.c_int
        self._get_params = self._lib_fn("get_params")
        self._get_params.argtypes, self._get_params.restype = [ctypes.c_void_p, ctypes.c_void_p], ctypes.c_int
        self._param_name = self._lib_fn("param_name")
        self._param_name.argtypes, self._param_name.restype = [ctypes.c_int], ctypes.c_char_p

    # -- same surface as Controller --------------------------------------------------------------

    @property
    def ref_layout(self) -> list[ReferenceInput]:
        return [
            ReferenceInput(r["task"], r["field"], r["offset"], r["size"], r["unit"], tuple(r["components"]))
            for r in self.manifest["ref_layout"]
        ]

    # -- run-time parameters (the C functions do the checking and the ramp) ------------------------

    def set_params(self, values: dict | np.ndarray) -> None:
        """As `Controller.set_params`: {name: value(s)} over the current set, or a whole vector;
        <name>_set_params checks it and either takes it (ramped) or keeps the old set, and a
        ParameterError names the field it refused."""
        vector = self.param_layout.vector(values, self._params_target())
        buffer = np.zeros(max(self.param_size, 1))
        buffer[: self.param_size] = vector
        field = ctypes.c_int(-1)
        status = self._set_params(self._ws, ctypes.c_void_p(buffer.ctypes.data), ctypes.byref(field))
        if status == 0:
            return
        name = self._param_name(field.value).decode()
        try:
            self.param_layout.check(vector)  # the reason, in words
        except ParameterError as error:
            if error.field == name:
                raise
        raise ParameterError(name, f"refused by {self.name}_set_params (status {status})")

    def params(self) -> dict[str, list[float]]:
        """The parameter set last taken, by name (read back from the workspace)."""
        return self.param_layout.as_dict(self._params_target())

    def params_default(self) -> dict[str, list[float]]:
        return self.param_layout.as_dict(self.param_layout.defaults)

    def _params_target(self) -> np.ndarray:
        buffer = np.zeros(max(self.param_size, 1))
        if self._get_params(self._ws, ctypes.c_void_p(buffer.ctypes.data)) != 0:
            raise RuntimeError("the controller was closed")
        return buffer[: self.param_size].copy()

    def status_name(self, status: int) -> str:
        return self._status_name(status).decode()

    def _vector(self, value, name: str, size: int) -> np.ndarray:
        value = np.asarray(value, dtype=float).reshape(-1)
        if value.size != size:
            raise ValueError(f"{name} must have {size} values, got {value.size}")
        return value

    def _call(self, q, dq, tau_ext, ref) -> int:
        """Copy the inputs into the buffers and run the C step; returns the status."""
        if not self._open:
            raise RuntimeError("the controller was closed")
        shape = self._shape
        # Fast path: float arrays of the right shape are copied as they are.
        if type(q) is np.ndarray and q.shape == shape:
            self._q[...] = q
        else:
            self._q[...] = self._vector(q, "q", self.n)
        if type(dq) is np.ndarray and dq.shape == shape:
            self._dq[...] = dq
        else:
            self._dq[...] = self._vector(dq, "dq", self.n)
        if tau_ext is None:
            args = self._args_no_tau_ext
        else:
            args = self._args
            if type(tau_ext) is np.ndarray and tau_ext.shape == shape:
                self._tau_ext[...] = tau_ext
            else:
                self._tau_ext[...] = self._vector(tau_ext, "tau_ext", self.n)
        if ref is None:
            if self.ref_size:
                raise ValueError(f"this controller takes a reference vector of {self.ref_size} values (see ref_layout)")
        elif type(ref) is np.ndarray and ref.shape == self._ref_shape:
            self._ref_in[...] = ref
        else:
            self._ref_in[...] = self._vector(ref, "ref", self.ref_size)
        return self._step(*args)

    def step(self, q, dq, tau_ext=None, ref=None) -> StepResult:
        """One control step of the C code: τ, commanded q̈, scalings, status and the QP solution.

        The arrays of the result are new (later steps do not change them)."""
        status = self._call(q, dq, tau_ext, ref)
        return StepResult(self._tau.copy(), self._ddq_out.copy(), self._scaling_out.copy(), int(status),
                          self._solution(status), self.last_relaxed())

    def step_into(self, q, dq, tau_ext, ref, tau: np.ndarray, ddq: np.ndarray | None = None,
                  scaling: np.ndarray | None = None) -> int:
        """`step` without allocating: writes τ, the commanded q̈ and the scalings into the given
        float arrays (shapes (n,), (n,), (levels,); ddq and scaling may be None) and returns
        the status. Same inputs, checks and values as `step`; `last_x()` gives the QP solution."""
        status = self._call(q, dq, tau_ext, ref)
        tau[...] = self._tau
        if ddq is not None:
            ddq[...] = self._ddq_out
        if scaling is not None:
            scaling[...] = self._scaling_out
        return status

    def last_relaxed(self) -> list[str]:
        """The bounds that gave way in the last step (status 1), as `StepResult.relaxed`."""
        if self._info.status != STATUS_LIMITS_RELAXED:
            return []
        return [name for name, flag in zip(self.bound_names, self._info.relaxed) if flag]

    def last_x(self) -> np.ndarray:
        """The QP solution of the last step, as `StepResult.x` (a copy)."""
        return self._solution(self._info.status)

    def _solution(self, status: int) -> np.ndarray:
        """x as the Python runtime reports it: kept on success and on an invalid output, else empty."""
        if status >= 0 or status == STATUS_INVALID_OUTPUT:
            return self._x_out[: self._info.nx].copy()
        return np.zeros(0)

    def last_info(self) -> dict:
        """Solver statistics of the last step: solves, DAQP iterations and exit flag."""
        return {"solves": self._info.solves, "iterations": self._info.iterations, "exitflag": self._info.exitflag}

    def reset(self) -> None:
        """Forget the history (the last finite q)."""
        if not self._open:  # (as step and the parameters: a closed controller says so)
            raise RuntimeError("the controller was closed")
        self._reset(self._ws)

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


def _load_copy(library: Path) -> ctypes.CDLL:
    """The library, loaded from a private copy. dlopen hands back the library already loaded under
    the same path, even after the file was rebuilt: a bundle compiled again into the same folder,
    in the same process (a notebook's change-and-recompile loop), kept stepping the old code, with
    the old gains and no warning. (The copy is unlinked once mapped.)"""
    handle, copy = tempfile.mkstemp(prefix=f"{library.stem}-", suffix=library.suffix)
    try:
        with os.fdopen(handle, "wb") as out, open(library, "rb") as source:
            shutil.copyfileobj(source, out)
        return ctypes.CDLL(copy)
    finally:
        os.unlink(copy)


def load_bundle(directory: str | Path) -> CompiledController:
    return CompiledController(directory)
