"""The user cache of kernels generated or compiled on demand: where it is and whether it can be
written (kernels.py passes it to the backends' loaders: generated files, compiled C libraries),
and numba's on-disk cache of compiled functions, kept there too (use_numba_cache).

Light on purpose: `import tensormass` calls use_numba_cache() before anything imports numba, so
this module imports neither numpy nor numba (TensormassError is imported where it is raised)."""
from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

from ...generator import GENERATOR_VERSION


def cache_dir() -> Path:
    """Where kernels generated or compiled on demand live ($TENSORMASS_CACHE overrides)."""
    root = os.environ.get("TENSORMASS_CACHE") or Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "tensormass"
    return Path(root) / GENERATOR_VERSION


def numba_cache_dir() -> Path:
    """Where numba keeps the compiled code of @njit(cache=True) functions (the runtime's helpers,
    the generated numba kernels): inside cache_dir(), never the install folder."""
    return cache_dir() / "numba"


def use_numba_cache() -> str:
    """Point numba's on-disk cache at numba_cache_dir() unless the user set NUMBA_CACHE_DIR;
    returns the folder in use. Numba reads NUMBA_CACHE_DIR when it is first imported, so this runs
    in `import tensormass`; a numba imported before that gets the folder in its config too.
    Without it numba writes *.nbi/*.nbc into __pycache__ next to each source file: inside
    site-packages, where pip uninstall leaves them behind."""
    folder = os.environ.get("NUMBA_CACHE_DIR")
    if folder:
        return folder
    folder = os.environ["NUMBA_CACHE_DIR"] = str(numba_cache_dir())
    config = sys.modules.get("numba.core.config")
    if config is not None:                 # numba imported before tensormass: its config is read already
        config.CACHE_DIR = folder
    return folder


def _cache_origin() -> str:
    """Which setting chose the cache folder (what the user has to change)."""
    if os.environ.get("TENSORMASS_CACHE"):
        return f"$TENSORMASS_CACHE={os.environ['TENSORMASS_CACHE']}"
    if os.environ.get("XDG_CACHE_HOME"):
        return f"$XDG_CACHE_HOME={os.environ['XDG_CACHE_HOME']}"
    return "the default ~/.cache/tensormass"


def writable_cache_dir(folder, needed_for: str) -> Path:
    """folder (inside cache_dir()), created if missing and checked writable, right before a write.

    Only called where something must be written (a kernel generated or compiled now): a
    run whose kernels are committed or already compiled works with a read-only cache.
    Raises TensormassError naming the folder, the setting behind it and what needed it."""
    # deferred: errors imports numpy, 0.07 s after `import tensormass` (0.01 s), which loads this module
    from .errors import TensormassError
    folder = Path(folder)
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(dir=folder, prefix=".tensormass-probe-", suffix=".tmp")
        os.close(fd)
        os.remove(probe)
    except OSError as exc:
        raise TensormassError(f"kernel cache {folder} cannot be written ({_blocker(folder, exc)}; set by "
                              f"{_cache_origin()}): {needed_for} needs it; set TENSORMASS_CACHE to a "
                              "writable folder") from None
    return folder


def _blocker(folder: Path, exc: OSError) -> str:
    """Why a folder cannot be written: an existing parent that is a file, or the OS's reason."""
    path = folder
    while not os.path.lexists(path) and path.parent != path:
        path = path.parent
    if os.path.lexists(path) and not path.is_dir():
        return f"{path} is not a folder"
    return exc.strerror or str(exc)
