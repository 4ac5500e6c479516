"""A Live in a process of its own: nothing the viewer's process does can hold its steps up.

    live = LiveProcess(scene)        # the same methods as runtime.run.live.Live
    live.step(10); live.play(); live.grab(point); live.drag(target); live.release(); live.pause()
    snap = live.snapshot("von_mises")     # asked of the child: its latest state, with the field's values

Python runs one thread of a process at a time (the GIL), and serving a view is Python work: pictures
encoded and sent, the page's state, the mouse. In one process that work and the steps take turns; in
two they run on two cores (tensormass bench view measures both). The child is started with "spawn"
(a fresh interpreter: no thread or lock of the parent is inherited) and holds a Live; each call here
is one message over a pipe, answered once the child has done it. The child ends with close(), or when
this object's process ends.

The child steps on one thread by default (threads=1: the assembly's, MKL's and OpenMP's), which
leaves the other cores to the pictures and the browser: a step's threads that share a core with
them wait on each other. On the 2-core machine, with Chromium on the same cores, the liver-sized
tetra organ's steps run 1.04x slower with one thread, 1.5x with two (tensormass bench view).
"""
from __future__ import annotations

import contextlib
import multiprocessing as mp
import os
import threading

from ..base.errors import RunStopped, TensormassError

__all__ = ["LiveProcess"]

# seconds the child may take to build and start the scene, and to answer a call
START_TIMEOUT = 600.0
CALL_TIMEOUT = 120.0


class LiveProcess:
    """runtime.run.live.Live's interface, served by a child process (see the module doc)."""

    def __init__(self, scene, *, stiffness: float | None = None, threads: int | None = 1):
        context = mp.get_context("spawn")
        self._conn, child = context.Pipe()
        self._lock = threading.Lock()        # one call at a time over the pipe
        self._process = context.Process(target=_serve, args=(child, scene, stiffness), name="tensormass-live",
                                        daemon=True)
        with _thread_environment(threads):
            self._process.start()
        child.close()
        self._body = self._answer(START_TIMEOUT)
        self.playing = False

    # -- calls -----------------------------------------------------------------------------------------
    def _answer(self, timeout):
        if not self._conn.poll(timeout):
            self._process.kill()
            raise TensormassError(f"live: the simulation process did not answer within {timeout:g} s")
        try:
            kind, value = self._conn.recv()
        except EOFError:
            raise TensormassError(f"live: the simulation process ended (exit code {self._process.exitcode})") from None
        if kind == "ok":
            return value
        error, message = value
        raise (RunStopped(message, None, "failed") if error == "RunStopped" else TensormassError(message))

    def _call(self, name, *args):
        with self._lock:
            if not self._process.is_alive():
                raise TensormassError(f"live: the simulation process ended (exit code {self._process.exitcode})")
            self._conn.send((name, args))
            return self._answer(CALL_TIMEOUT)

    # -- the Live interface ----------------------------------------------------------------------------
    def body(self) -> dict:
        snap = self.snapshot()
        if snap.version != self._body["version"]:
            self._body = self._call("body")
        return self._body

    def snapshot(self, field: str | None = None, curves: bool = False):
        return self._call("snapshot", field, curves)

    def step(self, n: int = 1):
        return self._call("step", n)

    def play(self, speed: float | None = None) -> None:
        self._call("play", speed)
        self.playing = True

    def pause(self) -> None:
        self._call("pause")
        self.playing = False

    def reset(self):
        self.playing = False
        return self._call("reset")

    def grab(self, point, stiffness: float | None = None) -> dict:
        return self._call("grab", point, stiffness)

    def drag(self, target) -> None:
        self._call("drag", target)

    def release(self) -> None:
        self._call("release")

    def move_obstacle(self, name: str, shift) -> None:
        self._call("move_obstacle", name, shift)

    def close(self) -> None:
        if self._process.is_alive():
            try:
                with self._lock:
                    self._conn.send(("close", ()))
            except (OSError, BrokenPipeError):
                pass
            self._process.join(timeout=5)
            if self._process.is_alive():
                self._process.kill()
        self._conn.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


# What the child's threads read when its libraries load: the assembly's (runtime.base.parallel) and
# the BLAS / PARDISO ones (MKL, OpenMP).
_THREAD_VARIABLES = ("TENSORMASS_THREADS", "MKL_NUM_THREADS", "OMP_NUM_THREADS")


@contextlib.contextmanager
def _thread_environment(threads):
    """The environment the child starts with (spawn copies it): `threads` threads (None: as it is)."""
    if threads is None:
        yield
        return
    if int(threads) < 1:
        raise TensormassError(f"live: threads must be >= 1, got {threads!r}")
    saved = {name: os.environ.get(name) for name in _THREAD_VARIABLES}
    os.environ.update({name: str(int(threads)) for name in _THREAD_VARIABLES})
    try:
        yield
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


def _serve(conn, scene, stiffness) -> None:
    """The child: a Live answering the parent's calls until "close" or the pipe closes."""
    from .live import Live
    try:
        live = Live(scene, stiffness=stiffness)
    except Exception as exc:                 # the scene cannot be stepped live: the parent says why
        conn.send(("error", (type(exc).__name__, str(exc))))
        return
    conn.send(("ok", live.body()))
    calls = {
        "body": live.body,
        "snapshot": lambda field, curves: _light(live.snapshot(field, curves)),
        "step": lambda n: _light(live.step(n)),
        "play": live.play, "pause": live.pause,
        "reset": lambda: _light(live.reset()),
        "grab": lambda point, stiffness: _grab_info(live.grab(point, stiffness)),
        "drag": live.drag, "release": live.release, "move_obstacle": live.move_obstacle,
    }
    try:
        while True:
            try:
                name, args = conn.recv()
            except EOFError:
                break
            if name == "close":
                break
            try:
                conn.send(("ok", calls[name](*args)))
            except Exception as exc:
                conn.send(("error", (type(exc).__name__, str(exc))))
    finally:
        live.close()


def _light(snap):
    """The snapshot without its Model (which stays in the child)."""
    from dataclasses import replace
    return replace(snap, model=None)


def _grab_info(grab) -> dict:
    return {"stiffness": grab.stiffness, "nodes": grab.nodes.tolist(), "weights": grab.weights.tolist()}
