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
from .output import OutputError, check_png_path
from ..base.files import write_bytes_atomic

__all__ = ["write_picture", "picture_of_simulation", "render_picture", "pick_field", "auto_scale", "pyvista_usable", "EDGE_LIMIT", "DEFAULT_VIEW"]

EDGE_LIMIT = 6000                 # mesh edges drawn up to this many visible faces (2D: cells)
DEFAULT_VIEW = (20.0, -60.0)      # elevation, azimuth in degrees
# Faces culled when their normal points away from the viewer by more than this (cosine): a
# little beyond edge-on, because a curved (quadratic) face whose mean normal points slightly
# away can still show part of itself at the silhouette; these are painted first (farthest).
_CULL = -0.25
_BACKGROUND = "white"


# ============================================================================== public


def write_picture(path, mesh, points, displacement, values, field_name: str = "displacement", unit: str = "",
                  scale: float = 1.0, title: str | None = None, step=None, time=None,
                  size=(1000, 640), cmap: str = "viridis", clim=None, view=None, edges=None,
                  shade: bool = True, backend: str = "auto") -> str:
    """Write a PNG of the deformed body coloured by a field; returns the back end used.

    points: reference positions (n, dim) (None: mesh.points). displacement: (n, dim) or the
    flat dof vector (None: zero). values: one value (or row) per point or per cell, a mapping
    {name: array} from which field_name is taken, a pair of mappings (point fields, cell fields)
    as Simulation.fields() returns them (the nodal one is drawn when both have the name), or
    None for |displacement|. scale: a number, or "auto" (auto_scale: the largest displacement
    drawn at about a tenth of the body's size, never less than as it is). size: (width,
    height) in pixels. clim: (low, high) of the colour bar (default: the field's range).
    """
    target = _check_path(path)
    image = render_picture(mesh, points, displacement, values, field_name, unit=unit, scale=scale,
                           title=title, step=step, time=time, size=size, cmap=cmap, clim=clim,
                           view=view, edges=edges, shade=shade, backend=backend)
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
    runtime.physics.fields.FIELDS gives it ("displacement" needs no fields). Returns the back end used."""
    mesh = sim.model.mesh
    u = sim.displacement
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
                from ..physics.fields import FIELDS
                unit = FIELDS[field].unit if field in FIELDS else ""
            except ImportError:
                unit = ""
    if title is None:
        title = getattr(sim.model, "name", None)
    return write_picture(path, mesh, mesh.points, u, values, field, unit=unit, scale=scale, title=title,
                         step=step, time=time, **options)


def render_picture(mesh, points, displacement, values, field_name: str = "displacement", unit: str = "",
                   scale: float = 1.0, title=None, step=None, time=None, size=(1000, 640), cmap="viridis",
                   clim=None, view=None, edges=None, shade=True, backend="auto") -> tuple:
    """(PNG bytes, back end used): write_picture without the file."""
    scene = _prepare(mesh, points, displacement, values, field_name, unit, scale, size, cmap, clim, view)
    scene.update(title=title, step=step, time=time, edges=edges, shade=bool(shade))
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


def _prepare(mesh, points, displacement, values, field_name, unit, scale, size, cmap, clim, view) -> dict:
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
    elev, azim = DEFAULT_VIEW if view is None else _view(view)
    polys, cells = _polygons(mesh)
    if not polys:
        raise TensormassError("picture: the mesh has no 2D or 3D cells to draw")
    return dict(mesh=mesh, dim=dim, x=X + scale * u, values=arr, where=where, label=label, unit=str(unit or ""),
                scale=scale, width=width, height=height, cmap=colormap, clim=(lo, hi), view=(elev, azim),
                polys=polys, cells=cells, moved=bool(np.any(u)))


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
    try:
        elev, azim = (float(v) for v in view)
    except (TypeError, ValueError):
        raise TensormassError(f"picture: view must be (elevation, azimuth) in degrees, got {view!r}") from None
    if not (math.isfinite(elev) and math.isfinite(azim)):
        raise TensormassError(f"picture: view must be finite, got {view!r}")
    return elev, azim


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


def _polygons(mesh):
    """Polygons to draw: [node id arrays (outline order)] and the global cell id of each.

    3D: the boundary faces of the volume cells; 2D: the area cells. Each polygon is returned
    with all nodes of its face (or cell) after the outline, in `nodes` of the same entry:
    (outline, all_nodes)."""
    offsets = np.concatenate([[0], np.cumsum([len(b) for b in mesh.blocks])])
    polys, cells = [], []
    if mesh.dim == 3:
        from ..mesh.faces import boundary_faces
        by_count = {}
        for b in mesh.blocks:
            el = _types.get(b.type)
            if el.dim == 3:
                by_count[b.type] = {len(f.nodes): f.type for f in el.faces}
        solid = [i for i, b in enumerate(mesh.blocks) if b.type in by_count]
        if not solid:
            return [], np.zeros(0, np.int64)
        outlines = {}
        for block, local, nodes in boundary_faces(mesh):
            ftype = by_count[mesh.blocks[block].type].get(len(nodes))
            key = (ftype, len(nodes))
            if key not in outlines:
                outlines[key] = _outline(ftype, len(nodes)) if ftype else list(range(len(nodes)))
            nodes = np.asarray(nodes, dtype=np.int64)
            polys.append((nodes[outlines[key]], nodes))
            cells.append(offsets[block] + local)
    else:
        for bi, b in enumerate(mesh.blocks):
            el = _types.get(b.type)
            if el.dim != 2:
                continue
            order = _outline(b.type, el.n_nodes)
            for j, row in enumerate(b.cells):
                polys.append((row[order], row))
                cells.append(offsets[bi] + j)
    return polys, np.asarray(cells, dtype=np.int64)


def _frame(elev: float, azim: float):
    """Right, up and toward-the-viewer unit vectors of an orthographic view (matplotlib's angles)."""
    e, a = math.radians(elev), math.radians(azim)
    toward = np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)])
    right = np.array([-math.sin(a), math.cos(a), 0.0])
    up = np.cross(toward, right)
    return right, up, toward


def _title(scene) -> str:
    head = scene["title"] or ""
    when = []
    if scene["step"] is not None:
        when.append(f"step {scene['step']}")
    if scene["time"] is not None:
        when.append(f"t = {float(scene['time']):.6g} s")
    line = ", ".join(when)
    first = f"{head}: {line}" if head and line else (head or line)
    unit = f" [{scene['unit']}]" if scene["unit"] else ""
    second = f"{scene['label']}{unit} on the deformed body (displacement x {scene['scale']:g})" if scene["moved"] \
        else f"{scene['label']}{unit} on the body (no displacement)"
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
        keep = np.flatnonzero(facing > _CULL * np.maximum(length, 1e-300))
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
    pad = 0.04 * max(float((hi - lo).max()), 1e-300)
    ax.set_xlim(lo[0] - pad, hi[0] + pad)
    ax.set_ylim(lo[1] - pad, hi[1] + pad)

    cax = fig.add_axes((0.83, 0.10, 0.025, 0.68))
    bar = fig.colorbar(ScalarMappable(norm=Normalize(*scene["clim"]), cmap=scene["cmap"]), cax=cax)
    bar.set_label(_colorbar_label(scene))
    fig.suptitle(_title(scene), fontsize=11, y=0.975)
    _triad(fig, right, up, dim)

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100, facecolor=_BACKGROUND, metadata={"Software": None})
    return buf.getvalue()


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
    from ..mesh.io import to_meshio
    mesh, dim = scene["mesh"], scene["dim"]
    m = to_meshio(mesh, pad_to_3d=True)
    x = scene["x"] if dim == 3 else np.column_stack([scene["x"], np.zeros(len(scene["x"]))])
    m.points = x
    m.cell_data = {}
    name = _colorbar_label(scene)
    grid = pv.from_meshio(m)
    if scene["where"] == "point":
        grid.point_data[name] = scene["values"]
    else:
        grid.cell_data[name] = scene["values"]
    surface = grid.extract_surface(algorithm="dataset_surface") if dim == 3 else grid
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
            plotter.view_xy()
        plotter.reset_camera()
        plotter.camera.zoom(1.05)
        img = plotter.screenshot(return_img=True)
    finally:
        plotter.close()
    from PIL import Image
    buf = io.BytesIO()
    Image.fromarray(np.asarray(img, dtype=np.uint8)).save(buf, format="PNG")
    return buf.getvalue()
