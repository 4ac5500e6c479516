"""`tensormass batch`: studies at scale, scene files x parameter variations as independent tasks.

    tensormass batch a.toml b.toml --vary material.0.E=1e6,1e7 --vary mesh.cells=[4,1,1],[8,2,2] \\
        [--workers N] [--scheduler tcp://host:8786] [--out table.csv]

Every scene file x every combination of the --vary values (a cartesian product, in the order
given) is one task: the scene's TOML is read, the variation written into the parsed dict
(dotted keys, list indices as numbers: ``material.0.E``) before validation, so a bad key or
value gives the scene parser's own SceneError naming it; the scene runs without writing any
output and the task returns one flat row (``run_task``). Rows come back in task order (never
completion order), so a table does not depend on the workers; a run is bit-identical in any
process (the runtime's assembly does not depend on threads), and floats are written with
repr() so that the table shows it.

The tasks run through ``map_tasks``: in this process one after the other (``--workers 1`` and
no scheduler: dask is not needed), or on dask.distributed, a LocalCluster of N single-threaded
worker processes (BLAS / OpenMP / numba at one thread each: set in the workers' environment
before they start, and again by every task) or an existing cluster (``--scheduler``). The
reports (apps/reports accuracy and stability) map their sweep cases through the same function.

Before the study: the table's path is checked (``check_table_path``: not a folder, not an input
scene, not a file that tensormass batch did not write, in a folder that can be written; the
same rules as ``run --json``), every task's resources are estimated (runtime.scene.resources) and the
study's cost printed (tasks, peak memory and stepping time per task, in all), and the local
workers are capped at the number of tasks and at what the memory allows (each worker gets the
largest task's estimate x MEMORY_MARGIN): a message says so when they are.

During the study each finished row is appended to ``<out>.partial`` (JSON lines: a header line
with the format, then one row per line in the order the tasks finished, flushed per row), so a
study that is interrupted or dies keeps what it computed. At the end the table is written in task
order to a temporary name and renamed into place, and the partial file removed. Ctrl-C stops the
study: exit 130 with one line naming the partial file (no worker traceback: the workers start
with SIGINT blocked, so only this process sees it, and the cluster is closed, client first, with
its logging silenced and a second Ctrl-C held until it is down).

Kernel caches: the first task of a process that needs a kernel loads (generates, compiles,
numba-compiles) it under a file lock per kernel in the cache folder (``kernel_locks``), so
concurrent workers generate and compile a kernel once and the others wait, then load it.
"""
from __future__ import annotations

import contextlib
import hashlib
import itertools
import json
import os
import signal
import sys
import threading
import time
import tomllib
from pathlib import Path

from ..runtime.base.errors import (EXIT_BAD_INPUT, EXIT_INTERNAL, EXIT_INTERRUPTED, EXIT_OK, RunInterrupted,
    RunStopped, SceneError, TensormassError)
from .batch_table import PARTIAL_FORMAT, PartialRows, check_table_path, is_batch_table, partial_path, write_table
from ..runtime.base.cache import cache_dir
from .commands import ProgressBar

# The scene, the resource estimate and the simulation stack are imported inside the functions that
# read, estimate or run a scene: `tensormass batch --help` imports this module in 0.17 s and skips
# 0.86 s of them (scene 0.22 s, resources 0.10 s, base.parallel with numba 0.32 s, model and
# simulation with scipy.sparse and pyamg 0.94 s, overlapping; python -X importtime, 2 shared cores).

__all__ = ["parse_vary", "split_values", "apply_override", "plan_tasks", "run_task", "map_tasks",
           "run_batch", "write_table", "add_batch_command", "THREAD_ENV", "TIMING_COLUMNS", "DASK_MISSING",
           "kernel_locks", "worker_environment", "check_table_path", "is_batch_table", "partial_path",
           "plan_workers", "study_cost", "PARTIAL_FORMAT"]

# One thread per worker for every pool a task may start (set before numpy / numba are imported).
THREAD_ENV = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
              "NUMBA_NUM_THREADS": "1", "TENSORMASS_THREADS": "1"}
# Columns that measure time: they differ between two runs of the same study (tests skip them).
TIMING_COLUMNS = ("wall_time", "time_total")
DASK_MISSING = ('dask.distributed is not installed: --workers above 1 and --scheduler need it; '
                'install it with: pip install "tensormass[distributed]" (or run with --workers 1)')
MEMORY_MARGIN = 1.5          # a worker's memory limit: this x the largest task's estimate ...
MEMORY_FLOOR = 1 << 30       # ... and no less than this (the dask worker itself, imports, a spread)
# The workers' own logs (distributed's warnings, and its errors while a cluster shuts down) are
# not the study's output: what a task did comes back in its row. Set before they start.
WORKER_QUIET_ENV = {"DASK_LOGGING__DISTRIBUTED": "error"}
HEALTH_KEYS = ("min_det_F", "min_det_F_final", "inverted_final", "max_relative_displacement",
               "max_energy_growth", "energy_scale")


# ============================================================================== variations


def split_values(text: str) -> list:
    """'1,2,[3,4]' -> ['1', '2', '[3,4]']: commas inside brackets, braces or quotes do not split."""
    parts, depth, quote, start = [], 0, None, 0
    for i, ch in enumerate(text):
        if quote:
            quote = None if ch == quote else quote
        elif ch in "\"'":
            quote = ch
        elif ch in "[{":
            depth += 1
        elif ch in "]}":
            depth -= 1
            if depth < 0:
                raise ValueError(f"unbalanced ']' or '}}' in {text!r}")
        elif ch == "," and depth == 0:
            parts.append(text[start:i])
            start = i + 1
    if depth or quote:
        raise ValueError(f"unclosed bracket or quote in {text!r}")
    parts.append(text[start:])
    return [p.strip() for p in parts]


def parse_value(text: str):
    """A value as TOML reads it (1e6, [8, 2, 2], true, "x"); a bare word is a string (hooke)."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        if any(ch in text for ch in "[]{}\"'=") or not text:
            raise ValueError(f"cannot read {text!r} as a TOML value") from None
        return text


def parse_vary(items) -> list:
    """['material.0.E=1e6,1e7', ...] -> [('material.0.E', [1000000.0, 10000000.0]), ...]; errors name the item."""
    out, seen = [], set()
    for item in items or ():
        key, sep, values = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise TensormassError(f"--vary {item!r}: expected KEY=V1,V2,... (e.g. material.0.E=1e6,1e7)")
        if any(not part for part in key.split(".")):
            raise TensormassError(f"--vary {item!r}: key {key!r} has an empty part")
        if key in seen:
            raise TensormassError(f"--vary {key}: given twice")
        seen.add(key)
        try:
            parsed = [parse_value(v) for v in split_values(values)]
        except ValueError as exc:
            raise TensormassError(f"--vary {key}: {exc}") from None
        out.append((key, parsed))
    return out


def apply_override(data: dict, key: str, value) -> None:
    """Write value at a dotted key of a parsed scene (list indices as numbers); a missing table on
    the way is created (the scene parser then judges the key), a path that cannot exist is refused."""
    parts = key.split(".")
    node = data
    for depth, part in enumerate(parts):
        last = depth == len(parts) - 1
        where = ".".join(parts[:depth]) or "the scene"
        if isinstance(node, list):
            if not part.isdigit():
                raise SceneError(f"--vary {key}: {where} is a list ([[{where}]] entries); index it with a number")
            index = int(part)
            if index >= len(node):
                raise SceneError(f"--vary {key}: {where} has {len(node)} entr{'y' if len(node) == 1 else 'ies'} "
                                 f"(indices from 0)")
            if last:
                node[index] = value
            else:
                node = node[index]
        elif isinstance(node, dict):
            if last:
                node[part] = value
            else:
                node = node.setdefault(part, {})
        else:
            raise SceneError(f"--vary {key}: {where} is a value ({node!r}), not a table or a list")


def plan_tasks(scenes, vary) -> list:
    """Every scene x the cartesian product of the variations: [{'task', 'scene', 'values'}], in order."""
    keys = [k for k, _ in vary]
    combos = list(itertools.product(*[v for _, v in vary])) if vary else [()]
    return [{"task": i, "scene": str(s), "values": dict(zip(keys, combo))}
            for i, (s, combo) in enumerate(itertools.product(scenes, combos))]


def load_scene(path, values, load_mesh=True, max_memory=None):
    """The scene of one task: the file's TOML with the variation written in, validated."""
    from ..runtime.scene.scene import Scene, read_scene_file
    path = Path(path)
    text = read_scene_file(path)
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SceneError(f"{path}: invalid TOML: {exc}") from None
    for key, value in values.items():
        apply_override(data, key, _copy(value))
    data.setdefault("name", path.stem)
    scene = Scene.from_dict(data, base_dir=path.parent, load_mesh=load_mesh, max_memory=max_memory)
    scene.source = str(path)
    return scene


def _copy(value):
    return json.loads(json.dumps(value)) if isinstance(value, (list, dict)) else value


# ============================================================================== one task


_WARMED: set = set()      # kernel keys this process has loaded (and compiled) already


def _lock_folder() -> Path | None:
    folder = cache_dir() / "locks"
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError:
        return None
    return folder


@contextlib.contextmanager
def kernel_locks(keys):
    """Hold an exclusive file lock per kernel key (sorted: no two processes wait on each other in a
    cycle) in <cache>/locks: the holder generates / compiles, the others wait and then load it
    from the cache. Without fcntl or a writable cache, no lock (the caches are still atomic)."""
    try:
        import fcntl
    except ImportError:            # not POSIX
        yield
        return
    folder = _lock_folder()
    if folder is None:
        yield
        return
    with contextlib.ExitStack() as stack:
        for key in sorted(set(keys), key=repr):
            name = hashlib.sha256(repr(key).encode()).hexdigest()[:20] + ".lock"
            handle = stack.enter_context(open(folder / name, "a+b"))
            fcntl.flock(handle.fileno(), fcntl.LOCK_EX)
            stack.callback(fcntl.flock, handle.fileno(), fcntl.LOCK_UN)
        yield


def _simulation(scene):
    """Simulation(scene, output=False) with its kernels loaded and compiled: under the kernels'
    locks the first time this process needs them (see kernel_locks)."""
    from ..runtime.model.model import Model
    from ..runtime.run.simulation import Simulation
    try:
        keys = {(k, scene.solver.backend) for k in Model.required_kernels(scene)}
    except Exception:              # noqa: BLE001 - the Simulation below reports the scene's problem
        keys = set()
    fresh = keys - _WARMED
    if not fresh:
        return Simulation(scene, output=False)
    with kernel_locks(fresh):
        sim = Simulation(scene, output=False)
        sim.model.warm_up()
    _WARMED.update(fresh)
    return sim


def _limit_threads(threads):
    """threads=1 (a worker): the runtime, numba and BLAS at one thread; None: leave them be."""
    if threads is None:
        return contextlib.nullcontext()
    from ..runtime.base import parallel
    parallel.set_threads(threads)
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        return contextlib.nullcontext()
    return threadpool_limits(limits=threads)


def _plain(value):
    """A cell of the table: numbers as they are, lists and tables as compact JSON text."""
    if isinstance(value, (list, tuple, dict)):
        return json.dumps(value, separators=(",", ":"))
    return value


def run_task(spec: dict, threads=None, max_memory=None) -> dict:
    """Run one task ({'task', 'scene', 'values'}) without writing output; never raises: one flat row
    (scene, the varied values, status, exit code, the probes' final values, the Summary's health
    fields, error, wall time)."""
    start = time.perf_counter()
    row = {"task": spec["task"], "scene": spec["scene"]}
    row.update({f"vary.{k}": _plain(v) for k, v in spec["values"].items()})
    row.update(status="", exit_code=EXIT_OK, error="")
    try:
        with _limit_threads(threads):
            scene = load_scene(spec["scene"], spec["values"], max_memory=max_memory)
            sim = _simulation(scene)
            try:
                summary, stopped = sim.run(), None
            except RunInterrupted:
                raise KeyboardInterrupt from None   # Ctrl-C stops the study, not only this task
            except RunStopped as exc:
                summary, stopped = exc.summary, exc
        row.update(_summary_fields(summary))
        if stopped is not None:
            row["error"] = f"run {summary.status}: {stopped}"
    except TensormassError as exc:
        row.update(status="refused", exit_code=EXIT_BAD_INPUT, error=str(exc))
    except (ArithmeticError, RuntimeError, MemoryError, OSError) as exc:
        row.update(status="failed", exit_code=EXIT_BAD_INPUT, error=f"{type(exc).__name__}: {exc}")
    except Exception as exc:      # noqa: BLE001 - a bug in one task must not lose the study
        row.update(status="error", exit_code=EXIT_INTERNAL, error=f"internal error: {type(exc).__name__}: {exc}")
    row["wall_time"] = time.perf_counter() - start
    return row


def _summary_fields(summary) -> dict:
    """The Summary's status and health numbers, flat (probe components as probe.NAME.0, .1, ...)."""
    d = summary.to_dict()
    out = {"status": d["status"], "exit_code": d["exit_code"], "message": d.get("message") or "",
           "steps": d["steps"], "steps_done": d["steps_done"], "n_dofs": d["n_dofs"],
           "n_elements": d["n_elements"], "newton_iterations": (d.get("iterations") or {}).get("newton"),
           "linear_iterations": (d.get("iterations") or {}).get("linear"), "energy": d.get("energy"),
           "kinetic_energy": d.get("kinetic_energy"), "warnings": len(d.get("warnings") or [])}
    health = d.get("health") or {}
    out.update({f"health.{k}": health.get(k) for k in HEALTH_KEYS if k in health})
    for name, u in (d.get("probes") or {}).items():
        for i, x in enumerate(u):
            out[f"probe.{name}.{i}"] = float(x)
    for name, r in (d.get("reactions") or {}).items():
        for i, x in enumerate(r.get("force") or ()):
            out[f"reaction.{name}.force.{i}"] = float(x)
    out["time_total"] = (d.get("time") or {}).get("total")
    return out


# ============================================================================== the engine


def _dask():
    try:
        import distributed
    except ImportError:
        raise TensormassError(DASK_MISSING) from None
    return distributed


def dask_available() -> bool:
    try:
        import distributed  # noqa: F401
    except ImportError:
        return False
    return True


@contextlib.contextmanager
def worker_environment():
    """THREAD_ENV (and WORKER_QUIET_ENV) in os.environ while the LocalCluster spawns its workers
    (they inherit it before importing anything), restored after."""
    env = {**THREAD_ENV, **WORKER_QUIET_ENV}
    old = {k: os.environ.get(k) for k in env}
    os.environ.update(env)
    try:
        yield
    finally:
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


class _Counter:
    """'label k/n' on stderr (redrawn on a terminal): the study's progress."""

    def __init__(self, n, label, stream=None):
        self.n, self.bar = n, ProgressBar(stream=stream if stream is not None else sys.stderr, label=label)

    def __call__(self, done):
        self.bar(done, self.n)

    def finish(self):
        self.bar.finish()


def map_tasks(fn, items, workers: int = 1, scheduler: str | None = None, mem_limit: int | None = None,
              label: str = "task", progress=True, on_result=None, capture: bool = True, on_done=None) -> list:
    """[(True, fn(*item)) or (False, 'error text')] in the order of items, whatever order they finish in.

    workers 1 and no scheduler: in this process, one after the other (no dask needed). Otherwise
    dask.distributed: a Client of `scheduler`, else a LocalCluster of `workers` single-threaded
    processes (THREAD_ENV, mem_limit bytes each). on_result(i, outcome) is called in item order
    as soon as the results up to i are in (to print a task's output in order); on_done(i, outcome)
    as soon as item i is done, in the order they finish. capture=False: a task's exception
    propagates (the first in item order that the engine sees), as it would in a loop. Ctrl-C
    (KeyboardInterrupt) propagates after the cluster is shut down (see _client)."""
    items = [tuple(it) for it in items]
    counter = _Counter(len(items), label) if progress and items else None
    results: list = [None] * len(items)
    shown = 0

    def _flush():
        nonlocal shown
        while shown < len(items) and results[shown] is not None:
            if on_result is not None:
                on_result(shown, results[shown])
            shown += 1
    try:
        if scheduler is None and workers <= 1:
            for i, item in enumerate(items):
                try:
                    results[i] = (True, fn(*item))
                except Exception as exc:     # noqa: BLE001 - the caller decides what a failure means
                    if not capture:
                        raise
                    results[i] = (False, f"{type(exc).__name__}: {exc}")
                if on_done is not None:
                    on_done(i, results[i])
                if counter:
                    counter(i + 1)
                _flush()
            return results
        distributed = _dask()
        with _client(distributed, workers, scheduler, mem_limit) as client:
            futures = [client.submit(fn, *item, pure=False, key=f"{label}-{i}-{os.getpid()}-{time.time_ns()}")
                       for i, item in enumerate(items)]
            index = {f.key: i for i, f in enumerate(futures)}
            done = 0
            for future in distributed.as_completed(futures):
                i = index[future.key]
                try:
                    results[i] = (True, future.result())
                except Exception as exc:     # noqa: BLE001 - KilledWorker (memory), pickling, the task's own
                    if not capture:
                        raise
                    results[i] = (False, f"{type(exc).__name__}: {exc}")
                if on_done is not None:
                    on_done(i, results[i])
                done += 1
                if counter:
                    counter(done)
                _flush()
        return results
    finally:
        if counter:
            counter.finish()


def _block_sigint():
    """Hold SIGINT in this thread (pending, delivered when unblocked); the old mask, None where
    masks cannot be set (not POSIX, not the main thread: nothing to hold there)."""
    if not hasattr(signal, "pthread_sigmask") or threading.current_thread() is not threading.main_thread():
        return None
    # multiprocessing starts its resource tracker with the first process and unblocks SIGINT in the
    # starting thread afterwards, whatever the mask was: started now, before the mask is set
    with contextlib.suppress(Exception):
        from multiprocessing import resource_tracker
        resource_tracker.ensure_running()
    return signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})


def _restore_mask(mask, drop_pending: bool = False) -> None:
    """Back to mask; drop_pending: a Ctrl-C that arrived while held is discarded, not delivered."""
    if mask is None:
        return
    if drop_pending and hasattr(signal, "sigtimedwait"):
        while signal.sigtimedwait([signal.SIGINT], 0) is not None:
            pass
    signal.pthread_sigmask(signal.SIG_SETMASK, mask)


@contextlib.contextmanager
def _distributed_logs(level):
    """distributed's loggers in this process at level while the block runs."""
    import logging
    logger = logging.getLogger("distributed")
    old = logger.level
    logger.setLevel(level)
    try:
        yield
    finally:
        logger.setLevel(old)


def _quiet_worker() -> None:
    """Run on every worker before the cluster closes: its shutdown is not worth a log line."""
    import logging
    logging.getLogger("distributed").setLevel(logging.CRITICAL)


@contextlib.contextmanager
def _client(distributed, workers, scheduler, mem_limit):
    """A Client of `scheduler`, else of a LocalCluster of `workers` processes; closed in order
    (client, then cluster) on every way out, Ctrl-C included.

    Ctrl-C at a terminal reaches every process of the foreground group, the workers too, which
    then die in the middle of a task with tracebacks. So SIGINT is blocked while the cluster
    starts: its worker processes (and the threads that start them) inherit the blocked mask and
    never see it; this process takes it once the cluster is up (a Ctrl-C during the start is
    delivered then). While the cluster closes, SIGINT is held again and a second Ctrl-C dropped."""
    import logging
    client = cluster = None
    mask = _block_sigint()
    with _distributed_logs(logging.ERROR):            # one line per event is noise here
        try:
            if scheduler is not None:
                try:
                    client = distributed.Client(scheduler, timeout="20s")
                except (OSError, TimeoutError) as exc:
                    raise TensormassError(f"--scheduler {scheduler}: cannot connect ({exc})") from None
            else:
                with worker_environment():
                    cluster = distributed.LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                                       memory_limit=mem_limit if mem_limit else "auto",
                                                       dashboard_address=None, env=dict(THREAD_ENV))
                client = distributed.Client(cluster)
            _restore_mask(mask)                       # a Ctrl-C held during the start lands here
            mask = None
            yield client
        finally:
            held = _block_sigint() if mask is None else mask
            try:
                with _distributed_logs(logging.CRITICAL):
                    _close(client, cluster, local=scheduler is None)
            finally:
                _restore_mask(held, drop_pending=True)


def _close(client, cluster, local: bool) -> None:
    """Client first (its futures cancelled), then the cluster; the workers told to keep quiet."""
    if client is not None:
        if local:
            with contextlib.suppress(Exception):
                client.run(_quiet_worker)
        with contextlib.suppress(Exception):
            client.close()
    if cluster is not None:
        with contextlib.suppress(Exception):
            cluster.close()


def worker_info() -> dict:
    """What a worker runs with (tests check the one-thread defaults): environment, numba and BLAS
    threads, and whether every thread of it blocks SIGINT (a terminal's Ctrl-C is not for it)."""
    import numba
    from threadpoolctl import threadpool_info
    return {"env": {k: os.environ.get(k) for k in THREAD_ENV}, "numba_threads": numba.get_num_threads(),
            "blas_threads": sorted({p["num_threads"] for p in threadpool_info()}), "pid": os.getpid(),
            "sigint_blocked": _threads_block_sigint()}


def _threads_block_sigint():
    """Whether every thread of this process blocks SIGINT (/proc; None where unknown)."""
    try:
        found = []
        for task in os.listdir(f"/proc/{os.getpid()}/task"):
            with open(f"/proc/{os.getpid()}/task/{task}/status", encoding="ascii") as handle:
                mask = next(int(line.split()[1], 16) for line in handle if line.startswith("SigBlk:"))
            found.append(bool(mask >> (signal.SIGINT - 1) & 1))
        return all(found) if found else None
    except (OSError, ValueError, StopIteration):
        return None


# ============================================================================== the command


def _default_workers(n_tasks: int) -> int:
    try:
        cores = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        cores = os.cpu_count() or 1
    return max(1, min(cores, n_tasks))


def _estimates(tasks) -> list:
    """Each task's resource estimate (runtime.scene.resources.Estimate: peak bytes, seconds), None where
    it cannot be made (the task itself will report why)."""
    from ..runtime.scene.resources import estimate
    out = []
    for t in tasks:
        try:
            out.append(estimate(load_scene(t["scene"], t["values"], load_mesh=False)))
        except Exception:          # noqa: BLE001 - a scene that does not load fails in its task
            out.append(None)
    return out


def _fmt_seconds(s: float) -> str:
    if s < 1.0:
        return f"{s * 1e3:.2g} ms"
    if s < 3600:
        return f"{s:.3g} s"
    return f"{s / 3600:.3g} h"


def plan_workers(requested, n_tasks: int, estimates, budget, explicit: bool) -> tuple:
    """(workers, per-worker memory limit in bytes or None, messages): the requested workers, no more
    than the tasks, and no more than budget (bytes the study may use; None: unknown) holds at the
    largest task's estimate x MEMORY_MARGIN (at least MEMORY_FLOOR) each."""
    messages = []
    workers = requested
    if workers > n_tasks:
        if explicit:
            messages.append(f"--workers {workers}: capped at {n_tasks}, the number of tasks")
        workers = n_tasks
    known = [e for e in estimates if e is not None]
    per = max(MEMORY_FLOOR, int(MEMORY_MARGIN * max(e.bytes for e in known))) if known else MEMORY_FLOOR
    if workers > 1 and budget:
        fit = max(1, int(budget // per))
        if workers > fit:
            from ..runtime.scene.resources import fmt_bytes
            messages.append(f"{workers} workers capped at {fit}: each needs up to {fmt_bytes(per)} (the largest "
                            f"task's estimate x {MEMORY_MARGIN:g}, at least {fmt_bytes(MEMORY_FLOOR)}) and "
                            f"{fmt_bytes(budget)} may be used")
            workers = fit
    return workers, (per if workers > 1 else None), messages


def study_cost(estimates, workers: int) -> str:
    """One line: the tasks, the largest peak memory and the stepping time per task, in all and per
    worker (runtime.scene.resources' estimates; setup and kernel compilation are not in them)."""
    from ..runtime.scene.resources import fmt_bytes
    known = [e for e in estimates if e is not None]
    n = len(estimates)
    if not known:
        return f"{n} task(s); no estimate (their scenes do not load: each task will say why)"
    seconds = [e.seconds for e in known]
    total = sum(seconds) * n / len(known)
    mean, most = _fmt_seconds(sum(seconds) / len(seconds)), _fmt_seconds(max(seconds))
    text = (f"{n} task(s), estimated per task: up to {fmt_bytes(max(e.bytes for e in known))} peak memory, "
            f"~{mean} of stepping" + (f" (up to ~{most})" if most != mean else "") + f"; "
            f"~{_fmt_seconds(total)} in all" + (f", ~{_fmt_seconds(total / workers)} on {workers} workers"
                                               if workers > 1 else ""))
    if len(known) < n:
        text += f" ({n - len(known)} task(s) not estimated: their scene does not load)"
    return text


def run_batch(scenes, vary=(), workers=None, scheduler=None, out="batch.csv", stream=None, progress=True) -> tuple:
    """Plan, run and tabulate a study; returns (rows, exit code). See the module docstring.
    Ctrl-C: (rows finished so far, EXIT_INTERRUPTED), their rows kept in the partial file."""
    stream = stream if stream is not None else sys.stderr
    tasks = plan_tasks(scenes, parse_vary(vary) if vary and isinstance(vary[0], str) else list(vary))
    out = check_table_path(out, scenes)
    explicit = workers is not None
    workers = _default_workers(len(tasks)) if workers is None else int(workers)
    if workers < 1:
        raise TensormassError(f"--workers must be at least 1, got {workers}")
    estimates = _estimates(tasks)
    limit = None
    if scheduler is None:
        from ..runtime.scene.resources import limit_bytes
        workers, limit, messages = plan_workers(workers, len(tasks), estimates, limit_bytes()[0], explicit)
        for line in messages:
            print(f"batch: {line}", file=stream)
    if (workers > 1 or scheduler) and not dask_available():
        if explicit or scheduler:
            raise TensormassError(DASK_MISSING)
        print(f"batch: dask.distributed is not installed: running sequentially "
              f'(pip install "tensormass[distributed]" for {workers} workers)', file=stream)
        workers, limit = 1, None
    distributed = workers > 1 or scheduler is not None
    where = (f"cluster {scheduler}" if scheduler else
             f"{workers} worker processes, 1 thread each" + (f", {limit / 2 ** 30:.2f} GiB each" if limit else "")
             if distributed else "this process, one task after the other")
    print(f"batch: {len(tasks)} task(s) ({len(scenes)} scene(s)) on {where}", file=stream)
    print(f"batch: cost: {study_cost(estimates, 1 if scheduler else workers)}", file=stream)
    start = time.perf_counter()
    partial = PartialRows(out, len(tasks))
    rows: list = [None] * len(tasks)

    def done(i, outcome):
        rows[i] = _row(tasks[i], outcome)
        partial.add(rows[i])
    try:
        map_tasks(run_task, [(t, 1 if distributed else None) for t in tasks], workers=workers,
                  scheduler=scheduler, mem_limit=limit, label="task", progress=progress, on_done=done)
    except KeyboardInterrupt:
        partial.close(remove=False)
        print(f"tensormass: interrupted: {partial.count} of {len(tasks)} task(s) finished, their rows kept in "
              f"{partial.path}", file=stream)
        return [r for r in rows if r is not None], EXIT_INTERRUPTED
    except BaseException:
        partial.close(remove=False)
        raise
    written = write_table(rows, out)
    partial.close(remove=True)
    failed = [r for r in rows if r["exit_code"] != EXIT_OK]
    print(f"batch: {len(rows) - len(failed)}/{len(rows)} task(s) ok in {time.perf_counter() - start:.1f} s; "
          f"wrote {', '.join(map(str, written))}", file=stream)
    if failed:
        print(f"batch: {len(failed)} task(s) failed:", file=stream)
        for r in failed:
            values = " ".join(f"{k[5:]}={r[k]}" for k in r if k.startswith("vary."))
            print(f"  [{r['task']}] {r['scene']}{' ' + values if values else ''}: {r['status']} "
                  f"(exit {r['exit_code']}): {r['error']}", file=stream)
    return rows, max((r["exit_code"] for r in failed), default=EXIT_OK)


def _row(task, outcome) -> dict:
    """A task's row: run_task's, or one saying that the task never ran to its end (worker killed,
    e.g. over its memory)."""
    ok, value = outcome
    if ok:
        return value
    row = {"task": task["task"], "scene": task["scene"], **{f"vary.{k}": _plain(v) for k, v in task["values"].items()}}
    row.update(status="error", exit_code=EXIT_INTERNAL, error=f"task lost: {value}")
    return row


def cmd_batch(args) -> int:
    _, code = run_batch(args.scenes, args.vary or (), workers=args.workers, scheduler=args.scheduler,
                        out=args.out, progress=not args.quiet)
    return code


def add_batch_command(subparsers) -> None:
    p = subparsers.add_parser("batch", help="run scene files x parameter variations as independent tasks "
                                            "(dask.distributed) into one table")
    p.add_argument("scenes", nargs="+", help="scene files (.toml)")
    p.add_argument("--vary", action="append", metavar="KEY=V1,V2,...",
                   help="a dotted scene key and its values (TOML; commas inside brackets do not split), e.g. "
                        "material.0.E=1e6,1e7 or mesh.cells=[4,1,1],[8,2,2]; repeat for a cartesian product")
    p.add_argument("--workers", type=int, metavar="N",
                   help="worker processes of a local dask cluster (default: the cores, at most the tasks); "
                        "1: in this process, without dask")
    p.add_argument("--scheduler", metavar="ADDRESS", help="run on an existing dask cluster (tcp://host:8786)")
    p.add_argument("--out", default="batch.csv", help="the table (CSV; also .parquet with pyarrow); default batch.csv")
    p.add_argument("--quiet", action="store_true", help="no progress counter")
    p.set_defaults(run=cmd_batch)
