"""tensormass: symbolic tensor-mass kernels (C and numba) and a small implicit runtime.

    import tensormass as tm
    k = tm.load_kernel("tetra", "stvk", "gauss1", backend="numba")
"""
from .generator import GENERATOR_VERSION as __version__
from .runtime.errors import (DegenerateElementError, ElementError, InvertedElementError,
                             KernelNotFoundError, TensormassError)
from .runtime.kernels import Kernel, load_kernel

__all__ = ["__version__", "load_kernel", "Kernel", "TensormassError", "ElementError",
           "InvertedElementError", "DegenerateElementError", "KernelNotFoundError"]
