"""numba backend: one Python module per kernel, @njit(cache=True) loops over elements."""
from __future__ import annotations

from pathlib import Path

from ..protocol import Backend
from . import loader


class NumbaBackend(Backend):
    name = "numba"
    suffix = ".py"
    folder = Path(__file__).resolve().parent

    def load(self, path: Path, cache: Path, writable=None):
        return loader.load_module(path)


BACKEND = NumbaBackend()
