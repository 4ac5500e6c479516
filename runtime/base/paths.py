"""The path rule of scene files: every path a scene names is relative to the scene file's folder.

    scene_path("mesh.msh", Path("scenes"))  -> "scenes/mesh.msh"
    scene_path("~/out", Path("scenes"))     -> "/home/me/out"  (absolute paths and ~ stay as given)

Keys that hold paths: ``mesh.file`` and ``output.dir`` (runtime.scene.scene); a new path key must be
resolved with scene_path too, so that a scene runs the same from any working directory.  Paths
given on the command line (``tensormass run --out DIR``, ``--json FILE``) are the shell's: they
are relative to the working directory, as every command-line tool's are.  A scene given as a
string or a dict (Scene.from_string / from_dict) without base_dir has no folder: its paths stay
as written (relative to the working directory at the time they are used).
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
