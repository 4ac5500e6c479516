"""Compile generated C kernels into shared libraries and call them through cffi (ABI mode).

    module = load_source(path, cache)     # path: a generated .c file; cache: a folder
    module.forces_and_stiffness(D, u, f, K, flags)

The runtime chooses the source (the committed ``generated/c/<name>.c`` or a file
generated on demand) and the cache folder. Libraries live in
``<cache>/c/<name>-<hash>.so`` where the hash covers the source, the
flags, the compiler and the CPU (``-march=native``); each has a sidecar
``<so>.sha256`` that is checked before loading, so a truncated or corrupted
library is rebuilt instead of crashing the process. Builds go to a temporary
file in the same folder and are renamed into place, under a file lock per
library (``<cache>/c/.<so>.lock``): of the processes that need a kernel at once
(pytest-xdist or dask workers, two runs), one compiles it and the others wait
for it and load its library.
"""
from __future__ import annotations

import contextlib
import hashlib
import json
import os
import platform
import shlex
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from functools import lru_cache
from pathlib import Path

import numpy as np

from ..protocol import KERNEL_FUNCTIONS, BackendError, check_metadata

CFLAGS = ("-O3", "-march=native", "-fPIC", "-shared", "-std=c99", "-fno-math-errno")
LIBS = ("-lm",)
METADATA_TAG = "tensormass-metadata"

# One record per library compiled by this process (name, path, seconds, peak compiler memory in MB).
COMPILATIONS: list[dict] = []

_lock = threading.Lock()
_loaded: dict[str, "CModule"] = {}


# -- compiler ---------------------------------------------------------------------------------
def compiler() -> list[str]:
    """The C compiler command: $CC (may hold arguments, e.g. "ccache gcc"), else cc, gcc or clang."""
    cc = os.environ.get("CC", "").strip()
    tried = [cc] if cc else ["cc", "gcc", "clang"]
    for candidate in tried:
        words = shlex.split(candidate)
        path = shutil.which(words[0]) if words else None
        if path:
            return [path] + words[1:]
    what = f"$CC={cc!r}" if cc else ", ".join(tried)
    raise BackendError(
        f"no C compiler was found (tried {what}): install gcc (e.g. `apt-get install gcc`) "
        f"or set $CC, or use backend=\"numba\"")


def default_backend() -> str:
    """The kernel backend of a scene that names none: "c" when a C compiler is found (gcc builds a
    kernel in about 1 s, cached in the user cache), else "numba" (6 to 40 s per kernel at its first
    call, cached too). Both give the same results (tests/generator/test_backends_agree.py)."""
    try:
        compiler()
    except BackendError:
        return "numba"
    return "c"


def cflags() -> list[str]:
    """CFLAGS, or $TENSORMASS_CFLAGS when set (-fPIC -shared are added when it lacks them)."""
    override = os.environ.get("TENSORMASS_CFLAGS")
    if override is None:
        return list(CFLAGS)
    flags = shlex.split(override)
    return flags + [f for f in ("-fPIC", "-shared") if f not in flags]


@lru_cache(maxsize=None)
def _compiler_version(command: tuple) -> str:
    try:
        done = subprocess.run(list(command) + ["--version"], capture_output=True, text=True, timeout=60)
    except (OSError, subprocess.SubprocessError) as error:
        raise BackendError(f"C compiler {' '.join(command)!r} does not run: {error}") from None
    return done.stdout + done.stderr


@lru_cache(maxsize=None)
def _cpu_signature() -> str:
    """What -march=native depends on: the machine and, on Linux, the CPU model and feature flags."""
    parts = [platform.machine(), platform.system()]
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as handle:
            seen = set()
            for line in handle:
                key = line.split(":", 1)[0].strip()
                if key in ("model name", "flags", "Features", "CPU part") and key not in seen:
                    seen.add(key)
                    parts.append(line.strip())
    except OSError:
        pass
    return "\n".join(parts)


# -- metadata ---------------------------------------------------------------------------------
def read_metadata(path: Path) -> dict:
    """The metadata comment of a generated C file."""
    try:
        with open(path, encoding="utf-8") as handle:
            head = "".join(handle.readline() for _ in range(10))
    except (OSError, UnicodeDecodeError) as error:
        raise BackendError(f"{path}: cannot read the kernel metadata ({error})") from None
    return parse_metadata(head, path)


def parse_metadata(source: str, where="source") -> dict:
    """The JSON block the template writes in a comment near the top of every C kernel."""
    for line in source.splitlines()[:10]:
        start = line.find(METADATA_TAG)
        if start >= 0:
            text = line[start + len(METADATA_TAG):].rsplit("*/", 1)[0]
            try:
                meta = json.loads(text)
            except ValueError:
                break
            return check_metadata(meta, where)
    raise BackendError(f"{where}: no valid '{METADATA_TAG}' comment (not a tensormass C kernel?)")


# -- building ---------------------------------------------------------------------------------
def library_path(name: str, source: str, command: list[str], flags: list[str], cache: Path) -> Path:
    h = hashlib.sha256()
    for part in (source, "\0".join(flags), "\0".join(command), _compiler_version(tuple(command)), _cpu_signature()):
        h.update(part.encode())
        h.update(b"\0\0")
    return Path(cache) / "c" / f"{name}-{h.hexdigest()[:16]}.so"


def _file_hash(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _sidecar(lib: Path) -> Path:
    return lib.with_name(lib.name + ".sha256")


def _verified(lib: Path) -> bool:
    """The library exists and its bytes hash to what its sidecar recorded at build time."""
    try:
        expected = _sidecar(lib).read_text(encoding="ascii").split()[0]
        return _file_hash(lib) == expected
    except (OSError, IndexError, UnicodeDecodeError):
        return False


def _write_atomic(path: Path, data: bytes) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as handle:
            handle.write(data)
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


# Runs the compiler as its only child and reports the peak memory of it and its children
# (cc1, as, ld). A direct child of this (large) process would report this process's own
# memory too: Linux carries ru_maxrss through fork and exec.
_MEASURE = """
import resource, subprocess, sys
code = subprocess.run(sys.argv[2:]).returncode
with open(sys.argv[1], "w") as out:
    out.write(str(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss))
sys.exit(code)
"""


def _run_measured(cmd: list[str]):
    """Run cmd; returns (exit code, output text, seconds, peak memory in MB of the compiler)."""
    with tempfile.TemporaryDirectory(prefix="tensormass-cc-") as folder:
        rss_file = os.path.join(folder, "maxrss")
        log_file = os.path.join(folder, "log")
        measured = bool(sys.executable)
        full = [sys.executable, "-I", "-S", "-c", _MEASURE, rss_file] + cmd if measured else cmd
        with open(log_file, "wb") as log:
            start = time.perf_counter()
            proc = subprocess.Popen(full, stdin=subprocess.DEVNULL, stdout=log, stderr=subprocess.STDOUT,
                                    start_new_session=True)
            try:
                code = proc.wait()
            except BaseException:
                _kill_group(proc)
                raise
            seconds = time.perf_counter() - start
        with open(log_file, "rb") as log:
            output = log.read().decode("utf-8", errors="replace")
        maxrss = 0.0
        if measured:
            try:
                with open(rss_file, encoding="ascii") as handle:
                    # ru_maxrss: kilobytes on Linux, bytes on macOS.
                    maxrss = int(handle.read()) / ((1 << 20) if sys.platform == "darwin" else (1 << 10))
            except (OSError, ValueError):
                pass
    return code, output, seconds, maxrss


def _kill_group(proc) -> None:
    try:
        os.killpg(proc.pid, 9)
    except OSError:
        proc.kill()
    proc.wait()


@contextlib.contextmanager
def _build_lock(lib: Path):
    """An exclusive lock on <folder>/.<library>.lock while one process builds the library.
    Without fcntl (not POSIX) there is no lock: the writes are atomic anyway, so processes that
    race only compile twice."""
    try:
        import fcntl
    except ImportError:
        yield
        return
    with open(lib.parent / f".{lib.name}.lock", "a+b") as handle:
        fcntl.flock(handle.fileno(), fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle.fileno(), fcntl.LOCK_UN)


def build(name: str, source: Path, lib: Path, command: list[str], flags: list[str], writable=None,
          rebuild: bool = False) -> dict | None:
    """Compile source into lib (atomically, with its sidecar hash); returns the compile record,
    or None when another process built a valid lib while this one waited for the build lock
    (rebuild=True compiles anyway: a library that verifies but does not load).
    writable(folder, needed_for), when given, checks the folder first (the runtime's clear
    error for a read-only cache); else the folder is created."""
    if writable is not None:
        writable(lib.parent, f"compiling C kernel {name}")
    else:
        lib.parent.mkdir(parents=True, exist_ok=True)
    with _build_lock(lib):
        if not rebuild and _verified(lib):
            return None
        return _compile(name, source, lib, command, flags)


def _compile(name: str, source: Path, lib: Path, command: list[str], flags: list[str]) -> dict:
    fd, tmp = tempfile.mkstemp(dir=lib.parent, prefix=f".{lib.stem}.", suffix=".so.tmp")
    os.close(fd)
    try:
        cmd = command + flags + ["-o", tmp, str(source)] + list(LIBS)
        code, output, seconds, maxrss = _run_measured(cmd)
        if code != 0:
            tail = "\n".join(output.strip().splitlines()[-30:])
            raise BackendError(f"compiling C kernel {name} failed (exit code {code}):\n"
                                  f"  {shlex.join(cmd)}\n{tail}")
        digest = _file_hash(Path(tmp))
        os.chmod(tmp, 0o755)
        os.replace(tmp, lib)
    finally:
        Path(tmp).unlink(missing_ok=True)
    _write_atomic(_sidecar(lib), f"{digest}  {lib.name}\n".encode("ascii"))
    record = {"name": name, "library": str(lib), "seconds": seconds, "maxrss_mb": maxrss}
    COMPILATIONS.append(record)
    return record


# -- loading ----------------------------------------------------------------------------------
def _cdef(prefix: str) -> str:
    return f"""
void {prefix}_constants(long n, const double *X, const double *params, double *D, int *flags);
void {prefix}_energy(long n, const double *D, const double *u, double *out, int *flags);
void {prefix}_forces(long n, const double *D, const double *u, double *f, int *flags);
void {prefix}_stiffness(long n, const double *D, const double *u, double *K, int *flags);
void {prefix}_forces_and_stiffness(long n, const double *D, const double *u, double *f, double *K, int *flags);
void {prefix}_forces_and_stiffness_scatter(long n, const double *D, const double *U, const long *cells,
    const int *pos, double *fg, double *data, int *flags);
void {prefix}_stress(long n, const double *D, const double *u, double *S, int *flags);
"""


class CModule:
    """A compiled kernel with the attributes and functions of a generated numba module."""

    def __init__(self, meta: dict, ffi, lib, library: Path, source: Path, compiled: dict | None):
        self._ffi, self._lib = ffi, lib
        prefix = meta["name"]
        self._functions = {kind: getattr(lib, f"{prefix}_{kind}") for kind in KERNEL_FUNCTIONS}
        self.METADATA = meta
        self.NAME = meta["name"]
        self.LIBRARY = library
        self.SOURCE = source
        self.COMPILED = compiled is not None
        self.COMPILE_SECONDS = compiled["seconds"] if compiled else 0.0
        self.COMPILE_MAXRSS_MB = compiled["maxrss_mb"] if compiled else 0.0
        self._n_dofs = int(meta["n_dofs"])
        self._n_coords = int(meta["n_nodes"]) * int(meta["dim"])     # X: fewer than the dofs for shells
        self._n_constants = int(meta["n_constants"])
        self._n_parameters = len(meta["parameters"])
        self._n_record = int(meta["n_points"]) * int(meta["stress_record"]["size"])

    def __repr__(self):
        return f"<C kernel {self.NAME} from {self.LIBRARY}>"

    def _pointer(self, array, ctype: str, dtype, per_element: int, n: int, what: str, writable: bool):
        if not isinstance(array, np.ndarray) or array.dtype != dtype or not array.flags.c_contiguous:
            raise BackendError(f"{self.NAME}: {what} must be a C-contiguous {np.dtype(dtype).name} numpy array")
        if array.size != n * per_element:
            raise BackendError(f"{self.NAME}: {what} has {array.size} values, expected {n} x {per_element}")
        if writable and not array.flags.writeable:
            raise BackendError(f"{self.NAME}: {what} is read-only")
        return self._ffi.from_buffer(f"{ctype}[]", array, require_writable=writable)

    def _double(self, array, per_element, n, what, writable=False):
        return self._pointer(array, "double", np.float64, per_element, n, what, writable)

    def _flags(self, flags, n):
        return self._pointer(flags, "int", np.int32, 1, n, "flags", True)

    def constants(self, X, params, D, flags):
        n = len(X)
        self._functions["constants"](
            n, self._double(X, self._n_coords, n, "X"), self._double(params, self._n_parameters, n, "params"),
            self._double(D, self._n_constants, n, "D", True), self._flags(flags, n))

    def energy(self, D, u, out, flags):
        n = len(D)
        self._functions["energy"](
            n, self._double(D, self._n_constants, n, "D"), self._double(u, self._n_dofs, n, "u"),
            self._double(out, 1, n, "out", True), self._flags(flags, n))

    def forces(self, D, u, f, flags):
        n = len(D)
        self._functions["forces"](
            n, self._double(D, self._n_constants, n, "D"), self._double(u, self._n_dofs, n, "u"),
            self._double(f, self._n_dofs, n, "f", True), self._flags(flags, n))

    def stiffness(self, D, u, K, flags):
        n = len(D)
        self._functions["stiffness"](
            n, self._double(D, self._n_constants, n, "D"), self._double(u, self._n_dofs, n, "u"),
            self._double(K, self._n_dofs ** 2, n, "K", True), self._flags(flags, n))

    def forces_and_stiffness(self, D, u, f, K, flags):
        n = len(D)
        self._functions["forces_and_stiffness"](
            n, self._double(D, self._n_constants, n, "D"), self._double(u, self._n_dofs, n, "u"),
            self._double(f, self._n_dofs, n, "f", True), self._double(K, self._n_dofs ** 2, n, "K", True),
            self._flags(flags, n))

    def stress(self, D, u, S, flags):
        """S (n, n_points, stress_record size): one record per element and point (the metadata's layout)."""
        n = len(D)
        self._functions["stress"](
            n, self._double(D, self._n_constants, n, "D"), self._double(u, self._n_dofs, n, "u"),
            self._double(S, self._n_record, n, "S", True), self._flags(flags, n))

    def forces_and_stiffness_scatter(self, D, U, cells, pos, fg, data, flags):
        """The fused evaluation and scatter (see the C template): U (n_points, dim) float64,
        cells (n, n_nodes) int64, pos (n, n_dofs, n_nodes) int32, fg (U.size,), data (nnz,).
        Only types and sizes are checked here; the Kernel API checks index ranges."""
        n = len(D)
        n_nodes = self._n_dofs // int(self.METADATA["dofs_per_node"])
        if U.size != fg.size:
            raise BackendError(f"{self.NAME}: fg has {fg.size} values, U {U.size}: they must match")
        self._functions["forces_and_stiffness_scatter"](
            n, self._double(D, self._n_constants, n, "D"), self._double(U, U.size, 1, "U"),
            self._pointer(cells, "long", np.int64, n_nodes, n, "cells", False),
            self._pointer(pos, "int", np.int32, self._n_dofs * n_nodes, n, "pos", False),
            self._double(fg, fg.size, 1, "fg", True), self._double(data, data.size, 1, "data", True),
            self._flags(flags, n))


def _open(meta: dict, lib: Path, source: Path, compiled):
    import cffi
    ffi = cffi.FFI()
    ffi.cdef(_cdef(meta["name"]))
    handle = ffi.dlopen(str(lib))
    return CModule(meta, ffi, handle, lib, source, compiled)


def build_missing(sources, cache: Path, writable=None) -> list[dict]:
    """Compile the libraries of several generated C files that the cache lacks, one compiler per
    core at once (a scene's kernels: 4 kernels of 5 s each take 10 s on 2 cores instead of 20 s);
    load_source then finds them built.  Returns the compile records."""
    command, flags = compiler(), cflags()
    todo, seen = [], set()
    for source in map(Path, sources):
        text = source.read_text(encoding="utf-8")
        name = parse_metadata(text, source).get("name")
        lib = library_path(name, text, command, flags, cache)
        if lib not in seen and not _verified(lib):
            seen.add(lib)
            todo.append((name, source, lib))
    if len(todo) <= 1:
        records = [build(name, source, lib, command, flags, writable) for name, source, lib in todo]
    else:
        # threads suffice: each waits on its compiler process, which runs on a core of its own
        with ThreadPoolExecutor(max_workers=min(len(todo), os.cpu_count() or 1)) as pool:
            jobs = [pool.submit(build, name, source, lib, command, flags, writable) for name, source, lib in todo]
            records = [job.result() for job in jobs]
    return [record for record in records if record is not None]


def load_source(source: Path, cache: Path, expected_name: str | None = None, writable=None) -> CModule:
    """Compile (or take from <cache>/c) and load one generated C file."""
    command = compiler()
    flags = cflags()
    source = Path(source)
    text = source.read_text(encoding="utf-8")
    meta = parse_metadata(text, source)
    name = meta.get("name")
    if expected_name is not None and name != expected_name:
        raise BackendError(f"{source}: holds kernel {name!r}, expected {expected_name!r}")
    lib = library_path(name, text, command, flags, cache)
    with _lock:
        module = _loaded.get(str(lib))
        if module is not None and _verified(lib):
            return module
        compiled = None
        if not _verified(lib):
            compiled = build(name, source, lib, command, flags, writable)
        try:
            module = _open(meta, lib, source, compiled)
        except (OSError, AttributeError):
            if compiled is not None:
                raise
            # The hash matched but the library does not load (or lacks a symbol): build it again.
            compiled = build(name, source, lib, command, flags, writable, rebuild=True)
            module = _open(meta, lib, source, compiled)
        _loaded[str(lib)] = module
        return module
