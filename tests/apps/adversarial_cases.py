"""The adversarial suite of issue #10 ("Never a silent wrong answer"): inputs as data, and the
harness that replays one through the real command line and says how it ended.

    from adversarial_cases import CASES, replay
    result = replay(CASES[0])          # Result: exit code, output, outcome, problems
    result.passed                      # met its expectation, no crash/traceback/silent wrong/half-written

Each Case is plain data: the argv given to ``tensormass.apps.cli.main`` (run in a fresh
temporary folder, paths relative to it), the files it builds there first (scene TOML text,
bytes, a mesh described as points + cells + damage, folders, links, fifos), environment
variables, earlier runs (an old summary, old frames, a compiled library to corrupt), and
"hooks": faults injected into the process (a folder that refuses writes, a full disk, Ctrl-C
at a given call or once a given frame exists).  Nothing in a case is code, so a case can be
printed, stored and replayed alone (``python tests/apps/adversarial_table.py --case NAME``).

Expectations (what the issue demands of every input):

    error        exit 2, one line ``tensormass: error: ...`` matching the case's regex (naming
                 the problem), no traceback, nothing written (unless the case says the run had
                 started: then what was written stays valid)
    untrusted    exit 3, summary JSON with status diverged/invalid/failed and a message,
                 ``tensormass: run <status>: ...``; frames without a health mark are not absurd
    warning      exit 0, status "warnings" with the warnings listed in the summary
    ok           exit 0, status "ok", and the result checked for sanity: finite energy and
                 probes, displacements below a bound, no inverted element, frames readable
    interrupted  exit 130, one line, frames so far kept and listed, summary (when asked for)
                 with status "interrupted"

Whatever the expectation, these are failures: a crash (exit 1, any other code, or an exception
escaping main), a traceback in the output, a silent wrong answer (exit 0 where the input or the
run is not trustworthy, or an "ok" result failing its sanity check) and a half-written output
(leftover *.tmp, a .pvd that does not parse or lists missing frames, frames it does not list, a
summary that does not parse, a file that existed before the run changed or gone).
"""
from __future__ import annotations

import _thread
import builtins
import contextlib
import errno
import fnmatch
import io
import json
import math
import os
import random
import re
import signal
import stat
import sys
import tempfile
import threading
import time
import traceback
import warnings
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["Case", "Result", "CASES", "FAMILIES", "EXPECTATIONS", "replay", "by_name", "scene_text", "toml"]

FAMILIES = ("scene", "mesh", "run", "interrupt", "cache", "output")
EXPECTATIONS = ("error", "untrusted", "warning", "ok", "interrupted")
UNTRUSTED_STATUSES = ("diverged", "invalid", "failed")


# ============================================================================== case data


@dataclass(frozen=True)
class Case:
    family: str
    name: str
    argv: tuple                        # given to cli.main, run in the case's temporary folder
    expect: str                        # one of EXPECTATIONS
    match: str = ""                    # regex the one-line message must match (error, untrusted, interrupted)
    files: tuple = ()                  # ((relative path, content), ...); see _build_file
    env: tuple = ()                    # ((name, value or None), ...); "{tmp}" is the case's folder
    before: tuple = ()                 # argv of earlier runs (must exit 0) made before the snapshot;
                                       # leading "@env:NAME=VALUE" items: settings for that run only
    damage: tuple = ()                 # (("corrupt", glob, how) | ("write", path, text) | ("copy", from, to)
                                       #  | ("seed", (element, law, quadrature), cache folder), ...) after them
    hooks: tuple = ()                  # faults injected while main runs; see _Hooks
    may_change: tuple = ()             # globs of files that existed before and may change or go
    ignore: tuple = ()                 # globs not checked at all
    scratch: tuple = ()                # globs where even a refused run may create files (a kernel cache)
    detail: bool = False               # an error whose first line is followed by detail (compiler output)
    wrote_before_error: bool = False   # error cases whose run had started: valid outputs may stay
    max_displacement: float = 0.2      # ok/warning sanity: largest |u| in meters (bodies here are ~1 m)
    min_frames: int = 0                # interrupted: frames that must have been kept
    clear_kernels: bool = False        # the case depends on the kernel cache: forget loaded kernels
    why: str = ""                      # what the case reproduces (the item), for the table

    def __post_init__(self):
        assert self.family in FAMILIES, self.family
        assert self.expect in EXPECTATIONS, self.expect


# -------------------------------------------------------------------------- TOML text from data


class _Delete:
    """Marker: remove this key from the base scene."""

    def __repr__(self):
        return "DELETE"


DELETE = _Delete()


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)             # a TOML basic string for everything json escapes
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{k} = {_toml_value(x)}" for k, x in v.items()) + "}"
    raise TypeError(f"no TOML for {type(v).__name__}")


def toml(data: dict, prefix: str = "") -> str:
    """TOML text of plain data: scalars first, then [tables] and [[arrays of tables]]."""
    lines, tail = [], []
    for k, v in data.items():
        if isinstance(v, dict):
            tail.append(f"\n[{prefix}{k}]\n" + toml(v, f"{prefix}{k}."))
        elif isinstance(v, list) and v and all(isinstance(x, dict) for x in v):
            for x in v:
                tail.append(f"\n[[{prefix}{k}]]\n" + toml(x, f"{prefix}{k}."))
        else:
            lines.append(f"{k} = {_toml_value(v)}")
    return "\n".join(lines) + ("\n" if lines else "") + "".join(tail)


BAR_SIZE = [1.0, 0.1, 0.1]
CLAMP = [[-1e-9, -1.0, -1.0], [1e-9, 1.0, 1.0]]         # the x = 0 face


def base_scene() -> dict:
    """A 1 m x 0.1 m x 0.1 m steel-stiff bar of 3 hexahedra clamped at x = 0 under gravity:
    tip deflection ~1.5 mm, a run of a few ms once the kernels are warm."""
    return {
        "name": "bar",
        "mesh": {"generate": "bar", "size": list(BAR_SIZE), "cells": [3, 1, 1], "element": "hexahedron"},
        "material": [{"law": "stvk", "quadrature": "gauss2", "E": 1.0e8, "nu": 0.3, "density": 1000.0}],
        "fixed": [{"box": CLAMP}],
        "loads": {"gravity": [0.0, 0.0, -9.81]},
        "solver": {"kind": "static", "steps": 2},
        "probe": [{"name": "tip", "point": [1.0, 0.05, 0.05]}],
        "output": {"every": 1},
    }


def _set(data, path: str, value) -> None:
    """data[a][b][0][c] = value for path 'a.b.0.c' (missing tables are created; DELETE removes)."""
    keys = path.split(".")
    node = data
    for k in keys[:-1]:
        if isinstance(node, list):
            node = node[int(k)]
        else:
            node = node.setdefault(k, {})
    last = keys[-1]
    if isinstance(node, list):
        node[int(last)] = value
    elif value is DELETE:
        node.pop(last, None)
    else:
        node[last] = value


def scene_text(changes: dict | None = None, base: dict | None = None) -> str:
    """The base scene with changes {"solver.steps": 5, "material.0.E": DELETE, ...} as TOML."""
    data = json.loads(json.dumps(base if base is not None else base_scene()))   # a deep copy
    for path, value in (changes or {}).items():
        _set(data, path, value)
    return toml(data)


# -------------------------------------------------------------------------- meshes from data


def hex_bar(n: int = 3, size=BAR_SIZE) -> dict:
    """n hexahedra in a row along x (VTK node order), as {"points", "cells": [(type, rows)]}."""
    L, b, h = size
    pts = [[L * i / n, b * j, h * k] for k in range(2) for j in range(2) for i in range(n + 1)]

    def node(i, j, k):
        return i + (n + 1) * (j + 2 * k)
    rows = [[node(i, 0, 0), node(i + 1, 0, 0), node(i + 1, 1, 0), node(i, 1, 0),
             node(i, 0, 1), node(i + 1, 0, 1), node(i + 1, 1, 1), node(i, 1, 1)] for i in range(n)]
    return {"points": pts, "cells": [["hexahedron", rows]]}


def tet_bar(n: int = 3, size=BAR_SIZE) -> dict:
    """The same bar with each hexahedron cut into 6 tetrahedra around its main diagonal (the
    same cut in every cell, so faces match), all positively oriented."""
    bar = hex_bar(n, size)
    P = np.asarray(bar["points"])
    rows = []
    # corners of a hexahedron in VTK order; the 6 paths from corner 0 to corner 6 along the axes
    paths = [(0, 1, 2, 6), (0, 1, 5, 6), (0, 3, 2, 6), (0, 3, 7, 6), (0, 4, 5, 6), (0, 4, 7, 6)]
    for hexa in bar["cells"][0][1]:
        for p in paths:
            t = [hexa[c] for c in p]
            a, b, c, d = P[t]
            if np.dot(np.cross(b - a, c - a), d - a) < 0:
                t[0], t[1] = t[1], t[0]
            rows.append(t)
    return {"points": bar["points"], "cells": [["tetra", rows]]}


def quad_strip(n: int = 3, size=BAR_SIZE) -> dict:
    """A 2D strip of n quads in the plane z = 0."""
    L, b = size[0], size[1]
    pts = [[L * i / n, b * j, 0.0] for j in range(2) for i in range(n + 1)]
    rows = [[i, i + 1, i + n + 2, i + n + 1] for i in range(n)]
    return {"points": pts, "cells": [["quad", rows]]}


def mesh_file(shape: str = "hex", fmt: str = "vtu", damage: tuple = (), n: int = 3) -> dict:
    """A mesh file as data: a bar ("hex" | "tet"; "points": its nodes without cells; "empty";
    "quad": a 2D strip)
    written with meshio in `fmt` ("vtu", "gmsh22", "vtk"; "text": VTU under another name), after `damage`:

        ("cell", block, row, col, node)      set one node id of a cell
        ("swap", block, row, a, b)           swap two nodes of a cell (inverts it)
        ("point", index, [x, y, z])          move a node
        ("add_point", [x, y, z])             an extra node no cell uses
        ("add_block", type, rows)            another cell block
        ("copy_cell", block, row)            the same cell twice
        ("tags", name, [values per cell of each block])   cell data
        ("truncate", fraction)               keep only this share of the file's bytes
    """
    return {"mesh": shape, "format": fmt, "damage": [list(d) for d in damage], "n": n}


def _write_mesh(path: Path, spec: dict) -> None:
    import meshio
    shape = spec["mesh"]
    bar = {"empty": {"points": [], "cells": []}, "hex": hex_bar(spec["n"]), "tet": tet_bar(spec["n"]),
           "points": {"points": hex_bar(spec["n"])["points"], "cells": []}, "quad": quad_strip(spec["n"])}[shape]
    points = [list(p) for p in bar["points"]]
    blocks = [[t, [list(r) for r in rows]] for t, rows in bar["cells"]]
    cell_data = {}
    truncate = None
    for d in spec["damage"]:
        kind = d[0]
        if kind == "cell":
            blocks[d[1]][1][d[2]][d[3]] = d[4]
        elif kind == "swap":
            row = blocks[d[1]][1][d[2]]
            row[d[3]], row[d[4]] = row[d[4]], row[d[3]]
        elif kind == "point":
            points[d[1]] = list(d[2])
        elif kind == "add_point":
            points.append(list(d[1]))
        elif kind == "add_block":
            blocks.append([d[1], [list(r) for r in d[2]]])
        elif kind == "copy_cell":
            blocks[d[1]][1].append(list(blocks[d[1]][1][d[2]]))
        elif kind == "tags":
            cell_data[d[1]] = [np.asarray(v) for v in d[2]]
        elif kind == "truncate":
            truncate = d[1]
        else:
            raise ValueError(f"unknown mesh damage {kind!r}")
    pts = np.asarray(points, dtype=float) if points else np.zeros((0, 3))
    cells = [(t, np.asarray(rows, dtype=np.int64).reshape(len(rows), -1)) for t, rows in blocks]
    fmt = spec["format"]
    target = path if fmt != "text" else path.with_name(path.name + ".vtu")
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        meshio.write(target, meshio.Mesh(pts, cells, cell_data=cell_data),   # (gmsh: "appending zeros" notes)
                     file_format={"text": "vtu"}.get(fmt, fmt))
    if fmt == "text":                    # a VTU file under a name meshio cannot recognise
        os.replace(target, path)
    if truncate is not None:
        data = path.read_bytes()
        path.write_bytes(data[: int(len(data) * truncate)])


# ============================================================================== running one case


@dataclass
class Result:
    case: Case
    code: int | None                   # exit code (None: an exception escaped main)
    out: str
    err: str
    escaped: str | None = None         # the exception that escaped main, if any
    summary: dict | None = None        # the summary JSON, when the case asked for one and it parses
    outcome: str = "?"                 # error | untrusted | warning | ok | interrupted | crash
    problems: list = field(default_factory=list)     # why the case failed its expectation
    crash: bool = False
    traceback: bool = False
    silent_wrong: bool = False
    half_written: list = field(default_factory=list)  # what is half-written
    seconds: float = 0.0

    @property
    def passed(self) -> bool:
        return not (self.problems or self.crash or self.traceback or self.silent_wrong or self.half_written)

    def describe(self) -> str:
        """Everything needed to see why a case failed."""
        lines = [f"{self.case.family}/{self.case.name}: expected {self.case.expect}, got {self.outcome} "
                 f"(exit {self.code})"]
        for label, items in (("problem", self.problems), ("half-written", self.half_written)):
            lines += [f"  {label}: {p}" for p in items]
        for flag in ("crash", "traceback", "silent_wrong"):
            if getattr(self, flag):
                lines.append(f"  {flag.replace('_', ' ')}")
        if self.escaped:
            lines.append(f"  escaped main: {self.escaped}")
        lines.append("  argv: " + " ".join(self.case.argv))
        lines += ["  stderr: " + line for line in self.err.splitlines()[-8:]]
        lines += ["  stdout: " + line for line in self.out.splitlines()[-4:]]
        return "\n".join(lines)


def _expand(value: str, tmp: Path) -> str:
    return value.replace("{tmp}", str(tmp))


def _build_file(root: Path, rel: str, content) -> None:
    """content: str (text), bytes, {"mesh": ...} (mesh_file), {"folder": True},
    {"symlink": target}, {"fifo": True}, {"copy_of": other relative path}."""
    path = root / rel
    path.parent.mkdir(parents=True, exist_ok=True)
    if isinstance(content, str):
        path.write_text(content, encoding="utf-8")
    elif isinstance(content, bytes):
        path.write_bytes(content)
    elif "mesh" in content:
        _write_mesh(path, content)
    elif content.get("folder"):
        path.mkdir(exist_ok=True)
    elif "symlink" in content:
        path.symlink_to(content["symlink"])
    elif content.get("fifo"):
        os.mkfifo(path)
    else:
        raise ValueError(f"unknown file spec {content!r}")


def _snapshot(root: Path) -> dict:
    """relative path -> bytes (regular files), "<folder>", "<link:target>" or "<special>"."""
    snap = {}
    for dirpath, dirnames, filenames in os.walk(root):
        for name in dirnames + filenames:
            full = Path(dirpath) / name
            rel = str(full.relative_to(root))
            info = os.lstat(full)
            if stat.S_ISLNK(info.st_mode):
                snap[rel] = f"<link:{os.readlink(full)}>"
            elif stat.S_ISDIR(info.st_mode):
                snap[rel] = "<folder>"
            elif stat.S_ISREG(info.st_mode):
                snap[rel] = full.read_bytes()
            else:
                snap[rel] = "<special>"
    return snap


def _matches(rel: str, globs) -> bool:
    return any(fnmatch.fnmatch(rel, g) or rel.startswith(g.rstrip("*").rstrip("/") + "/") and g.endswith("**")
               for g in globs)


# -------------------------------------------------------------------------- fault injection


def _resolve(target: str):
    """'module:attr.attr' -> (owner object, attribute name)."""
    import importlib
    module, _, attrs = target.partition(":")
    owner = importlib.import_module(module)
    parts = attrs.split(".")
    for p in parts[:-1]:
        owner = getattr(owner, p)
    return owner, parts[-1]


def _partial_write(target: str, real, args) -> None:
    """Half of what the call was about to write, as a crash or a full disk would leave it
    (real: the function the hook replaced)."""
    if target == "meshio:write":
        Path(args[0]).write_bytes(b'<?xml version="1.0"?>\n<VTKFile type="Unstruct')
    elif target == "os:pwrite":
        fd, data, at = args[:3]
        real(fd, data[: len(data) // 2], at)


class _Hooks:
    """The faults of a case, installed while main runs and removed afterwards.

        ("readonly", folder)                       writes into folder fail with EACCES (also as root)
        ("fail", "module:attr", n, error, partial) the n-th call and later ones raise error
                                                   ("ENOSPC", "EACCES"); partial: half the data first;
                                                   a full disk still lets os.pwrite overwrite bytes
        ("interrupt_at", "module:attr", n, partial) the n-th call raises KeyboardInterrupt (Ctrl-C)
        ("interrupt_when", relative path)           Ctrl-C (SIGINT to the main thread) once the file
                                                   exists, from a watcher thread
    """

    def __init__(self, hooks, root: Path):
        self.hooks = hooks
        self.root = root
        self.saved = []
        self.lock = threading.Lock()
        self.running = False
        self.watchers = []
        self.fired = []

    def __enter__(self):
        for hook in self.hooks:
            kind = hook[0]
            if kind == "readonly":
                self._readonly(self.root / hook[1])
            elif kind == "fail":
                self._wrap(hook[1], hook[2], hook[3], hook[4] if len(hook) > 4 else False)
            elif kind == "interrupt_at":
                self._wrap(hook[1], hook[2], "KeyboardInterrupt", hook[3] if len(hook) > 3 else False)
            elif kind == "interrupt_when":
                self.watchers.append(self.root / hook[1])
            else:
                raise ValueError(f"unknown hook {kind!r}")
        return self

    def start(self):
        """Called right before main: the watcher threads may interrupt from now on."""
        with self.lock:
            self.running = True
        for path in self.watchers:
            t = threading.Thread(target=self._watch, args=(path,), daemon=True)
            t.start()

    def stop(self):
        """Called right after main: no interrupt may land in the harness."""
        with self.lock:
            self.running = False

    def _watch(self, path: Path) -> None:
        deadline = time.monotonic() + 300
        while time.monotonic() < deadline:
            with self.lock:
                if not self.running:
                    return
                if path.exists():
                    self.fired.append(str(path))
                    _thread.interrupt_main()
                    return
            time.sleep(0.002)

    def __exit__(self, *exc):
        for owner, name, raw in reversed(self.saved):
            if raw is None:
                delattr(owner, name)
            else:
                setattr(owner, name, raw)
        self.saved = []
        return False

    def _patch(self, owner, name, new) -> None:
        raw = vars(owner).get(name) if isinstance(owner, type) else getattr(owner, name)
        self.saved.append((owner, name, raw if raw is not None or not isinstance(owner, type) else None))
        if isinstance(owner, type) and raw is not None and isinstance(raw, (classmethod, staticmethod)):
            new = staticmethod(new)
        setattr(owner, name, new)

    def _wrap(self, target: str, n: int, error: str, partial: bool) -> None:
        owner, name = _resolve(target)
        real = getattr(owner, name)
        calls = {"n": 0}

        def wrapper(*args, **kw):
            if target == "os:pwrite" and error == "ENOSPC" and args[2] + len(args[1]) <= os.fstat(args[0]).st_size:
                return real(*args, **kw)         # overwriting bytes a file has needs no free space
            calls["n"] += 1
            hit = calls["n"] == n if error == "KeyboardInterrupt" else calls["n"] >= n
            if not hit:
                return real(*args, **kw)
            if partial:
                _partial_write(target, real, args)
            if error == "KeyboardInterrupt":
                self.fired.append(target)
                raise KeyboardInterrupt
            code = getattr(errno, error)
            raise OSError(code, os.strerror(code))
        self._patch(owner, name, wrapper)

    def _readonly(self, folder: Path) -> None:
        """Writes under folder fail with EACCES: creating, opening for writing, renaming into,
        removing. chmod does not stop root, so the calls themselves refuse."""
        folder = os.path.realpath(folder)

        def inside(path) -> bool:
            if isinstance(path, int):
                return False
            full = os.path.realpath(os.fspath(path))
            return full == folder or full.startswith(folder + os.sep)

        def denied(path):
            return PermissionError(errno.EACCES, os.strerror(errno.EACCES), os.fspath(path))

        real_open, real_io_open = os.open, io.open
        real = {name: getattr(os, name) for name in ("mkdir", "replace", "rename", "remove", "unlink", "rmdir")}
        writing = os.O_WRONLY | os.O_RDWR | os.O_CREAT | os.O_TRUNC | os.O_APPEND

        def os_open(path, flags, *a, **kw):
            if flags & writing and inside(path):
                raise denied(path)
            return real_open(path, flags, *a, **kw)

        def io_open(file, mode="r", *a, **kw):
            if any(c in mode for c in "wax+") and inside(file):
                raise denied(file)
            return real_io_open(file, mode, *a, **kw)

        def guarded(name, *which):
            def call(*args, **kw):
                for i in which:
                    if i < len(args) and inside(args[i]):
                        if name == "mkdir" and os.path.lexists(args[i]):
                            raise FileExistsError(errno.EEXIST, os.strerror(errno.EEXIST), os.fspath(args[i]))
                        raise denied(args[i])
                return real[name](*args, **kw)
            return call

        self._patch(os, "open", os_open)
        self._patch(io, "open", io_open)
        self._patch(builtins, "open", io_open)
        for name, which in (("mkdir", (0,)), ("replace", (0, 1)), ("rename", (0, 1)), ("remove", (0,)),
                            ("unlink", (0,)), ("rmdir", (0,))):
            self._patch(os, name, guarded(name, *which))


@contextlib.contextmanager
def _environment(env, tmp: Path):
    saved = {k: os.environ.get(k) for k, _ in env}
    try:
        for k, v in env:
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = _expand(v, tmp)
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


@contextlib.contextmanager
def _sigint_raises():
    """Ctrl-C must raise KeyboardInterrupt in this process (a test runner may have changed the
    handler; interrupt_main does nothing while SIGINT is ignored)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = signal.getsignal(signal.SIGINT)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old)


def _forget_kernels() -> None:
    """Kernels loaded by earlier cases would hide the cache state this case sets up."""
    from tensormass.runtime.kernels import kernels
    kernels.load_kernel.cache_clear()


def _call_main(argv) -> tuple:
    """(exit code or None, stdout, stderr, escaped exception text or None)."""
    from tensormass.apps.cli import main
    out, err = io.StringIO(), io.StringIO()
    code, escaped = None, None
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err), warnings.catch_warnings():
        warnings.simplefilter("ignore")          # numpy's overflow notes are not the program's output
        try:
            code = main(list(argv))
        except SystemExit as exc:                # argparse, or a library calling sys.exit
            code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
            if not isinstance(exc.code, int) and exc.code is not None:
                err.write(str(exc.code) + "\n")
        except BaseException as exc:             # noqa: BLE001 - an exception escaping main is a crash
            escaped = "".join(traceback.format_exception_only(type(exc), exc)).strip() or type(exc).__name__
    return code, out.getvalue(), err.getvalue(), escaped


def replay(case: Case, root: Path | None = None) -> Result:
    """Run one case in a fresh temporary folder (or root) and classify how it ended."""
    if root is None:
        label = re.sub(r"[^A-Za-z0-9_.-]+", "-", case.name)[:40]
        with tempfile.TemporaryDirectory(prefix=f"tm-adv-{label}-") as tmp:
            return replay(case, Path(tmp))
    root = Path(root).resolve()
    root.mkdir(parents=True, exist_ok=True)
    from tensormass.runtime.base.cache import cache_dir
    session = cache_dir()                         # the cache of this process, before the case's settings
    for rel, content in case.files:
        _build_file(root, rel, content)
    cwd = os.getcwd()
    os.chdir(root)
    t0 = time.perf_counter()
    try:
        with _environment(case.env, root):
            if case.clear_kernels:
                _forget_kernels()
            try:
                for argv in case.before:
                    settings = tuple(tuple(a[5:].split("=", 1)) for a in argv if a.startswith("@env:"))
                    with _environment(settings, root):
                        code, out, err, escaped = _call_main([a for a in argv if not a.startswith("@env:")])
                    if code != 0:
                        raise RuntimeError(f"case setup: {' '.join(argv)} ended with {code}: {err or escaped}")
                for d in case.damage:
                    _damage(root, d, session)
                snap = _snapshot(root)
                with _sigint_raises(), _Hooks(case.hooks, root) as hooks:
                    pending = None
                    try:
                        hooks.start()
                        code, out, err, escaped = _call_main(case.argv)
                        hooks.stop()
                        time.sleep(0.01 if hooks.watchers else 0)   # a Ctrl-C already sent lands here
                    except KeyboardInterrupt:
                        hooks.stop()
                        pending = "KeyboardInterrupt after main returned"
                if pending and escaped is None:
                    escaped = pending
            finally:
                if case.clear_kernels:
                    _forget_kernels()
    finally:
        os.chdir(cwd)
    result = Result(case, code, out, err, escaped, seconds=time.perf_counter() - t0)
    _classify(result, root, snap)
    return result


def _damage(root: Path, d, session: Path) -> None:
    kind = d[0]
    if kind == "seed":
        _seed(root / d[2], d[1], session)
        return
    if kind == "write":
        _build_file(root, d[1], d[2])
        return
    if kind == "copy":
        import shutil
        shutil.copytree(root / d[1], root / d[2], symlinks=True)
        return
    if kind != "corrupt":
        raise ValueError(f"unknown damage {kind!r}")
    found = sorted(p for p in root.rglob("*") if p.is_file() and fnmatch.fnmatch(str(p.relative_to(root)), d[1]))
    if not found:
        raise RuntimeError(f"case setup: nothing matches {d[1]} to corrupt")
    for path in found:
        data = path.read_bytes()
        if d[2] == "garbage":                    # same length, fixed seed: replayable
            path.write_bytes(random.Random(len(data)).randbytes(len(data)))
        elif d[2] == "truncate":
            path.write_bytes(data[: len(data) // 2])
        elif d[2] == "remove":
            path.unlink()
        elif d[2] == "text":
            path.write_text("not a hash\n")
        else:
            raise ValueError(f"unknown corruption {d[2]!r}")


def _seed(cache: Path, kernel: tuple, session: Path) -> None:
    """The compiled C library of kernel (element, law, quadrature), with its hash sidecar, copied
    from the session's cache into the folder `cache` (a TENSORMASS_CACHE) as a run would have left
    it there.  The session's cache compiles it once for all cases; a case about what a later
    process meets in its cache (a damaged library or sidecar, a read-only cache) then compiles only
    what that process has to rebuild.  This process never maps the copy, so damaging it is safe."""
    import shutil
    from tensormass.backends.c import loader
    from tensormass.runtime.kernels.kernels import kernel_source
    source = kernel_source(*kernel, "c")
    text = source.read_text(encoding="utf-8")
    name = loader.parse_metadata(text, source)["name"]
    lib = loader.library_path(name, text, loader.compiler(), loader.cflags(), session)
    loader.build_missing([source], session)
    folder = cache / session.name / "c"            # session is <cache root>/<generator version>
    folder.mkdir(parents=True, exist_ok=True)
    for path in (lib, lib.with_name(lib.name + ".sha256")):
        shutil.copy2(path, folder / path.name)


# ============================================================================== classification


_ERROR_LINE = re.compile(r"^tensormass: error: ")
_PROGRESS = re.compile(r"^(load )?step \d+/\d+ \[")        # the progress bar of a run without --quiet
_STOP_LINE = re.compile(r"^tensormass: run (diverged|invalid|failed): ")
_EXIT_OF = {0: None, 2: "error", 3: "untrusted", 130: "interrupted"}


def _json_path(argv) -> str | None:
    argv = list(argv)
    return argv[argv.index("--json") + 1] if "--json" in argv else None


def _classify(r: Result, root: Path, before: dict) -> None:
    case = r.case
    text = r.out + r.err
    r.traceback = "Traceback (most recent call last)" in text
    lines = [line for line in r.err.splitlines() if line.strip() and not _PROGRESS.match(line)]
    last = lines[-1] if lines else ""
    quiet = "--quiet" in case.argv or case.argv[:1] != ("run",)

    # how it ended
    if r.escaped is not None or r.code not in (0, 2, 3, 130):
        r.crash = True
        r.outcome = "crash"
    elif r.code == 0:
        r.outcome = "ok"
    else:
        r.outcome = _EXIT_OF[r.code]

    js = _json_path(case.argv)
    if js is not None and (root / js).is_file() and not os.path.islink(root / js):
        try:
            data = json.loads((root / js).read_text(encoding="utf-8"))
            r.summary = data if isinstance(data, dict) and data.get("format") == "tensormass-summary/1" else None
        except (ValueError, UnicodeDecodeError):
            r.summary = None
    if r.outcome == "ok" and r.summary is not None and r.summary.get("status") == "warnings":
        r.outcome = "warning"

    r.half_written = _half_written(r, root, before)

    expect = case.expect
    if r.crash:
        r.problems.append(f"crash: exit {r.code}" + (f", {r.escaped}" if r.escaped else ""))
        return
    if r.code == 0 and expect in ("error", "untrusted", "interrupted"):
        r.silent_wrong = True
        r.problems.append(f"exit 0 where {expect} was expected")
        return

    def message_matches(line: str) -> None:
        if case.match and not re.search(case.match, line):
            r.problems.append(f"message does not match /{case.match}/: {line!r}")

    if expect == "error":
        if r.code != 2:
            r.problems.append(f"exit {r.code}, expected 2")
        said = lines[0] if case.detail and lines else last
        if not _ERROR_LINE.match(said):
            r.problems.append(f"stderr line is not 'tensormass: error: ...': {said!r}")
        message_matches(said)
        if quiet and len(lines) != 1 and not case.detail:
            r.problems.append(f"{len(lines)} lines on stderr, expected one")
        if not case.wrote_before_error:
            new = [rel for rel in _snapshot(root)
                   if rel not in before and not _matches(rel, case.ignore + case.scratch)]
            if new:
                r.problems.append(f"wrote {', '.join(sorted(new)[:5])} although the input was refused")
    elif expect == "untrusted":
        if r.code != 3:
            r.problems.append(f"exit {r.code}, expected 3")
        if not _STOP_LINE.match(last):
            r.problems.append(f"last stderr line is not 'tensormass: run <status>: ...': {last!r}")
        message_matches(last)
        if js is not None:
            if r.summary is None:
                r.problems.append(f"no summary JSON at {js}")
            elif r.summary.get("status") not in UNTRUSTED_STATUSES or not r.summary.get("message"):
                r.problems.append(f"summary status {r.summary.get('status')!r}, message {r.summary.get('message')!r}")
        r.problems += _unmarked_frames(root, case)
    elif expect == "interrupted":
        if r.code != 130:
            r.problems.append(f"exit {r.code}, expected 130")
        if len(lines) != 1 or not last.startswith("tensormass: ") or "interrupted" not in last:
            r.problems.append(f"expected one line 'tensormass: ... interrupted ...' on stderr, got {lines[-3:]}")
        message_matches(last)
        if js is not None and case.min_frames:
            if r.summary is None or r.summary.get("status") != "interrupted":
                r.problems.append(f"summary JSON {js}: status {None if r.summary is None else r.summary.get('status')!r}, "
                                  "expected 'interrupted'")
        if case.min_frames:
            listed = _listed_frames(root)
            if len(listed) < case.min_frames:
                r.problems.append(f"{len(listed)} frame(s) kept, expected at least {case.min_frames}")
    else:                                        # ok / warning: exit 0 and a sane result
        if r.code != 0:
            r.problems.append(f"exit {r.code}, expected 0 ({last})")
            return
        insane = _insane(r, root)
        if insane:
            r.silent_wrong = True
            r.problems += insane
        elif expect == "warning" and r.outcome != "warning":
            r.problems.append(f"status {r.outcome!r}, expected 'warnings' with the warnings listed")
        elif expect == "ok" and r.outcome != "ok":
            r.problems.append(f"status {r.outcome!r}, expected 'ok'")


def _frames_folders(root: Path) -> list:
    return sorted({p.parent for p in root.rglob("*.pvd")} | {p.parent for p in root.rglob("frame_*.vtu")})


def _listed_frames(root: Path) -> list:
    out = []
    for pvd in sorted(root.rglob("*.pvd")):
        try:
            out += [pvd.parent / d.get("file") for d in ET.parse(pvd).getroot().iter("DataSet")]
        except ET.ParseError:
            pass
    return out


def _half_written(r: Result, root: Path, before: dict) -> list:
    """What the run left half-written, broken or changed that it must not have."""
    case = r.case
    after = _snapshot(root)
    bad = []
    for rel, old in before.items():
        if _matches(rel, case.ignore) or _matches(rel, case.may_change):
            continue
        if rel not in after:
            bad.append(f"{rel} existed before the run and is gone")
        elif after[rel] != old:
            bad.append(f"{rel} existed before the run and was modified")
    changed = {rel for rel, v in after.items() if before.get(rel) != v and not _matches(rel, case.ignore)}
    for rel in sorted(changed):
        if rel.endswith(".tmp") or fnmatch.fnmatch(os.path.basename(rel), ".*.tmp*"):
            bad.append(f"temporary file left: {rel}")
    for pvd in sorted(root.rglob("*.pvd")):
        rel = str(pvd.relative_to(root))
        if _matches(rel, case.ignore) or rel not in changed:
            continue
        try:
            tree = ET.parse(pvd)
        except ET.ParseError as exc:
            bad.append(f"{rel} is not valid XML ({exc})")
            continue
        names = [d.get("file") for d in tree.getroot().iter("DataSet")]
        missing = [n for n in names if not (pvd.parent / n).is_file()]
        if missing:
            bad.append(f"{rel} lists missing frames {missing[:3]}")
        listed = set(names)
        for frame in sorted(pvd.parent.glob("frame_*.vtu")):
            frel = str(frame.relative_to(root))
            if frame.name not in listed and (frel in changed or before.get(frel) is not None
                                             and not _matches(frel, case.may_change)):
                if frel in changed or pvd.stem == "frame":
                    bad.append(f"{frel} is not listed in {rel}")
    for folder in _frames_folders(root):
        if not (folder / "frame.pvd").exists():
            for frame in folder.glob("frame_*.vtu"):
                frel = str(frame.relative_to(root))
                if frel in changed:
                    bad.append(f"{frel} written without a .pvd listing it")
    for rel in sorted(changed):
        path = root / rel
        if rel.endswith(".vtu") and path.is_file():
            try:
                ET.parse(path)
            except ET.ParseError as exc:
                bad.append(f"{rel} is not valid XML ({exc})")
        elif rel.endswith(".json") and path.is_file() and not path.is_symlink():
            try:
                json.loads(path.read_text(encoding="utf-8"))
            except (ValueError, UnicodeDecodeError) as exc:
                bad.append(f"{rel} does not parse as JSON ({exc})")
    js = _json_path(case.argv)
    if js is not None and (root / js).is_file() and str(Path(js)) in changed and r.summary is None:
        bad.append(f"{js} written without our format marker")
    if r.summary is not None and "status" not in r.summary:
        bad.append(f"{js} has no status")
    return bad


def _read_frame(path: Path):
    import meshio
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        return meshio.read(path)


def _unmarked_frames(root: Path, case: Case) -> list:
    """Frames of an untrusted run with no health mark must not show an absurd state (issue item 4):
    displacement spread within 10 body sizes (the monitor's default limit), finite everywhere."""
    problems = []
    for frame in _listed_frames(root)[-60:]:
        try:
            m = _read_frame(frame)
        except Exception as exc:                 # noqa: BLE001 - any reading failure is a finding
            problems.append(f"{frame.name} cannot be read: {exc}")
            continue
        u = np.asarray(m.point_data.get("displacement"))
        if not np.all(np.isfinite(u)):
            problems.append(f"{frame.name}: non-finite displacement")
            continue
        if "health_warning" in m.cell_data:
            continue
        size = float(np.linalg.norm(np.ptp(m.points, axis=0)))
        spread = float(np.linalg.norm(u - u.mean(axis=0), axis=1).max())
        if spread > 10 * size:
            problems.append(f"{frame.name}: displacement spread {spread:.3g} m on a {size:.3g} m body, no health mark")
    return problems


def _insane(r: Result, root: Path) -> list:
    """Sanity of a result reported as trustworthy (exit 0)."""
    case = r.case
    if case.argv[:1] != ("run",) and case.argv[:1] != ("demo",):
        return []                                # generate, list: no physical result
    s = r.summary
    if s is None:
        return [f"no summary JSON ({_json_path(case.argv)}) to check the result against"]
    bad = []
    if s.get("status") not in ("ok", "warnings") or s.get("exit_code") != 0:
        bad.append(f"exit 0 with summary status {s.get('status')!r}, exit_code {s.get('exit_code')!r}")
    if s.get("status") == "warnings" and not s.get("warnings"):
        bad.append("status 'warnings' without any warning listed")
    energy = s.get("energy")
    if energy is not None and not (isinstance(energy, (int, float)) and math.isfinite(energy) and energy >= -1e-9):
        bad.append(f"final energy {energy!r}")
    for name, u in (s.get("probes") or {}).items():
        if u is None or not all(isinstance(x, (int, float)) and math.isfinite(x) for x in u):
            bad.append(f"probe {name}: {u!r}")
        elif math.sqrt(sum(x * x for x in u)) > case.max_displacement:
            bad.append(f"probe {name}: |u| = {math.sqrt(sum(x * x for x in u)):.3g} m > {case.max_displacement} m")
    h = s.get("health") or {}
    if h.get("monitor", True):
        if h.get("inverted_final"):
            bad.append(f"{h['inverted_final']} inverted element(s) at the end")
        low = h.get("min_det_F_final")
        if low is not None and low <= 0:
            bad.append(f"min det F = {low} at the end")
    listed = _listed_frames(root)
    if listed:
        try:
            m = _read_frame(listed[-1])
            u = np.asarray(m.point_data["displacement"])
            if not np.all(np.isfinite(u)):
                bad.append(f"{listed[-1].name}: non-finite displacement")
            elif np.abs(u).max() > case.max_displacement * 1.75:     # |u| vector <= sqrt(3) max component
                bad.append(f"{listed[-1].name}: |u| up to {np.abs(u).max():.3g} m")
        except Exception as exc:                 # noqa: BLE001
            bad.append(f"{listed[-1].name} cannot be read: {exc}")
    return bad


# ============================================================================== the cases

RUN = ("run", "scene.toml", "--out", "out", "--json", "summary.json", "--quiet")
CASES: list = []


def add(family, name, expect, match="", scene=None, changes=None, argv=RUN, files=(), **kw) -> None:
    """One case; scene: full TOML text (default: the base scene with `changes`)."""
    text = scene if scene is not None else scene_text(changes)
    given = {rel for rel, _ in files}
    files = ((("scene.toml", text),) if "scene.toml" in argv and "scene.toml" not in given else ()) + tuple(files)
    CASES.append(Case(family, name, tuple(argv), expect, match, files=files, **kw))


def by_name(name: str) -> Case:
    return next(c for c in CASES if c.name == name)


# -------------------------------------------------------------------------- scene family


def _scene_cases() -> None:
    err = "error"
    add("scene", "baseline static bar", "ok")
    add("scene", "material as a single table", "ok",
        scene=scene_text().replace("[[material]]", "[material]"))
    add("scene", "same clamp given twice", "ok", changes={"fixed": [{"box": CLAMP}, {"box": CLAMP}]})
    # unknown keys and tables
    add("scene", "unknown top-level key", err, r"colour.*unknown", changes={"colour": "red"})
    add("scene", "misspelt table [solvr]", err, r"solvr.*unknown", changes={"solvr": {"steps": 3}})
    add("scene", "unknown solver key", err, r"solver\.tolerance.*unknown", changes={"solver.tolerance": 1e-6})
    add("scene", "unknown material key", err, r"material\[0\]\.young", changes={"material.0.young": 1e6})
    add("scene", "unknown mesh key", err, r"mesh\.resolution", changes={"mesh.resolution": 3})
    add("scene", "unknown output key", err, r"output\.format", changes={"output.format": "vtk"})
    # wrong types
    add("scene", "E as a string", err, r"material\[0\]\.E.*number", changes={"material.0.E": "1e8"})
    add("scene", "nu as a boolean", err, r"material\[0\]\.nu", changes={"material.0.nu": True})
    add("scene", "steps as a string", err, r"solver\.steps", changes={"solver.steps": "ten"})
    add("scene", "steps as true", err, r"solver\.steps", changes={"solver.steps": True})
    add("scene", "gravity as a string", err, r"loads\.gravity", changes={"loads.gravity": "down"})
    add("scene", "mesh as a string", err, r"mesh.*table", changes={"mesh": "bar.msh"})
    add("scene", "name as a number", err, r"name", changes={"name": 42})
    add("scene", "health_monitor as a string", err, r"solver\.health_monitor", changes={"solver.health_monitor": "yes"})
    # NaN, inf, negative and out-of-range numbers
    add("scene", "E = nan", err, r"material\[0\]\.E.*finite", changes={"material.0.E": math.nan})
    add("scene", "E = inf", err, r"material\[0\]\.E.*finite", changes={"material.0.E": math.inf})
    add("scene", "E negative", err, r"material\[0\]\.E", changes={"material.0.E": -1e8})
    add("scene", "E = 0", err, r"material\[0\]\.E", changes={"material.0.E": 0.0})
    add("scene", "nu = 0.5", err, r"material\[0\]\.nu", changes={"material.0.nu": 0.5})
    add("scene", "nu = 0.7", err, r"material\[0\]\.nu", changes={"material.0.nu": 0.7})
    add("scene", "nu = -1.5", err, r"material\[0\]\.nu", changes={"material.0.nu": -1.5})
    add("scene", "nu = nan", err, r"material\[0\]\.nu", changes={"material.0.nu": math.nan})
    add("scene", "density negative", err, r"material\[0\]\.density", changes={"material.0.density": -1000.0})
    add("scene", "density = inf", err, r"material\[0\]\.density", changes={"material.0.density": math.inf})
    add("scene", "density = 0 in a dynamic run", err, r"material\[0\]\.density",
        changes={"material.0.density": 0.0, "solver.kind": "implicit_euler"})
    add("scene", "law unknown", err, r"material\[0\]\.law.*rubber", changes={"material.0.law": "rubber"})
    add("scene", "quadrature unknown", err, r"gauss9", changes={"material.0.quadrature": "gauss9"})
    add("scene", "exact quadrature on hexahedra", err, r"quadrature.*exact.*not available",
        changes={"material.0.quadrature": "exact"})
    add("scene", "element unknown", err, r"mesh\.element.*octahedron", changes={"mesh.element": "octahedron"})
    add("scene", "cells zero", err, r"mesh\.cells", changes={"mesh.cells": [0, 1, 1]})
    add("scene", "cells negative", err, r"mesh\.cells", changes={"mesh.cells": [-3, 1, 1]})
    add("scene", "cells fractional", err, r"mesh\.cells", changes={"mesh.cells": [3.5, 1, 1]})
    add("scene", "cells with 2 entries in 3D", err, r"mesh\.(cells|size)", changes={"mesh.cells": [3, 1]})
    add("scene", "cells with 1000 entries", err, r"mesh\.cells", changes={"mesh.cells": [3] * 1000})
    add("scene", "cells 1000 x 1000 x 300", err, r"(?i)memory",
        changes={"mesh.cells": [1000, 1000, 300]}, why="item 5: 20.7 GB, killed by the kernel")
    add("scene", "size zero", err, r"mesh\.size", changes={"mesh.size": [1.0, 0.0, 0.1]})
    add("scene", "size nan", err, r"mesh\.size", changes={"mesh.size": [math.nan, 0.1, 0.1]})
    add("scene", "size 1e200", err, r"mesh\.size.*too large", changes={"mesh.size": [1e200, 0.1, 0.1]},
        why="item 9: 1e200 coordinates called degenerate cells")
    add("scene", "origin nan", err, r"mesh\.origin", changes={"mesh.origin": [math.nan, 0.0, 0.0]})
    add("scene", "origin 1e300", err, r"mesh\.origin.*too large", changes={"mesh.origin": [1e300, 0.0, 0.0]})
    add("scene", "no [mesh]", err, r"mesh: missing", changes={"mesh": DELETE})
    add("scene", "no [[material]]", err, r"material", changes={"material": DELETE})
    add("scene", "empty material array", err, r"material", changes={"material": []})
    add("scene", "empty [mesh] table", err, r"mesh", changes={"mesh": {}})
    add("scene", "generate and file both", err, r"mesh", changes={"mesh.file": "bar.vtu"})
    add("scene", "generate unknown", err, r"mesh\.generate.*torus", changes={"mesh.generate": "torus"})
    add("scene", "mesh file does not exist", err, r"(?i)not found.*nowhere\.vtu",
        changes={"mesh": {"file": "nowhere.vtu"}})
    add("scene", "mesh file is a folder", err, r"mesh", changes={"mesh": {"file": "meshes"}},
        files=(("meshes", {"folder": True}),))
    # solver
    add("scene", "solver kind unknown", err, r"solver\.kind.*rk4", changes={"solver.kind": "rk4"})
    add("scene", "dt = 0", err, r"solver\.dt", changes={"solver.kind": "implicit_euler", "solver.dt": 0.0})
    add("scene", "dt negative", err, r"solver\.dt", changes={"solver.kind": "implicit_euler", "solver.dt": -0.01})
    add("scene", "dt = nan", err, r"solver\.dt", changes={"solver.kind": "implicit_euler", "solver.dt": math.nan})
    add("scene", "steps = 1e12 (float)", err, r"solver\.steps.*(limit|<=)", changes={"solver.steps": 1e12},
        why="item 5: accepted")
    add("scene", "steps = 10**12 (integer)", err, r"solver\.steps.*<=", changes={"solver.steps": 10 ** 12})
    add("scene", "steps = 0", err, r"solver\.steps", changes={"solver.steps": 0})
    add("scene", "steps negative", err, r"solver\.steps", changes={"solver.steps": -5})
    add("scene", "linear solver unknown", err, r"solver\.linear.*magic", changes={"solver.linear": "magic"})
    add("scene", "backend unknown", err, r"solver\.backend.*fortran", changes={"solver.backend": "fortran"})
    add("scene", "rayleigh nan", err, r"solver\.rayleigh", changes={"solver.rayleigh": [math.nan, 0.0]})
    add("scene", "rayleigh negative", err, r"solver\.rayleigh", changes={"solver.rayleigh": [-1.0, 0.0]})
    add("scene", "newton tolerance negative", err, r"solver\.newton_tolerance",
        changes={"solver.newton_tolerance": -1e-8})
    add("scene", "newton iterations zero", err, r"solver\.newton_max_iterations",
        changes={"solver.newton_max_iterations": 0})
    add("scene", "max_energy_growth negative", err, r"solver\.max_energy_growth",
        changes={"solver.max_energy_growth": -1.0})
    add("scene", "on_inversion unknown", err, r"solver\.on_inversion", changes={"solver.on_inversion": "ignore"})
    # loads, fixed, probes
    add("scene", "gravity nan", err, r"loads\.gravity", changes={"loads.gravity": [0.0, 0.0, math.nan]})
    add("scene", "gravity with 2 components", err, r"loads\.gravity", changes={"loads.gravity": [0.0, -9.81]})
    add("scene", "gravity 1e160", err, r"double", changes={"loads.gravity": [0.0, 0.0, -1e160]},
        why="item 3: 0 Newton iterations, u = 0, exit 0")
    add("scene", "force 1e300", err, r"(?i)double|too large|overflow",
        changes={"loads.force": [{"box": [[0.99, -1, -1], [1.01, 1, 1]], "value": [0.0, 0.0, -1e300]}]})
    add("scene", "force box holds no node", err, r"loads\.force\[0\]\.box.*no mesh node",
        changes={"loads.force": [{"box": [[5.0, 5.0, 5.0], [6.0, 6.0, 6.0]], "value": [0.0, 0.0, -1.0]}]})
    add("scene", "traction nan", err, r"loads\.traction\[0\]\.value",
        changes={"loads.traction": [{"box": [[0.99, -1, -1], [1.01, 1, 1]], "value": [0.0, math.nan, 0.0]}]})
    add("scene", "fixed box with nan", err, r"fixed\[0\]\.box",
        changes={"fixed.0.box": [[math.nan, -1.0, -1.0], [1e-9, 1.0, 1.0]]},
        why="item 9: reported as 'no mesh node inside'")
    add("scene", "fixed box min > max", err, r"fixed\[0\]\.box.*min > max",
        changes={"fixed.0.box": [[1.0, -1.0, -1.0], [0.0, 1.0, 1.0]]})
    add("scene", "fixed box holds no node", err, r"fixed\[0\]\.box.*no mesh node",
        changes={"fixed.0.box": [[5.0, 5.0, 5.0], [6.0, 6.0, 6.0]]})
    add("scene", "fixed component 5", err, r"fixed\[0\]\.components", changes={"fixed.0.components": [5]})
    add("scene", "prescribed displacement 1e200", err, r"(?i)double|too large|overflow",
        changes={"fixed": [{"box": CLAMP}, {"box": [[0.99, -1, -1], [1.01, 1, 1]], "displacement": [0.0, 0.0, 1e200]}]})
    add("scene", "conflicting fixed entries", err, r"fixed\[1\].*fixed\[0\]",
        changes={"fixed": [{"box": CLAMP}, {"box": CLAMP, "displacement": [0.0, 0.0, 0.01]}]},
        why="item 9: resolved silently")
    add("scene", "no [[fixed]] in a static solve", err, r"(?i)fixed|rigid|constrain|singular",
        changes={"fixed": DELETE})
    add("scene", "probe 100 m outside", err, r"probe\[0\]\.point.*not on the body",
        changes={"probe.0.point": [101.0, 0.05, 0.05]}, why="item 9: nearest node reported silently")
    add("scene", "probe nan", err, r"probe\[0\]\.point", changes={"probe.0.point": [math.nan, 0.0, 0.0]})
    add("scene", "probe without a name (named by its index)", "ok", changes={"probe.0.name": DELETE})
    add("scene", "two probes with one name", err, r"probe\[1\]\.name",
        changes={"probe": [{"name": "tip", "point": [1.0, 0.05, 0.05]}, {"name": "tip", "point": [0.5, 0.05, 0.05]}]})
    add("scene", "unused material (region)", err, r"material\[1\].*no cell uses it",
        changes={"material": [{"law": "stvk", "quadrature": "gauss2", "E": 1e8, "nu": 0.3},
                              {"region": "tetra", "law": "hooke", "quadrature": "gauss1", "E": 1e8, "nu": 0.3}]},
        why="item 9: not reported")
    add("scene", "unused material (shadowed)", err, r"material\[1\].*no cell uses it",
        changes={"material": [{"law": "stvk", "quadrature": "gauss2", "E": 1e8, "nu": 0.3},
                              {"law": "hooke", "quadrature": "gauss2", "E": 1e8, "nu": 0.3}]})
    add("scene", "material box nan", err, r"material\[0\]\.box",
        changes={"material.0.box": [[math.nan, -1, -1], [2, 1, 1]]})
    # adaptation rules
    add("scene", "adapt criterion unknown", err, r"adapt\[0\]\.criterion",
        changes={"adapt": [{"criterion": "R_X", "threshold": 1.0, "law": "hooke"}]})
    add("scene", "adapt threshold nan", err, r"adapt\[0\]\.threshold",
        changes={"adapt": [{"criterion": "rotation", "threshold": math.nan, "law": "hooke"}]})
    add("scene", "adapt switch without law", err, r"adapt\[0\]\.law",
        changes={"adapt": [{"criterion": "rotation", "threshold": 5.0}]})
    add("scene", "adapt to an unknown law", err, r"adapt\[0\]\.law.*rubber",
        changes={"adapt": [{"criterion": "rotation", "threshold": 5.0, "law": "rubber"}]})
    add("scene", "adapt back above threshold", err, r"adapt\[0\]\.back",
        changes={"adapt": [{"criterion": "rotation", "threshold": 5.0, "law": "hooke", "back": 9.0}]})
    add("scene", "adapt refine on hexahedra", err, r"adapt\[0\]\.action.*refine",
        changes={"adapt": [{"criterion": "R_S", "threshold": 0.5, "action": "refine", "relative": True}]})
    add("scene", "adapt relative threshold 5", err, r"adapt\[0\]\.threshold",
        changes={"adapt": [{"criterion": "R_S", "threshold": 5.0, "law": "hooke", "relative": True}]})
    # output
    add("scene", "output every 0", err, r"output\.every", changes={"output.every": 0})
    add("scene", "output dir empty", err, r"output\.dir", changes={"output.dir": ""})
    # the file itself
    deep = "a = " + "[" * 100000 + "]" * 100000 + "\n"
    add("scene", "deeply nested TOML", err, r"nested too deeply", scene=deep, why="item 7: RecursionError traceback")
    add("scene", "binary garbage", err, r"scene\.toml",
        files=(("scene.toml", random.Random(10).randbytes(4096)),))
    add("scene", "empty file", err, r"mesh: missing", scene="")
    add("scene", "not UTF-8", err, r"scene\.toml",
        files=(("scene.toml", ("# caf\xe9\n" + scene_text()).encode("latin-1")),))
    add("scene", "NUL byte", err, r"invalid TOML", scene=scene_text() + "\x00\n")
    add("scene", "TOML syntax error", err, r"invalid TOML.*line", scene=scene_text().replace("steps = 2", "steps = [2"))
    add("scene", "duplicate key", err, r"invalid TOML", scene=scene_text().replace("steps = 2", "steps = 2\nsteps = 3"))
    add("scene", "scene is a folder", err, r"scenes\.toml.*(folder|directory)", argv=("run", "scenes.toml", "--quiet"),
        files=(("scenes.toml", {"folder": True}),))
    add("scene", "scene file missing", err, r"not found", argv=("run", "missing.toml", "--quiet"))
    add("scene", "max-memory 1K", err, r"(?i)memory", argv=RUN + ("--max-memory", "1K"))
    add("scene", "max-memory garbage", err, r"--max-memory", argv=RUN + ("--max-memory", "lots"))
    add("scene", "TENSORMASS_MAX_MEMORY negative", err, r"TENSORMASS_MAX_MEMORY",
        env=(("TENSORMASS_MAX_MEMORY", "-5"),))


# -------------------------------------------------------------------------- mesh family

HEX_MATERIAL = {"law": "stvk", "quadrature": "gauss2", "E": 1.0e8, "nu": 0.3, "density": 1000.0}
TET_MATERIAL = {"law": "stvk", "quadrature": "gauss1", "E": 1.0e8, "nu": 0.3, "density": 1000.0}
_MESH_NAMES = {"vtu": "bar.vtu", "gmsh22": "bar.msh", "vtk": "bar.vtk", "text": "bar.txt"}


def _mesh_case(name, expect, match="", shape="hex", fmt="vtu", damage=(), file_name=None, n=3,
               files=None, **kw) -> None:
    """The base scene on a mesh file (the same 1 m bar: clamp, probe and loads still apply)."""
    file_name = file_name or _MESH_NAMES[fmt]
    changes = {"mesh": {"file": file_name},
               "material": [dict(TET_MATERIAL if shape == "tet" else HEX_MATERIAL)]}
    changes.update(kw.pop("changes", {}))
    if files is None:
        files = ((file_name, mesh_file(shape, fmt, damage, n)),)
    add("mesh", name, expect, match, changes=changes, files=files, **kw)


def _mesh_cases() -> None:
    err = "error"
    # node ids of the 3-hexahedron bar: i + 4 j + 8 k for the corner (x = i/3, y = 0.1 j, z = 0.1 k)
    _mesh_case("good hexahedra (vtu)", "ok")
    _mesh_case("good hexahedra (legacy vtk)", "ok", fmt="vtk")
    _mesh_case("good tetrahedra (gmsh)", "ok", shape="tet", fmt="gmsh22")
    _mesh_case("tetrahedra with boundary triangles (mixed dimensions)", "ok", shape="tet",
               damage=(("add_block", "triangle", [[0, 1, 5], [0, 5, 4]]),))
    _mesh_case("node index out of range", err, r"bar\.vtu.*cell 1 .*node\(s\) 99", damage=(("cell", 0, 1, 2, 99),),
               why="item 7: IndexError traceback")
    _mesh_case("negative node index", err, r"bar\.vtu.*cell 1 .*-1", damage=(("cell", 0, 1, 2, -1),))
    _mesh_case("node index out of range (gmsh)", err, r"bar\.msh", shape="tet", fmt="gmsh22",
               damage=(("cell", 0, 4, 3, 500),))
    _mesh_case("NaN coordinate", err, r"(?i)non-finite|nan", damage=(("point", 3, [math.nan, 0.0, 0.0]),),
               why="item 9: reported as 'fixed[0].box: no mesh node inside'")
    _mesh_case("infinite coordinate", err, r"(?i)non-finite|inf", damage=(("point", 3, [math.inf, 0.0, 0.0]),))
    _mesh_case("coordinate 1e200", err, r"too large", damage=(("point", 3, [1e200, 0.0, 0.0]),),
               why="item 9: called degenerate cells")
    _mesh_case("whole mesh beyond 1e200", err, r"too large",
               damage=tuple(("point", i, [1e200 * (1 + i % 4), 1e199 * (i // 4 % 2), 1e199 * (i // 8)])
                            for i in range(16)))
    _mesh_case("inverted hexahedron", err, r"(?i)inverted",
               damage=(("swap", 0, 1, 0, 4), ("swap", 0, 1, 1, 5), ("swap", 0, 1, 2, 6), ("swap", 0, 1, 3, 7)))
    _mesh_case("inverted tetrahedron", err, r"(?i)inverted", shape="tet", damage=(("swap", 0, 7, 0, 1),))
    _mesh_case("flat hexahedron", err, r"(?i)flat|degenerate|inverted|volume",
               damage=(("point", 1, [0.0, 0.0, 0.0]), ("point", 5, [0.0, 0.1, 0.0]),
                       ("point", 9, [0.0, 0.0, 0.1]), ("point", 13, [0.0, 0.1, 0.1])))
    _mesh_case("repeated node in a cell", err, r"(?i)repeated node", damage=(("cell", 0, 0, 1, 0),))
    _mesh_case("cell given twice", err, r"(?i)overlap|more than two|duplicate", damage=(("copy_cell", 0, 1),))
    # a stray node carries no mass and no stiffness: the runtime pins it, the result is the bar's
    _mesh_case("node no cell uses", "ok", damage=(("add_point", [0.5, 0.5, 0.5]),))
    # the last hexahedron gets its own copies of the 4 nodes it shared: a loose piece
    _mesh_case("duplicate nodes cut the bar in two", err,
               r"(?i)duplicate|coincident|connected|free|rigid|constrain|singular|piece",
               damage=(("add_point", [2 / 3, 0.0, 0.0]), ("add_point", [2 / 3, 0.1, 0.0]),
                       ("add_point", [2 / 3, 0.0, 0.1]), ("add_point", [2 / 3, 0.1, 0.1]),
                       ("cell", 0, 2, 0, 16), ("cell", 0, 2, 3, 17), ("cell", 0, 2, 4, 18), ("cell", 0, 2, 7, 19)))
    # a tetrahedron glued on half of the x = 0 quad face of hexahedron 0
    _mesh_case("non-conforming: tetrahedron on half a hexahedron face", err, r"(?i)conform",
               damage=(("add_point", [-1 / 3, 0.05, 0.05]), ("add_block", "tetra", [[4, 0, 12, 16]])))
    _mesh_case("unsupported cell type", err, r"(?i)unsupported|unknown",
               damage=(("add_block", "hexahedron20", [list(range(16)) + [0, 1, 2, 3]]),))
    _mesh_case("only line cells", err, r"no 2D or 3D cells", shape="points", damage=(("add_block", "line", [[0, 1]]),))
    _mesh_case("empty mesh", err, r"(?i)no 2D or 3D cells|no cells|empty|could not read mesh bar\.vtu", shape="empty")
    _mesh_case("surface triangles in 3D", err, r"(?i)surface|nonzero z", shape="points",
               damage=(("add_block", "triangle", [[0, 1, 9], [0, 9, 8]]),))
    _mesh_case("2D mesh in a 3D scene", err, r"loads\.gravity.*2", shape="quad")
    _mesh_case("truncated file", err, r"could not read mesh", damage=(("truncate", 0.5),))
    _mesh_case("truncated gmsh file", err, r"broken \.msh file: \$Elements", shape="tet", fmt="gmsh22", damage=(("truncate", 0.6),))
    _mesh_case("unknown extension", err, r"could not read mesh", fmt="text")
    _mesh_case("garbage named .vtu", err, r"could not read mesh", files=(("bar.vtu", random.Random(3).randbytes(2000)),))
    _mesh_case("non-integer tags", err, r"(?i)tag", damage=(("tags", "cell_tags", [[0.5, 1.5, 2.5]]),))
    _mesh_case("mesh path is /dev/null", err, r"mesh", file_name="/dev/null", files=())


# -------------------------------------------------------------------------- run family

# The 1 m bar (issue items 1, 2, 4): 6 hexahedra, clamped at x = 0, implicit Euler.
RUN_BAR = {"mesh.cells": [6, 1, 1], "solver.kind": "implicit_euler", "solver.dt": 0.01, "solver.steps": 10}
# The stable explicit step of the 6-hexahedron Hooke bar below, E = 1e6 (stable_time_step: 2.2756e-3 s).
STABLE_DT = 2.2756e-3


def _run_case(name, expect, match="", changes=None, **kw) -> None:
    add("run", name, expect, match, changes={**RUN_BAR, **(changes or {})}, **kw)


def _run_cases() -> None:
    soft = {"material.0.E": 1e3, "loads.gravity": [0.0, 0.0, -9810.0], "solver.steps": 100}
    for law in ("stvk", "stable_neohookean", "hooke"):
        _run_case(f"soft {law} bar under 1000 g", "untrusted", r"run (diverged|invalid)",
                  {**soft, "material.0.law": law}, why="item 1: energy 1e12-1e22 J, exit 0")
    _run_case("soft neohookean bar under 1000 g", "untrusted", r"run (diverged|invalid|failed)",
              {**soft, "material.0.law": "neohookean"})
    _run_case("soft tetra10 stable_neohookean bar under 1000 g", "untrusted", r"run (diverged|invalid)",
              {**soft, "mesh.element": "tetra10", "mesh.cells": [4, 1, 1], "material.0.law": "stable_neohookean",
               "material.0.nu": 0.45}, why="item 1: the soft organ, 0.26 J -> 2.5e21 J, exit 0")
    _run_case("explicit at 2x the stable step", "untrusted", r"run diverged",
              {"material.0.law": "hooke", "material.0.E": 1e6, "solver.kind": "explicit", "solver.dt": 2 * STABLE_DT,
               "solver.steps": 400}, why="item 4: frames of |u| = 90 m written unmarked")
    _run_case("explicit at 2x the stable step, displacement limit off", "untrusted", r"run diverged",
              {"material.0.law": "hooke", "material.0.E": 1e6, "solver.kind": "explicit",
               "solver.dt": 2.5 * STABLE_DT, "solver.steps": 400, "solver.max_displacement": 1e9})
    _run_case("static Hooke under an absurd load", "untrusted", r"run diverged.*body size",
              {"material.0.law": "hooke", "material.0.E": 1e3, "solver.kind": "static", "solver.steps": 1},
              why="item 2: 326 km tip on a 1 m bar, exit 0")
    _run_case("inverted final state", "untrusted", r"run invalid.*inverted",
              {"material.0.E": 1e3, "loads.gravity": [0.0, 0.0, -98.1], "solver.steps": 100},
              why="item 2: 23 of 40 cells inverted, exit 0")
    _run_case("on_inversion = stop", "untrusted", r"run diverged.*on_inversion",
              {"material.0.E": 1e3, "loads.gravity": [0.0, 0.0, -98.1], "solver.steps": 100,
               "solver.on_inversion": "stop"})
    _run_case("good implicit Euler run", "ok")
    _run_case("good backward Euler run", "ok", changes={"solver.kind": "backward_euler"})
    _run_case("good static Hooke run", "ok", changes={"material.0.law": "hooke", "solver.kind": "static",
                                                      "solver.steps": 1})
    _run_case("good explicit run at half the stable step", "ok", changes={"material.0.law": "hooke", "material.0.E": 1e6, "solver.kind": "explicit",
               "solver.dt": 0.5 * STABLE_DT, "solver.steps": 40})
    _run_case("good mixed-element bar", "ok", changes={"mesh.element": "mixed", "mesh.cells": [4, 1, 1],
                                                       "material.0.quadrature": "gauss2"})
    add("run", "good 2D quad beam", "ok", changes={
        "mesh": {"generate": "bar", "size": [1.0, 0.1], "cells": [6, 1], "element": "quad"},
        "fixed": [{"box": [[-1e-9, -1.0], [1e-9, 1.0]]}], "loads": {"gravity": [0.0, -9.81]},
        "probe": [{"name": "tip", "point": [1.0, 0.05]}]})
    _run_case("health monitor off", "warning", changes={"solver.health_monitor": False})
    _run_case("monitor off on an explicit run", "warning", changes={"material.0.law": "hooke", "material.0.E": 1e6, "solver.kind": "explicit",
               "solver.dt": 0.5 * STABLE_DT, "solver.steps": 20, "solver.health_monitor": False})
    # a soft stable neo-Hookean cube on a clamped base dropped under 10 g: the first swing
    # overshoots and inverts the bottom cells (steps ~33-46), the cube settles 0.42 m lower with
    # none inverted. The same with linear = direct, cg or auto; 9.2 g never inverts and 10.2 g
    # settles inverted (then "invalid"), so the load sits in the middle of the recovering band.
    _run_case("recovered inversion", "warning", changes={
        "mesh.size": [1.0, 1.0, 1.0], "mesh.cells": [2, 2, 2], "material.0.law": "stable_neohookean",
        "material.0.E": 1e5, "fixed.0.box": [[-1, -1, -1e-9], [2, 2, 1e-9]], "probe.0.point": [0.5, 0.5, 1.0],
        "loads.gravity": [0.0, 0.0, -97.0], "solver.dt": 0.005, "solver.steps": 300, "output.every": 10},
        max_displacement=1.0)
    # the demo bar is 8 m long and bends 0.52 m under its own weight
    add("run", "demo", "ok", argv=("demo", "--out", "demo", "--json", "demo.json"), max_displacement=1.0)


# -------------------------------------------------------------------------- interrupt family

# Many cheap steps, a frame each: Ctrl-C lands while the run steps and writes.
LONG_RUN = {"solver.kind": "implicit_euler", "solver.dt": 1e-4, "solver.steps": 50000}


def _interrupt_cases() -> None:
    ctrl_c = r"interrupted"
    add("interrupt", "Ctrl-C while stepping (implicit)", "interrupted", ctrl_c, changes=LONG_RUN,
        hooks=(("interrupt_when", "out/frame_000003.vtu"),), min_frames=3, why="item 7: traceback, exit 1")
    add("interrupt", "Ctrl-C while stepping, no --json", "interrupted", ctrl_c, changes=LONG_RUN,
        argv=("run", "scene.toml", "--out", "out", "--quiet"),
        hooks=(("interrupt_when", "out/frame_000003.vtu"),), min_frames=3)
    add("interrupt", "Ctrl-C while stepping (explicit)", "interrupted", ctrl_c,
        changes={"material.0.law": "hooke", "material.0.E": 1e6, "mesh.cells": [6, 1, 1], "solver.kind": "explicit",
                 "solver.dt": 0.5 * STABLE_DT, "solver.steps": 2000000, "output.every": 100},
        hooks=(("interrupt_when", "out/frame_000300.vtu"),), min_frames=3)
    add("interrupt", "Ctrl-C between static load steps", "interrupted", ctrl_c,
        changes={"solver.steps": 50000}, hooks=(("interrupt_when", "out/frame_000003.vtu"),), min_frames=3)
    add("interrupt", "Ctrl-C with progress bar and summary on", "interrupted", ctrl_c, changes=LONG_RUN,
        argv=("run", "scene.toml", "--out", "out", "--json", "summary.json"),
        hooks=(("interrupt_when", "out/frame_000003.vtu"),), min_frames=3)
    add("interrupt", "Ctrl-C while a frame is written", "interrupted", ctrl_c, changes=LONG_RUN,
        hooks=(("interrupt_at", "meshio:write", 5, True),), min_frames=4)
    add("interrupt", "Ctrl-C while the .pvd is appended", "interrupted", ctrl_c, changes=LONG_RUN,
        hooks=(("interrupt_at", "os:pwrite", 4, True),), min_frames=4)
    add("interrupt", "Ctrl-C twice (again while stopping)", "interrupted", ctrl_c, changes=LONG_RUN,
        hooks=(("interrupt_when", "out/frame_000003.vtu"),
               ("interrupt_at", "tensormass.runtime.run.output:Writer.mark_stopped", 1)), min_frames=3)
    add("interrupt", "Ctrl-C while reading the scene", "interrupted", ctrl_c,
        hooks=(("interrupt_at", "tensormass.runtime.scene.scene:Scene.from_toml", 1),))
    # file_cache.load reads the file's bytes first, whether or not an earlier case left its mesh cached
    _mesh_case("Ctrl-C while reading the mesh file", "interrupted", ctrl_c,
               hooks=(("interrupt_at", "tensormass.runtime.mesh.file_cache:load", 1),))
    CASES[-1] = Case(**{**CASES[-1].__dict__, "family": "interrupt"})
    add("interrupt", "Ctrl-C while loading kernels", "interrupted", ctrl_c, clear_kernels=True,
        hooks=(("interrupt_at", "tensormass.runtime.kernels.kernels:load_kernel", 1),))
    add("interrupt", "Ctrl-C while the summary is written", "interrupted", ctrl_c,
        hooks=(("interrupt_at", "tensormass.runtime.run.output:write_json_atomic", 1),))
    add("interrupt", "Ctrl-C while compiling a C kernel", "interrupted", ctrl_c, changes=C_SCENE,
        env=(("TENSORMASS_CACHE", "{tmp}/cache"),), clear_kernels=True,
        hooks=(("interrupt_at", "tensormass.backends.c.loader:_run_measured", 1),))


# -------------------------------------------------------------------------- cache family

# The cheapest C kernel to compile (tetra, Hooke, one point): each case compiles into its own cache.
C_SCENE = {"mesh.element": "tetra", "mesh.cells": [2, 1, 1], "material.0.law": "hooke",
           "material.0.quadrature": "gauss1", "solver.steps": 1, "solver.backend": "c"}
NUMBA_SCENE = {**C_SCENE, "solver.backend": "numba"}


def _generator_version() -> str:
    from tensormass.generator import GENERATOR_VERSION
    return GENERATOR_VERSION


# The cache cases are about the cache, not the kernel's speed: gcc -O0 builds the kernel in a third
# of the time of the default -O3 (the flags are part of the library's name, so nothing is shared
# with libraries built with the defaults).
CACHE_CFLAGS = "-O0 -march=native -std=c99 -fno-math-errno"


def _cache_case(name, expect, match="", backend="c", cache="{tmp}/cache", **kw) -> None:
    env = (("TENSORMASS_CACHE", cache),) + ((("TENSORMASS_CFLAGS", CACHE_CFLAGS),) if backend == "c" else ())
    env += tuple(kw.pop("env", ()))
    add("cache", name, expect, match, changes=C_SCENE if backend == "c" else NUMBA_SCENE, env=env,
        clear_kernels=True, scratch=("cache", "cache/**"), **kw)


def _cache_cases() -> None:
    err = "error"
    ro = (("readonly", "cache"),)
    bad_cache = r"TENSORMASS_CACHE.*cache"
    _cache_case("numba, cache read-only", "ok", backend="numba", files=(("cache", {"folder": True}),), hooks=ro)
    _cache_case("C, cache read-only", err, bad_cache, files=(("cache", {"folder": True}),), hooks=ro,
                why="item 7: PermissionError traceback")
    _cache_case("numba, cache is a file", "ok", backend="numba", files=(("cache", "not a folder"),))
    _cache_case("C, cache is a file", err, bad_cache, files=(("cache", "not a folder"),),
                why="item 7: NotADirectoryError traceback")
    _cache_case("numba, cache inside a file", "ok", backend="numba", cache="{tmp}/cache/sub",
                files=(("cache", "not a folder"),))
    _cache_case("C, cache inside a file", err, bad_cache, cache="{tmp}/cache/sub", files=(("cache", "not a folder"),))
    _cache_case("C, its subfolder is a file", err, r"cache.*not a folder",
                files=((f"cache/{_generator_version()}/c", "not a folder"),))
    _cache_case("C, fresh cache", "ok")
    _cache_case("C, relative cache path", "ok", cache="rel/cache", ignore=("rel/**",))
    # The library an earlier run compiled into cache/, copied from the session's cache (see _seed):
    # only a rebuild the case itself needs compiles.
    copied = (("seed", ("tetra", "hooke", "gauss1"), "cache"),)
    for how, what in (("garbage", "library overwritten with garbage"), ("truncate", "library truncated"),
                      ("remove", "library removed")):
        _cache_case(f"C, {what}", "ok", damage=copied + (("corrupt", "cache/*/c/*.so", how),),
                    may_change=("cache/**", "out/**", "summary.json", "summary.csv"))
    _cache_case("C, hash sidecar removed", "ok", damage=copied + (("corrupt", "cache/*/c/*.so.sha256", "remove"),),
                may_change=("cache/**", "out/**", "summary.json", "summary.csv"))
    _cache_case("C, hash sidecar garbage", "ok", damage=copied + (("corrupt", "cache/*/c/*.so.sha256", "text"),),
                may_change=("cache/**", "out/**", "summary.json", "summary.csv"))
    _cache_case("C, compiled library in a read-only cache", "ok", damage=copied, hooks=ro,
                may_change=("out/**", "summary.json", "summary.csv"))
    _cache_case("C, stale temporary file of a crashed compile", "ok", files=(("cache/x/c/.lib.so.tmp", b"\x7fELF"),))
    _cache_case("C, no compiler", err, r"no C compiler", env=(("CC", "/nonexistent/cc"),))
    # the compiler's own output follows the one-line message: what the user needs to fix it
    _cache_case("C, compiler that fails", err, r"compiling C kernel .* failed", env=(("CC", "false"),), detail=True)


# -------------------------------------------------------------------------- output family

_DONE = (RUN,)                       # an earlier run of the same scene: out/ with frames, summary.json


def _output_cases() -> None:
    err = "error"
    ours = ("run", "scene.toml", "--out", "out", "--quiet")
    add("output", "--json onto the scene file", err, r"--json scene\.toml.*scene file",
        argv=ours + ("--json", "scene.toml"), why="item 6: the scene replaced")
    add("output", "--json onto a frame", err, r"--json .*frame_000001\.vtu.*output files",
        argv=ours + ("--json", "out/frame_000001.vtu"), before=(ours,), why="item 6: a frame replaced")
    add("output", "--json onto the .pvd", err, r"--json .*frame\.pvd.*output files",
        argv=ours + ("--json", "out/frame.pvd"), before=(ours,), why="item 6: the .pvd replaced")
    add("output", "--json onto the .pvd to be", err, r"--json .*frame\.pvd", argv=ours + ("--json", "out/frame.pvd"))
    add("output", "--json onto /dev/null", err, r"--json /dev/null", argv=ours + ("--json", "/dev/null"),
        why="item 6: a device node replaced (as root)")
    add("output", "--json onto a folder", err, r"--json .*folder", argv=ours + ("--json", "docs"),
        files=(("docs", {"folder": True}),))
    add("output", "--json into a missing folder", err, r"--json .*does not exist", argv=ours + ("--json", "no/s.json"))
    add("output", "--json into a read-only folder", err, r"--json .*locked.*Permission denied",
        argv=ours + ("--json", "locked/s.json"), files=(("locked", {"folder": True}),), hooks=(("readonly", "locked"),),
        why="item 7: traceback after all frames were written")
    add("output", "--json onto someone's notes", err, r"--json notes\.txt.*not a tensormass summary",
        argv=ours + ("--json", "notes.txt"), files=(("notes.txt", "my notes\n"),))
    add("output", "--json onto someone's JSON", err, r"--json data\.json.*not a tensormass summary",
        argv=ours + ("--json", "data.json"), files=(("data.json", '{"format": "mine", "a": 1}\n'),))
    add("output", "--json onto the mesh file", err, r"--json bar\.vtu", argv=ours + ("--json", "bar.vtu"),
        changes={"mesh": {"file": "bar.vtu"}}, files=(("bar.vtu", mesh_file()),))
    add("output", "--json onto a symlink", err, r"symbolic link", argv=ours + ("--json", "link.json"),
        files=(("notes.txt", "my notes\n"), ("link.json", {"symlink": "notes.txt"})))
    add("output", "--json onto a fifo", err, r"not a regular file", argv=ours + ("--json", "pipe"),
        files=(("pipe", {"fifo": True}),))
    add("output", "--json onto an earlier summary", "ok", before=_DONE, may_change=("summary.json", "summary.csv", "out/**"))
    add("output", "--out onto a file", err, r"out.*not a folder", files=(("out", "a file\n"),))
    add("output", "--out onto /dev/null", err, r"/dev/null", argv=("run", "scene.toml", "--out", "/dev/null", "--quiet"))
    add("output", "--out into a read-only folder", err, r"locked.*Permission denied",
        argv=("run", "scene.toml", "--out", "locked/out", "--quiet"), files=(("locked", {"folder": True}),),
        hooks=(("readonly", "locked"),))
    add("output", "[output] dir is a file", err, r"frames.*not a folder", argv=("run", "scene.toml", "--quiet"),
        changes={"output.dir": "frames"}, files=(("frames", "a file\n"),))
    add("output", "someone's frame in --out", err, r"frame_000001\.vtu.*--overwrite",
        files=(("out/frame_000001.vtu", "<mine/>\n"),))
    add("output", "someone's .pvd in --out", err, r"frame\.pvd.*--overwrite", files=(("out/frame.pvd", "<mine/>\n"),))
    add("output", "someone's frame in --out, --overwrite", "ok", argv=RUN + ("--overwrite",),
        files=(("out/frame_000001.vtu", "<mine/>\n"),), may_change=("out/frame_000001.vtu",))
    add("output", "someone's frame_1.vtu in --out", err, r"frame_1\.vtu.*--overwrite",
        files=(("out/frame_1.vtu", "<mine/>\n"),))
    add("output", "unrelated files in --out", "ok",
        files=(("out/notes.txt", "kept\n"), ("out/frame-old.vtu", "<x/>\n"), ("out/other.pvd", "<x/>\n")))
    add("output", "rerun with fewer steps", "ok", before=(("run", "long.toml", "--out", "out", "--quiet"),),
        files=(("long.toml", scene_text({"solver.steps": 6})),), may_change=("out/**",),
        why="item 9: frames of the longer run left next to the new ones")
    add("output", "rerun after an interrupted run's leftovers", "ok", before=(ours,),
        damage=(("write", "out/.frame_000002.vtu.tmp", "<VTKFile"),), may_change=("out/**",))
    add("output", "generate --out onto a file", err, r"--out kernels.*not a folder",
        argv=("generate", "--element", "tetra", "--law", "hooke", "--quadrature", "gauss1", "--backend", "numba",
              "--no-compile", "--out", "kernels"), files=(("kernels", "mine\n"),), why="item 7: traceback")
    add("output", "generate --out into a read-only folder", err, r"locked.*Permission denied",
        argv=("generate", "--element", "tetra", "--law", "hooke", "--quadrature", "gauss1", "--backend", "numba",
              "--no-compile", "--out", "locked/k"), files=(("locked", {"folder": True}),), hooks=(("readonly", "locked"),))
    add("output", "demo --out onto a file", err, r"demo.*not a folder", argv=("demo", "--out", "demo"),
        files=(("demo", "a file\n"),))
    # issue #29 item 6, data loss: the history beside --json, a folder another run writes, batch --out
    add("output", "--json s.csv (its own history)", err, r"--json s\.csv.*same name with \.csv",
        argv=ours + ("--json", "s.csv"), why="#29: the history written over the summary")
    add("output", "--json onto the picture", err, r"--json out/von_mises\.png.*written over",
        argv=ours + ("--picture", "--json", "out/von_mises.png"), files=(("out", {"folder": True}),))
    add("output", "a folder another run is writing", err, r"output folder out: another tensormass run \(pid 1 on ",
        files=(("out/.tensormass.lock", "pid=1 host=another-machine start=?\n"),),
        why="#29: two runs into one folder, the .pvd listing frames twice")
    batch = ("batch", "scene.toml", "--vary", "material.0.E=1e6,2e6", "--workers", "1", "--quiet")
    add("output", "batch --out onto the scene", err, r"--out scene\.toml.*input scene file",
        argv=batch + ("--out", "scene.toml"), why="#29: the scene overwritten by the table")
    add("output", "batch --out onto someone's CSV", err, r"--out data\.csv.*not a table of tensormass batch",
        argv=batch + ("--out", "data.csv"), files=(("data.csv", "x,y\n1,2\n"),), why="#29: a user's CSV replaced")
    add("output", "batch --out onto a folder", err, r"--out docs.*is a folder", argv=batch + ("--out", "docs"),
        files=(("docs", {"folder": True}),), why="#29: the whole study ran, then its results were lost")
    add("output", "batch --out into a missing folder", err, r"--out no/t\.csv.*does not exist",
        argv=batch + ("--out", "no/t.csv"))
    add("output", "batch --out .parquet", err, r"--out t\.parquet.*CSV", argv=batch + ("--out", "t.parquet"))
    add("output", "batch --out into a read-only folder", err, r"--out locked/t\.csv.*Permission denied",
        argv=batch + ("--out", "locked/t.csv"), files=(("locked", {"folder": True}),), hooks=(("readonly", "locked"),))
    add("output", "batch --out onto an earlier table", "ok", argv=batch + ("--out", "t.csv"),
        before=(batch + ("--out", "t.csv"),), may_change=("t.csv",))
    full = ("fail", "meshio:write", 3, "ENOSPC", True)
    add("output", "disk full at the third frame", err, r"frame_000002\.vtu.*No space left", hooks=(full,),
        wrote_before_error=True, why="item 7: traceback")
    add("output", "disk full while appending to the .pvd", err, r"frame\.pvd.*No space left",
        hooks=(("fail", "os:pwrite", 1, "ENOSPC", True),), wrote_before_error=True)
    add("output", "disk full while writing the summary", err, r"summary.*No space left",
        hooks=(("fail", "tensormass.runtime.base.files:write_text_atomic", 1, "ENOSPC"),), wrote_before_error=True)
    add("output", "permission lost while writing frames", err, r"frame_000001\.vtu.*Permission denied",
        hooks=(("fail", "meshio:write", 2, "EACCES", True),), wrote_before_error=True)


for _family in (_scene_cases, _mesh_cases, _run_cases, _cache_cases, _interrupt_cases, _output_cases):
    _family()
_names = [c.name for c in CASES]
assert len(_names) == len(set(_names)), sorted({n for n in _names if _names.count(n) > 1})
