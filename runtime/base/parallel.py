"""The one thread switch of the runtime: how many threads assembly (and numba's parallel loops) use.

    from tensormass.runtime.base import parallel
    parallel.worker_threads()        # the configured count (default: every core numba sees)
    parallel.set_threads(1)          # pin one thread (the whole process)
    with parallel.threads(2): ...    # temporarily

Sources, strongest first: set_threads() (the CLI's `tensormass run --threads N` and the scene key
`[solver] threads` call it), the environment variable TENSORMASS_THREADS, every core numba sees
(numba.config.NUMBA_NUM_THREADS).  Results never depend on the count: assembly adds element
contributions in a fixed order (runtime.assembly.assembly, block colours), whatever the threads.
"""
from __future__ import annotations

import os
import threading
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager

import numba

from .errors import TensormassError

__all__ = ["ENV", "available", "worker_threads", "set_threads", "set_threads_from", "threads", "parse_threads",
           "run_shares"]

ENV = "TENSORMASS_THREADS"

_configured: int | None = None      # set_threads(); None: the environment variable, else every core
_pool: ThreadPoolExecutor | None = None
_pool_size = 0
_lock = threading.Lock()


def available() -> int:
    """Every core numba may use (its NUMBA_NUM_THREADS): the most threads a run can have."""
    return int(numba.config.NUMBA_NUM_THREADS)


def parse_threads(value, where: str) -> int:
    """A thread count from a setting named `where` (an integer from 1 to available()); else a clear error."""
    if isinstance(value, str):
        text = value.strip()
        try:
            value = int(text)
        except ValueError:
            raise TensormassError(f"{where}: expected a whole number of threads >= 1, got {value!r}") from None
    if isinstance(value, bool) or not isinstance(value, int):
        raise TensormassError(f"{where}: expected a whole number of threads >= 1, got {value!r}")
    if value < 1:
        raise TensormassError(f"{where}: expected a whole number of threads >= 1, got {value}")
    if value > available():
        raise TensormassError(f"{where}: {value} threads asked, but numba sees {available()} core(s) on this "
                              f"machine (NUMBA_NUM_THREADS); use at most {available()}")
    return value


def worker_threads() -> int:
    """The configured thread count (set_threads, else $TENSORMASS_THREADS, else every core)."""
    if _configured is not None:
        return _configured
    env = os.environ.get(ENV)
    if env is not None and env.strip():
        return parse_threads(env, f"environment variable {ENV}")
    return available()


def set_threads(n) -> int:
    """Use n threads from now on (None: back to $TENSORMASS_THREADS / every core); returns the count."""
    global _configured
    _configured = None if n is None else parse_threads(n, "threads")
    count = worker_threads()
    numba.set_num_threads(count)
    return count


def set_threads_from(value, where: str) -> int:
    """set_threads(value) with errors naming the setting it came from (e.g. "solver.threads")."""
    global _configured
    _configured = parse_threads(value, where)
    numba.set_num_threads(_configured)
    return _configured


@contextmanager
def threads(n):
    """Temporarily use n threads (tests, benchmarks)."""
    global _configured
    before = _configured
    set_threads(n)
    try:
        yield worker_threads()
    finally:
        _configured = before
        numba.set_num_threads(worker_threads())


def _executor(workers: int) -> ThreadPoolExecutor:
    global _pool, _pool_size
    with _lock:
        if _pool is None or _pool_size < workers:
            if _pool is not None:
                _pool.shutdown(wait=True)
            _pool, _pool_size = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="tensormass"), workers
        return _pool


def run_shares(task, n_shares: int) -> None:
    """Run task(0) .. task(n_shares - 1) concurrently: share 0 on the calling thread, the others on
    the pool's threads; waits for all and re-raises the first error (by share index, deterministic)."""
    if n_shares <= 1:
        task(0)
        return
    pool = _executor(n_shares - 1)
    futures = [pool.submit(task, s) for s in range(1, n_shares)]
    errors = []
    try:
        task(0)
    except BaseException as error:         # wait for the others before raising
        errors.append((0, error))
    for s, fut in enumerate(futures, start=1):
        try:
            fut.result()
        except BaseException as error:
            errors.append((s, error))
    if errors:
        raise min(errors, key=lambda x: x[0])[1]
