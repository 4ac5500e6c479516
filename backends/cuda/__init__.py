"""CUDA backend: one CUDA C++ file per kernel, one element per GPU thread, compiled at run time by
NVRTC through CuPy (optional extra tensormass[cuda]). The same file compiles as C99 on the host
with -DTM_HOST_SHIM (each kernel's grid-stride loop then runs every element on one thread): that is
how machines without a GPU, CI included, check the printed CUDA against the C backend."""
from __future__ import annotations

from pathlib import Path

from ..protocol import Backend
from . import loader


class CudaBackend(Backend):
    name = "cuda"
    suffix = ".cu"
    folder = Path(__file__).resolve().parent

    def load(self, path: Path, cache: Path, writable=None):
        return loader.load_source(path, cache, writable=writable)


BACKEND = CudaBackend()
