"""C backend: one C99 file per kernel (plain loops, and 4 elements per instruction for
forces_and_stiffness), compiled into a shared library and called through cffi."""
from __future__ import annotations

from pathlib import Path

from ..protocol import Backend
from . import loader


class CBackend(Backend):
    name = "c"
    suffix = ".c"
    folder = Path(__file__).resolve().parent

    def prepare(self, paths, cache: Path, writable=None) -> None:
        loader.build_missing(paths, cache, writable=writable)

    def load(self, path: Path, cache: Path, writable=None):
        return loader.load_source(path, cache, writable=writable)


BACKEND = CBackend()
