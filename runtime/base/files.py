"""Files written so that no reader ever sees half of one: a temporary file next to the target,
then a rename over it (an interrupted write leaves the old file, or none); and a check that a
folder can be written before a run starts rather than after its last step."""
from __future__ import annotations

import errno
import json
import os
import tempfile
from pathlib import Path

import numpy as np

from .errors import TensormassError

__all__ = ["write_atomic", "write_bytes_atomic", "write_text_atomic", "write_json_atomic",
           "check_writable", "os_reason", "remove_quietly"]


def write_atomic(path: Path, data) -> None:
    """Write text or bytes to a temporary file next to path, then rename it over path:
    readers never see a half-written file, an interrupted run leaves the old one (or none)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as handle:
            handle.write(data.encode("utf-8") if isinstance(data, str) else data)
        os.chmod(tmp, 0o644)          # mkstemp creates 0600; these are ordinary files
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def write_bytes_atomic(path, data: bytes) -> None:
    """Bytes written atomically (temporary file + rename; write_atomic)."""
    write_atomic(Path(path), data)


def write_text_atomic(path, text: str) -> None:
    """UTF-8 text, written atomically."""
    write_atomic(Path(path), text)


def _jsonable(value):
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return _jsonable(value.tolist())
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, float) and not np.isfinite(value):
        return None      # JSON has no NaN / Inf
    return value


def write_json_atomic(path, data) -> None:
    """JSON (numpy values converted, NaN/Inf as null), written atomically."""
    write_text_atomic(path, json.dumps(_jsonable(data), indent=2, allow_nan=False) + "\n")


def os_reason(exc: OSError) -> str:
    """'No space left on device' and the like (the OS's words; the errno name when it has none)."""
    return exc.strerror or errno.errorcode.get(exc.errno or 0, "") or str(exc)


def _existing_ancestor(path: Path) -> Path:
    """path itself or its closest existing parent (what a later mkdir -p would write into)."""
    path = Path(os.path.abspath(path))
    while not os.path.lexists(path) and path.parent != path:
        path = path.parent
    return path


def check_writable(folder, what: str) -> None:
    """Create and remove a temporary file in folder (or its closest existing parent when it
    does not exist yet): permissions, read-only mounts and quotas show up now, before a run,
    instead of after its last step. Raises TensormassError naming what and where."""
    where = _existing_ancestor(Path(folder))
    if not where.is_dir():
        raise TensormassError(f"{what} {folder}: {where} is not a folder")
    try:
        fd, probe = tempfile.mkstemp(dir=where, prefix=".tensormass-probe-", suffix=".tmp")
        os.close(fd)
        os.remove(probe)
    except OSError as exc:
        raise TensormassError(f"{what} {folder}: cannot write in {where} ({os_reason(exc)})") from None


def remove_quietly(path) -> None:
    """Remove a file on a failure path, where a second error would hide the first."""
    try:
        os.remove(path)
    except OSError:
        pass
