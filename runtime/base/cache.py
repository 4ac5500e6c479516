"""The user cache of kernels generated or compiled on demand: where it is and whether it can be
written (kernels.py passes it to the backends' loaders: generated files, compiled C libraries)."""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

from ...generator import GENERATOR_VERSION
from .errors import TensormassError


def cache_dir() -> Path:
    """Where kernels generated or compiled on demand live ($TENSORMASS_CACHE overrides)."""
    root = os.environ.get("TENSORMASS_CACHE") or Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "tensormass"
    return Path(root) / GENERATOR_VERSION


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
