"""The path rule of scene files: every path a scene names is relative to the scene file's folder.

    scene_path("mesh.msh", Path("scenes"))  -> "scenes/mesh.msh"
    scene_path("~/out", Path("scenes"))     -> "/home/me/out"  (absolute paths and ~ stay as given)

Keys that hold paths (resolved by runtime.scene.parser with scene_path): ``mesh.file``,
``output.dir`` and a [[material]]'s ``law_file``.  mesh.file and law_file are read while the scene
is parsed (a missing file is a SceneError naming the resolved path); law_file is kept as its
absolute path (Material.law_file), its law loaded and registered then (laws.load_file).  A new
path key must be resolved with scene_path too, so that a scene runs the same from any working
directory.  Paths given on the command line (``tensormass run --out DIR``, ``--json FILE``) are
the shell's: they are relative to the working directory, as every command-line tool's are.  A
scene given as a string or a dict (Scene.from_string / from_dict) without base_dir has no folder:
mesh.file and law_file are relative to the working directory when it is parsed, and output.dir
stays as written (relative to the working directory at the time the run writes).
"""
from __future__ import annotations

from pathlib import Path

__all__ = ["scene_path"]


def scene_path(raw: str, scene_dir) -> str:
    """`raw` (a path written in a scene) resolved against the scene's folder; ~ is expanded."""
    path = Path(raw).expanduser()
    if scene_dir is not None and not path.is_absolute():
        path = Path(scene_dir) / path
    return str(path)
