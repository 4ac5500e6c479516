"""runtime.run.picture: a PNG of the deformed body, coloured by a field, drawn off-screen.

The images are decoded and checked: the asked size, a body that covers a fair part of the
drawing area, many distinct colours, and (without shading) both ends of the colour map
present on the body when the field varies (a blank or one-coloured picture fails)."""
from __future__ import annotations

import os

import numpy as np
import pytest

from tensormass.runtime.base.errors import TensormassError
from tensormass.runtime.mesh.bars import generate_bar
from tensormass.runtime.run.picture import render_picture, pyvista_usable, write_picture

PIL = pytest.importorskip("PIL.Image")

SIZE = (500, 320)


def _image(path):
    with PIL.open(path) as im:
        assert im.format == "PNG"
        return im.size, np.asarray(im.convert("RGB"), dtype=np.int64)


def _body(rgb):
    """The drawing area: left of the colour bar, below the title, above the axis triad."""
    h, w, _ = rgb.shape
    return rgb[int(0.16 * h):int(0.84 * h), int(0.02 * w):int(0.79 * w)].reshape(-1, 3)


def _lut(cmap="viridis"):
    import matplotlib
    return np.rint(matplotlib.colormaps[cmap](np.linspace(0, 1, 256))[:, :3] * 255).astype(np.int64)


def _colormap_positions(pixels, cmap="viridis"):
    """Positions in [0, 1] of the pixels that are colours of the map (within a few levels)."""
    lut = _lut(cmap)
    d = ((pixels[:, None, :] - lut[None, :, :]) ** 2).sum(axis=2)
    best = d.argmin(axis=1)
    ok = d[np.arange(len(pixels)), best] <= 3 * 4 ** 2
    return best[ok] / 255.0


def _bent(mesh, amount=0.1):
    X = mesh.points
    L = X[:, 0].max()
    u = np.zeros_like(X)
    u[:, -1] = -amount * L * (X[:, 0] / L) ** 2
    return u


def _check_picture(path, size=SIZE, extremes=True):
    got, rgb = _image(path)
    assert got == size
    body = _body(rgb)
    background = (body == 255).all(axis=1)
    covered = 1.0 - background.mean()
    assert covered > 0.15, f"the body covers only {covered:.1%} of the drawing area"
    colours = np.unique(body[~background], axis=0)
    assert len(colours) > 40, f"only {len(colours)} distinct colours"
    if extremes:
        sample = body[~background][::3]
        pos = _colormap_positions(sample)
        assert pos.size > 0.3 * len(sample), "the body's pixels are not colours of the colour map"
        assert pos.min() < 0.04 and pos.max() > 0.96, (pos.min(), pos.max())
    return rgb


CASES = [
    ("hexahedron", (1.0, 0.2, 0.2), (8, 2, 2)),
    ("tetra10", (1.0, 0.3, 0.3), (4, 1, 1)),
    ("mixed", (2.0, 0.4, 0.4), (8, 1, 1)),
    ("triangle", (1.0, 0.3), (8, 2)),
    ("triangle6", (1.0, 0.3), (6, 2)),
    ("mixed", (1.0, 0.3), (8, 2)),
]


@pytest.mark.parametrize("element,size,cells", CASES, ids=[f"{c[0]}{len(c[1])}d" for c in CASES])
def test_picture_of_every_kind_of_mesh(tmp_path, element, size, cells):
    mesh = generate_bar(size=size, cells=cells, element=element)
    path = tmp_path / "x.png"
    used = write_picture(path, mesh, mesh.points, _bent(mesh), {"x": mesh.points[:, 0]}, "x", unit="m",
                         title=element, step=2, time=0.25, size=SIZE, shade=False, edges=False,
                         backend="matplotlib")
    assert used == "matplotlib"
    _check_picture(path)
    assert sorted(os.listdir(tmp_path)) == ["x.png"]          # no temporary left behind


def test_defaults_shaded_with_edges_and_cell_values(tmp_path):
    mesh = generate_bar(size=(1.0, 0.2, 0.2), cells=(6, 2, 2), element="mixed")
    u = _bent(mesh)
    path = tmp_path / "u.png"
    write_picture(path, mesh, None, u, None, "displacement", unit="m", size=SIZE, backend="matplotlib")
    _check_picture(path, extremes=False)                      # |u|, shaded, edges drawn
    cell_x = np.arange(mesh.n_cells, dtype=float)             # a cell field
    write_picture(path, mesh, None, u, cell_x, "cell id", size=SIZE, shade=False, backend="matplotlib")
    _check_picture(path)


def test_scale_moves_the_body(tmp_path):
    """The body is drawn deformed: a larger scale bends it further down the picture."""
    mesh = generate_bar(size=(1.0, 0.2), cells=(6, 2), element="quad")
    u = _bent(mesh, 0.05)
    aspect = []
    for scale in (0.0, 5.0):
        png, _ = render_picture(mesh, None, u, mesh.points[:, 0], "x", scale=scale, size=SIZE,
                                clim=(0, 1), backend="matplotlib")
        path = tmp_path / f"s{scale}.png"
        path.write_bytes(png)
        _, rgb = _image(path)
        area = rgb[int(0.16 * SIZE[1]):int(0.84 * SIZE[1]), :int(0.79 * SIZE[0])]
        ink = np.ptp(area, axis=2) > 20                       # coloured: the body (the length scale is black)
        rows, cols = np.flatnonzero(ink.any(axis=1)), np.flatnonzero(ink.any(axis=0))
        aspect.append((rows[-1] - rows[0]) / (cols[-1] - cols[0]))
    # the straight bar is 0.2 high for 1 long; bent by 5 * 0.05 at the tip it spans ~0.45
    assert 0.15 < aspect[0] < 0.3 and aspect[1] > 1.6 * aspect[0], aspect


def test_blank_or_flat_pictures_fail_the_check(tmp_path):
    """The check itself: a white picture and a one-coloured body are refused."""
    blank = tmp_path / "blank.png"
    PIL.fromarray(np.full((SIZE[1], SIZE[0], 3), 255, np.uint8)).save(blank)
    with pytest.raises(AssertionError):
        _check_picture(blank)
    mesh = generate_bar(size=(1.0, 0.2, 0.2), cells=(4, 1, 1), element="hexahedron")
    flat = tmp_path / "flat.png"
    write_picture(flat, mesh, None, None, np.zeros(mesh.n_points), "zero", size=SIZE, shade=False,
                  edges=False, backend="matplotlib")
    with pytest.raises(AssertionError):
        _check_picture(flat)


def test_bad_input_is_refused_and_nothing_is_written(tmp_path):
    mesh = generate_bar(size=(1.0, 0.2, 0.2), cells=(2, 1, 1), element="hexahedron")
    u = _bent(mesh)
    fields = {"x": mesh.points[:, 0], "energy": np.ones(mesh.n_cells)}

    def refused(match, **kw):
        args = dict(path=tmp_path / "p.png", mesh=mesh, points=None, displacement=u, values=fields,
                    field_name="x", backend="matplotlib")
        args.update(kw)
        with pytest.raises(TensormassError, match=match):
            write_picture(**args)
        assert os.listdir(tmp_path) == []

    refused("unknown field 'von_mises'; available: displacement, energy, x", field_name="von_mises")
    refused("must end in .png", path=tmp_path / "p.jpg")
    (tmp_path / "d.png").mkdir()
    with pytest.raises(TensormassError, match="is a folder"):
        write_picture(tmp_path / "d.png", mesh, None, u, fields, "x", backend="matplotlib")
    (tmp_path / "d.png").rmdir()
    bad = dict(fields, x=np.where(np.arange(mesh.n_points) == 3, np.nan, 1.0))
    refused(r"field 'x' has NaN or Inf at 1 of 12 points, first 3", values=bad)
    refused("displacement has NaN", displacement=np.full_like(u, np.inf))
    refused("has 5 rows; expected 12 \\(points\\) or 2 \\(cells\\)", values=np.ones(5))
    refused("unknown colour map", cmap="no-such-map")
    refused("backend must be auto, matplotlib or pyvista", backend="vtk")
    (tmp_path / "file").write_text("not a folder")
    with pytest.raises(TensormassError, match="picture"):
        write_picture(tmp_path / "file" / "p.png", mesh, None, u, fields, "x", backend="matplotlib")


def test_environment_chooses_matplotlib(tmp_path, monkeypatch):
    monkeypatch.setenv("TENSORMASS_PICTURE", "matplotlib")
    mesh = generate_bar(size=(1.0, 0.3), cells=(3, 1), element="quad")
    assert write_picture(tmp_path / "a.png", mesh, None, None, mesh.points[:, 1], "y", size=SIZE) == "matplotlib"


def test_pyvista_when_it_renders(tmp_path, monkeypatch):
    pytest.importorskip("pyvista")
    if not pyvista_usable():
        pytest.skip("pyvista is installed but does not render off-screen here")
    monkeypatch.delenv("TENSORMASS_PICTURE", raising=False)
    mesh = generate_bar(size=(1.0, 0.2, 0.2), cells=(4, 1, 1), element="hexahedron")
    path = tmp_path / "pv.png"
    assert write_picture(path, mesh, None, _bent(mesh), mesh.points[:, 0], "x", unit="m", size=SIZE) == "pyvista"
    _check_picture(path, extremes=False)


def test_fields_as_simulation_gives_them_and_auto_scale(tmp_path):
    """values=(point_fields, cell_fields): the nodal field wins when both have the name."""
    from tensormass.runtime.run.picture import auto_scale, pick_field
    mesh = generate_bar(size=(1.0, 0.2, 0.2), cells=(2, 1, 1), element="hexahedron")
    point = {"von_mises": mesh.points[:, 0].copy()}
    cell = {"von_mises": np.array([7.0, 8.0]), "det_F_min": np.ones(2)}
    arr, where, label = pick_field((point, cell), "von_mises", mesh.n_points, mesh.n_cells)
    assert where == "point" and np.array_equal(arr, point["von_mises"]) and label == "von_mises"
    arr, where, _ = pick_field((point, cell), "det_F_min", mesh.n_points, mesh.n_cells)
    assert where == "cell" and list(arr) == [1.0, 1.0]
    with pytest.raises(TensormassError, match="unknown field 'pressure'; available: det_F_min, von_mises"):
        pick_field((point, cell), "pressure", mesh.n_points, mesh.n_cells)
    # auto scale: largest displacement ~ a tenth of the diagonal (1.039 m), rounded down to 1-2-5
    u = np.zeros_like(mesh.points)
    u[:, 2] = -0.006 * mesh.points[:, 0]
    assert auto_scale(mesh.points, u) == 10.0                 # 0.1039 / 0.006 = 17.3 -> 10
    assert auto_scale(mesh.points, 100 * u) == 1.0            # 0.6 m: drawn as it is
    assert auto_scale(mesh.points, 0 * u) == 1.0
    png, _ = render_picture(mesh, None, u, (point, cell), "von_mises", scale="auto", size=SIZE,
                            backend="matplotlib")
    assert png[:8] == b"\x89PNG\r\n\x1a\n"


def test_picture_of_a_simulation(tmp_path):
    """picture_of_simulation reads the mesh, displacement and fields a Simulation offers."""
    from types import SimpleNamespace

    from tensormass.runtime.run.picture import picture_of_simulation
    mesh = generate_bar(size=(1.0, 0.2, 0.2), cells=(3, 1, 1), element="hexahedron")
    asked = []

    def fields(names):
        asked.append(list(names))
        return {"von_mises": mesh.points[:, 0] * 1e5}, {"von_mises": np.ones(mesh.n_cells)}

    sim = SimpleNamespace(model=SimpleNamespace(mesh=mesh, name="bar"), displacement=_bent(mesh, 0.01),
                          fields=fields)
    path = tmp_path / "vm.png"
    assert picture_of_simulation(sim, path, "von_mises", size=SIZE, shade=False, backend="matplotlib") == "matplotlib"
    assert asked == [["von_mises"]]
    _check_picture(path)
    older = SimpleNamespace(model=sim.model, displacement=sim.displacement)     # no fields(): |u| only
    picture_of_simulation(older, path, "displacement", size=SIZE, backend="matplotlib")
    with pytest.raises(TensormassError, match="computes no fields"):
        picture_of_simulation(older, tmp_path / "no.png", "von_mises", backend="matplotlib")
    assert not (tmp_path / "no.png").exists()


# -- camera, clip, length scale, titles, shells -------------------------------------------------------
def _bar3d():
    mesh = generate_bar(size=(0.08, 0.06, 0.03), cells=(4, 3, 2), element="tetra10")
    u = np.zeros_like(mesh.points)
    u[:, 2] = -0.5 * mesh.points[:, 0] ** 2
    return mesh, u


def _pixels(png, tmp_path, name):
    path = tmp_path / name
    path.write_bytes(png)
    return _image(path)[1]


def test_views_show_the_body_from_where_they_say(tmp_path):
    """Named views and angles render different pictures; a name is its angles; the default is (-60, 20)."""
    from tensormass.runtime.run.picture import DEFAULT_VIEW, VIEWS
    mesh = generate_bar(size=(0.08, 0.06, 0.03), cells=(3, 2, 1), element="hexahedron")
    u = np.zeros_like(mesh.points)
    u[:, 2] = -0.5 * mesh.points[:, 0] ** 2
    x, size = mesh.points[:, 0], (320, 220)

    def draw(view):
        return render_picture(mesh, None, u, x, "x", size=size, view=view, shade=False, backend="matplotlib")[0]

    views = {"top": "top", "bottom": "bottom", "front": "front", "angles": [30.0, -20.0], "default": None}
    pngs = {name: draw(view) for name, view in views.items()}
    shots = {name: _pixels(png, tmp_path, f"{name}.png") for name, png in pngs.items()}
    names = list(shots)
    for i, a in enumerate(names):
        _check_picture(tmp_path / f"{a}.png", size=size, extremes=False)
        for b in names[i + 1:]:
            differ = (shots[a] != shots[b]).any(axis=2).mean()
            assert differ > 0.02, f"views {a} and {b} give the same picture ({differ:.1%} of the pixels differ)"
    assert pngs["top"] == draw(list(VIEWS["top"])) and pngs["default"] == draw(list(DEFAULT_VIEW))
    assert DEFAULT_VIEW == (-60.0, 20.0)
    # from the top, x runs to the right: the body's colours (x) grow from left to right
    h, w = int(0.84 * size[1]) - int(0.16 * size[1]), int(0.79 * size[0]) - int(0.02 * size[0])
    body = _body(shots["top"]).reshape(h, w, 3)
    left, right = body[:, : w // 3], body[:, w // 3:]
    assert np.median(_colormap_positions(left[np.ptp(left, axis=2) > 20])) < \
        np.median(_colormap_positions(right[np.ptp(right, axis=2) > 20]))


def test_a_clip_plane_shows_the_inside(tmp_path):
    """A clip keeps the cells on the side the normal points away from, with the faces the cut exposes."""
    from tensormass.runtime.run import picture
    mesh, u = _bar3d()
    x = mesh.points[:, 0]
    whole = render_picture(mesh, None, u, x, "x", size=SIZE, view="front", shade=False, backend="matplotlib")[0]
    plane = [[0.04, 0.02, 0.015], [0.0, -1.0, 0.0]]          # the front third (y < 0.02) is cut away
    clipped = render_picture(mesh, None, u, x, "x", size=SIZE, view="front", clip=plane, shade=False,
                             backend="matplotlib")[0]
    a, b = _pixels(whole, tmp_path, "whole.png"), _pixels(clipped, tmp_path, "clipped.png")
    assert (a != b).any(axis=2).mean() > 0.01
    _check_picture(tmp_path / "clipped.png")
    X = mesh.points
    polys, cells, _ = picture._polygons(mesh, picture._clip(mesh, X, plane))
    centres = np.concatenate([X[blk.cells].mean(axis=1) for blk in mesh.blocks])
    assert np.all(centres[cells][:, 1] > 0.02)                # only kept cells are drawn
    faces_at_cut = [p for p, _ in polys if np.allclose(X[p][:, 1], 0.02)]
    assert len(faces_at_cut) == 2 * 4 * 2                     # the exposed cut: 4 x 2 hexahedra, 2 triangles each
    with pytest.raises(TensormassError, match=r"clip .* removes every cell"):
        render_picture(mesh, None, u, x, "x", clip=[[0.0, -1.0, 0.0], [0.0, 1.0, 0.0]], backend="matplotlib")
    with pytest.raises(TensormassError, match="need 3 components each"):
        render_picture(mesh, None, u, x, "x", clip=[[0.0, 0.0], [0.0, 1.0]], backend="matplotlib")
    with pytest.raises(TensormassError, match="non-zero normal"):
        render_picture(mesh, None, u, x, "x", clip=[[0.0, 0.0, 0.0], [0.0, 0.0, 0.0]], backend="matplotlib")


def test_the_length_scale_is_a_round_length_drawn_to_scale(tmp_path):
    """From the top of a 1 m wide body, the bar is 0.2 m: a fifth of the body's width in pixels."""
    from tensormass.runtime.run.picture import _length_text, round_length
    assert [round_length(v) for v in (0.25, 0.019, 7.0, 1.0)] == [0.2, 0.01, 5.0, 1.0]
    assert [_length_text(v) for v in (2.0, 0.02, 5e-5)] == ["2 m", "20 mm", "50 \u00b5m"]
    mesh = generate_bar(size=(1.0, 0.3), cells=(5, 2), element="quad")
    rgb = _pixels(render_picture(mesh, None, None, mesh.points[:, 0], "x", size=(800, 500), edges=False,
                                 backend="matplotlib")[0], tmp_path, "bar.png")
    area = rgb[int(0.16 * 500):, int(0.12 * 800): int(0.79 * 800)]   # no title, colour bar or axis triad
    body_cols = np.flatnonzero((np.ptp(area, axis=2) > 20).any(axis=0))
    black_rows = (area.max(axis=2) < 40).sum(axis=1)
    row = int(black_rows.argmax())                             # the bar: the longest black row
    bar_cols = np.flatnonzero(area[row].max(axis=1) < 40)
    ratio = (bar_cols[-1] - bar_cols[0]) / (body_cols[-1] - body_cols[0])
    assert abs(ratio - 0.2) < 0.02, ratio
    assert row > np.flatnonzero((np.ptp(area, axis=2) > 20).any(axis=1)).max()      # under the body


def test_static_runs_are_titled_by_load(tmp_path):
    from types import SimpleNamespace

    from tensormass.runtime.run import picture
    mesh = generate_bar(size=(1.0, 0.2, 0.2), cells=(2, 1, 1), element="hexahedron")
    got = {}
    for kind in ("static", "implicit_euler"):
        model = SimpleNamespace(mesh=mesh, name="bar", solver=SimpleNamespace(kind=kind, steps=4),
                                output=SimpleNamespace(view="top", clip=None))
        sim = SimpleNamespace(model=model, displacement=_bent(mesh, 0.01))
        seen = {}
        original = picture.render_picture

        def spy(*args, **kw):
            seen.update(kw)
            return original(*args, **kw)

        picture.render_picture = spy
        try:
            picture.picture_of_simulation(sim, tmp_path / f"{kind}.png", "displacement", step=4, time=1.0,
                                          size=SIZE, backend="matplotlib")
        finally:
            picture.render_picture = original
        got[kind] = seen
    assert got["static"]["load"] == (4, 4) and got["static"]["time"] is None and got["static"]["view"] == "top"
    assert got["implicit_euler"].get("load") is None and got["implicit_euler"]["time"] == 1.0
    base = dict(title="organ", step=4, time=None, unit="Pa", label="von_mises", scale=5.0, moved=True)
    assert picture._title({**base, "load": (4, 4)}).splitlines()[0] == "organ: load 4/4"
    assert picture._title({**base, "time": 0.5, "step": 50}).splitlines()[0] == "organ: step 50, t = 0.5 s"


def test_a_shell_is_drawn_from_either_side(tmp_path):
    """Shell triangles in 3D (no volume cells): the deformed surface, seen from above and below."""
    from tensormass.runtime.scene.scene import Scene
    scene = Scene.from_string('[mesh]\ngenerate = "plate"\nsize = [1.0, 1.0]\ncells = [6, 6]\n'
                              '[[material]]\nlaw = "cst_dkt"\nE = 1e7\nnu = 0.3\nthickness = 0.01\n'
                              '[[fixed]]\nbox = [[-1, -1, -1], [1e-9, 2, 1]]\n', load_mesh=False)
    mesh = scene.load_mesh()
    assert mesh.dim == 3 and all(b.type == "shell" for b in mesh.blocks)
    u = np.zeros_like(mesh.points)
    u[:, 2] = 0.3 * mesh.points[:, 0] ** 2
    for view in (None, "bottom"):
        path = tmp_path / f"shell_{view}.png"
        write_picture(path, mesh, None, u, None, "displacement", unit="m", size=SIZE, shade=False,
                      view=view, backend="matplotlib")
        _check_picture(path, extremes=False)


def test_bad_views_and_clips_are_scene_errors():
    from tensormass.runtime.base.errors import SceneError
    from tensormass.runtime.scene.parser import view_text
    from tensormass.runtime.scene.scene import Scene
    base = ('[mesh]\ngenerate = "bar"\nsize = [1.0, 0.2, 0.2]\ncells = [2, 1, 1]\n'
            '[[material]]\nlaw = "stvk"\nE = 1e6\nnu = 0.3\n[[fixed]]\nbox = [[-1, -1, -1], [1e-9, 1, 1]]\n[output]\n')
    ok = Scene.from_string(base + 'view = "top"\nclip = [[0.5, 0, 0], [1, 0, 0]]\n', load_mesh=False).output
    assert ok.view == (-90.0, 90.0) and ok.clip == ((0.5, 0.0, 0.0), (1.0, 0.0, 0.0))
    assert Scene.from_string(base + "view = [30, -20]\n", load_mesh=False).output.view == (30.0, -20.0)
    for text, message in [
        ('view = "above"', "output.view: unknown view 'above'; expected one of top, bottom, front, back, left, right"),
        ("view = [30, 95]", r"output.view\[1\]: the elevation must be within \[-90, 90\] degrees, got 95"),
        ("view = [30]", "output.view: expected a view name"),
        ('view = ["a", 1]', r"output.view\[0\]: expected a number"),
        ("clip = [[0, 0, 0]]", r"output.clip: expected \[\[point...\], \[normal...\]\]"),
        ("clip = [[0, 0, 0], [0, 0, 0]]", r"output.clip\[1\]: the normal must not be zero"),
        ("clip = [[0, 0], [1, 0]]", r"output.clip\[0\]: expected 3 components, got 2"),
    ]:
        with pytest.raises(SceneError, match=message):
            Scene.from_string(base + text + "\n", load_mesh=False)
    assert view_text("front") == (-90.0, 0.0) and view_text("-45,30") == (-45.0, 30.0)
    with pytest.raises(SceneError, match="--view: expected a view name"):
        view_text("-45;30")


def test_run_view_argument_reaches_the_scene(tmp_path, monkeypatch):
    """run --view overrides [output] view (one argument passed through to the scene)."""
    import argparse

    from tensormass.apps import commands
    seen = {}
    monkeypatch.setattr(commands, "run_scene", lambda scene, **kw: seen.update(view=scene.output.view) or
                        {"exit_code": 0})
    scene = tmp_path / "s.toml"
    scene.write_text('[mesh]\ngenerate = "bar"\nsize = [1.0, 0.2, 0.2]\ncells = [2, 1, 1]\n'
                     '[[material]]\nlaw = "stvk"\nE = 1e6\nnu = 0.3\n[[fixed]]\nbox = [[-1, -1, -1], [1e-9, 1, 1]]\n')
    parser = argparse.ArgumentParser()
    commands.add_commands(parser.add_subparsers())
    for argv, want in ((["--view", "back"], (90.0, 0.0)), (["--view=-30,10"], (-30.0, 10.0)), ([], None)):
        args = parser.parse_args(["run", str(scene), *argv])
        assert args.run(args) == 0 and seen["view"] == want
