"""Fibre directions per cell: what a law with directions (laws/hgo.py) receives as kernel inputs.

A [[material]]'s ``fibres`` gives one entry per direction the law declares (Law.directions):
- a constant vector ``[1, 0, 0]``;
- ``"FILE.py:FUNCTION"``: a Python function of the cells' rest centroids, an (n, dim) array, returning
  an (n, 3) array (or (n, 2) in 2D; one vector: every cell), loaded from a file relative to the
  scene's folder;
- ``"NAME"``: the mesh file's cell data NAME, a vector per cell (Mesh.cell_data);
- in Python, any callable of the same form.
Each direction is normalised per cell; a zero, NaN or wrongly shaped result is refused naming the
cells.  They are evaluated where the model builds its parts (at the centroids of the mesh it has,
refined or cut: a child cell gets the field's value at its own centroid).
"""
from __future__ import annotations

import importlib.util
import hashlib
import sys
from pathlib import Path

import numpy as np

from ..base.errors import TensormassError


class CellData(str):
    """A fibre entry naming the mesh file's cell data (checked against the mesh when the model is built)."""


def parse_entry(value, what: str, base_dir=None):
    """One fibre entry of a scene: a tuple of 2 or 3 numbers, the function a "FILE.py:FUNCTION"
    string names (loaded now: a missing file or function is a scene error), or CellData(NAME)."""
    if isinstance(value, str):
        if ".py:" not in value and value.strip() and ":" not in value:
            return CellData(value)
        return load_function(value, what, base_dir)
    if callable(value):
        return value
    try:
        vector = np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        vector = None
    if vector is None or vector.size not in (2, 3) or not np.all(np.isfinite(vector)) or not np.any(vector):
        raise TensormassError(f"{what}: a fibre direction is a non-zero vector of 3 numbers (2 in 2D) or "
                              f"\"FILE.py:FUNCTION\", got {value!r}")
    return tuple(float(x) for x in vector)


def load_function(text: str, what: str, base_dir=None):
    """The function FUNCTION of the Python file FILE.py that "FILE.py:FUNCTION" names."""
    file, sep, name = text.rpartition(":")
    if not sep or not file.endswith(".py") or not name.isidentifier():
        raise TensormassError(f"{what}: {text!r} is not \"FILE.py:FUNCTION\" (a Python file and the name of "
                              "a function in it) nor a vector")
    path = Path(file).expanduser()
    if not path.is_absolute() and base_dir is not None:
        path = Path(base_dir) / path
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise TensormassError(f"{what}: cannot read {path} ({exc.strerror or exc}); relative paths are "
                              "relative to the scene file") from None
    module_name = f"tensormass_fibres_{hashlib.sha256(data).hexdigest()[:16]}"
    module = sys.modules.get(module_name)
    if module is None:
        spec = importlib.util.spec_from_file_location(module_name, path)
        module = importlib.util.module_from_spec(spec)
        try:
            spec.loader.exec_module(module)
        except Exception as exc:              # whatever the user's file raises: named, with the file
            raise TensormassError(f"{what}: importing {path} failed: {type(exc).__name__}: {exc}") from None
        sys.modules[module_name] = module
    function = getattr(module, name, None)
    if not callable(function):
        raise TensormassError(f"{what}: {path} defines no function {name!r}")
    return function


def directions(entry, centroids: np.ndarray, what: str, cell_ids=None, cell_data=None) -> np.ndarray:
    """(n, 3) unit vectors: the entry evaluated at the cells' rest centroids (n, dim); a CellData
    entry reads the mesh's cell data (cell_data: name -> (n_cells, k)) at cell_ids."""
    n, dim = centroids.shape
    if isinstance(entry, CellData):
        cell_data = cell_data or {}
        if entry not in cell_data:
            have = ", ".join(sorted(cell_data)) or "none"
            raise TensormassError(f"{what}: the mesh has no cell data {str(entry)!r} (it has: {have}); a "
                                  "refined or cut mesh keeps none")
        entry = cell_data[entry][np.asarray(cell_ids)]
    if callable(entry):
        try:
            raw = entry(np.array(centroids))
        except Exception as exc:              # the user's function: named, with what it raised
            raise TensormassError(f"{what}: the fibre function failed: {type(exc).__name__}: {exc}") from None
    else:
        raw = entry
    try:
        values = np.asarray(raw, dtype=float)
    except (TypeError, ValueError):
        raise TensormassError(f"{what}: the fibre direction is not an array of numbers") from None
    if values.ndim == 1:
        values = np.broadcast_to(values, (n, values.size))
    if values.ndim != 2 or values.shape[0] != n or values.shape[1] not in (dim, 3):
        raise TensormassError(f"{what}: the fibre direction must be one vector or one per cell, shape ({n}, 3) "
                              f"(or ({n}, {dim})), got {values.shape}")
    if values.shape[1] == 2:
        values = np.hstack([values, np.zeros((n, 1))])
    length = np.linalg.norm(values, axis=1)
    bad = np.flatnonzero(~np.isfinite(length) | (length <= 1e-12 * max(1.0, float(np.nanmax(length, initial=0)))))
    if bad.size:
        ids = bad if cell_ids is None else np.asarray(cell_ids)[bad]
        raise TensormassError(f"{what}: the fibre direction is zero or not finite in cell(s) "
                              f"{', '.join(map(str, ids[:10]))}{' ...' if ids.size > 10 else ''}")
    if dim == 2 and np.any(values[:, 2] != 0):
        raise TensormassError(f"{what}: a 2D mesh takes in-plane fibre directions (z component 0)")
    return values / length[:, None]
