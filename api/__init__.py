"""tensormass: symbolic tensor-mass kernels (C and numba) and a small implicit runtime.

    import tensormass as tm
    k = tm.load_kernel("tetra", "stvk", "gauss1", backend="numba")
    summary = tm.Simulation(tm.Scene.from_toml("beam.toml")).run()
    # a run the health monitor does not trust raises tm.RunStopped (its .summary says why)

Every name is imported on first use: `import tensormass` alone loads neither sympy, numpy nor
numba, so the command line can take Ctrl-C cleanly from its first instant (see launcher.py).
"""
from .generator import GENERATOR_VERSION as __version__

_ERRORS = ("TensormassError", "ElementError", "InvertedElementError", "DegenerateElementError",
           "KernelNotFoundError", "RunStopped", "RunInterrupted")
__all__ = ["__version__", "load_kernel", "Kernel", "Scene", "Simulation", *_ERRORS]


def __dir__():
    """The public names (imported on first use, so dir() lists them before they are loaded)."""
    return sorted(set(globals()) | set(__all__))


def __getattr__(name):
    if name in _ERRORS:
        from .runtime import errors
        return getattr(errors, name)
    if name in ("load_kernel", "Kernel"):
        from .runtime import kernels
        return getattr(kernels, name)
    if name == "Scene":
        from .runtime.scene import Scene
        return Scene
    if name == "Simulation":
        from .runtime.simulation import Simulation
        return Simulation
    raise AttributeError(f"module 'tensormass' has no attribute {name!r}")
