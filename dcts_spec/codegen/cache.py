"""A cache of built bundles, so that `dcts simulate` and `dcts compare` build each C controller once.

An entry is a complete, built bundle in `<cache>/<spec name>-<formulation>-<key>/`, where the
key is the SHA-256 of everything that determines the bundle (`cache_key.json` in the entry
lists the parts):

- the spec: its file's bytes (which the bundle embeds), its normalized JSON and its path;
- the formulation, and the controller's robot model (`model.model_digest`: the spec's robot, or
  a modified one for model mismatch, with the recorded changes such as the mass scale);
- the generator: dcts-spec's version and a digest of the package sources that generate the
  bundle (so an edited generator or formulation never reuses an old bundle);
- the toolchain: CasADi, the DAQP library and headers it links (digest of the archive), NumPy
  and Pinocchio (golden vectors), the compiler (path and `--version`) and the make variables
  taken from the environment (CC, CFLAGS, OPT, LDFLAGS, DAQP_*, MAKEFLAGS assignments).

The cache lives in `$DCTS_CACHE_DIR`, else `$XDG_CACHE_HOME/dcts/bundles`, else
`~/.cache/dcts/bundles`. Reuse is safe:

- an entry is used only if it is complete: its key file matches, its manifest says it was
  built, and its library loads and has the manifest's struct sizes;
- a bundle is built in a private temporary directory inside the cache and renamed into place
  in one step, so readers never see a partial entry; concurrent builds of the same key are
  serialized with a lock file (where `fcntl` exists) and, should two still race, the first
  rename wins and the other keeps the winner's entry;
- a broken entry is moved aside and rebuilt; if its library was already loaded into this
  process (whose dynamic loader would keep returning it), the bundle is rebuilt privately for
  this process instead, and the next process rebuilds the entry.

At most `max_entries` entries are kept (least recently used first out).
"""

from __future__ import annotations

import errno
import hashlib
import json
import os
import platform
import shlex
import shutil
import subprocess
import sys
import tempfile
import time
import uuid
import weakref
from contextlib import contextmanager
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import casadi

from ..robot.model import Robot
from ..spec import Spec, load_spec
from .build import cache_root, compile_bundle, compiler_identity
from .bundle import DAQP_VERSION, GENERATOR, CodegenError, spec_digest, version
from .loader import CompiledController, load_bundle
from .model import model_digest

try:  # POSIX: serialize builds of the same entry (an optimization; renames keep it correct anyway)
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None

CACHE_ENV = "DCTS_CACHE_DIR"
KEY_FILE = "cache_key.json"
KEY_FORMAT = 1
MAX_ENTRIES = 64
# Make variables of the bundle's Makefile that the environment can set (`VAR ?= ...`).
MAKE_ENVIRONMENT = ("CC", "CFLAGS", "OPT", "LDFLAGS", "CPPFLAGS", "DAQP_SRC", "DAQP_INC", "DAQP_LIB")
STALE_SECONDS = 6 * 3600  # temporary and discarded directories older than this are removed
RECENT_SECONDS = 600  # entries used this recently are never pruned (another run may be loading them)


def default_cache_dir() -> Path:
    """`$DCTS_CACHE_DIR`, else `$XDG_CACHE_HOME/dcts/bundles`, else `~/.cache/dcts/bundles`."""
    explicit = os.environ.get(CACHE_ENV)
    if explicit:
        return Path(explicit).expanduser()
    return cache_root() / "bundles"


# -- the key ---------------------------------------------------------------------------------------


def _sha256_file(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


@lru_cache(maxsize=1)
def source_digest() -> str:
    """SHA-256 of the package sources the bundle is generated from: every module but the
    simulation, analysis and command-line ones, and the C templates."""
    base = Path(__file__).resolve().parents[1]  # the dcts_spec package
    h = hashlib.sha256()
    files = sorted(p for p in base.rglob("*") if p.is_file() and (p.suffix == ".py" or "templates" in p.parts))
    for path in files:
        rel = path.relative_to(base).as_posix()
        if rel.startswith(("sim/", "analysis/")) or rel == "cli.py" or "__pycache__" in rel:
            continue
        h.update(rel.encode() + b"\0" + hashlib.sha256(path.read_bytes()).digest())
    return h.hexdigest()


def _daqp_identity() -> dict:
    """The DAQP whose sources every bundle compiles (downloaded once, by version)."""
    return {"version": DAQP_VERSION}


def _module_version(name: str) -> str | None:
    module = sys.modules.get(name)
    if module is None:
        try:
            module = __import__(name)
        except ImportError:
            return None
    return getattr(module, "__version__", None)


def toolchain() -> dict:
    """The parts of the key that do not depend on the spec (environment read on every call)."""
    makeflags = [w for w in shlex.split(os.environ.get("MAKEFLAGS", "")) if "=" in w and not w.startswith("-")]
    return {
        "casadi": casadi.__version__,
        "daqp": _daqp_identity(),
        "numpy": _module_version("numpy"),
        "pinocchio": _module_version("pinocchio"),
        "python": platform.python_version(),
        "machine": platform.machine(),
        "compiler": compiler_identity(os.environ.get("CC") or "cc"),
        "make_environment": {k: os.environ[k] for k in MAKE_ENVIRONMENT if k in os.environ},
        "makeflags": makeflags,
    }


@dataclass(frozen=True)
class CacheKey:
    parts: dict
    digest: str
    entry: str  # directory name in the cache

    @classmethod
    def of(cls, parts: dict, spec_name: str, formulation: str) -> CacheKey:
        digest = hashlib.sha256(json.dumps(parts, sort_keys=True).encode()).hexdigest()
        return cls(parts, digest, f"{spec_name}-{formulation}-{digest[:20]}")


# -- the cache -------------------------------------------------------------------------------------


class BundleCache:
    """Built bundles, keyed by what determines them; `load` returns the loaded C controller.

        cache = BundleCache()                      # $DCTS_CACHE_DIR or ~/.cache/dcts/bundles
        controller = cache.load(spec, "dcts")      # built on the first call, loaded afterwards
        cache.last_hit                             # whether that came from the cache
    """

    def __init__(self, directory: str | Path | None = None, max_entries: int = MAX_ENTRIES):
        self.directory = Path(directory).expanduser() if directory is not None else default_cache_dir()
        self.max_entries = max_entries
        self.last_hit: bool | None = None

    def __repr__(self) -> str:
        return f"BundleCache({str(self.directory)!r})"

    # -- keys ------------------------------------------------------------------------------------

    def key(self, spec: Spec | str | Path, formulation: str | None = None, robot: Robot | None = None,
            model_changes: dict | None = None) -> CacheKey:
        """The key of the bundle `compile_c(spec, ..., formulation, robot=robot)` would build."""
        spec = spec if isinstance(spec, Spec) else load_spec(spec)
        if robot is None:
            from ..validate import validate_spec

            robot = validate_spec(spec).robot
        formulation = formulation or spec.controller.formulation
        file = Path(spec.source.file) if spec.source.file else None
        has_file = file is not None and file.is_file()
        parts = {
            "format": KEY_FORMAT,
            "generator": GENERATOR,
            "dcts_version": version(),
            "dcts_sources": source_digest(),
            "spec_sha256": spec_digest(spec),
            "spec_json_sha256": hashlib.sha256(spec.model_dump_json().encode()).hexdigest(),
            "spec_file": str(file.resolve()) if has_file else str(spec.source.file or ""),
            "formulation": formulation,
            "model_sha256": model_digest(robot),
            "model_changes": dict(model_changes or {}),
            "options": {"golden_count": None, "target": "host"},
            "toolchain": toolchain(),
        }
        return CacheKey.of(parts, spec.name, formulation)

    # -- entries ---------------------------------------------------------------------------------

    def entries(self) -> list[Path]:
        if not self.directory.is_dir():
            return []
        return sorted(p for p in self.directory.iterdir() if p.is_dir() and not p.name.startswith("."))

    def _complete(self, entry: Path, key: CacheKey) -> bool:
        """Everything but loading: the key file matches, the manifest says built, the library is there."""
        try:
            stored = json.loads((entry / KEY_FILE).read_text())
            manifest = json.loads((entry / "manifest.json").read_text())
        except (OSError, ValueError):
            return False
        return (stored.get("digest") == key.digest and manifest.get("generator") == GENERATOR
                and manifest.get("built") is True and (entry / str(manifest.get("library", ""))).is_file())

    def _open(self, entry: Path) -> CompiledController:
        try:
            controller = load_bundle(entry)
        except OSError as exc:  # the library does not load (truncated, wrong architecture)
            raise CodegenError(f"{entry}: {exc}") from None
        try:
            os.utime(entry / KEY_FILE)  # last use, for pruning
        except OSError:
            pass
        return controller

    def lookup(self, key: CacheKey, repair: bool = False) -> CompiledController | None:
        """The entry's controller if the entry is complete and loads; None if there is none.

        With `repair` (under the entry's lock), an incomplete entry is moved aside. An entry
        whose library does not load is moved aside and CodegenError raised (its library may be
        loaded into this process)."""
        entry = self.directory / key.entry
        if not entry.exists():
            return None
        if not self._complete(entry, key):
            if repair:
                self._discard(entry)
            return None
        try:
            return self._open(entry)
        except CodegenError:
            self._discard(entry)
            raise

    def load(self, spec: Spec | str | Path, formulation: str | None = None, robot: Robot | None = None,
             model_changes: dict | None = None) -> CompiledController:
        """The C controller of the spec, from the cache or built into it (then kept)."""
        spec = spec if isinstance(spec, Spec) else load_spec(spec)
        key = self.key(spec, formulation, robot, model_changes)
        entry = self.directory / key.entry
        found = self._reuse(spec, key, robot, model_changes)
        if found is not None:
            return found
        self.directory.mkdir(parents=True, exist_ok=True)
        with self._lock(key):
            found = self._reuse(spec, key, robot, model_changes, repair=True)  # built by another process meanwhile?
            if found is not None:
                return found
            self.last_hit = False
            staging = Path(tempfile.mkdtemp(prefix=f".tmp-{key.entry}-", dir=self.directory))
            try:
                bundle = self._build(spec, key, robot, model_changes, staging / "bundle")
                self._install(bundle, entry, key)
            finally:
                shutil.rmtree(staging, ignore_errors=True)
        self._prune(keep=entry)
        return self._open(entry)

    def _reuse(self, spec: Spec, key: CacheKey, robot: Robot | None, model_changes: dict | None,
               repair: bool = False) -> CompiledController | None:
        """The entry's controller (a hit); a private build if the entry is broken but loaded into
        this process (see the module doc); None if there is no complete entry."""
        try:
            found = self.lookup(key, repair)
        except CodegenError:
            self.last_hit = False
            return self._private_build(spec, key, robot, model_changes)
        if found is not None:
            self.last_hit = True
        return found

    # -- building --------------------------------------------------------------------------------

    def _build(self, spec: Spec, key: CacheKey, robot: Robot | None, model_changes: dict | None, out: Path) -> Path:
        compile_bundle(spec, out, formulation=key.parts["formulation"], robot=robot, model_changes=model_changes)
        record = {"digest": key.digest, "created": time.time(), "parts": key.parts}
        (out / KEY_FILE).write_text(json.dumps(record, indent=2, sort_keys=True) + "\n")
        return out

    def _private_build(self, spec: Spec, key: CacheKey, robot: Robot | None,
                       model_changes: dict | None) -> CompiledController:
        self.directory.mkdir(parents=True, exist_ok=True)
        staging = Path(tempfile.mkdtemp(prefix=f".tmp-{key.entry}-", dir=self.directory))
        try:
            controller = load_bundle(self._build(spec, key, robot, model_changes, staging / "bundle"))
        except BaseException:
            shutil.rmtree(staging, ignore_errors=True)
            raise
        weakref.finalize(controller, shutil.rmtree, staging, True)
        return controller

    def _install(self, bundle: Path, entry: Path, key: CacheKey) -> None:
        """Rename the finished bundle into place; a complete entry another process installed
        meanwhile is kept (ours is dropped), an incomplete one is replaced."""
        for _ in range(3):
            try:
                os.rename(bundle, entry)
                return
            except OSError as exc:
                if exc.errno not in (errno.EEXIST, errno.ENOTEMPTY, errno.EISDIR):
                    raise CodegenError(f"cannot install the bundle into the cache at {entry}: {exc}") from None
            if self._complete(entry, key):
                return
            self._discard(entry)
        raise CodegenError(f"cannot install the bundle into the cache at {entry}: it keeps changing")

    def _discard(self, entry: Path) -> None:
        """Move an entry aside (atomically) and delete it."""
        trash = entry.with_name(f".trash-{entry.name}-{os.getpid()}-{uuid.uuid4().hex[:8]}")
        try:
            os.rename(entry, trash)
        except OSError:
            return  # gone already (another process discarded or replaced it)
        shutil.rmtree(trash, ignore_errors=True)

    @contextmanager
    def _lock(self, key: CacheKey):
        if fcntl is None:
            yield
            return
        path = self.directory / f".lock-{key.entry}"
        with open(path, "a") as handle:
            fcntl.flock(handle, fcntl.LOCK_EX)
            try:
                yield
            finally:
                fcntl.flock(handle, fcntl.LOCK_UN)

    # -- housekeeping ----------------------------------------------------------------------------

    def _prune(self, keep: Path | None = None) -> None:
        """Keep the `max_entries` most recently used entries; remove stale temporary folders."""
        now = time.time()
        for path in self.directory.glob(".*"):
            try:
                age = now - path.stat().st_mtime
            except OSError:
                continue
            if age > STALE_SECONDS and path.name.startswith((".tmp-", ".trash-")):
                shutil.rmtree(path, ignore_errors=True)
            elif path.name.startswith(".lock-") and not (self.directory / path.name[len(".lock-"):]).exists() \
                    and age > STALE_SECONDS:
                path.unlink(missing_ok=True)

        def last_use(entry: Path) -> float:
            try:
                return (entry / KEY_FILE).stat().st_mtime
            except OSError:
                return 0.0

        entries = sorted(self.entries(), key=last_use, reverse=True)
        for entry in entries[self.max_entries:]:
            if entry != keep and now - last_use(entry) > RECENT_SECONDS:
                self._discard(entry)
