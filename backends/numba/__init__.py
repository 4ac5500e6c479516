"""numba backend: one Python module per kernel, @njit(cache=True) loops over elements."""
from __future__ import annotations

from pathlib import Path

from ..protocol import Backend
from . import loader


class NumbaBackend(Backend):
    name = "numba"
    suffix = ".py"
    folder = Path(__file__).resolve().parent

    def render(self, ir) -> str:
        # Deferred: the printer needs sympy and jinja2, which loading a committed kernel must
        # not import (`tensormass run` start-up time).
        from .printer import render
        return render(ir, self)

    def read_metadata(self, path: Path) -> dict:
        return loader.read_metadata(path)

    def load(self, path: Path, cache: Path, writable=None):
        return loader.load_module(path)


BACKEND = NumbaBackend()
