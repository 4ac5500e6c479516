"""The live view (apps/view.py, tensormass[view]): the body is drawn, a drag with the mouse pulls it,
and in a real browser (headless Chromium driven by Playwright) the page shows the body, a shift-drag
moves the probe toward the dragged point and Pause stops the time. Skipped without pyvista and trame;
the browser test also without Playwright or Chromium. Heavy: CI's heavy step installs tensormass[view],
Playwright and Chromium and runs them (.ci/run); the README's quick suite has none of them."""
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pyvista")
pytest.importorskip("trame")
pytest.importorskip("trame_vtk")

from tensormass.apps.bench_view import CHROMIUM_ARGS, chromium_path  # noqa: E402
from tensormass.apps.view import Viewer, require_view  # noqa: E402
from tensormass.runtime.base.errors import TensormassError  # noqa: E402
from tensormass.runtime.run.live import Live  # noqa: E402
from tensormass.runtime.run.live_process import LiveProcess  # noqa: E402
from tensormass.runtime.run.picture import pyvista_usable  # noqa: E402
from tensormass.runtime.scene.scene import Scene  # noqa: E402

LIVE = Path(__file__).resolve().parents[2] / "examples" / "organ" / "live.toml"
POLE = np.array([0.0, 0.0, 0.03])
BACKGROUND = np.array([247, 247, 247])

if not pyvista_usable():
    pytest.skip("pyvista cannot render off-screen here", allow_module_level=True)

pytestmark = pytest.mark.heavy


def body_share(img) -> float:
    """The share of the picture's pixels that are not the background."""
    return float((np.abs(img[..., :3].astype(int) - BACKGROUND).sum(axis=2) > 30).mean())


def pole(live) -> np.ndarray:
    return POLE + np.array(live.snapshot().probes["pole"])


def test_the_view_draws_the_body_and_a_mouse_drag_pulls_it():
    require_view()
    with Live(Scene.from_toml(str(LIVE))) as live:
        viewer = Viewer(live, field="von_mises", size=(480, 320))
        live.step(3)
        img = viewer.image()
        assert img.shape == (320, 480, 3) and 0.1 < body_share(img) < 0.8
        x, y = viewer.picture.display_of(pole(live))
        assert viewer.press(x, y)                         # shift + left button on the pole
        start = pole(live)
        for i in range(1, 11):
            viewer.move(x, y + 8 * i)                     # up the screen
            live.step(3)
        up = viewer.picture.at_depth(x, y + 80, viewer.picture.depth_of(start)) - start
        moved = pole(live) - start
        assert moved @ up / np.linalg.norm(up) > 0.3 * np.linalg.norm(up)     # toward the dragged point
        dragged = viewer.image()
        assert np.abs(dragged.astype(int) - img.astype(int)).sum(axis=2).astype(bool).mean() > 0.001
        viewer.release()
        assert live.snapshot().grab is None
        assert not viewer.press(2, 2)                     # the corner: no body there
        with pytest.raises(TensormassError, match="not drawn"):
            Viewer(live, field="fibre_stretch")
        viewer.picture.close()


def test_a_mouse_drag_on_the_tool_moves_it_into_the_body():
    with Live(Scene.from_toml(str(LIVE.parent / "live_tool.toml"))) as live:
        viewer = Viewer(live, size=(480, 320))
        live.step(60)                                     # settled under gravity
        viewer.picture.plotter.view_xz()                  # from the front: the screen's up is z
        viewer.image()
        tip = np.array([0.0, -0.015, 0.034])              # on the probe's front face
        x, y = viewer.picture.display_of(tip)
        assert not viewer.press(x, y + 400)               # nothing there
        assert viewer.press_tool(x, y)                    # ctrl + left button on the tool
        rest = live.snapshot().probes["pole"][2]
        pixels = y - viewer.picture.display_of(tip - [0.0, 0.0, 0.003])[1]    # 3 mm on the screen
        for i in range(1, 11):
            viewer.move(x, y - pixels * i / 10)           # down the screen
            live.step(4)
        viewer.release()                                  # the tool stays where it was left
        live.step(20)
        shift = np.asarray(live.sim.model.contact.obstacles[0].shift)
        assert np.isclose(shift[2], -0.003, rtol=0.05) and abs(shift[0]) + abs(shift[1]) < 1e-3 * abs(shift[2])
        assert live.snapshot().tools["tool"][2] > 0      # touching: the organ pushes back
        assert live.snapshot().probes["pole"][2] < rest - 1e-4
        assert "tool" in viewer._status(live.snapshot())
        viewer.picture.close()


def test_view_screenshot_command(tmp_path):
    from tensormass.apps.cli import main
    out = tmp_path / "view.png"
    assert main(["view", str(LIVE), "--screenshot", str(out), "--steps", "2", "--field", "von_mises"]) == 0
    from PIL import Image
    assert body_share(np.asarray(Image.open(out))) > 0.1
    assert main(["view", str(LIVE), "--screenshot", str(tmp_path / "v.png"), "--field", "nope"]) == 2
    assert not (tmp_path / "v.png").exists()


def test_the_page_in_headless_chromium():
    playwright = pytest.importorskip("playwright.sync_api")
    chromium = chromium_path()
    if chromium is None:
        pytest.skip("no Chromium (apt install chromium, or TENSORMASS_CHROMIUM)")
    live = LiveProcess(Scene.from_toml(str(LIVE)))
    viewer = Viewer(live).serve(port=0)
    try:
        with playwright.sync_playwright() as p:
            browser = p.chromium.launch(executable_path=chromium, args=CHROMIUM_ARGS)
            page = browser.new_page(viewport={"width": 1400, "height": 800})
            page.goto(viewer.url)
            page.wait_for_selector("#render img, #render canvas", timeout=60000)
            page.wait_for_timeout(2000)
            box = page.locator("#render").bounding_box()
            shot = np.asarray(_png(page.screenshot(clip=box)))
            assert 0.1 < body_share(shot) < 0.8           # the body, on the page
            page.click("#play")
            page.wait_for_timeout(1000)
            page.click("#pause")
            page.wait_for_timeout(300)
            paused = live.snapshot()
            assert paused.step > 0 and paused.status == "paused"
            page.wait_for_timeout(1000)
            assert live.snapshot().step == paused.step    # Pause stops the time
            w, h = viewer.picture.plotter.ren_win.GetSize()
            x, y = viewer.picture.display_of(pole(live))
            px, py = box["x"] + x * box["width"] / w, box["y"] + (h - y) * box["height"] / h
            start = pole(live)
            page.click("#play")
            page.keyboard.down("Shift")
            page.mouse.move(px, py)
            page.mouse.down()
            for i in range(1, 16):
                page.mouse.move(px, py - 6 * i)
                page.wait_for_timeout(40)
            page.wait_for_timeout(1000)
            held = live.snapshot()
            page.mouse.up()
            page.keyboard.up("Shift")
            assert held.grab is not None and np.linalg.norm(held.grab["force"]) > 0
            target = held.grab["target"] - start
            moved = np.array(held.probes["pole"]) + POLE - start
            assert moved @ target > 0.3 * target @ target  # the probe followed the dragged point
            for _ in range(100):                          # released with the button
                if live.snapshot().grab is None:
                    break
                page.wait_for_timeout(100)
            assert live.snapshot().grab is None
            start = pole(live)                            # grab again, then the page's Release button
            page.keyboard.down("Shift")
            page.mouse.move(px, py - 30)
            page.mouse.down()
            page.mouse.move(px, py - 40)
            page.wait_for_timeout(300)
            page.mouse.up()
            page.keyboard.up("Shift")
            page.click("#release")
            page.wait_for_timeout(500)
            assert live.snapshot().grab is None
            page.click("#pause")
            browser.close()
    finally:
        viewer.close()


def _png(data: bytes):
    import io
    from PIL import Image
    return Image.open(io.BytesIO(data)).convert("RGB")


def test_bench_view_reports_each_phase_against_the_alone_one(tmp_path):
    from tensormass.apps.cli import main
    out = tmp_path / "view.json"
    assert main(["bench", "view", str(LIVE), "--seconds", "0.5", "--no-browser", "--json", str(out)]) == 0
    import json
    data = json.loads(out.read_text())
    assert data["alone"]["steps"] > 0 and data["drawn"]["frames_per_second"] > 0
    assert np.isclose(data["drawn"]["slowdown"], data["alone"]["steps_per_second"] / data["drawn"]["steps_per_second"])
    assert data["browser"] == {"skipped": "not asked"}
