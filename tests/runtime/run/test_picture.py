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
        ink = (rgb[int(0.16 * SIZE[1]):int(0.84 * SIZE[1]), :int(0.79 * SIZE[0])] != 255).any(axis=2)
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
