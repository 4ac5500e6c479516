"""`tensormass view SCENE`: the running simulation in a browser, pulled with the mouse.

    viewer = Viewer(Live(scene)).serve(port=8080)    # a web server in a thread; open the URL it prints
    viewer.live.step(10)                             # the view shows each step as it comes
    viewer.close()

pyvista draws the deformed body with VTK on the server; trame serves the page and streams the
pictures (remote rendering: the browser receives images, so a remote machine over a forwarded port
needs no GPU or VTK on the laptop, and a deforming mesh costs the same bandwidth as a still one).
Mouse events go back to the server's VTK interactor: a left drag turns the camera; a left drag with
shift held, or any left drag while "grab" is on, picks the body point under the cursor and pulls it
with a spring (runtime.physics.grab) toward the point under the cursor in the plane facing the
camera, until the button is released. A left drag with ctrl held (or "tool" on) on an obstacle moves
it in that plane (penalty contact: runtime.run.live.Live.move_obstacle).

The steps run in the Live's own thread (runtime.run.live); the page refreshes at most `fps` times
a second from the latest Snapshot and skips the steps in between, so drawing never holds up a step.
Nothing is written to disk; the scene's [output] is ignored.
"""
from __future__ import annotations

import asyncio
import base64
import io
import itertools
import sys
import threading
import time

import numpy as np

from ..runtime.base.errors import TensormassError

__all__ = ["Viewer", "Picture", "require_view", "cmd_view", "add_view_command"]

_NEEDS = "the live view needs pyvista and trame: pip install 'tensormass[view]'"
_VIEWERS = itertools.count()
_BACKGROUND = (0.97, 0.97, 0.97)


def require_view():
    """(pyvista, trame's get_server), or a TensormassError naming the extra to install."""
    import importlib
    try:
        for module in ("pyvista", "trame_vtk", "trame_vuetify"):
            importlib.import_module(module)
        from trame.app import get_server
    except ImportError as exc:
        raise TensormassError(f"{_NEEDS} ({exc})") from None
    from ..runtime.run.picture import _pyvista
    return _pyvista(), get_server


class Picture:
    """The VTK scene of one body: its surface deformed and coloured, the probes, the grab, the obstacles.
    Only the thread that serves the view touches it (VTK is not thread-safe)."""

    def __init__(self, body: dict, field: str = "displacement", size=(960, 640)):
        pv, _ = require_view()
        self.pv = pv
        self.plotter = pv.Plotter(off_screen=True, window_size=tuple(size))
        self.plotter.set_background(_BACKGROUND)
        self.body_actor = None
        self.field = None
        self.probe_cloud = None
        self.grab_line = pv.PolyData(np.zeros((2, 3)), lines=np.array([2, 0, 1]))
        self.grab_actor = self.plotter.add_mesh(self.grab_line, color=(0.85, 0.1, 0.1), line_width=4,
                                                point_size=14, render_points_as_spheres=True, name="grab",
                                                pickable=False)
        self.grab_actor.SetVisibility(False)
        self.set_body(body, field)
        self.plotter.add_axes(color="black")
        self.plotter.view_isometric()
        self.plotter.reset_camera()

    def set_body(self, body: dict, field: str | None = None) -> None:
        """Draw this body (runtime.run.live.describe_body; a reset or a cut gives a new one: the plotter
        and the camera stay)."""
        from ..runtime.run.picture import _polygons
        mesh = body["mesh"]
        polys, cells, _ = _polygons(mesh)
        if not polys:
            raise TensormassError("view: the mesh has no surface to draw (no volume faces, shells or 2D cells)")
        faces = np.concatenate([np.concatenate([[len(outline)], outline]) for outline, _ in polys]).astype(np.int64)
        self.body, self.version, self.X = body, body["version"], _pad(mesh.points)
        # triangles (VTK's picker misses on the curved six-node outlines of quadratic faces), each with
        # the global id of its cell (cell fields) carried through the triangulation
        outlines = self.pv.PolyData(self.X.copy(), faces)
        outlines.cell_data["cell"] = cells
        self.surface = outlines.triangulate()
        self.cells = np.asarray(self.surface.cell_data["cell"], dtype=np.int64)
        self.fields = list(body["fields"])
        field = field or self.field or "displacement"
        self._set_field(field if field in self.fields else "displacement")
        self._add_probes(body["probes"])
        self._add_obstacles(body["obstacles"])

    def _add_probes(self, probes: dict) -> None:
        if self.probe_cloud is not None:
            self.plotter.remove_actor("probes")
            self.probe_cloud = None
        self.probe_points = {name: np.asarray(info.get("point") if info.get("point") is not None else [np.nan] * 3,
                                              dtype=float) for name, info in probes.items()}
        if probes:
            self.probe_cloud = self.pv.PolyData(np.zeros((len(probes), 3)))
            self.plotter.add_mesh(self.probe_cloud, color="black", point_size=12, render_points_as_spheres=True,
                                  name="probes", pickable=False)

    def _add_obstacles(self, obstacles) -> None:
        for name in getattr(self, "_obstacle_names", []):
            self.plotter.remove_actor(name)
        self._obstacle_meshes, self._obstacle_names = [], []
        self.obstacle_actors = {}
        for name, V, F in obstacles:
            mesh = self.pv.PolyData(np.asarray(V, float), np.column_stack([np.full(len(F), 3), F]).ravel())
            key = f"obstacle {name}"
            self.obstacle_actors[name] = self.plotter.add_mesh(mesh, color=(0.6, 0.6, 0.7), opacity=0.5, name=key)
            self._obstacle_meshes.append(mesh)
            self._obstacle_names.append(key)

    # -- drawing ---------------------------------------------------------------------------------------
    def _set_field(self, name: str) -> None:
        if name not in self.fields:
            raise TensormassError(f"view: field {name!r} is not drawn for this scene; choose one of "
                                  f"{', '.join(self.fields)}")
        self.field = name
        self.label = f"{name} [{self.body['units'][name]}]"
        self.surface.clear_data()
        self.surface.point_data[self.label] = np.zeros(self.surface.n_points)
        if self.body_actor is not None:
            self.plotter.remove_actor(self.body_actor)
            self.plotter.remove_scalar_bar()
        self.body_actor = self.plotter.add_mesh(
            self.surface, scalars=self.label, cmap="viridis", show_edges=self.surface.n_cells <= 20000,
            edge_color=(0.3, 0.3, 0.3), name="body",
            scalar_bar_args=dict(title=self.label, vertical=True, color="black", position_x=0.87,
                                 position_y=0.15, height=0.7, width=0.05))
        self._where = "point"
        self._range = None

    def set_field(self, name: str) -> None:
        if name != self.field:
            self._set_field(name)

    def update(self, snapshot) -> None:
        """Move the surface to the snapshot's state (taken with this picture's field) and colour it; the
        probes, the grab and the obstacles too."""
        self.surface.points = self.X + _pad(snapshot.displacement)
        values, where = snapshot.values
        data = values if where == "point" else values[self.cells]
        if where != self._where:
            self.surface.clear_data()
            (self.surface.point_data if where == "point" else self.surface.cell_data)[self.label] = data
            self.surface.set_active_scalars(self.label, preference=where)
            self.body_actor.mapper.scalar_map_mode = where
            self._where = where
        else:
            (self.surface.point_data if where == "point" else self.surface.cell_data)[self.label] = data
        lo, hi = float(np.min(data)), float(np.max(data))
        # the colour range only grows (a steady scale while the body moves); reset_range() starts it again
        self._range = (lo, hi) if self._range is None else (min(lo, self._range[0]), max(hi, self._range[1]))
        if self._range[1] > self._range[0]:
            self.body_actor.mapper.scalar_range = self._range
        if self.probe_cloud is not None:
            at = [_pad(self.probe_points[name][None, :])[0] + _pad(np.asarray(value, float)[None, :])[0]
                  for name, value in snapshot.probes.items() if name in self.probe_points]
            if len(at) == self.probe_cloud.n_points:
                self.probe_cloud.points = np.asarray(at)
        grab = snapshot.grab
        self.grab_actor.SetVisibility(grab is not None)
        if grab is not None:
            self.grab_line.points = np.vstack([_pad(np.asarray(grab["point"])[None, :]),
                                               _pad(np.asarray(grab["target"])[None, :])])
        for mesh, V in zip(self._obstacle_meshes, snapshot.obstacles):
            mesh.points = V

    def reset_range(self) -> None:
        self._range = None

    def image(self) -> np.ndarray:
        """The current picture, (height, width, 3) uint8."""
        self.plotter.render()
        return np.asarray(self.plotter.screenshot(return_img=True))

    # -- the mouse ---------------------------------------------------------------------------------------
    def pick(self, x: float, y: float, actors=None):
        """The point of the body (or of one of `actors`) under display pixel (x, y) (origin bottom
        left), and the actor picked; (None, None) when there is none."""
        import vtk
        picker = vtk.vtkCellPicker()
        picker.SetTolerance(1e-4)
        picker.PickFromListOn()
        for actor in actors if actors is not None else [self.body_actor]:
            picker.AddPickList(actor)
        if not picker.Pick(x, y, 0, self.plotter.renderer) or picker.GetCellId() < 0:
            return None, None
        return np.asarray(picker.GetPickPosition(), dtype=float), picker.GetActor()

    def obstacle_at(self, x: float, y: float):
        """(name, point) of the obstacle under display pixel (x, y), or (None, None)."""
        if not self.obstacle_actors:
            return None, None
        point, actor = self.pick(x, y, list(self.obstacle_actors.values()))
        for name, candidate in self.obstacle_actors.items():
            if actor is not None and candidate.GetAddressAsString("vtkActor") == actor.GetAddressAsString("vtkActor"):
                return name, point
        return None, None

    def depth_of(self, point) -> float:
        ren = self.plotter.renderer
        ren.SetWorldPoint(*point, 1.0)
        ren.WorldToDisplay()
        return ren.GetDisplayPoint()[2]

    def at_depth(self, x: float, y: float, depth: float) -> np.ndarray:
        """The world point under display pixel (x, y) at display depth `depth` (the plane facing the camera)."""
        ren = self.plotter.renderer
        ren.SetDisplayPoint(x, y, depth)
        ren.DisplayToWorld()
        w = np.asarray(ren.GetWorldPoint(), dtype=float)
        return w[:3] / w[3]

    def display_of(self, point) -> tuple:
        """Display pixel (x, y) of a world point (origin bottom left)."""
        ren = self.plotter.renderer
        ren.SetWorldPoint(*_pad(np.asarray(point, float)[None, :])[0], 1.0)
        ren.WorldToDisplay()
        x, y, _ = ren.GetDisplayPoint()
        return x, y

    def close(self) -> None:
        self.plotter.close()


class Viewer:
    """A Live shown in a browser (see the module doc). serve() starts the page; without it, draw() and
    image() give pictures (a script or a test that wants no server)."""

    def __init__(self, live, *, field: str = "displacement", fps: float = 20.0, speed: float | None = 1.0,
                 size=(960, 640), curves_every: float = 1.0):
        if not (float(fps) > 0):
            raise TensormassError(f"view: fps must be > 0, got {fps!r}")
        self.live, self.fps, self.speed = live, float(fps), speed
        self.curves_every = float(curves_every)      # seconds between redraws of the curves (0: never)
        body = live.body()
        if field not in body["fields"]:
            raise TensormassError(f"view: field {field!r} is not drawn for this scene; choose one of "
                                  f"{', '.join(body['fields'])}")
        self.picture = Picture(body, field, size)
        self._drawn = None                   # the snapshot last drawn
        self.frames = 0                      # pictures drawn
        self._frame_times = []
        self._grabbing = None                # display depth of the grabbed point while the mouse holds it
        self._tool = None                    # (obstacle, its shift at the press, point picked, depth) while held
        self._shifts = {}                    # obstacle -> the shift the mouse last gave it
        self.grab_mode = self.tool_mode = False
        self.server = None
        self.url = None
        self._thread = None
        self._install_mouse()
        self.draw()

    # -- drawing -----------------------------------------------------------------------------------------
    def draw(self, force: bool = False) -> bool:
        """Bring the picture to the latest snapshot; False when there was nothing new."""
        snap = self.live.snapshot(self.picture.field)
        if self._drawn is not None and not force and (snap.step, snap.version, snap.status, snap.grab is None) == \
                (self._drawn.step, self._drawn.version, self._drawn.status, self._drawn.grab is None):
            return False
        if snap.version != self.picture.version:          # a reset, a cut or a refinement: a new body
            self.picture.set_body(self.live.body())
        self.picture.update(snap)
        self._drawn = snap
        self.frames += 1
        self._frame_times.append(time.perf_counter())
        return True

    def image(self) -> np.ndarray:
        self.draw()
        return self.picture.image()

    @property
    def frame_rate(self) -> float:
        """Pictures drawn per second over the last two seconds."""
        times = self._frame_times
        now = time.perf_counter()
        recent = [t for t in times[-200:] if now - t <= 2.0]
        self._frame_times = recent
        return (len(recent) - 1) / (recent[-1] - recent[0]) if len(recent) > 1 and recent[-1] > recent[0] else 0.0

    # -- the mouse ------------------------------------------------------------------------------------------
    def _install_mouse(self) -> None:
        import vtk
        style = vtk.vtkInteractorStyleTrackballCamera()
        iren = self.picture.plotter.iren.interactor
        iren.SetInteractorStyle(style)
        self._style = style
        # an observer on the style replaces its own handler of that event (VTK's rule), so the camera
        # handlers are called explicitly when the mouse is not grabbing
        style.AddObserver("LeftButtonPressEvent", self._on_press)
        style.AddObserver("MouseMoveEvent", self._on_move)
        style.AddObserver("LeftButtonReleaseEvent", self._on_release)

    def _on_press(self, style, _event) -> None:
        iren = style.GetInteractor()
        x, y = iren.GetEventPosition()
        if self._grabbing is not None or self._tool is not None:   # a release the page did not deliver
            self.release()
        if (self.tool_mode or iren.GetControlKey()) and self.press_tool(x, y):
            return
        if (self.grab_mode or iren.GetShiftKey()) and self.press(x, y):
            return
        style.OnLeftButtonDown()

    def _on_move(self, style, _event) -> None:
        if self._grabbing is not None or self._tool is not None:
            self.move(*style.GetInteractor().GetEventPosition())
            return
        style.OnMouseMove()

    def _on_release(self, style, _event) -> None:
        if self._grabbing is not None or self._tool is not None:
            self.release()
            return
        style.OnLeftButtonUp()

    def press_tool(self, x: float, y: float) -> bool:
        """Take hold of the obstacle under display pixel (x, y); False: none there (or not movable)."""
        name, point = self.picture.obstacle_at(x, y)
        if name is None:
            return False
        start = self._shifts.get(name, np.zeros(3))
        try:
            self.live.move_obstacle(name, start)
        except TensormassError:
            return False                     # IPC contact: its obstacles move by their motion only
        self._tool = (name, start, point, self.picture.depth_of(point))
        return True

    def press(self, x: float, y: float) -> bool:
        """Grab the body under display pixel (x, y) (origin bottom left); False: nothing there."""
        point, _ = self.picture.pick(x, y)
        if point is None:
            return False
        try:
            self.live.grab(point[:self.picture.body["dim"]])
        except TensormassError:
            return False                     # the live run stopped, or the point is off the body
        self._grabbing = self.picture.depth_of(point)
        return True

    def move(self, x: float, y: float) -> None:
        """Drag the grab (or the tool held) to display pixel (x, y), in the plane facing the camera
        through the point picked."""
        if self._tool is not None:
            name, start, point, depth = self._tool
            shift = start + self.picture.at_depth(x, y, depth) - point
            self._shifts[name] = shift
            self.live.move_obstacle(name, shift)
            return
        if self._grabbing is None:
            return
        target = self.picture.at_depth(x, y, self._grabbing)
        self.live.drag(target[:self.picture.body["dim"]])

    def release(self) -> None:
        """Let go: of the grab (the body springs back), or of the tool (it stays where it is)."""
        self._tool = None
        if self._grabbing is not None or self.live.snapshot().grab is not None:
            self._grabbing = None
            self.live.release()

    # -- the page ----------------------------------------------------------------------------------------------
    def serve(self, port: int = 8080, host: str = "127.0.0.1", *, block: bool = False):
        """Serve the page (trame) at http://host:port/; port 0: any free port (self.url says which).
        block=False: in a thread, returning once the server listens; True: until Ctrl-C."""
        self._build_page()
        ready = threading.Event()

        def on_ready(**_):
            self._loop = asyncio.get_event_loop()
            ready.set()

        self.server.controller.on_server_ready.add(on_ready)
        argv, sys.argv = sys.argv, sys.argv[:1]          # trame reads its own options from argv
        try:
            if block:
                self._announce_on_ready(host)
                self.server.start(port=port, host=host, open_browser=False, timeout=0, show_connection_info=False)
                return self
            self._thread = threading.Thread(
                target=lambda: self.server.start(port=port, host=host, open_browser=False, timeout=0, thread=True,
                                                 show_connection_info=False),
                name="tensormass-view", daemon=True)
            self._thread.start()
            if not ready.wait(timeout=30):
                raise TensormassError(f"view: the web server did not start on {host}:{port}")
        finally:
            sys.argv = argv
        self.url = f"http://{host}:{self.server.port}/"
        return self

    def _announce_on_ready(self, host) -> None:
        def announce(**_):
            self.url = f"http://{host}:{self.server.port}/"
            print(f"tensormass view: open {self.url} (Ctrl-C stops)", flush=True)
        self.server.controller.on_server_ready.add(announce)

    def _build_page(self) -> None:
        _, get_server = require_view()
        from trame.ui.vuetify3 import SinglePageLayout
        from trame.widgets import html, vuetify3 as v3
        from trame.widgets import vtk as vtk_widgets
        server = self.server = get_server(f"tensormass-view-{next(_VIEWERS)}", client_type="vue3")
        state, ctrl = server.state, server.controller
        name = self.picture.body["name"]
        state.trame__title = f"tensormass view: {name}"
        state.field = self.picture.field
        state.fields = self.picture.fields
        state.grab_mode = state.tool_mode = False
        state.status_text = ""
        state.curves = ""
        state.playing = False

        @state.change("field")
        def _field(field, **_):
            if field != self.picture.field:
                self.picture.set_field(field)
                self.draw(force=True)
                ctrl.view_update()

        @state.change("grab_mode", "tool_mode")
        def _modes(grab_mode, tool_mode, **_):
            self.grab_mode, self.tool_mode = bool(grab_mode), bool(tool_mode)

        def play():
            self.live.play(self.speed)
            state.playing = True

        def pause():
            self.live.pause()
            state.playing = False

        def step():
            self.live.pause()
            state.playing = False
            try:
                self.live.step(1)
            except TensormassError:
                pass                         # the snapshot says why
            self._refresh()

        def reset():
            self.live.reset()
            self._shifts = {}
            state.playing = False
            self.picture.reset_range()
            self._refresh()

        with SinglePageLayout(server, full_height=True) as layout:
            layout.title.set_text(f"tensormass · {name}")
            with layout.toolbar:
                v3.VSpacer()
                v3.VBtn("Play", click=play, id="play", disabled=("playing",))
                v3.VBtn("Pause", click=pause, id="pause", disabled=("!playing",))
                v3.VBtn("Step", click=step, id="step")
                v3.VBtn("Reset", click=reset, id="reset")
                v3.VBtn("Release", click=self.release, id="release")
                v3.VSwitch(v_model=("grab_mode",), label="grab", id="grab", hide_details=True, density="compact",
                           color="red", style="max-width: 120px; margin-left: 12px")
                if self.picture.obstacle_actors:
                    v3.VSwitch(v_model=("tool_mode",), label="tool", id="tool", hide_details=True,
                               density="compact", color="blue", style="max-width: 120px; margin-left: 8px")
                v3.VSelect(v_model=("field",), items=("fields",), id="field", hide_details=True, density="compact",
                           style="max-width: 220px; margin-left: 12px")
            with layout.content:
                with html.Div(style="display: flex; height: 100%; width: 100%"):
                    with html.Div(style="flex: 3; position: relative; height: 100%"):
                        view = vtk_widgets.VtkRemoteView(self.picture.plotter.ren_win, interactive_ratio=1,
                                                         still_quality=90, interactive_quality=70, id="render")
                        ctrl.view_update = view.update
                    with html.Div(style="flex: 1; padding: 8px; font-family: monospace; font-size: 13px"):
                        html.Pre("{{ status_text }}", id="status", style="white-space: pre-wrap")
                        html.Img(src=("curves",), style="width: 100%")
        ctrl.on_server_ready.add(lambda **_: setattr(self, "_task", asyncio.ensure_future(self._refresh_loop())))

    def _status(self, snap) -> str:
        lines = [f"step      {snap.step}", f"time      {snap.time:.4g} s",
                 f"steps/s   {snap.steps_per_second:.0f}", f"frames/s  {self.frame_rate:.1f}",
                 f"status    {snap.status}"]
        if snap.message:
            lines.append(f"          {snap.message}")
        if snap.grab is not None:
            f = snap.grab["force"]
            lines.append(f"grab      {np.linalg.norm(f):.3g} N  (k = {snap.grab['stiffness']:.3g} N/m)")
        for name, force in snap.tools.items():
            lines.append(f"{name:<9} {np.linalg.norm(force):.3g} N on it")
        for name, value in snap.probes.items():
            lines.append(f"{name:<9} [{', '.join(f'{v * 1e3:+.3f}' for v in value)}] mm")
        lines.append("")
        lines.append("shift + left drag (or grab on): pull the body")
        if self.picture.obstacle_actors:
            lines.append("ctrl + left drag (or tool on): move a tool")
        return "\n".join(lines)

    def _refresh(self) -> None:
        state = self.server.state
        with state:
            if self.draw():
                self.server.controller.view_update()
            snap = self._drawn
            state.status_text = self._status(snap)
            state.playing = snap.status == "playing"

    @property
    def _curves(self) -> _Curves:
        if getattr(self, "_curves_figure", None) is None:
            self._curves_figure = _Curves()
        return self._curves_figure

    async def _refresh_loop(self) -> None:
        """At most fps pictures a second, each of the latest snapshot; the curves every curves_every seconds."""
        curves_at, cost = 0.0, 0.0
        while True:
            # at least as long as the last refresh took between two: the page's events (the mouse, the
            # buttons) get half the server's loop whatever a picture costs
            await asyncio.sleep(max(1.0 / self.fps, cost))
            began = time.perf_counter()
            try:
                self._refresh()
                now = time.perf_counter()
                if self.curves_every and now - curves_at >= self.curves_every:
                    curves_at = now
                    with self.server.state:
                        self.server.state.curves = self._curves.png(self.live.snapshot(curves=True))
            except Exception as exc:         # a drawing error must not end the page's loop silently
                with self.server.state:
                    self.server.state.status_text = f"view error: {exc}"
            cost = time.perf_counter() - began

    def close_server(self) -> None:
        """Stop the page's server (the Live goes on)."""
        loop, self._loop = getattr(self, "_loop", None), None
        if self.server is None or loop is None:
            return
        try:
            task = getattr(self, "_task", None)
            if task is not None:
                loop.call_soon_threadsafe(task.cancel)
            asyncio.run_coroutine_threadsafe(self.server.stop(), loop).result(timeout=10)
        except Exception:
            pass
        if self._thread is not None:
            self._thread.join(timeout=10)
            self._thread = None

    def close(self) -> None:
        """Stop the server and the Live."""
        self.close_server()
        self.live.close()
        self.picture.close()


class _Curves:
    """The probes' vertical displacement and the grab's force against time, as a PNG data URL. One
    matplotlib figure, kept: each redraw only moves the lines' data (a new figure and its layout cost
    as much as the body's picture)."""

    def __init__(self):
        import matplotlib
        matplotlib.use("Agg")
        from matplotlib.figure import Figure
        self.fig = Figure(figsize=(3.2, 3.6), dpi=90)
        self.probes, self.force = self.fig.subplots(2, 1, sharex=True)
        self.probes.set_ylabel("probe [mm]")
        self.force.set_ylabel("grab force [N]")
        self.force.set_xlabel("time [s]")
        for ax in (self.probes, self.force):
            ax.tick_params(labelsize=7)
            ax.grid(alpha=0.3)
        self.force_line, = self.force.plot([], [], color="tab:red")
        self.lines = {}
        self.fig.tight_layout()

    def png(self, snap) -> str:
        curves = snap.curves
        t = np.asarray(curves.get("time", np.zeros(0)))
        every = max(1, len(t) // 400)                # at most ~400 points a line
        for name, values in curves.items():
            if name.endswith(" uz") or (name.endswith(" uy") and f"{name[:-3]} uz" not in curves):
                if name not in self.lines:
                    self.lines[name], = self.probes.plot([], [], label=name)
                    self.probes.legend(fontsize=7)
                self.lines[name].set_data(t[::every], np.asarray(values)[::every] * 1e3)
        self.force_line.set_data(t[::every], np.asarray(curves.get("grab force", np.zeros_like(t)))[::every])
        for ax in (self.probes, self.force):
            ax.relim()
            ax.autoscale_view()
        buf = io.BytesIO()
        self.fig.savefig(buf, format="png")
        return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode()


def _pad(points: np.ndarray) -> np.ndarray:
    """(n, 3) points from (n, 2) or (n, 3)."""
    points = np.asarray(points, dtype=float)
    return points if points.shape[1] == 3 else np.column_stack([points, np.zeros(len(points))])


def cmd_view(args) -> int:
    """tensormass view SCENE: serve the live view until Ctrl-C (or write a still with --screenshot)."""
    from ..runtime.run.live import Live
    from ..runtime.run.live_process import LiveProcess
    from ..runtime.scene.scene import Scene
    require_view()
    scene = Scene.from_toml(args.scene)
    # a still is made here; a served view steps in a process of its own (runtime.run.live_process)
    live = Live(scene, stiffness=args.stiffness) if args.screenshot else \
        LiveProcess(scene, stiffness=args.stiffness, threads=args.threads)
    viewer = Viewer(live, field=args.field, fps=args.fps, speed=None if args.fast else 1.0)
    if args.screenshot:
        from ..runtime.run.picture import check_png_path
        path = check_png_path(args.screenshot, "view --screenshot")
        live.step(args.steps)
        from PIL import Image
        Image.fromarray(viewer.image()).save(path)
        print(f"tensormass view: step {live.snapshot().step} drawn to {path}")
        live.close()
        return 0
    if args.play:
        live.play(viewer.speed)
    try:
        viewer.serve(port=args.port, host=args.host, block=True)
    finally:
        live.close()
    return 0


def add_view_command(subparsers) -> None:
    p = subparsers.add_parser("view", help="watch a scene run live in a browser and pull it with the mouse "
                                           "(needs tensormass[view])")
    p.add_argument("scene", help="scene file (.toml); solver.kind implicit_euler or explicit")
    p.add_argument("--port", type=int, default=8080, help="the page's port (default 8080; 0: any free port)")
    p.add_argument("--host", default="127.0.0.1", help="the address to listen on (default 127.0.0.1; a remote "
                   "machine: forward the port with ssh -L 8080:localhost:8080)")
    p.add_argument("--field", default="displacement", help="the field coloured at start (displacement, von_mises, ...)")
    p.add_argument("--fps", type=float, default=20.0, help="most pictures a second (default 20)")
    p.add_argument("--fast", action="store_true", help="step as fast as possible (default: real time, dt per dt)")
    p.add_argument("--play", action="store_true", help="start playing at once")
    p.add_argument("--stiffness", type=float, help="the grab's spring [N/m] (default: 0.3 x the body's own where grabbed)")
    p.add_argument("--threads", type=int, default=1, help="the steps' threads (default 1: the other cores draw "
                   "and serve the pictures)")
    p.add_argument("--screenshot", metavar="PNG", help="no server: step --steps steps, draw the view to PNG and exit")
    p.add_argument("--steps", type=int, default=0, help="steps before --screenshot (default 0)")
    p.set_defaults(run=cmd_view)
