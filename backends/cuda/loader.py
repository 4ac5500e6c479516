"""Load a generated CUDA file: on a GPU (NVRTC compiles it, CuPy launches it), or on the host as C.

    module = load_source(path, cache)        # a GPU, CuPy and NVRTC: tensormass[cuda]
    module.forces_and_stiffness(D, u, f, K, flags)   # numpy arrays (copied) or CuPy arrays (in place)
    cubin, log = compile_cubin(path, "sm_90", cache) # NVRTC alone, no GPU needed
    shim = load_host_shim(path, cache)       # no GPU: the same file compiled by the C compiler

Compiled kernels live in <cache>/cuda/<name>-<hash>-<arch>.cubin, the hash covering the source, the
NVRTC options and NVRTC's version; like the C backend's libraries each has a sidecar hash that is
checked before loading, and a build goes to a temporary file renamed into place under a file lock.
"""
from __future__ import annotations

import hashlib
import re
import threading
from pathlib import Path

import numpy as np

from ..c import loader as c_loader
from ..protocol import KERNEL_FUNCTIONS, BackendError

# One thread per element; 128 threads a block keeps the big kernels (a tetra10 K is 900 doubles of
# thread-local scratch) within the registers and local memory of any architecture.
THREADS_PER_BLOCK = 128
# -diag-suppress=177: a law's constant unused by one function is not worth a warning per file.
NVRTC_OPTIONS = ("-std=c++14", "--ptxas-options=-v", "-diag-suppress=177")
SHIM_FLAGS = ("-x", "c", "-DTM_HOST_SHIM")
INSTALL_HINT = "pip install 'tensormass[cuda]' (CuPy and NVRTC for CUDA 12)"

_lock = threading.Lock()
_loaded: dict = {}


def read_metadata(path: Path) -> dict:
    """The metadata comment (the C backend's format) of a generated CUDA file."""
    return c_loader.read_metadata(path)


def cupy(instead: str = "use backend = \"c\""):
    """CuPy with a usable device, or BackendError saying what is missing, how to get it, and (instead)
    what to do without it."""
    try:
        import cupy as cp
    except ImportError:
        raise BackendError(f"CUDA needs CuPy and an NVIDIA GPU: {INSTALL_HINT}, or {instead}") from None
    try:
        count = cp.cuda.runtime.getDeviceCount()
    except Exception as error:          # CuPy raises its own runtime errors when there is no driver
        raise BackendError(f"CuPy found no usable CUDA device ({error}); {instead}") from None
    if count < 1:
        raise BackendError(f"CuPy found no CUDA device; {instead}")
    return cp


def _nvrtc():
    try:
        from cuda.bindings import nvrtc
    except ImportError:
        raise BackendError(f"compiling CUDA kernels needs NVRTC: {INSTALL_HINT}") from None
    return nvrtc


def _checked(result, what: str, log: str = ""):
    error, *values = result
    if int(error) != 0:
        raise BackendError(f"NVRTC {what} failed ({error.name if hasattr(error, 'name') else error})"
                           + (f":\n{log}" if log else ""))
    return values[0] if len(values) == 1 else values


def _nvrtc_compile(text: str, name: str, arch: str) -> tuple[bytes, str]:
    """The cubin of one CUDA source for arch (e.g. "sm_90"), and NVRTC's log."""
    nvrtc = _nvrtc()
    program = _checked(nvrtc.nvrtcCreateProgram(text.encode(), f"{name}.cu".encode(), 0, [], []), "create")
    try:
        options = [o.encode() for o in NVRTC_OPTIONS + (f"--gpu-architecture={arch}",)]
        compiled = nvrtc.nvrtcCompileProgram(program, len(options), options)
        size = _checked(nvrtc.nvrtcGetProgramLogSize(program), "log size")
        log = b" " * size
        nvrtc.nvrtcGetProgramLog(program, log)
        log = log.rstrip(b"\0 ").decode(errors="replace")
        _checked(compiled, f"compiling kernel {name} for {arch}", log[-3000:])
        size = _checked(nvrtc.nvrtcGetCUBINSize(program), "cubin size")
        cubin = b" " * size
        _checked(nvrtc.nvrtcGetCUBIN(program, cubin), "cubin")
        return cubin, log
    finally:
        nvrtc.nvrtcDestroyProgram(program)


def cubin_path(name: str, text: str, arch: str, cache: Path) -> Path:
    version = ".".join(map(str, _checked(_nvrtc().nvrtcVersion(), "version")))
    h = hashlib.sha256("\0".join((text, *NVRTC_OPTIONS, arch, version)).encode()).hexdigest()[:16]
    return Path(cache) / "cuda" / f"{name}-{h}-{arch}.cubin"


def compile_cubin(source: Path, arch: str, cache: Path, writable=None, name: str | None = None
                  ) -> tuple[Path, dict | None]:
    """The cached cubin of a CUDA file for arch, compiled by NVRTC when missing (no GPU is needed to
    compile). name: the file's kernel name (read from a generated file's metadata when None).
    Returns (path, record): record None when the cache had it, else the name, seconds and the
    per-function registers and spills ptxas reported (see resources)."""
    import time
    source = Path(source)
    text = source.read_text(encoding="utf-8")
    name = name or c_loader.parse_metadata(text, source)["name"]
    path = cubin_path(name, text, arch, cache)
    if writable is not None:
        writable(path.parent, f"compiling CUDA kernel {name}")
    else:
        path.parent.mkdir(parents=True, exist_ok=True)
    with c_loader._build_lock(path):
        if c_loader._verified(path):
            return path, None
        start = time.perf_counter()
        cubin, log = _nvrtc_compile(text, name, arch)
        seconds = time.perf_counter() - start
        c_loader._write_atomic(path, cubin)
        c_loader._write_atomic(c_loader._sidecar(path), f"{c_loader._file_hash(path)}  {path.name}\n".encode())
    return path, {"name": name, "arch": arch, "seconds": seconds, "resources": resources(log)}


def resources(log: str) -> dict:
    """Per function (a generated kernel's constants, energy, ...; the solver's own names otherwise):
    registers, spill bytes (stores) and stack frame bytes, read from ptxas' verbose report in NVRTC's log."""
    out, current = {}, None
    for line in log.splitlines():
        m = (re.search(r"Function properties for \w+?_(" + "|".join(KERNEL_FUNCTIONS) + r")$", line.strip())
             or re.search(r"Function properties for (tm_\w+)$", line.strip()))
        if m:
            current = out.setdefault(m.group(1), {})
            continue
        if current is None:
            continue
        m = re.search(r"(\d+) bytes stack frame, (\d+) bytes spill stores", line)
        if m:
            current["stack_bytes"], current["spill_bytes"] = int(m.group(1)), int(m.group(2))
        m = re.search(r"Used (\d+) registers", line)
        if m:
            current["registers"] = int(m.group(1))
    # "Function properties for X_forces" also matches X_forces_and_stiffness's prefix: the regex is
    # anchored at the end of the line, so each kernel keeps its own entry.
    return out


def device_arch(cp) -> str:
    return "sm_" + cp.cuda.Device().compute_capability


def load_source(source: Path, cache: Path, writable=None) -> "CudaModule":
    """Compile (or take from the cache) and load one generated CUDA file on the current device."""
    cp = cupy()
    source = Path(source)
    meta = read_metadata(source)
    arch = device_arch(cp)
    with _lock:
        path, record = compile_cubin(source, arch, cache, writable)
        key = (str(path), cp.cuda.runtime.getDevice())
        module = _loaded.get(key)
        if module is None:
            try:
                raw = cp.RawModule(path=str(path))
                functions = {kind: raw.get_function(f"{meta['name']}_{kind}") for kind in KERNEL_FUNCTIONS}
            except Exception as error:
                raise BackendError(f"loading CUDA kernel {meta['name']} ({path}) failed: {error}") from None
            module = _loaded[key] = CudaModule(meta, functions, source, cp, record)
        return module


def load_host_shim(source: Path, cache: Path, writable=None):
    """The generated CUDA file compiled as C99 by the C compiler (-DTM_HOST_SHIM) and loaded like a C
    kernel: the same functions on numpy arrays, each kernel's loop running the elements in order."""
    source = Path(source)
    text = source.read_text(encoding="utf-8")
    meta = c_loader.parse_metadata(text, source)
    command, flags = c_loader.compiler(), c_loader.cflags() + list(SHIM_FLAGS)
    lib = c_loader.library_path(f"{meta['name']}.cuda-host", text, command, flags, cache)
    with _lock:
        compiled = None
        if not c_loader._verified(lib):
            compiled = c_loader.build(meta["name"], source, lib, command, flags, writable)
        return c_loader._open(meta, lib, source, compiled)


class CudaModule:
    """A compiled CUDA kernel with the attributes and functions of the other backends' modules.

    Arguments are CuPy arrays (used in place, nothing crosses to the host) or numpy arrays (copied to
    the device, and the outputs back: the runtime's host path, correct but paying the transfers)."""

    def __init__(self, meta: dict, functions: dict, source: Path, cp, compiled: dict | None = None):
        self._functions, self._cp = functions, cp
        self.COMPILED = compiled is not None
        self.COMPILE_SECONDS = compiled["seconds"] if compiled else 0.0
        self.METADATA = meta
        self.NAME = meta["name"]
        self.SOURCE = source
        self._sizes = {"X": int(meta["n_nodes"]) * int(meta["dim"]), "params": len(meta["parameters"]),
                       "D": int(meta["n_constants"]), "u": int(meta["n_dofs"]), "f": int(meta["n_dofs"]),
                       "K": int(meta["n_dofs"]) ** 2, "out": 1,
                       "S": int(meta["n_points"]) * int(meta["stress_record"]["size"])}

    def __repr__(self):
        return f"<CUDA kernel {self.NAME} from {self.SOURCE}>"

    def launch(self, kind: str, n: int, *arrays) -> None:
        """Run kernel kind over n elements on device arrays (no checks: the device path's call)."""
        if n <= 0:
            return
        blocks = min((n + THREADS_PER_BLOCK - 1) // THREADS_PER_BLOCK, 65535 * 32)
        self._functions[kind]((blocks,), (THREADS_PER_BLOCK,), (np.int64(n),) + tuple(arrays))

    def _run(self, kind: str, n: int, named: list) -> None:
        """Check sizes and types, move numpy arrays to the device, launch, copy the outputs back."""
        cp = self._cp
        device, back = [], []
        for what, array, dtype, per_element, writable in named:
            if array.dtype != dtype or array.size != n * per_element:
                raise BackendError(f"{self.NAME}: {what} must hold {n} x {per_element} {np.dtype(dtype).name} values")
            if isinstance(array, np.ndarray):
                moved = cp.asarray(np.ascontiguousarray(array))
                if writable:
                    back.append((array, moved))
                array = moved
            elif not array.flags.c_contiguous:
                raise BackendError(f"{self.NAME}: {what} must be C-contiguous")
            device.append(array)
        self.launch(kind, n, *device)
        for host, moved in back:
            host[...] = moved.get().reshape(host.shape)

    def _call(self, kind, n, inputs, outputs, flags):
        named = [(w, a, np.float64, self._sizes[w], False) for w, a in inputs]
        named += [(w, a, np.float64, self._sizes[w], True) for w, a in outputs]
        named.append(("flags", flags, np.int32, 1, True))
        self._run(kind, n, named)

    def constants(self, X, params, D, flags):
        self._call("constants", len(X), [("X", X), ("params", params)], [("D", D)], flags)

    def energy(self, D, u, out, flags):
        self._call("energy", len(D), [("D", D), ("u", u)], [("out", out)], flags)

    def forces(self, D, u, f, flags):
        self._call("forces", len(D), [("D", D), ("u", u)], [("f", f)], flags)

    def stiffness(self, D, u, K, flags):
        self._call("stiffness", len(D), [("D", D), ("u", u)], [("K", K)], flags)

    def forces_and_stiffness(self, D, u, f, K, flags):
        self._call("forces_and_stiffness", len(D), [("D", D), ("u", u)], [("f", f), ("K", K)], flags)

    def stress(self, D, u, S, flags):
        self._call("stress", len(D), [("D", D), ("u", u)], [("S", S)], flags)

    def forces_and_stiffness_scatter(self, D, U, cells, pos, fg, data, flags):
        """The fused evaluation and scatter.

        CuPy arrays (the device path): one launch over elements that share no node (one colour: the
        caller launches the colours one after the other, runtime.solve.device). numpy arrays (the
        runtime's host path): the element forces and stiffness are evaluated on the device and added
        on the host in element order, as the C backend's serial scatter does."""
        n = len(D)
        if not isinstance(D, np.ndarray):
            self.launch("forces_and_stiffness_scatter", n, D, U, cells, pos, fg, data, flags)
            return
        n_dofs = self._sizes["u"]
        f, K = np.empty((n, n_dofs)), np.empty((n, n_dofs, n_dofs))
        u = np.ascontiguousarray(np.asarray(U).reshape(-1, n_dofs // cells.shape[1])[cells].reshape(n, n_dofs))
        self.forces_and_stiffness(D, u, f, K, flags)
        _scatter_in_order(f, K, cells, pos, fg, data)


def _scatter_in_order(f, K, cells, pos, fg, data) -> None:
    """fg += f and data += K, each entry's terms added element after element (the order of the C
    backend's scatter: numpy's add.at adds in the order of its indices)."""
    n, n_dofs = f.shape
    n_nodes = cells.shape[1]
    per_node = n_dofs // n_nodes
    dofs = (np.asarray(cells, dtype=np.int64)[:, :, None] * per_node + np.arange(per_node)).reshape(n, n_dofs)
    np.add.at(fg, dofs.ravel(), f.ravel())
    entries = np.asarray(pos, dtype=np.int64)[..., None] + np.arange(per_node)          # (n, n_dofs, n_nodes, per_node)
    np.add.at(data, entries.ravel(), K.reshape(n, n_dofs, n_nodes, per_node).ravel())


# -- the device solver's kernels (solvers/pcg.cu) -----------------------------------------------
PCG_SOURCE = Path(__file__).resolve().parent / "solvers" / "pcg.cu"
PCG_FUNCTIONS = ("tm_spmv", "tm_dot_partial", "tm_dot2_partial", "tm_dot_finish", "tm_update_xrz", "tm_update_p",
                 "tm_shift")
PCG_BLOCK_THREADS = 256          # TM_BLOCK_THREADS of pcg.cu (its shared-memory trees need it)
PCG_ROW_LANES = 8                # TM_ROW_LANES of pcg.cu
_PCG_CDEF = """
void tm_spmv(long n, const int *indptr, const int *indices, const double *data, const double *x, double *y);
void tm_dot_partial(long n, const double *a, const double *b, double *partial);
void tm_dot2_partial(long n, const double *a, const double *b, long blocks, double *partial);
void tm_dot_finish(long blocks, long pairs, const double *partial, double *s, long slot);
void tm_update_xrz(long n, const double *s, const double *p, const double *Ap, const double *inverse_diagonal,
                   double *x, double *r, double *z);
void tm_update_p(long n, const double *s, const double *z, double *p);
void tm_shift(double *s);
"""


class PCGFunctions:
    """The kernels of solvers/pcg.cu, called as launch(name, blocks, *args) with blocks of
    PCG_BLOCK_THREADS threads; on the device (CuPy arrays, the current stream) or, from the host
    shim, on numpy arrays (one block of one thread: blocks is ignored)."""

    def __init__(self, functions: dict, host_ffi=None):
        self._functions, self._ffi = functions, host_ffi
        self.on_device = host_ffi is None

    def launch(self, name: str, blocks: int, *args) -> None:
        fn = self._functions[name]
        if self.on_device:
            fn((int(blocks),), (PCG_BLOCK_THREADS,), tuple(np.int64(a) if isinstance(a, int) else a for a in args))
            return
        fn(*(self._pointer(a) for a in args))

    def _pointer(self, a):
        if isinstance(a, np.ndarray):
            kind = {np.dtype(np.float64): "double[]", np.dtype(np.int32): "int[]"}[a.dtype]
            return self._ffi.from_buffer(kind, a, require_writable=False)
        return a


def load_pcg(cache: Path, writable=None) -> PCGFunctions:
    """The device solver's kernels on the current device (cached cubin, like the generated kernels)."""
    cp = cupy()
    with _lock:
        key = ("pcg", cp.cuda.runtime.getDevice())
        if key not in _loaded:
            path, _ = compile_cubin(PCG_SOURCE, device_arch(cp), cache, writable, name="tm_pcg")
            raw = cp.RawModule(path=str(path))
            _loaded[key] = PCGFunctions({name: raw.get_function(name) for name in PCG_FUNCTIONS})
        return _loaded[key]


def load_pcg_host_shim(cache: Path, writable=None) -> PCGFunctions:
    """The device solver's kernels compiled as C99 for the host (the checks without a GPU)."""
    import cffi
    text = PCG_SOURCE.read_text(encoding="utf-8")
    command, flags = c_loader.compiler(), c_loader.cflags() + list(SHIM_FLAGS)
    lib = c_loader.library_path("tm_pcg.cuda-host", text, command, flags, cache)
    with _lock:
        if ("pcg-host", str(lib)) not in _loaded:
            if not c_loader._verified(lib):
                c_loader.build("tm_pcg", PCG_SOURCE, lib, command, flags, writable)
            ffi = cffi.FFI()
            ffi.cdef(_PCG_CDEF)
            handle = ffi.dlopen(str(lib))
            _loaded[("pcg-host", str(lib))] = PCGFunctions({name: getattr(handle, name) for name in PCG_FUNCTIONS}, ffi)
        return _loaded[("pcg-host", str(lib))]
