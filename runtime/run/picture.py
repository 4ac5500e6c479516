"""A PNG of the deformed body coloured by a scalar field, drawn off-screen.

    write_picture("out/tip.png", mesh, mesh.points, u, von_mises, "von_mises", unit="Pa",
                  title="cantilever", step=10, time=0.1)
    write_picture("out/u.png", mesh, None, u, None, "displacement", unit="m")   # |u| (values=None)
    write_picture(path, mesh, X, u, sim.fields(["von_mises"]), "von_mises", scale="auto")  # by name

What is drawn. The body at points + scale * displacement. 3D meshes: the boundary faces of the
volume cells (runtime.mesh.faces.boundary_faces: outward, quadratic faces with their midside nodes),
projected orthographically along a view direction (`view` = (elevation, azimuth) in degrees, as
matplotlib's 3D axes name them; default (20, -60): from the front right, above), back faces
culled (the boundary of a volume mesh is closed and outward, so a face turned away is hidden by
another; faces just past edge-on are kept, see _CULL) and the rest painted back to front by
mean depth. 2D meshes: the cells themselves,
x to the right, y up. Each face (2D: cell) is a polygon through its corners and midside nodes,
so quadratic faces show their curved outline. Colours: a nodal field is interpolated linearly on
a fan of triangles around each face's centre (the centre value is the mean over the face's
nodes), a cell field colours the faces of its cell uniformly; a vector or tensor field
(n, k) is drawn as its Euclidean norm per row ("|name|"). 3D faces are shaded a little by the
angle between their normal and the view direction (faces seen head-on keep the colour bar's
colour exactly: shade=False turns this off). Mesh edges are drawn while the picture has at most
`EDGE_LIMIT` visible faces (edges=True/False forces). The picture has a colour bar labelled
"name [unit]", a title (title, step, time) with a line saying the displacement scale, equal
axes, and a small axis triad.

Back ends. backend="auto" (default) draws with pyvista (VTK, off-screen) when pyvista is
installed and renders here, otherwise with matplotlib (a dependency; the Agg canvas is used
directly, so no window opens and no $DISPLAY is needed). TENSORMASS_PICTURE=matplotlib or
pyvista overrides "auto". Both give the same content (deformed boundary, colours, colour bar,
title); pyvista adds lighting and smooth shading.

Errors (TensormassError, nothing written): a path that is not *.png, is a folder, or cannot
be written; a field name that is not among the given fields (the message lists them); values
of the wrong length; NaN or Inf in the points, the displacement or the values; a mesh with no
2D/3D cells. The PNG is written atomically (base.files.write_bytes_atomic): a reader never sees half
a picture and a failure leaves the previous file (or none).
"""
from __future__ import annotations

import io
import math
import os
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from ... import elements as _types
from ..base.errors import TensormassError
from ..scene.parser import DEFAULT_VIEW, VIEWS, view_angles
from .output import OutputError, check_png_path
from ..base.files import write_bytes_atomic
from ..physics.fields import FIELDS
from ..base import integrator_kinds
from ..mesh.faces import face_table

__all__ = ["write_picture", "picture_of_simulation", "render_picture", "check_picture", "pick_field", "auto_scale",
           "round_length", "pyvista_usable", "EDGE_LIMIT", "DEFAULT_VIEW", "VIEWS"]

EDGE_LIMIT = 6000                 # mesh edges drawn up to this many visible faces (2D: cells)
# Faces culled when their normal points away from the viewer by more than this (cosine): a
# little beyond edge-on, because a curved (quadratic) face whose mean normal points slightly
# away can still show part of itself at the silhouette; these are painted first (farthest).
_CULL = -0.25
_BACKGROUND = "white"


# ============================================================================== public


def write_picture(path, mesh, points, displacement, values, field_name: str = "displacement", unit: str = "",
                  scale: float = 1.0, title: str | None = None, step=None, time=None,
                  size=(1000, 640), cmap: str = "viridis", clim=None, view=None, edges=None,
                  shade: bool = True, backend: str = "auto", clip=None, load=None) -> str:
    """Write a PNG of the deformed body coloured by a field; returns the back end used.

    points: reference positions (n, dim) (None: mesh.points). displacement: (n, dim) or the
    flat dof vector (None: zero). values: one value (or row) per point or per cell, a mapping
    {name: array} from which field_name is taken, a pair of mappings (point fields, cell fields)
    as Simulation.fields() returns them (the nodal one is drawn when both have the name), or
    None for |displacement|. scale: a number, or "auto" (auto_scale: the largest displacement
    drawn at about a tenth of the body's size, never less than as it is). size: (width,
    height) in pixels. clim: (low, high) of the colour bar (default: the field's range). view: a
    name of VIEWS ("top", "front", ...) or (azimuth, elevation) in degrees (3D; default
    DEFAULT_VIEW). clip: ((point), (normal)): only the cells whose rest centre (mean of their nodes
    at `points`) lies on the side the normal points away from are drawn, with the faces the cut
    exposes. load: (k, n) titles a static run "load k/n" (time is then left out).
    """
    target = _check_path(path)
    image = render_picture(mesh, points, displacement, values, field_name, unit=unit, scale=scale,
                           title=title, step=step, time=time, size=size, cmap=cmap, clim=clim,
                           view=view, edges=edges, shade=shade, backend=backend, clip=clip, load=load)
    png, used = image
    try:
        write_bytes_atomic(target, png)
    except OSError as exc:
        raise OutputError(f"cannot write the picture {target}: {exc.strerror or exc}") from None
    return used


def picture_of_simulation(sim, path, field: str = "von_mises", scale="auto", title=None, step=None, time=None,
                          **options) -> str:
    """write_picture for a Simulation at its current state: its mesh (the current one after
    refinement), its displacement, and the field from sim.fields([field]) with the unit that
    runtime.physics.fields.FIELDS gives it ("displacement" needs no fields). The scene's [output]
    view and clip apply unless given; a static run is titled by its load ("load k/n") rather than
    its time. Returns the back end used."""
    mesh = sim.model.mesh
    u = sim.displacement
    options = {**_scene_options(sim.model), **options}
    if "load" not in options and step is not None and _static(sim.model):
        options["load"], time = (step, getattr(sim.model.solver, "steps", step)), None
    unit = options.pop("unit", None)
    if field in ("displacement", "u"):
        values, unit = None, "m" if unit is None else unit
    else:
        fields = getattr(sim, "fields", None)
        if fields is None:
            raise TensormassError("picture: this simulation computes no fields; only 'displacement' can be drawn")
        values = fields([field])
        if unit is None:
            try:
                unit = FIELDS[field].unit if field in FIELDS else ""
            except ImportError:
                unit = ""
    if title is None:
        title = getattr(sim.model, "name", None)
    return write_picture(path, mesh, mesh.points, u, values, field, unit=unit, scale=scale, title=title,
                         step=step, time=time, **options)


def _scene_options(model) -> dict:
    """The picture options of a model's scene ([output] view, clip) that are set."""
    out = getattr(model, "output", None)
    return {k: getattr(out, k) for k in ("view", "clip") if getattr(out, k, None) is not None}


def _static(model) -> bool:
    kind = getattr(getattr(model, "solver", None), "kind", None)
    return kind in integrator_kinds.KINDS and not integrator_kinds.get(kind).dynamic


def check_picture(model, field: str = "displacement") -> None:
    """Refuse (TensormassError), writing nothing, a picture of this model that could not be drawn:
    its mesh with the scene's view and clip is rendered at rest, in memory (a clip that keeps no
    cell, a plane of the wrong dimension, a mesh with nothing to draw)."""
    mesh = model.mesh
    render_picture(mesh, mesh.points, np.zeros_like(mesh.points), None, "displacement", unit="m", size=(160, 120),
                   backend="matplotlib", **_scene_options(model))


def render_picture(mesh, points, displacement, values, field_name: str = "displacement", unit: str = "",
                   scale: float = 1.0, title=None, step=None, time=None, size=(1000, 640), cmap="viridis",
                   clim=None, view=None, edges=None, shade=True, backend="auto", clip=None, load=None) -> tuple:
    """(PNG bytes, back end used): write_picture without the file."""
    scene = _prepare(mesh, points, displacement, values, field_name, unit, scale, size, cmap, clim, view, clip)
    scene.update(title=title, step=step, time=None if load is not None else time, edges=edges, shade=bool(shade),
                 load=_load(load))
    choice = _backend(backend)
    if choice in ("auto", "pyvista") and pyvista_usable():
        try:
            return _render_pyvista(scene), "pyvista"
        except Exception as exc:                       # a broken VTK: matplotlib still draws (auto)
            if choice == "pyvista":
                raise TensormassError(f"pyvista could not render the picture: {type(exc).__name__}: {exc}") from None
    elif choice == "pyvista":
        raise TensormassError("backend 'pyvista': pyvista is not installed or cannot render off-screen here "
                              "(pip install pyvista; it needs an OpenGL library such as Mesa's libEGL or OSMesa)")
    return _render_matplotlib(scene), "matplotlib"


def pick_field(values, field_name: str, n_points: int, n_cells: int, displacement=None):
    """(array, "point" | "cell", label) of the field to draw; see write_picture for `values`."""
    if isinstance(values, (tuple, list)) and len(values) == 2 and all(isinstance(v, Mapping) for v in values):
        point, cell = values                           # Simulation.fields(): nodal values first
        values = {**cell, **point}
    if values is None or (isinstance(values, Mapping) and field_name not in values):
        if field_name in ("displacement", "u") and displacement is not None:
            return np.linalg.norm(displacement, axis=1), "point", "|displacement|"
        if values is None:
            raise TensormassError(f"picture: no values given for field {field_name!r} (only 'displacement' "
                                  "is drawn without values)")
        known = sorted(set(values) | ({"displacement"} if displacement is not None else set()))
        raise TensormassError(f"picture: unknown field {field_name!r}; available: {', '.join(known) or 'none'}")
    arr = values[field_name] if isinstance(values, Mapping) else values
    try:
        arr = np.asarray(arr, dtype=np.float64)
    except (TypeError, ValueError):
        raise TensormassError(f"picture: field {field_name!r} is not numeric") from None
    if arr.ndim == 0:
        raise TensormassError(f"picture: field {field_name!r} is a single number; need one value per point or cell")
    label = field_name
    if arr.ndim > 1:
        arr = np.linalg.norm(arr.reshape(len(arr), -1), axis=1)
        label = f"|{field_name}|"
    if len(arr) == n_points:
        where = "point"
    elif len(arr) == n_cells:
        where = "cell"
    else:
        raise TensormassError(f"picture: field {field_name!r} has {len(arr)} rows; expected {n_points} (points) "
                              f"or {n_cells} (cells)")
    bad = np.flatnonzero(~np.isfinite(arr))
    if bad.size:
        raise TensormassError(f"picture: field {field_name!r} has NaN or Inf at {bad.size} of {len(arr)} "
                              f"{where}s, first {int(bad[0])}")
    return arr, where, label


# ============================================================================== checks and geometry


def _check_path(path) -> Path:
    return check_png_path(path, "picture")


def _finite(name: str, arr: np.ndarray) -> None:
    bad = np.flatnonzero(~np.isfinite(arr.reshape(len(arr), -1)).all(axis=1))
    if bad.size:
        raise TensormassError(f"picture: {name} has NaN or Inf at {bad.size} of {len(arr)} rows, first {int(bad[0])}")


def _prepare(mesh, points, displacement, values, field_name, unit, scale, size, cmap, clim, view, clip=None) -> dict:
    """Everything both back ends need, checked: deformed points, polygons, values, labels."""
    n, dim = mesh.n_points, mesh.dim
    X = mesh.points if points is None else np.asarray(points, dtype=np.float64)
    if X.shape != (n, dim):
        raise TensormassError(f"picture: points must have shape ({n}, {dim}), got {X.shape}")
    _finite("points", X)
    if displacement is None:
        u = np.zeros((n, dim))
    else:
        u = np.asarray(displacement, dtype=np.float64)
        if u.ndim == 1 and u.size == n * dim:
            u = u.reshape(n, dim)
        if u.shape != (n, dim):
            raise TensormassError(f"picture: displacement must have shape ({n}, {dim}), got {u.shape}")
        _finite("displacement", u)
    if isinstance(scale, str) and scale == "auto":
        scale = auto_scale(X, u)
    try:
        scale = float(scale)
    except (TypeError, ValueError):
        raise TensormassError(f"picture: scale must be a number or \"auto\", got {scale!r}") from None
    if not math.isfinite(scale):
        raise TensormassError(f"picture: scale must be finite, got {scale}")
    try:
        width, height = (int(s) for s in size)
    except (TypeError, ValueError):
        raise TensormassError(f"picture: size must be (width, height) in pixels, got {size!r}") from None
    if not (100 <= width <= 8000 and 100 <= height <= 8000):
        raise TensormassError(f"picture: size {width} x {height} pixels; each side must be 100 to 8000")
    import matplotlib                                  # colormaps only: no pyplot, no window
    try:
        colormap = matplotlib.colormaps[cmap]
    except (KeyError, TypeError):
        raise TensormassError(f"picture: unknown colour map {cmap!r} (matplotlib's names: viridis, plasma, ...)") from None
    arr, where, label = pick_field(values, str(field_name), n, mesh.n_cells,
                                   None if displacement is None else u)
    if clim is None:
        lo, hi = float(arr.min()), float(arr.max())
    else:
        try:
            lo, hi = (float(c) for c in clim)
        except (TypeError, ValueError):
            raise TensormassError(f"picture: clim must be (low, high), got {clim!r}") from None
        if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
            raise TensormassError(f"picture: clim must be finite with low <= high, got {clim!r}")
    if hi - lo <= 1e-12 * max(abs(lo), abs(hi), 1e-300):   # a constant field: a colour bar around it
        pad = max(abs(lo) * 1e-3, 1e-12)
        lo, hi = lo - pad, hi + pad
    azim, elev = DEFAULT_VIEW if view is None else _view(view)
    kept = _clip(mesh, X, clip)
    polys, cells, two_sided = _polygons(mesh, kept)
    if not polys:
        if kept is not None and _polygons(mesh, None)[0]:
            raise TensormassError(f"picture: clip {_fmt_clip(clip)} removes every cell (the rest centre of each lies "
                                  "on the side the normal points to, which is cut away); nothing is left to draw: "
                                  "move the clip's point into the body, or turn its normal round")
        raise TensormassError("picture: the mesh has no 2D or 3D cells to draw")
    return dict(mesh=mesh, dim=dim, x=X + scale * u, values=arr, where=where, label=label, unit=str(unit or ""),
                scale=scale, width=width, height=height, cmap=colormap, clim=(lo, hi), view=(azim, elev),
                polys=polys, cells=cells, two_sided=two_sided, moved=bool(np.any(u)), clipped=kept is not None)


def auto_scale(points, displacement, target: float = 0.1) -> float:
    """A displacement scale that makes the largest displacement about `target` of the body's
    size (bounding-box diagonal), rounded down to 1, 2 or 5 times a power of ten; never below 1
    (a visible deformation is drawn as it is)."""
    X = np.asarray(points, dtype=np.float64)
    u = np.asarray(displacement, dtype=np.float64).reshape(len(X), -1)
    size = float(np.linalg.norm(X.max(axis=0) - X.min(axis=0))) if len(X) else 0.0
    umax = float(np.sqrt((u * u).sum(axis=1)).max()) if len(u) else 0.0
    if not (umax > 0.0 and size > 0.0) or umax >= target * size:
        return 1.0
    raw = target * size / umax
    power = 10.0 ** math.floor(math.log10(raw))
    return float(max(m for m in (1.0, 2.0, 5.0) if m * power <= raw * (1 + 1e-12)) * power)


def _view(view):
    """(azimuth, elevation) in degrees of a view name or pair (the scene's rules: runtime.scene.parser)."""
    if isinstance(view, np.ndarray):
        view = view.tolist()
    if isinstance(view, tuple):
        view = list(view)
    if isinstance(view, list):
        view = [float(v) if isinstance(v, (np.floating, np.integer)) else v for v in view]
    return view_angles(view, "picture: view")


def _fmt_clip(clip) -> str:
    return str([[float(v) for v in part] for part in clip])


def _clip(mesh, X, clip):
    """The cells kept by a clip plane (bool per cell, global order), or None without one."""
    if clip is None:
        return None
    try:
        point, normal = (np.asarray(part, dtype=np.float64) for part in clip)
    except (TypeError, ValueError):
        raise TensormassError(f"picture: clip must be [[point...], [normal...]], got {clip!r}") from None
    if point.shape != (mesh.dim,) or normal.shape != (mesh.dim,):
        raise TensormassError(f"picture: clip point and normal need {mesh.dim} components each (the mesh is "
                              f"{mesh.dim}D), got {clip!r}")
    if not (np.isfinite(point).all() and np.isfinite(normal).all()) or not np.any(normal):
        raise TensormassError(f"picture: clip needs a finite point and a non-zero normal, got {clip!r}")
    kept = []
    for b in mesh.blocks:
        centre = X[b.cells].mean(axis=1) if len(b) else np.zeros((0, mesh.dim))
        kept.append((centre - point) @ normal <= 0.0)
    return np.concatenate(kept) if kept else np.zeros(0, bool)


def _load(load):
    """(k, n) of a static run's load step, checked, or None."""
    if load is None:
        return None
    try:
        k, n = (int(v) for v in load)
    except (TypeError, ValueError):
        raise TensormassError(f"picture: load must be (step, steps), got {load!r}") from None
    if n < 1 or not 0 <= k <= n:
        raise TensormassError(f"picture: load must be (step, steps) with 0 <= step <= steps, got {load!r}")
    return k, n


def round_length(length: float) -> float:
    """The largest 1, 2 or 5 times a power of ten that is at most `length` (> 0)."""
    power = 10.0 ** math.floor(math.log10(length))
    return float(max(m for m in (1.0, 2.0, 5.0) if m * power <= length * (1 + 1e-12)) * power)


def _length_text(length: float) -> str:
    """A length in metres as a person writes it: 2 m, 50 mm, 200 um."""
    for factor, unit in ((1.0, "m"), (1e-3, "mm"), (1e-6, "\u00b5m")):
        if length >= factor * (1 - 1e-9):
            return f"{length / factor:.6g} {unit}"
    return f"{length:.3g} m"


def _outline(type_name: str, n_nodes: int) -> list:
    """Local node ids of a 2D cell or face type around its outline: corners with the midside
    node of each edge between them (corners only for types the table cannot say this for)."""
    try:
        el = _types.get(type_name)
    except ValueError:
        return list(range(n_nodes))
    k = el.n_corners
    mids = {frozenset(e): el.n_corners + m for m, e in enumerate(el.midside_edges)}
    out = []
    for i in range(k):
        out.append(i)
        m = mids.get(frozenset((i, (i + 1) % k)))
        if m is not None and m < n_nodes:
            out.append(m)
    return out


def _polygons(mesh, kept=None):
    """Polygons to draw: [(outline node ids, all node ids)], the global cell id of each, and
    whether each is two-sided (a shell's cell: seen from both sides, never culled).

    3D: the boundary faces of the kept volume cells (those used by exactly one kept cell: the
    body's surface and, with a clip, the faces the cut exposes) and the kept 2D cells (shells,
    triangles in 3D) themselves; 2D: the kept area cells. kept: bool per cell, None for all."""
    offsets = np.concatenate([[0], np.cumsum([len(b) for b in mesh.blocks])]).astype(np.int64)
    polys, cells, two_sided = [], [], []
    if mesh.dim == 3:
        ft = face_table(mesh)
        if len(ft.cell):
            mine = np.ones(len(ft.cell), bool) if kept is None else kept[ft.cell]
            users = np.bincount(ft.group, weights=mine.astype(np.float64), minlength=len(ft.count))
            outlines = {}
            for r in np.flatnonzero(mine & (users[ft.group] == 1)):
                bi = int(ft.block[r])
                el = _types.get(mesh.blocks[bi].type)
                face = el.faces[int(ft.lface[r])]
                key = (mesh.blocks[bi].type, int(ft.lface[r]))
                if key not in outlines:
                    outlines[key] = _outline(face.type, len(face.nodes)) if face.type else list(range(len(face.nodes)))
                nodes = np.asarray(mesh.blocks[bi].cells[int(ft.local[r]), list(face.nodes)], dtype=np.int64)
                polys.append((nodes[outlines[key]], nodes))
                cells.append(int(ft.cell[r]))
                two_sided.append(False)
    for bi, b in enumerate(mesh.blocks):
        el = _types.get(b.type)
        if el.dim != 2:
            continue
        order = _outline(b.type, el.n_nodes)
        for j, row in enumerate(b.cells):
            if kept is None or kept[offsets[bi] + j]:
                polys.append((row[order], row))
                cells.append(offsets[bi] + j)
                two_sided.append(mesh.dim == 3)
    return polys, np.asarray(cells, dtype=np.int64), np.asarray(two_sided, dtype=bool)


def _frame(azim: float, elev: float):
    """Right, up and toward-the-viewer unit vectors of an orthographic view (matplotlib's angles)."""
    e, a = math.radians(elev), math.radians(azim)
    toward = np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)])
    right = np.array([-math.sin(a), math.cos(a), 0.0])
    up = np.cross(toward, right)
    return right, up, toward


def _title(scene) -> str:
    head = scene["title"] or ""
    when = []
    if scene.get("load") is not None:
        k, n = scene["load"]
        when.append(f"load {k}/{n}")
    elif scene["step"] is not None:
        when.append(f"step {scene['step']}")
    if scene["time"] is not None:
        when.append(f"t = {float(scene['time']):.6g} s")
    line = ", ".join(when)
    first = f"{head}: {line}" if head and line else (head or line)
    unit = f" [{scene['unit']}]" if scene["unit"] else ""
    second = f"{scene['label']}{unit} on the deformed body (displacement x {scene['scale']:g})" if scene["moved"] \
        else f"{scene['label']}{unit} on the body (no displacement)"
    if scene.get("clipped"):
        second += ", clipped"
    return f"{first}\n{second}" if first else second


def _colorbar_label(scene) -> str:
    return f"{scene['label']} [{scene['unit']}]" if scene["unit"] else scene["label"]


# ============================================================================== matplotlib


def _triangles(scene, keep, shade_of):
    """Screen triangles (m, 3, 2) with vertex colours (m, 3, 4), in painting order, and the
    first triangle of each kept face (len(keep) + 1 offsets).

    Each face is a fan of triangles around its centre. A nodal field: vertex colours from the
    values, the centre's from the mean over the face's nodes (all of them, midsides included),
    interpolated across each triangle (Gouraud). A cell field: every vertex has the cell's
    colour. 3D faces are darkened by shade_of (one factor per face)."""
    from matplotlib.colors import Normalize
    xy, vals, polys, cells = scene["xy"], scene["values"], scene["polys"], scene["cells"]
    norm = Normalize(*scene["clim"])
    tris, tvals, owner, starts = [], [], [], [0]
    for i in keep:
        outline, nodes = polys[i]
        k = len(outline)
        c = xy[outline].mean(axis=0)
        p = xy[outline]
        q = np.roll(p, -1, axis=0)
        tris.append(np.stack([np.broadcast_to(c, p.shape), p, q], axis=1))
        if scene["where"] == "cell":
            tvals.append(np.full((k, 3), vals[cells[i]]))
        else:
            v = vals[outline]
            tvals.append(np.column_stack([np.full(k, vals[nodes].mean()), v, np.roll(v, -1)]))
        owner.append(np.full(k, i))
        starts.append(starts[-1] + k)
    tris = np.concatenate(tris)
    colours = scene["cmap"](norm(np.concatenate(tvals)))
    colours[..., :3] *= shade_of[np.concatenate(owner)][:, None, None]
    return tris, colours, np.asarray(starts)


def _body_artist(scene, keep, shade_of, draw_edges):
    """An artist that paints the faces back to front, each face's edges right after it (so a
    face in front covers the edges of the faces behind it)."""
    from matplotlib.artist import Artist
    from matplotlib.path import Path as MplPath

    tris, colours, starts = _triangles(scene, keep, shade_of)
    outlines = [MplPath(scene["xy"][scene["polys"][i][0][list(range(len(scene["polys"][i][0]))) + [0]]], closed=True)
                for i in keep] if draw_edges else None

    class Body(Artist):
        def draw(self, renderer):
            if not self.get_visible():
                return
            transform = self.axes.transData
            gc = renderer.new_gc()
            gc.set_antialiased(True)
            if outlines is None:
                renderer.draw_gouraud_triangles(gc, tris, colours, transform)
            else:
                edge = renderer.new_gc()
                edge.set_foreground((0.1, 0.1, 0.1, 0.55), isRGBA=True)
                edge.set_linewidth(0.45)
                edge.set_antialiased(True)
                for j, poly in enumerate(outlines):
                    a, b = starts[j], starts[j + 1]
                    renderer.draw_gouraud_triangles(gc, tris[a:b], colours[a:b], transform)
                    renderer.draw_path(edge, poly, transform)
                edge.restore()
            gc.restore()
            self.stale = False

    return Body()


def _render_matplotlib(scene) -> bytes:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize
    from matplotlib.figure import Figure

    x, dim = scene["x"], scene["dim"]
    polys = scene["polys"]
    shade_of = np.ones(len(polys))
    if dim == 3:
        right, up, toward = _frame(*scene["view"])
        xy = np.column_stack([x @ right, x @ up])
        depth = x @ toward
        normals = np.array([_newell(x[outline]) for outline, _ in polys])
        length = np.linalg.norm(normals, axis=1)
        facing = normals @ toward
        two = scene["two_sided"]
        facing[two] = np.abs(facing[two])          # a shell is seen from either side
        keep = np.flatnonzero(two | (facing > _CULL * np.maximum(length, 1e-300)))
        mean_depth = np.array([depth[polys[i][0]].mean() for i in keep])
        keep = keep[np.argsort(mean_depth, kind="stable")]          # back to front
        if scene["shade"]:
            shade_of = 0.72 + 0.28 * np.clip(facing / np.maximum(length, 1e-300), 0.0, 1.0)
    else:
        right, up = np.array([1.0, 0.0]), np.array([0.0, 1.0])
        xy = x.copy()
        keep = np.arange(len(polys))
    if keep.size == 0:
        raise TensormassError("picture: no face of the body is visible (a degenerate deformed shape?)")
    scene["xy"] = xy
    draw_edges = scene["edges"] if scene["edges"] is not None else len(keep) <= EDGE_LIMIT

    fig = Figure(figsize=(scene["width"] / 100.0, scene["height"] / 100.0), dpi=100, facecolor=_BACKGROUND)
    FigureCanvasAgg(fig)
    ax = fig.add_axes((0.03, 0.04, 0.76, 0.80))
    ax.set_axis_off()
    ax.set_aspect("equal")
    body = _body_artist(scene, keep, shade_of, draw_edges)
    body.set_figure(fig)
    body.axes = ax
    ax.add_artist(body)
    shown = xy[np.unique(np.concatenate([polys[i][0] for i in keep]))]
    lo, hi = shown.min(axis=0), shown.max(axis=0)
    span = max(float((hi - lo).max()), 1e-300)
    pad = 0.04 * span
    band = 0.12 * span                               # below the body: the length scale
    ax.set_xlim(lo[0] - pad, hi[0] + pad)
    ax.set_ylim(lo[1] - pad - band, hi[1] + pad)
    _scale_bar(ax, lo, hi, pad, band, span)

    cax = fig.add_axes((0.83, 0.10, 0.025, 0.68))
    bar = fig.colorbar(ScalarMappable(norm=Normalize(*scene["clim"]), cmap=scene["cmap"]), cax=cax)
    bar.set_label(_colorbar_label(scene))
    fig.suptitle(_title(scene), fontsize=11, y=0.975)
    _triad(fig, right, up, dim)

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100, facecolor=_BACKGROUND, metadata={"Software": None})
    return buf.getvalue()


def _scale_bar(ax, lo, hi, pad, band, span) -> None:
    """A bar of a round length (1, 2 or 5 times a power of ten, about a quarter of the body's
    width on the screen) under the body's right end, labelled with its length; orthographic
    projection: a length in the picture's plane is drawn at its true size."""
    width = float(hi[0] - lo[0])
    length = round_length(0.25 * (width if width > 0.05 * span else span))
    x1 = float(hi[0])
    x0 = x1 - length
    y = float(lo[1]) - pad - 0.35 * band
    tick = 0.12 * band
    ax.plot([x0, x1], [y, y], color="black", lw=2.0, solid_capstyle="butt", zorder=5)
    ax.plot([x0, x0], [y - tick, y + tick], color="black", lw=1.2, zorder=5)
    ax.plot([x1, x1], [y - tick, y + tick], color="black", lw=1.2, zorder=5)
    ax.text(0.5 * (x0 + x1), y - 1.6 * tick, _length_text(length), ha="center", va="top", fontsize=9, zorder=5)


def _pyvista_scale_bar(plotter, x, polys, right, up, toward) -> None:
    """The length scale of the matplotlib picture as a pyvista ruler under the body (text if the
    pyvista at hand has no ruler)."""
    shown = x[np.unique(np.concatenate([outline for outline, _ in polys]))]
    r, u, d = shown @ right, shown @ up, shown @ toward
    span = max(float(np.ptp(r)), float(np.ptp(u)), 1e-300)
    width = float(np.ptp(r))
    length = round_length(0.25 * (width if width > 0.05 * span else span))
    end = r.max() * right + (u.min() - 0.08 * span) * up + d.mean() * toward
    try:
        plotter.add_ruler(tuple(end - length * right), tuple(end), title=_length_text(length), show_labels=False,
                          number_minor_ticks=0, font_size_factor=0.6)
    except (AttributeError, TypeError):
        plotter.add_text(f"scale: {_length_text(length)}", position="lower_right", font_size=9, color="black")


def _newell(p: np.ndarray) -> np.ndarray:
    """Area-weighted normal of a (possibly non-planar) polygon, right-hand rule (Newell's method)."""
    q = np.roll(p, -1, axis=0)
    return 0.5 * np.array([np.sum((p[:, 1] - q[:, 1]) * (p[:, 2] + q[:, 2])),
                           np.sum((p[:, 2] - q[:, 2]) * (p[:, 0] + q[:, 0])),
                           np.sum((p[:, 0] - q[:, 0]) * (p[:, 1] + q[:, 1]))])


def _triad(fig, right, up, dim) -> None:
    """Axis directions in the lower left corner: x, y (and z) as seen in the picture."""
    tax = fig.add_axes((0.01, 0.01, 0.09, 0.14))
    tax.set_axis_off()
    tax.set_xlim(-1.35, 1.35)
    tax.set_ylim(-1.35, 1.35)
    tax.set_aspect("equal")
    for axis, name, colour in zip(range(dim), "xyz", ("#c0392b", "#27ae60", "#2c3e9f")):
        dx, dy = float(right[axis]), float(up[axis])
        if math.hypot(dx, dy) < 0.08:               # along the view direction: a dot
            tax.plot([0], [0], marker="o", markersize=3, color=colour)
            tax.text(0.15, 0.15, name, color=colour, fontsize=8)
            continue
        tax.annotate("", xy=(dx, dy), xytext=(0, 0),
                     arrowprops=dict(arrowstyle="-|>", color=colour, lw=1.2, shrinkA=0, shrinkB=0))
        tax.text(1.22 * dx, 1.22 * dy, name, color=colour, fontsize=8, ha="center", va="center")


# ============================================================================== pyvista


def _backend(backend: str) -> str:
    choice = os.environ.get("TENSORMASS_PICTURE", "") if backend == "auto" else backend
    choice = choice or "auto"
    if choice not in ("auto", "matplotlib", "pyvista"):
        where = "TENSORMASS_PICTURE" if backend == "auto" else "backend"
        raise TensormassError(f"picture: {where} must be auto, matplotlib or pyvista, got {choice!r}")
    return choice


_PYVISTA_OK = None


def pyvista_usable() -> bool:
    """Whether pyvista is installed and renders a tiny scene off-screen here (tried once)."""
    global _PYVISTA_OK
    if _PYVISTA_OK is None:
        try:
            pv = _pyvista()
            plotter = pv.Plotter(off_screen=True, window_size=(32, 32))
            plotter.add_mesh(pv.Cube())
            img = plotter.screenshot(return_img=True)
            plotter.close()
            _PYVISTA_OK = img is not None and img.size > 0 and int(np.ptp(img)) > 0
        except Exception:
            _PYVISTA_OK = False
    return _PYVISTA_OK


def _pyvista():
    import pyvista as pv                             # ImportError when not installed
    try:                                             # VTK's own logging to stderr (e.g. "bad X server
        import vtk                                   # connection" before it falls back to EGL): off
        vtk.vtkLogger.SetStderrVerbosity(vtk.vtkLogger.VERBOSITY_OFF)
        vtk.vtkObject.GlobalWarningDisplayOff()
    except Exception:
        pass
    pv.OFF_SCREEN = True
    return pv


def _render_pyvista(scene) -> bytes:
    pv = _pyvista()
    dim = scene["dim"]
    x = scene["x"] if dim == 3 else np.column_stack([scene["x"], np.zeros(len(scene["x"]))])
    # the polygons the matplotlib path draws (surface, clip's cut faces, shells), as one PolyData
    faces = np.concatenate([np.concatenate([[len(outline)], outline]) for outline, _ in scene["polys"]])
    surface = pv.PolyData(np.ascontiguousarray(x, dtype=np.float64), faces.astype(np.int64))
    name = _colorbar_label(scene)
    if scene["where"] == "point":
        surface.point_data[name] = scene["values"]
    else:
        surface.cell_data[name] = scene["values"][scene["cells"]]
    plotter = pv.Plotter(off_screen=True, window_size=(scene["width"], scene["height"]))
    try:
        plotter.set_background(_BACKGROUND)
        show_edges = scene["edges"] if scene["edges"] is not None else len(scene["polys"]) <= EDGE_LIMIT
        plotter.add_mesh(surface, scalars=name, cmap=scene["cmap"].name, clim=scene["clim"],
                         show_edges=show_edges, edge_color=(0.25, 0.25, 0.25), lighting=scene["shade"],
                         smooth_shading=False,
                         scalar_bar_args=dict(title=name, vertical=True, color="black", position_x=0.86,
                                              position_y=0.12, height=0.7, width=0.05))
        plotter.add_text(_title(scene), position="upper_edge", font_size=10, color="black")
        plotter.enable_parallel_projection()
        if dim == 3:
            right, up, toward = _frame(*scene["view"])
            centre = np.asarray(surface.center)
            radius = float(np.linalg.norm(np.ptp(x, axis=0))) or 1.0
            plotter.camera.focal_point = tuple(centre)
            plotter.camera.position = tuple(centre + 3.0 * radius * toward)
            plotter.camera.up = tuple(up)
            plotter.add_axes(color="black")
        else:
            right, up, toward = np.eye(3)
            plotter.view_xy()
        _pyvista_scale_bar(plotter, x, scene["polys"], right, up, toward)
        plotter.reset_camera()
        plotter.camera.zoom(1.05)
        img = plotter.screenshot(return_img=True)
    finally:
        plotter.close()
    from PIL import Image
    buf = io.BytesIO()
    Image.fromarray(np.asarray(img, dtype=np.uint8)).save(buf, format="PNG")
    return buf.getvalue()
