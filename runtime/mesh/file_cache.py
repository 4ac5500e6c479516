"""Mesh files read once: the parsed mesh of a file that passed every check, kept in the user cache.

    mesh = load(path)        # the Mesh read and checked before from these very bytes, or None
    store(path, mesh)        # after check_mesh passed on the mesh read_mesh gave for path
    fingerprint(mesh)        # a digest of what is kept: the caller stores only the mesh as read

Reading a gmsh file costs its ASCII parse twice (msh_check's section check, then meshio's) and
check_mesh walks every face: most of the time to a run's first step on an organ of a few thousand
nodes.  A file whose bytes, and the reading and checking code, are those of a stored entry gives
the same mesh and the same verdict, so the entry stands for both.  The key is the SHA-256 of the
file's bytes, its suffix (meshio picks its reader by it), and the source of this package (the
readers and the checks) and of the element registry: editing either makes every entry a miss.  Entries are .npz files (arrays and one JSON
header, no pickle).  The cache is a convenience: a folder that cannot be written, or an entry that
cannot be read, only means the file is read again (a damaged entry is removed).
"""
from __future__ import annotations

import hashlib
import io
import json
from pathlib import Path

import numpy as np

from ..base.cache import cache_dir
from ..base.files import remove_quietly, write_bytes_atomic
from .container import CellBlock, Mesh
from .mesh_groups import Group

__all__ = ["load", "store", "folder", "fingerprint"]

_CODE = None


def folder() -> Path:
    return cache_dir() / "meshes"


def _code_digest() -> str:
    """The source of the mesh package and of the element registry: what reading and checking run."""
    global _CODE
    if _CODE is None:
        from ... import elements
        h = hashlib.sha256()
        for package in (Path(__file__).parent, Path(elements.__file__).parent):
            for source in sorted(package.glob("*.py")):
                h.update(source.name.encode() + b"\0" + source.read_bytes())
        _CODE = h.hexdigest()
    return _CODE


def fingerprint(mesh: Mesh) -> str:
    """A digest of what the cache keeps of a mesh (points, cells, tags, groups, cell data): tells the mesh read
    from a file from one changed or put in its place since."""
    h = hashlib.sha256()
    for name, array in _pack(mesh).items():
        h.update(name.encode() + b"\0" + str(array.dtype).encode() + str(array.shape).encode()
                 + np.ascontiguousarray(array).tobytes())
    return h.hexdigest()


def _entry(path) -> Path | None:
    try:
        data = Path(path).read_bytes()
    except OSError:
        return None
    # the suffix too: meshio picks its reader by it (the same bytes named .txt are refused)
    key = hashlib.sha256(_code_digest().encode() + b"\0" + Path(path).suffix.encode() + b"\0" + data).hexdigest()
    return folder() / f"{key[:40]}.npz"


def load(path) -> Mesh | None:
    entry = _entry(path)
    if entry is None or not entry.is_file():
        return None
    try:
        with np.load(entry, allow_pickle=False) as z:
            mesh = _unpack(z)
    except Exception:                       # a damaged or foreign entry: read the file again
        remove_quietly(entry)
        return None
    mesh.checked = True
    return mesh


def store(path, mesh: Mesh) -> None:
    entry = _entry(path)
    if entry is None:
        return
    buf = io.BytesIO()
    np.savez(buf, **_pack(mesh))
    try:
        entry.parent.mkdir(parents=True, exist_ok=True)
        write_bytes_atomic(entry, buf.getvalue())
    except OSError:                         # a read-only cache: the next run reads the file again
        pass


def _pack(mesh: Mesh) -> dict:
    arrays = {"points": mesh.points}
    head = {"blocks": [], "groups": [], "midpoints": mesh.midpoints is not None}
    for i, b in enumerate(mesh.blocks):
        arrays[f"block{i}"] = b.cells
        if b.tags is not None:
            arrays[f"block{i}_tags"] = b.tags
        head["blocks"].append({"type": b.type, "tags": b.tags is not None})
    for i, g in enumerate(mesh.groups):
        arrays[f"group{i}_ids"] = g.cell_ids
        types = list(g.cells)
        for j, t in enumerate(types):
            arrays[f"group{i}_cells{j}"] = g.cells[t]
        head["groups"].append({"name": g.name, "id": g.id, "dim": g.dim, "cells": types})
    if mesh.midpoints is not None:
        arrays["midpoints"] = mesh.midpoints
    head["cell_data"] = sorted(mesh.cell_data)
    for i, name in enumerate(head["cell_data"]):
        arrays[f"cell_data{i}"] = mesh.cell_data[name]
    arrays["head"] = np.frombuffer(json.dumps(head).encode(), dtype=np.uint8)
    return arrays


def _unpack(z) -> Mesh:
    head = json.loads(bytes(z["head"]).decode())
    blocks = [CellBlock(b["type"], z[f"block{i}"], z[f"block{i}_tags"] if b["tags"] else None)
              for i, b in enumerate(head["blocks"])]
    groups = [Group(g["name"], g["id"], g["dim"], np.asarray(z[f"group{i}_ids"]),
                    {t: np.asarray(z[f"group{i}_cells{j}"]) for j, t in enumerate(g["cells"])})
              for i, g in enumerate(head["groups"])]
    cell_data = {name: np.asarray(z[f"cell_data{i}"]) for i, name in enumerate(head.get("cell_data", []))}
    return Mesh(np.asarray(z["points"]), blocks, groups, np.asarray(z["midpoints"]) if head["midpoints"] else None,
                cell_data)
