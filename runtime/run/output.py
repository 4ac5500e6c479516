"""Write a simulation as a VTU time series with a ParaView .pvd collection.

    writer = Writer("out", mesh)                     # nothing is created yet
    writer.prepare()                                 # before the run: checks only (see below)
    writer.write_frame(step, time, points, u, {"energy": e_per_cell})
    writer.write_frame(step, time, points, u, flag="inverted elements (3)")   # a frame after a warning

Precision. Points, displacement and other arrays are written as given (floats as Float64); the
stress and strain fields of runtime.physics.fields (those its FIELDS marks single: von Mises,
Cauchy stress, ...) as Float32, about half the bytes of a frame's field data.
    writer.mark_stopped(step, "run diverged: energy grew 1e9-fold")
    writer.close()

Files. Every frame is a complete <name>_<step>.vtu written to a temporary
name and renamed. The collection <name>.pvd starts with the comment
``<!-- tensormass frames -->`` (how a later run knows the folder's frames are
ours) and ends with its closing tags; each frame appends its DataSet line by
one os.pwrite of "new line + closing tags" at the offset where the closing
tags were. That costs the same for the 10th and the 10 000th frame, never
rewrites earlier lines, and the file is valid XML after every frame: a
write that fails half-way (disk full) is undone by putting the closing tags
back, and a run that crashes leaves a collection ParaView can open.

Health marks. ``write_frame(..., flag=text)`` marks a frame written after a
health warning: the .pvd gets the comment ``<!-- health warning (step k): text -->``
just before the frame's DataSet line, and the .vtu a cell field
``health_warning`` (1 on every cell; unflagged frames have no such field).
``mark_stopped(step, message)`` appends ``<!-- run stopped at step k: message -->``
after the last frame (never raises: it only annotates). Comment texts are made
valid XML comments (one line, no "--", no characters XML forbids).

Output folder. ``prepare()`` (run by the first write_frame when not called
before) checks, without writing or removing anything, that the folder (or the
closest existing parent) is writable and looks at files with the names this
writer uses: frames of an earlier run of ours (listed in a .pvd carrying our
comment) and leftover temporary files are stale and are removed when the
first frame is written, so a shorter rerun leaves no frames of a longer one;
a .pvd without our comment or a frame it does not list is someone else's:
prepare() refuses (TensormassError) unless ``overwrite=True`` (``--overwrite``),
which replaces them too. Other files in the folder are never touched. The
folder is created with the first frame; if the run ends before any frame
(bad input, a failing first step), discard() removes it again when this
writer created it and it is still empty. Frames with NaN or Inf are refused
(TensormassError) and nothing of them is written. A file that cannot be
written (disk full, permissions) raises OutputError naming it; the frames
written before stay listed in the .pvd.

One run per folder. The first frame takes the folder's lock, ``.tensormass.lock``:
a file created atomically (O_CREAT | O_EXCL) holding the run's pid, host and
process start, removed when the writer closes (release_lock(): a RunFiles holds it
until the summary is written). Another run that finds the lock held by a live
process is refused (TensormassError naming the folder and the pid): prepare()
refuses before the run, and a run that passed prepare() at the same moment is
refused at its first frame, before it removes or writes anything. A lock whose
process is gone (killed, crashed) is stale and taken over.

Summaries. ``write_summary(path, data)`` writes the run summary JSON
atomically with the key ``"format": "tensormass-summary/1"``;
``check_summary_path`` refuses (before the run) a path holding anything but
such a summary: the scene file, frames, the .pvd, symbolic links, devices.
"""
from __future__ import annotations

import contextlib
import errno
import os
import re
import signal
import stat
import threading
from pathlib import Path
from xml.sax.saxutils import quoteattr, unescape

import numpy as np

from ..base.errors import TensormassError
from ..mesh.io import to_meshio
from ..physics.fields import frame_dtype
from .lock import LOCK_NAME, FolderLock
from ..base.files import check_writable, os_reason as _reason, remove_quietly, write_bytes_atomic, write_json_atomic

__all__ = ["Writer", "OutputError", "FolderLock", "LOCK_NAME",
           "write_summary", "check_summary_path", "is_summary_file", "check_png_path", "xml_comment",
           "PVD_MARKER", "SUMMARY_FORMAT"]

PVD_MARKER = "<!-- tensormass frames -->"
SUMMARY_FORMAT = "tensormass-summary/1"
# A summary of ours has its "format" key first; a file without it in its first bytes is not ours.
_SUMMARY_PROBE_BYTES = 4096
_SUMMARY_RE = re.compile(rb'"format"\s*:\s*"' + re.escape(SUMMARY_FORMAT.encode()) + rb'"')

_PVD_HEAD = ('<?xml version="1.0"?>\n' + PVD_MARKER + "\n"
             '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">\n'
             "  <Collection>\n").encode()
_PVD_TAIL = b"  </Collection>\n</VTKFile>\n"
_DATASET_FILE_RE = re.compile(rb'<DataSet\b[^>]*\bfile="([^"<>]*)"')
_MAX_COMMENT = 400


class OutputError(TensormassError):
    """An output file could not be written (disk full, permissions); the message names the file."""


def _remove(path) -> None:
    try:
        os.remove(path)
    except FileNotFoundError:
        pass


def _check_finite(name: str, values: np.ndarray) -> None:
    if values.dtype.kind in "fc" and not np.all(np.isfinite(values)):
        bad = np.flatnonzero(~np.isfinite(values.reshape(len(values), -1)).all(axis=1)) if values.ndim else []
        where = f" at {len(bad)} of {len(values)} entries, first {int(bad[0])}" if len(bad) else ""
        raise TensormassError(f"refusing to write {name} with NaN or Inf values{where}")


# ============================================================================== checks before a run


def is_summary_file(path) -> bool:
    """A regular file (not a link) whose first bytes carry our summary marker."""
    try:
        info = os.lstat(path)
        if not stat.S_ISREG(info.st_mode):
            return False
        with open(path, "rb") as handle:
            return bool(_SUMMARY_RE.search(handle.read(_SUMMARY_PROBE_BYTES)))
    except OSError:
        return False


def _same_file(a, b) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def check_summary_path(path, scene_file=None, writer=None, what: str = "--json") -> Path | None:
    """A summary path (--json, or [output] summary.json: `what` names it), checked before the run:
    None stays None.

    Refused: a folder, a missing folder, the scene file, the .pvd or a frame of the
    writer's folder (now or later), a symbolic link, a device/fifo/socket, and any
    existing file that is not a summary of ours; its folder must be writable.
    """
    if path is None:
        return None
    path = Path(path)
    if path.is_dir():
        raise TensormassError(f"{what} {path}: is a folder; give a file name")
    if not path.parent.is_dir():
        raise TensormassError(f"{what} {path}: folder {path.parent} does not exist")
    if scene_file is not None and _same_file(path, scene_file):
        raise TensormassError(f"{what} {path}: is the scene file; give another file name")
    if writer is not None and writer.owns_name(path):
        raise TensormassError(f"{what} {path}: is one of the output files ({writer.out_dir}/"
                              f"{writer.name}.pvd or {writer.name}_*.vtu); give another file name")
    _check_existing_summary(path, what)
    check_writable(path.parent, what)
    return path


def _check_existing_summary(path: Path, what: str = "--json") -> None:
    """An existing file at path may only be replaced when it is one of our summaries."""
    try:
        info = os.lstat(path)
    except FileNotFoundError:
        return
    except OSError as exc:
        raise TensormassError(f"{what} {path}: {_reason(exc)}") from None
    if stat.S_ISLNK(info.st_mode):
        raise TensormassError(f"{what} {path}: is a symbolic link (to {os.readlink(path)}); "
                              "refusing to replace it, give the file itself or another name")
    if not stat.S_ISREG(info.st_mode):
        raise TensormassError(f"{what} {path}: exists and is not a regular file (a device, fifo or socket); "
                              "refusing to write there")
    if not is_summary_file(path):
        raise TensormassError(f"{what} {path}: exists and is not a tensormass summary (no "
                              f'"format": "{SUMMARY_FORMAT}"); refusing to replace it, remove it or give another name')


def check_png_path(path, what: str) -> Path:
    """A PNG target, checked before drawing: a *.png name, not a folder, a link or a device, in a
    folder that can be written (created if missing). Raises TensormassError naming what and path."""
    target = Path(path)
    if target.suffix.lower() != ".png":
        raise TensormassError(f"{what} {target}: the file name must end in .png")
    if target.is_dir():
        raise TensormassError(f"{what} {target}: is a folder; give a file name")
    if os.path.islink(target):
        raise TensormassError(f"{what} {target}: is a symbolic link; refusing to replace it")
    if target.exists() and not target.is_file():
        raise TensormassError(f"{what} {target}: exists and is not a regular file")
    check_writable(target.parent, what)
    return target


def write_summary(path, data: dict) -> None:
    """The summary JSON, atomically, with the format marker as its first key."""
    out = {"format": SUMMARY_FORMAT}
    out.update((k, v) for k, v in data.items() if k != "format")
    try:
        write_json_atomic(path, out)
    except OSError as exc:
        raise OutputError(f"cannot write the summary {path}: {_reason(exc)}") from None


def xml_comment(text) -> str:
    """text as one valid XML comment: one line, no '--', only characters XML allows, bounded."""
    text = " ".join(str(text).split())
    text = "".join(c if _xml_char(c) else "?" for c in text)
    while "--" in text:
        text = text.replace("--", "- ")
    if len(text) > _MAX_COMMENT:
        text = text[:_MAX_COMMENT - 3] + "..."
    return f"<!-- {text} -->"


def _xml_char(c: str) -> bool:
    o = ord(c)
    return 0x20 <= o <= 0xD7FF or 0xE000 <= o <= 0xFFFD or o >= 0x10000


# ============================================================================== one run per folder

# ============================================================================== the writer


class Writer:
    """A VTU series <out_dir>/<name>_<step>.vtu and its collection <out_dir>/<name>.pvd.

    deformed=False writes the given points (reference positions by default)
    with the displacement as point data, for ParaView's "Warp By Vector";
    deformed=True writes the reference points moved by the displacement.
    overwrite=True replaces files with this writer's names that an earlier run
    of ours did not write (refused otherwise; see the module docstring).
    """

    def __init__(self, out_dir, mesh, name: str = "frame", deformed: bool = False, overwrite: bool = False):
        if not name or "/" in name or "\\" in name or name.startswith("."):
            raise TensormassError(f"bad output name {name!r}")
        self.out_dir = Path(out_dir)
        if self.out_dir.exists() and not self.out_dir.is_dir():
            raise TensormassError(f"output path {self.out_dir} exists and is not a folder")
        self.mesh = mesh
        self.name = name
        self.deformed = deformed
        self.overwrite = overwrite
        self.frames: list = []          # [(time, file name)] of finished frames
        self._listed: set = set()       # their file names: a frame's bookkeeping never walks the list
        self.created_dir = False
        self.closed = False
        self.stopped = None             # (step, message) once mark_stopped() was called
        self.error = None               # the OutputError that ended the writing, if any
        self.lock = FolderLock(self.out_dir, self)
        self.keep_lock = False          # True: close() leaves the lock to release_lock() (RunFiles)
        self._prepared = False          # prepare() ran
        self._stale: list = []          # files of an earlier run, removed with the first frame
        self._lines: list = []          # [(file name or None, bytes)]: the .pvd between head and tail
        self._pvd_written = False       # the .pvd of this run exists (appends from now on)
        self._frame_re = re.compile(rf"{re.escape(name)}_\d+\.vtu\Z")
        # temporary names of an interrupted frame (.<frame>.tmp) or .pvd (.<name>.pvd.<random>.tmp)
        self._tmp_re = re.compile(rf"\.{re.escape(name)}(_\d+\.vtu|\.pvd\.[A-Za-z0-9_]+)\.tmp\Z")
        self.block_offsets = np.concatenate([[0], np.cumsum([len(b) for b in mesh.blocks])]).astype(np.int64)

    def set_mesh(self, mesh) -> None:
        """Frames from now on are of this mesh (adaptive refinement changes it during a run)."""
        self.mesh = mesh
        self.block_offsets = np.concatenate([[0], np.cumsum([len(b) for b in mesh.blocks])]).astype(np.int64)

    # -- paths ---------------------------------------------------------------------------------
    @property
    def pvd_path(self) -> Path:
        return self.out_dir / f"{self.name}.pvd"

    def frame_path(self, step: int) -> Path:
        return self.out_dir / f"{self.name}_{int(step):06d}.vtu"

    def _kind(self, file_name: str):
        """'pvd', 'frame' or 'tmp' for a name this writer writes in its folder, else None."""
        if file_name == self.pvd_path.name:
            return "pvd"
        if self._frame_re.match(file_name):
            return "frame"
        return "tmp" if self._tmp_re.match(file_name) else None

    def owns_name(self, path) -> bool:
        """Whether path is, or may become, one of this writer's files (its .pvd, a frame, a temporary)."""
        path = Path(path)
        same = os.path.realpath(path.parent) == os.path.realpath(self.out_dir)
        return same and self._kind(path.name) is not None

    # -- before the run ------------------------------------------------------------------------
    def prepare(self) -> None:
        """Check the output folder before a run; writes and removes nothing (see the module docstring).

        Raises TensormassError when the folder cannot be written, or holds files with this
        writer's names that an earlier run of ours did not write (unless overwrite).
        """
        self._prepared = True
        check_writable(self.out_dir, "output folder")
        if not self.out_dir.is_dir():
            return
        self.lock.check()
        self._scan()

    def _scan(self) -> None:
        """The files with this writer's names in the folder: stale (ours, removed with the first
        frame) or foreign (refused unless overwrite)."""
        listed = self._listed_by_our_pvd()
        stale, foreign = [], []
        for entry in sorted(os.scandir(self.out_dir), key=lambda e: e.name):
            kind = self._kind(entry.name)
            if kind is None:
                continue
            if entry.is_dir(follow_symlinks=False):
                raise TensormassError(f"output folder {self.out_dir}: {entry.name} is a folder; "
                                      "remove it or choose another output folder")
            regular = entry.is_file(follow_symlinks=False)
            ours = regular and (kind == "tmp" or (listed is not None and (kind == "pvd" or entry.name in listed)))
            (stale if ours else foreign).append(Path(entry.path))
        if foreign and not self.overwrite:
            names = ", ".join(p.name for p in foreign[:3]) + (f" and {len(foreign) - 3} more" if len(foreign) > 3 else "")
            raise TensormassError(
                f"output folder {self.out_dir} holds {len(foreign)} file(s) with the names this run writes "
                f"that no earlier tensormass run there wrote ({names}); refusing to replace them: "
                "use --overwrite to replace them, or choose another output folder")
        # the old .pvd goes first: at no moment does a .pvd list a frame that was removed
        self._stale = sorted(stale + foreign, key=lambda p: p.name != self.pvd_path.name)

    def _listed_by_our_pvd(self):
        """The frame names listed in an existing .pvd of ours (a set), None when there is none."""
        try:
            if not stat.S_ISREG(os.lstat(self.pvd_path).st_mode):
                return None
            with open(self.pvd_path, "rb") as handle:
                head = handle.read(_SUMMARY_PROBE_BYTES)
                if PVD_MARKER.encode() not in head:
                    return None
                text = head + handle.read()
        except FileNotFoundError:
            return None
        except OSError as exc:
            raise TensormassError(f"cannot read {self.pvd_path}: {_reason(exc)}") from None
        names = {unescape(m.decode("utf-8", "replace")) for m in _DATASET_FILE_RE.findall(text)}
        return {n for n in names if self._frame_re.match(n)}   # never a path out of the folder

    def _start(self) -> None:
        """With the first frame: create the folder and remove the stale files found by prepare()."""
        if not self._prepared:
            self.prepare()
        self._make_dir()
        try:
            self.lock.acquire()
            self._scan()                          # as the folder is now that no other run can change it
        except TensormassError:
            self.lock.release()
            self.discard()
            raise
        for path in self._stale:
            try:
                _remove(path)
            except OSError as exc:
                raise self._fail(f"cannot remove {path} of an earlier run: {_reason(exc)}") from None
        self._stale = []

    # -- writing ---------------------------------------------------------------------------------
    def write_frame(self, step, time, points, displacement, fields=None, cell_fields=None, flag=None) -> Path:
        """Write one frame and append it to the .pvd; returns the frame's path.

        points: the coordinates to write, (n_points, dim) (None: the mesh's
        reference points); displacement: (n_points, dim). fields: name ->
        array with one row per point (point data) or, when the length differs,
        one row per cell in block order (cell data); cell_fields: always cell
        data. 2-component vectors of 2D meshes are padded with z = 0.
        flag: None, or the health warning this frame is written under (a .pvd
        comment and the cell field health_warning = 1).
        """
        m, time = self._frame_mesh(step, time, points, displacement, fields, cell_fields)
        if flag is not None:
            m.cell_data["health_warning"] = [np.ones(len(b), dtype=np.uint8) for b in self.mesh.blocks]
        if not self.frames and not self._pvd_written:
            self._start()
        with _interrupts_deferred():              # the frame and its .pvd line land together
            return self._commit_frame(m, step, time, flag)

    def _commit_frame(self, m, step, time, flag) -> Path:
        target = self.frame_path(step)
        self._write_vtu(m, target)
        lines = [] if flag is None else [(None, xml_comment(f"health warning (step {int(step)}): {flag}"))]
        lines.append((target.name, f'<DataSet timestep="{time!r}" group="" part="0" file={quoteattr(target.name)}/>'))
        name = target.name
        relisted = name in self._listed
        try:
            self._add_to_pvd(lines)
        except BaseException as exc:              # also Ctrl-C: a rerun would take the frame for a stranger's
            if not relisted:
                remove_quietly(target)           # a frame the .pvd does not list is no output
            self.discard()
            if not isinstance(exc, OSError):
                raise
            kept = f"; the {len(self.frames)} frame(s) written before stay listed in it" if self.frames else ""
            raise self._fail(f"cannot write {self.pvd_path}: {_reason(exc)}{kept}") from None
        if relisted:                              # rare (a step written twice): the one O(frames) path
            self.frames[:] = [f for f in self.frames if f[1] != name]
        self.frames.append((time, name))
        self._listed.add(name)
        return target

    def mark_stopped(self, step, message) -> None:
        """Note in the .pvd, after the last frame, that the run stopped at `step` and why.

        Never raises: the frames and their listing are valid without the note."""
        self.stopped = (int(step), str(message))
        if not self._pvd_written:
            return                                # no frame, no collection to annotate
        try:
            self._add_to_pvd([(None, xml_comment(f"run stopped at step {int(step)}: {message}"))])
        except OSError:
            pass

    def close(self) -> None:
        """Finish (idempotent): the .pvd is complete after every frame, nothing is left to write;
        the folder's lock is released (unless keep_lock: then release_lock() does it)."""
        self.closed = True
        if not self.keep_lock:
            self.lock.release()

    def release_lock(self) -> None:
        """Let other runs write into the folder (idempotent)."""
        self.lock.release()

    def discard(self) -> None:
        """After a failure: remove the output folder if this writer created it and it is empty."""
        if self.created_dir and not self.frames:
            self.lock.release()
            try:
                self.out_dir.rmdir()
                self.created_dir = False
            except OSError:
                pass

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is not None:
            self.discard()
        self.close()
        return False

    # -- helpers -------------------------------------------------------------------------------
    def _fail(self, message: str) -> OutputError:
        """The OutputError that ends this writer's output (kept in .error for the caller)."""
        self.error = OutputError(message)
        return self.error

    def _frame_mesh(self, step, time, points, displacement, fields, cell_fields):
        """Validate one frame's data; (meshio mesh, time). Nothing is written here."""
        if self.closed:
            raise TensormassError("Writer.write_frame after close()")
        mesh = self.mesh
        n, dim = mesh.n_points, mesh.dim
        time = float(time)
        if not np.isfinite(time):
            raise TensormassError(f"refusing to write frame {step} with time {time}")
        u = self._point_array("displacement", displacement, vector=True)
        if u.shape[1] != dim:
            raise TensormassError(f"displacement must have shape ({n}, {dim}), got {u.shape}")
        if self.deformed or points is None:
            X = mesh.points + u if self.deformed else mesh.points
        else:
            X = self._point_array("points", points, vector=True)
            if X.shape[1] != dim:
                raise TensormassError(f"points must have shape ({n}, {dim}), got {X.shape}")
        point_data = {"displacement": self._pad(u)}
        cell_data = {}
        for key, value in (fields or {}).items():
            arr = np.asarray(value)
            if arr.ndim >= 1 and arr.shape[0] == n:
                point_data[key] = _stored(key, self._pad(self._point_array(key, arr)))
            elif arr.ndim >= 1 and arr.shape[0] == mesh.n_cells:
                cell_data[key] = [_stored(key, part) for part in self._cell_array(key, arr)]
            else:
                raise TensormassError(f"field {key!r} has {arr.shape[0] if arr.ndim else 'no'} rows; expected "
                                      f"{n} (points) or {mesh.n_cells} (cells)")
        for key, value in (cell_fields or {}).items():
            cell_data[key] = [_stored(key, part) for part in self._cell_array(key, value)]
        _check_finite("points", X)
        for key, arr in point_data.items():
            _check_finite(f"point field {key!r}", arr)
        for key, parts in cell_data.items():
            for part in parts:
                _check_finite(f"cell field {key!r}", part)

        m = to_meshio(mesh, pad_to_3d=True)
        m.points = self._pad(X)
        m.point_data = point_data
        m.cell_data.update(cell_data)
        return m, time

    def _write_vtu(self, m, target: Path) -> None:
        """The frame to a temporary name, renamed into place: a reader never sees half a frame."""
        import meshio
        tmp = self.out_dir / f".{target.name}.tmp"
        try:
            meshio.write(tmp, m, file_format="vtu")
            os.replace(tmp, target)
        except BaseException as exc:
            remove_quietly(tmp)
            self.discard()
            kept = f"; the {len(self.frames)} frame(s) written before stay listed in {self.pvd_path}" if self.frames else ""
            if isinstance(exc, OSError):
                raise self._fail(f"cannot write frame {target}: {_reason(exc)}{kept}") from None
            if isinstance(exc, Exception) and not isinstance(exc, TensormassError):
                raise self._fail(f"could not write {target}: {type(exc).__name__}: {exc}") from exc
            raise

    def _add_to_pvd(self, lines) -> None:
        """Put lines [(frame name or None, text)] before the .pvd's closing tags (OSError on failure).

        Appending costs O(1) per frame; the whole file is written (atomically) only for the
        first lines of a run, for a frame written again under the same name, or when the
        closing tags are not where this writer left them (the file was changed under it)."""
        encoded = [(name, f"    {text}\n".encode("utf-8")) for name, text in lines]
        names = {name for name, _ in encoded if name is not None}
        if names & self._listed:
            kept = [(n, b) for n, b in self._lines if n not in names] + encoded
            self._write_whole_pvd(kept)
        elif not (self._pvd_written and self._append_pvd(b"".join(b for _, b in encoded))):
            self._write_whole_pvd(self._lines + encoded)
        else:
            self._lines += encoded

    def _write_whole_pvd(self, lines) -> None:
        write_bytes_atomic(self.pvd_path, _PVD_HEAD + b"".join(b for _, b in lines) + _PVD_TAIL)
        self._lines = lines
        self._pvd_written = True

    def _append_pvd(self, data: bytes) -> bool:
        """One pwrite of data + closing tags where the closing tags are; False when they are not there.

        Only the last len(closing tags) bytes are read; earlier bytes are neither read nor
        written. A short or failed write is undone by putting the closing tags back."""
        try:
            fd = os.open(self.pvd_path, os.O_RDWR)
        except FileNotFoundError:
            return False                          # removed under us: written whole again
        try:
            at = os.fstat(fd).st_size - len(_PVD_TAIL)
            if at < len(_PVD_HEAD) or os.pread(fd, len(_PVD_TAIL), at) != _PVD_TAIL:
                return False
            chunk = data + _PVD_TAIL
            try:
                if os.pwrite(fd, chunk, at) != len(chunk):
                    raise OSError(errno.ENOSPC, "No space left on device (short write)")
            except BaseException:
                _put_back_tail(fd, at)
                raise
            return True
        finally:
            os.close(fd)

    def _make_dir(self) -> None:
        if not self.out_dir.is_dir():
            try:
                self.out_dir.mkdir(parents=True)
            except FileExistsError:
                pass
            except OSError as exc:
                raise self._fail(f"cannot create output folder {self.out_dir}: {_reason(exc)}") from None
            else:
                self.created_dir = True

    def _point_array(self, name, values, vector=False) -> np.ndarray:
        arr = np.asarray(values)
        if arr.dtype.kind not in "biuf":
            raise TensormassError(f"{name} must be numeric, got dtype {arr.dtype}")
        if arr.ndim == 1 and vector and arr.size == self.mesh.n_points * self.mesh.dim:
            arr = arr.reshape(self.mesh.n_points, self.mesh.dim)   # flat dof vector
        if arr.ndim == 0 or arr.shape[0] != self.mesh.n_points or (vector and arr.ndim != 2):
            raise TensormassError(f"{name} must have one row per point ({self.mesh.n_points}), got shape {arr.shape}")
        return np.ascontiguousarray(arr, dtype=np.float64 if arr.dtype.kind == "f" else arr.dtype)

    def _cell_array(self, name, values) -> list:
        arr = np.asarray(values)
        if arr.ndim == 0 or arr.shape[0] != self.mesh.n_cells:
            raise TensormassError(f"cell field {name!r} must have one row per cell ({self.mesh.n_cells}), "
                                  f"got shape {arr.shape}")
        if arr.dtype.kind not in "biuf":
            raise TensormassError(f"cell field {name!r} must be numeric, got dtype {arr.dtype}")
        if self.mesh.dim == 2 and arr.ndim == 2 and arr.shape[1] == 2:
            arr = np.column_stack([arr, np.zeros(len(arr))])
        return [np.ascontiguousarray(arr[a:b]) for a, b in zip(self.block_offsets[:-1], self.block_offsets[1:])]

    def _pad(self, arr: np.ndarray) -> np.ndarray:
        """2D vectors -> 3 components (VTK's vectors and points have 3)."""
        if self.mesh.dim == 2 and arr.ndim == 2 and arr.shape[1] == 2:
            return np.column_stack([arr, np.zeros(len(arr), dtype=arr.dtype)])
        return arr


def _stored(name: str, arr: np.ndarray) -> np.ndarray:
    """The array as the frame stores it: the output fields FIELDS marks single as Float32
    (runtime.physics.fields.frame_dtype), everything else as it is."""
    dtype = frame_dtype(name, arr)
    return arr if arr.dtype == dtype else arr.astype(dtype)


@contextlib.contextmanager
def _interrupts_deferred():
    """Hold Ctrl-C until the block is done, then deliver it.

    A frame is renamed into place and then listed in the .pvd: an interrupt between the two
    would leave a frame no .pvd lists. Writing one frame takes milliseconds, so SIGINT waits
    for the block (main thread only: signal handlers live there) and is then handed to the
    handler that was in place, as if it had arrived just after."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught = []
    try:
        previous = signal.signal(signal.SIGINT, lambda signum, frame: caught.append(frame))
    except ValueError:                            # not the main interpreter: nothing to hold
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
        if caught:
            if callable(previous):
                previous(signal.SIGINT, caught[0])
            elif previous == signal.SIG_DFL:
                raise KeyboardInterrupt


def _put_back_tail(fd: int, at: int) -> None:
    """After a failed append: the closing tags at `at` again and nothing after them.

    Rewriting bytes the file already has needs no new disk space."""
    try:
        os.pwrite(fd, _PVD_TAIL, at)
        os.ftruncate(fd, at + len(_PVD_TAIL))
    except OSError:
        pass
