"""tensormass: symbolic tensor-mass kernels (C and numba) and a small implicit runtime.

    import tensormass as tm
    k = tm.load_kernel("tetra", "stvk", "gauss1")          # C where a compiler is found, else numba
    summary = tm.Simulation(tm.Scene.from_toml("beam.toml")).run()
    # a run the health monitor does not trust raises tm.RunStopped (its .summary says why)

Every name is imported on first use: `import tensormass` alone loads neither sympy, numpy nor
numba, so the command line can take Ctrl-C cleanly from its first instant (see launcher.py).
"""
from .generator import GENERATOR_VERSION as __version__
from .runtime.base.cache import use_numba_cache

# numba's compiled functions go to the user cache, never into this package's folder (numba reads
# NUMBA_CACHE_DIR when first imported: here, before any tensormass module imports it)
use_numba_cache()

_ERRORS = ("TensormassError", "ElementError", "InvertedElementError", "DegenerateElementError",
           "KernelNotFoundError", "RunStopped", "RunInterrupted")
# name -> the runtime module that defines it (imported on first use)
_LAZY = {"load_kernel": "kernels.kernels", "Kernel": "kernels.kernels", "Scene": "scene.scene",
         "Simulation": "run.simulation", "Summary": "run.simulation", "FIELDS": "physics.fields",
         "write_picture": "run.picture", "plot_history": "run.curves", "Live": "run.live",
         "LiveProcess": "run.live_process", **{name: "base.errors" for name in _ERRORS}}
__all__ = ["__version__", *_LAZY]


def __dir__():
    """The public names (imported on first use, so dir() lists them before they are loaded)."""
    return sorted(set(globals()) | set(__all__))


def __getattr__(name):
    if name in _LAZY:
        import importlib
        return getattr(importlib.import_module(f".runtime.{_LAZY[name]}", __name__), name)
    raise AttributeError(f"module 'tensormass' has no attribute {name!r}")
