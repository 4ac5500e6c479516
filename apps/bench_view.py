"""`tensormass bench view`: what the live view costs the simulation, and its frame rate.

The scene (examples/organ/live.toml by default: the tetra10 organ, implicit Euler with the budgeted
step) plays as fast as its steps go for `seconds`, in a process of its own (LiveProcess, as
`tensormass view` runs it), in each phase:

- alone: nobody watching (the baseline);
- drawn: a Viewer drawing the latest snapshot `fps` times a second, no browser;
- browser: the page served and open in headless Chromium (Playwright, /usr/bin/chromium or
  $TENSORMASS_CHROMIUM), its pictures streamed; skipped, and said so, without them;
- one process: the browser phase with the steps in the viewer's own process (Live), which shows
  why the view runs them in another.

Each phase reports the steps per second and the mean wall time of a step; the view phases also the
pictures drawn per second. The ratios are against the alone phase of the same run.
"""
from __future__ import annotations

import json
import os
import shutil
import time
from pathlib import Path


from ..runtime.base.errors import TensormassError

DEFAULT_SCENE = Path(__file__).resolve().parents[1] / "examples" / "organ" / "live.toml"


def chromium_path() -> str | None:
    """The Chromium the browser tests and this benchmark drive (None: not installed)."""
    path = os.environ.get("TENSORMASS_CHROMIUM") or shutil.which("chromium") or shutil.which("chromium-browser")
    return path if path and os.path.exists(path) else None


CHROMIUM_ARGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking", "--disable-component-update",
                 "--disable-sync", "--no-first-run", "--disable-dev-shm-usage"]


def _phase(live, seconds: float, during=None) -> dict:
    live.reset()
    live.step(5)                                       # the first factor made before timing
    start = live.snapshot()
    live.play(None)
    t0 = time.perf_counter()
    if during is not None:
        during(seconds)
    else:
        time.sleep(seconds)
    live.pause()
    elapsed = time.perf_counter() - t0
    snap = live.snapshot()
    steps = snap.step - start.step
    return {"steps": steps, "seconds": elapsed, "steps_per_second": steps / elapsed,
            "step_ms": 1e3 * snap.step_wall, "status": snap.status}


def bench(scene_path=None, seconds: float = 5.0, fps: float = 20.0, browser: bool = True) -> dict:
    """The phases of the module doc; the simulation in a process of its own (LiveProcess, as
    `tensormass view` runs it), and once more in the viewer's process (Live) with the browser."""
    from ..runtime.scene.scene import Scene
    from ..runtime.run.live import Live
    from ..runtime.run.live_process import LiveProcess
    from .view import Viewer
    if scene_path is None and not DEFAULT_SCENE.is_file():
        raise TensormassError("bench view: give a scene file; the default, examples/organ/live.toml, is in a "
                              "checkout, not in an installed package")
    scene = Scene.from_toml(str(scene_path or DEFAULT_SCENE))
    out = {"scene": scene.name, "seconds": seconds, "fps": fps}
    live = LiveProcess(scene)
    try:
        out["alone"] = _phase(live, seconds)
        viewer = Viewer(live, fps=fps, speed=None)
        out["drawn"] = _drawn_phase(viewer, live, seconds, fps)
        out["browser"] = _browser_phase(viewer, live, seconds) if browser else {"skipped": "not asked"}
    finally:
        live.close()
    if browser and "skipped" not in out["browser"]:
        same = Live(scene)                     # the view and the steps in one process: they take turns
        try:
            out["one process"] = _browser_phase(Viewer(same, fps=fps, speed=None), same, seconds)
        finally:
            same.close()
    for phase in PHASES[1:]:
        if "steps_per_second" in out.get(phase, {}):
            out[phase]["slowdown"] = out["alone"]["steps_per_second"] / out[phase]["steps_per_second"]
    return out


PHASES = ("alone", "drawn", "browser", "one process")


def _drawn_phase(viewer, live, seconds, fps) -> dict:
    box = {}

    def draw_loop(seconds):
        end = time.perf_counter() + seconds
        frames0 = viewer.frames
        while time.perf_counter() < end:
            if viewer.draw():
                viewer.picture.plotter.render()
            time.sleep(1.0 / fps)
        box["frames"] = viewer.frames - frames0

    result = _phase(live, seconds, draw_loop)
    result["frames_per_second"] = box["frames"] / result["seconds"]
    return result


def _browser_phase(viewer, live, seconds) -> dict:
    chromium = chromium_path()
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        return {"skipped": "playwright is not installed (pip install playwright)"}
    if chromium is None:
        return {"skipped": "no Chromium (apt install chromium, or set TENSORMASS_CHROMIUM)"}
    viewer.serve(port=0)
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=chromium, args=CHROMIUM_ARGS)
        try:
            page = browser.new_page(viewport={"width": 1400, "height": 800})
            page.goto(viewer.url)
            page.wait_for_selector("#render", timeout=30000)
            page.wait_for_timeout(2000)
            box = {}

            def watch(seconds):
                frames0 = viewer.frames
                page.wait_for_timeout(int(seconds * 1000))
                box["frames"] = viewer.frames - frames0

            result = _phase(live, seconds, watch)
            result["frames_per_second"] = box["frames"] / result["seconds"]
            # the page really shows the body: a measure of a blank view would mean nothing
            result["body_on_page"] = _body_share(page.screenshot(clip=page.locator("#render").bounding_box()))
            if result["body_on_page"] < 0.05:
                raise TensormassError(f"bench view: the page shows no body ({100 * result['body_on_page']:.1f} % of "
                                      "its pixels); the pictures did not reach the browser")
            return result
        finally:
            browser.close()
            viewer.close_server()


def _body_share(png: bytes) -> float:
    """The share of a screenshot's pixels that are not the view's background."""
    import io
    import numpy as np
    from PIL import Image
    img = np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).astype(int)
    return float((np.abs(img - 247).sum(axis=2) > 30).mean())


def print_report(out: dict) -> None:
    print(f"live view cost on {out['scene']} ({out['seconds']:g} s per phase, view at most {out['fps']:g} pictures/s)")
    print(f"{'phase':<12} {'steps/s':>9} {'ms/step':>9} {'pictures/s':>11} {'slowdown':>9}")
    for phase in PHASES:
        r = out.get(phase)
        if r is None:
            continue
        if "skipped" in r:
            print(f"{phase:<12} skipped: {r['skipped']}")
            continue
        fps = r.get("frames_per_second")
        print(f"{phase:<12} {r['steps_per_second']:>9.1f} {r['step_ms']:>9.2f} "
              f"{'' if fps is None else f'{fps:.1f}':>11} {r.get('slowdown', 1.0):>8.2f}x")
    print("alone: nobody draws; drawn: pictures made, no browser; browser: served to headless Chromium; "
          "one process: the same with the steps in the viewer's process")


def main(args) -> int:
    out = bench(args.scene, seconds=args.seconds, fps=args.fps, browser=not args.no_browser)
    print_report(out)
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=2))
    bad = [p for p in PHASES if out.get(p, {}).get("status") == "stopped"]
    if bad:
        raise TensormassError(f"bench view: the scene stopped during {', '.join(bad)}")
    return 0


def add_view_bench_command(bench_subparsers) -> None:
    p = bench_subparsers.add_parser("view", help="the live view's frame rate and what it costs the simulation's steps")
    p.add_argument("scene", nargs="?", help="scene file (default: examples/organ/live.toml)")
    p.add_argument("--seconds", type=float, default=5.0, help="length of each phase (default 5)")
    p.add_argument("--fps", type=float, default=20.0, help="the view's most pictures a second (default 20)")
    p.add_argument("--no-browser", action="store_true", help="skip the headless Chromium phase")
    p.add_argument("--json", metavar="FILE", help="also write the report as JSON")
    p.set_defaults(run=main)
