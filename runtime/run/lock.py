"""One run per output folder: <folder>/.tensormass.lock, created atomically (O_CREAT | O_EXCL) with
the holder's pid, host and process start time, held until the run's summary is written. A lock
of a process that no longer exists (killed, crashed, or its pid reused) is taken over."""
from __future__ import annotations

import contextlib
import itertools
import os
import weakref
from pathlib import Path

from ..base.errors import TensormassError
from ..base.files import os_reason as _reason, remove_quietly

__all__ = ["FolderLock", "LOCK_NAME"]

LOCK_NAME = ".tensormass.lock"

# Locks held by this process: lock path -> (token, weak reference to the holder). A lock file
# with this process's pid is live only while its holder is.
_HELD: dict = {}
_TOKENS = itertools.count()


def _process_start(pid: int):
    """The kernel's start time of process pid (clock ticks since boot; Linux), None where unknown:
    a pid reused by a new process after the holder died has another start."""
    try:
        with open(f"/proc/{int(pid)}/stat", "rb") as handle:
            fields = handle.read().rsplit(b")", 1)[1].split()
        return int(fields[19])
    except (OSError, ValueError, IndexError):
        return None


def _host() -> str:
    import socket
    return socket.gethostname() or "?"


class FolderLock:
    """<folder>/.tensormass.lock: one run writes into a folder at a time (see the module docstring).

        lock = FolderLock(folder, owner)
        lock.check()        # TensormassError when a live run holds it (reads only)
        lock.acquire()      # the folder exists; TensormassError when a live run holds it
        lock.release()      # idempotent; removes the file only while it is still ours
    """

    def __init__(self, folder, owner=None):
        self.folder = Path(folder)
        self.path = self.folder / LOCK_NAME
        # weak: the Writer holds its lock, and a dropped Writer must be freed (and release it) at once
        self._owner = weakref.ref(owner) if owner is not None else (lambda: self)
        self.held = False
        self._finalizer = None

    @property
    def owner(self):
        return self._owner()

    @staticmethod
    def record(pid: int | None = None) -> str:
        """The text of a lock held by process pid (default: this one)."""
        pid = os.getpid() if pid is None else int(pid)
        start = _process_start(pid)
        return f"pid={pid} host={_host()} start={'?' if start is None else start}\n"

    def _holder(self):
        """None: no lock file; else a dict of its fields (pid, host, start; empty when unreadable)."""
        try:
            with open(self.path, "rb") as handle:
                text = handle.read(256).decode("utf-8", "replace")
        except FileNotFoundError:
            return None
        except OSError as exc:
            raise TensormassError(f"output folder {self.folder}: cannot read its lock {self.path}: "
                                  f"{_reason(exc)}") from None
        fields = dict(part.split("=", 1) for part in text.split() if "=" in part)
        return fields

    def _alive(self, holder: dict) -> bool:
        """Whether the lock's process may still be running (unknown: yes, the safe answer)."""
        try:
            pid = int(holder.get("pid", ""))
        except ValueError:
            return True                           # being written right now, or not ours to judge
        if holder.get("host") != _host():
            return True                           # another machine's process: cannot be checked
        if pid == os.getpid():
            entry = _HELD.get(str(self.path.resolve()))
            owner = entry[1]() if entry is not None else None
            return owner is not None and owner is not self.owner
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return False
        except PermissionError:
            pass                                  # alive, another user's
        except OSError:
            return True
        start = holder.get("start", "?")
        now = _process_start(pid)
        return not (start.isdigit() and now is not None and int(start) != now)

    def _refuse(self, holder: dict):
        pid = holder.get("pid") or "unknown"
        host = holder.get("host")
        where = f" on {host}" if host and host != _host() else ""
        same = " (this process)" if pid == str(os.getpid()) else ""
        return TensormassError(f"output folder {self.folder}: another tensormass run (pid {pid}{where}{same}) is "
                               f"writing there; wait for it to end or choose another output folder (if no run is "
                               f"using it, remove {self.path})")

    def check(self) -> None:
        """Refuse when a live run holds the folder; reads only."""
        holder = self._holder()
        if holder is not None and not self.held and self._alive(holder):
            raise self._refuse(holder)

    def acquire(self) -> None:
        """Take the lock (the folder must exist); a stale lock is taken over."""
        if self.held:
            return
        text = self.record().encode()
        for _ in range(4):
            try:
                fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
            except FileExistsError:
                holder = self._holder()
                if holder is None:
                    continue                      # released meanwhile: try again
                if self._alive(holder):
                    raise self._refuse(holder) from None
                self._take_over(holder)
                continue
            except OSError as exc:
                raise TensormassError(f"output folder {self.folder}: cannot create its lock {self.path}: "
                                      f"{_reason(exc)}") from None
            try:
                written = os.write(fd, text)
            except BaseException:                 # Ctrl-C too: an empty lock would name no run
                os.close(fd)
                remove_quietly(self.path)
                raise
            os.close(fd)
            if written != len(text):
                remove_quietly(self.path)
                raise TensormassError(f"output folder {self.folder}: cannot write its lock {self.path} (disk full?)")
            self.held = True
            key, token = str(self.path.resolve()), next(_TOKENS)
            _HELD[key] = (token, weakref.ref(self.owner))
            # released when the holder is dropped without close() (or at exit): no lock outlives its run
            self._finalizer = weakref.finalize(self.owner, _unlock, key, token, str(self.path), text)
            return
        raise TensormassError(f"output folder {self.folder}: its lock {self.path} keeps changing hands; "
                              "another run is starting there")

    def _take_over(self, stale: dict) -> None:
        """Move a stale lock aside, then delete it; a lock that turns out live (replaced by a new run
        between the read and the move) is put back."""
        aside = self.folder / f"{LOCK_NAME}.stale-{os.getpid()}"
        try:
            os.replace(self.path, aside)
        except FileNotFoundError:
            return
        except OSError as exc:
            raise TensormassError(f"output folder {self.folder}: cannot remove the stale lock {self.path} "
                                  f"(pid {stale.get('pid')}, no longer running): {_reason(exc)}") from None
        moved = FolderLock(self.folder, self.owner)
        moved.path = aside
        holder = moved._holder()
        if holder is not None and holder != stale and self._alive(holder):
            with contextlib.suppress(OSError):
                os.link(aside, self.path)         # back where it was, unless a newer lock is there
        remove_quietly(aside)

    def release(self) -> None:
        if not self.held:
            return
        self.held = False
        self._finalizer()


def _unlock(key: str, token: int, path: str, text: bytes) -> None:
    """Forget the lock taken with token, and remove its file while it still holds text (ours)."""
    if _HELD.get(key, (None,))[0] == token:
        del _HELD[key]
    try:
        with open(path, "rb") as handle:
            ours = handle.read(256) == text
    except OSError:
        return
    if ours:
        remove_quietly(path)


