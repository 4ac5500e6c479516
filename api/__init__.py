"""tensormass: symbolic tensor-mass kernels (C and numba) and a small implicit runtime.

    import tensormass as tm
    k = tm.load_kernel("tetra", "stvk", "gauss1", backend="numba")
    summary = tm.Simulation(tm.Scene.from_toml("beam.toml")).run()
    # a run the health monitor does not trust raises tm.RunStopped (its .summary says why)
"""
from .generator import GENERATOR_VERSION as __version__
from .runtime.errors import (DegenerateElementError, ElementError, InvertedElementError,
                             KernelNotFoundError, RunInterrupted, RunStopped, TensormassError)
from .runtime.kernels import Kernel, load_kernel

__all__ = ["__version__", "load_kernel", "Kernel", "Scene", "Simulation", "TensormassError", "ElementError",
           "InvertedElementError", "DegenerateElementError", "KernelNotFoundError", "RunStopped", "RunInterrupted"]


def __getattr__(name):
    # The runtime pulls in scipy and the assembly code: import it only when used.
    if name == "Scene":
        from .runtime.scene import Scene
        return Scene
    if name == "Simulation":
        from .runtime.simulation import Simulation
        return Simulation
    raise AttributeError(f"module 'tensormass' has no attribute {name!r}")
