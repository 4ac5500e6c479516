"""The [contact] table and the [[obstacle]] tables of a scene (runtime.scene.parser calls these).

    [contact]
    method = "ipc"                  # or "penalty" (runtime.contact.base.METHODS_OF: which solver takes which)
    dhat = 1e-3                     # IPC: the barrier's activation distance [m] (default 1e-3 x body diagonal)
    stiffness = 1e4                 # IPC: barrier stiffness (default adaptive); penalty: N/m per vertex
    mu = 0.2                        # IPC: Coulomb friction, lagged (friction_iterations = 2)
    self = false                    # a body against itself; bodies = true: distinct bodies of the mesh
    check_every = 1                 # IPC: intersection test of the surfaces every this many steps

    [[obstacle]]
    name = "tool"
    shape = "capsule"               # plane | sphere | capsule | box | mesh
    a = [0.0, 0.0, 0.1]             # capsule's segment, radius
    b = [0.0, 0.0, 0.2]
    radius = 0.01
    translation = [0.0, 0.0, -0.02] # and/or rotation = {axis, point, angle}; amplitude = "press"
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..base.errors import SceneError
from ..physics.motion import parse_rotation
from .base import METHODS, ContactSpec
from .obstacles import SHAPES, Obstacle

__all__ = ["parse_contact", "parse_obstacle", "check_obstacles", "CONTACT_KEYS", "OBSTACLE_KEYS"]

CONTACT_KEYS = ("method", "dhat", "dhat_relative", "stiffness", "mu", "friction_iterations", "eps_v", "self",
                "bodies", "check_every", "max_penetration")
OBSTACLE_KEYS = ("name", "shape", "point", "normal", "center", "radius", "a", "b", "box", "file", "scale",
                 "resolution", "translation", "rotation", "amplitude")
# the keys each shape needs, and the ones it takes
_SHAPE_KEYS = {"plane": (("point", "normal"), ()), "sphere": (("center", "radius"), ("resolution",)),
               "capsule": (("a", "b", "radius"), ("resolution",)), "box": (("box",), ()),
               "mesh": (("file",), ("scale",))}
_MOTION = ("name", "shape", "translation", "rotation", "amplitude")


def parse_contact(parser, t) -> ContactSpec:
    t = parser.table(t, "contact")
    parser.keys(t, "contact", CONTACT_KEYS)
    spec = ContactSpec()
    if "method" in t:
        spec.method = parser.string(t["method"], "contact.method", METHODS)
    if "dhat" in t:
        spec.dhat = parser.number(t["dhat"], "contact.dhat", positive=True)
    if "dhat_relative" in t:
        spec.dhat_relative = parser.number(t["dhat_relative"], "contact.dhat_relative", positive=True)
    if "stiffness" in t:
        spec.stiffness = parser.number(t["stiffness"], "contact.stiffness", positive=True)
    if "mu" in t:
        spec.mu = parser.number(t["mu"], "contact.mu", min_value=0.0)
    if "friction_iterations" in t:
        spec.friction_iterations = parser.integer(t["friction_iterations"], "contact.friction_iterations", 1, 100)
    if "eps_v" in t:
        spec.eps_v = parser.number(t["eps_v"], "contact.eps_v", positive=True)
    if "self" in t:
        spec.self_contact = parser.boolean(t["self"], "contact.self")
    if "bodies" in t:
        spec.bodies = parser.boolean(t["bodies"], "contact.bodies")
    if "check_every" in t:
        spec.check_every = parser.integer(t["check_every"], "contact.check_every", 1)
    if "max_penetration" in t:
        spec.max_penetration = parser.number(t["max_penetration"], "contact.max_penetration", positive=True)
    ipc_only = [k for k in ("dhat", "dhat_relative", "mu", "friction_iterations", "eps_v", "check_every", "self")
                if k in t and not (k == "self" and not spec.self_contact) and not (k == "mu" and spec.mu == 0)]
    if spec.method == "penalty" and ipc_only:
        raise SceneError(f"contact.{ipc_only[0]}: an IPC setting; penalty contact (contact.method = \"penalty\") "
                         "has no barrier, CCD or friction: leave it out, or use method = \"ipc\"")
    if spec.method == "ipc" and "max_penetration" in t:
        raise SceneError("contact.max_penetration: a penalty setting; IPC never lets surfaces in")
    return spec


def parse_obstacle(parser, t, key) -> Obstacle:
    t = parser.table(t, key)
    parser.keys(t, key, OBSTACLE_KEYS)
    if "shape" not in t:
        raise SceneError(f"{key}.shape: missing ({', '.join(SHAPES)})")
    shape = parser.string(t["shape"], f"{key}.shape", SHAPES)
    needs, takes = _SHAPE_KEYS[shape]
    for k in needs:
        if k not in t:
            raise SceneError(f"{key}.{k}: missing (a {shape} obstacle needs {', '.join(needs)})")
    extra = [k for k in t if k not in needs + takes + _MOTION]
    if extra:
        raise SceneError(f"{key}.{extra[0]}: not a key of a {shape} obstacle (it takes {', '.join(needs + takes)}, "
                         "and name, translation, rotation, amplitude)")
    name = parser.string(t.get("name", key), f"{key}.name")
    if not name.strip():
        raise SceneError(f"{key}.name: must not be empty")
    o = Obstacle(name=name, shape=shape)
    vec = lambda k: parser.vector(t[k], f"{key}.{k}", dim=3)           # noqa: E731
    if shape == "plane":
        o.point, o.normal = vec("point"), vec("normal")
        if not np.linalg.norm(o.normal) > 0:
            raise SceneError(f"{key}.normal: must not be the zero vector (it points to the side the body stays on)")
    if "radius" in t:
        o.radius = parser.number(t["radius"], f"{key}.radius", positive=True)
    if shape == "sphere":
        o.center = vec("center")
    if shape == "capsule":
        o.a, o.b = vec("a"), vec("b")
        if np.allclose(o.a, o.b):
            raise SceneError(f"{key}: a and b are the same point; a ball is shape = \"sphere\"")
    if shape == "box":
        o.box = parser.box(t["box"], f"{key}.box")
        if len(o.box[0]) != 3 or not all(np.isfinite(o.box[0] + o.box[1])):
            raise SceneError(f"{key}.box: needs finite 3D corners")
        if not all(hi > lo for lo, hi in zip(*o.box)):
            raise SceneError(f"{key}.box: has no volume (min == max in a component)")
    if shape == "mesh":
        path = Path(parser.string(t["file"], f"{key}.file"))
        if parser.scene_dir is not None and not path.is_absolute():
            path = parser.scene_dir / path
        if not path.is_file():
            raise SceneError(f"{key}.file: no such file: {path}")
        o.file = str(path)
        if "scale" in t:
            o.scale = parser.number(t["scale"], f"{key}.scale", positive=True)
    if "resolution" in t:
        o.resolution = parser.number(t["resolution"], f"{key}.resolution", positive=True)
        if o.radius is not None and o.resolution >= 2 * o.radius:
            raise SceneError(f"{key}.resolution: {o.resolution:g} m is not below the diameter {2 * o.radius:g} m")
    if "translation" in t:
        o.translation = vec("translation")
    if "rotation" in t:
        o.rotation = parse_rotation(parser, t["rotation"], f"{key}.rotation", 3)
    if "amplitude" in t:
        o.amplitude = parser.string(t["amplitude"], f"{key}.amplitude")
        if not o.moves:
            raise SceneError(f"{key}.amplitude: the obstacle does not move (give translation and/or rotation)")
    return o


def check_obstacles(obstacles) -> None:
    """Obstacle names are unique (they name the forces in the history)."""
    names = [o.name for o in obstacles]
    dup = next((n for n in names if names.count(n) > 1), None)
    if dup is not None:
        raise SceneError(f"obstacle[{names.index(dup, names.index(dup) + 1)}].name: duplicate obstacle name {dup!r}")
