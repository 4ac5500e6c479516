"""Write a simulation as a VTU time series with a ParaView .pvd collection.

    writer = Writer("out", mesh)                     # nothing is created yet
    writer.write_frame(step, time, points, u, {"energy": e_per_cell})
    writer.close()

Every frame is a complete .vtu file written to a temporary name and renamed,
and the .pvd that lists the finished frames is rewritten the same way after
each frame: a run that crashes leaves a collection ParaView can open. The
output folder is created with the first frame; if the run ends before any
frame (bad input, a failing first step), discard() removes it again when this
writer created it and it is still empty. Frames with NaN or Inf are refused
(TensormassError) and nothing of them is written.
"""
from __future__ import annotations

import json
import os
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np

from ..generator.pipeline import write_atomic
from .errors import TensormassError

__all__ = ["Writer", "write_bytes_atomic", "write_json_atomic", "write_text_atomic"]


def write_bytes_atomic(path, data: bytes) -> None:
    """Bytes written atomically (temporary file + rename; see generator.pipeline.write_atomic)."""
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


class Writer:
    """A VTU series <out_dir>/<name>_<step>.vtu and its collection <out_dir>/<name>.pvd.

    deformed=False writes the given points (reference positions by default)
    with the displacement as point data, for ParaView's "Warp By Vector";
    deformed=True writes the reference points moved by the displacement.
    """

    def __init__(self, out_dir, mesh, name: str = "frame", deformed: bool = False):
        if not name or "/" in name or "\\" in name or name.startswith("."):
            raise TensormassError(f"bad output name {name!r}")
        self.out_dir = Path(out_dir)
        if self.out_dir.exists() and not self.out_dir.is_dir():
            raise TensormassError(f"output path {self.out_dir} exists and is not a folder")
        self.mesh = mesh
        self.name = name
        self.deformed = deformed
        self.frames: list = []          # [(time, file name)] of finished frames
        self.created_dir = False
        self.closed = False
        self._offsets = np.concatenate([[0], np.cumsum([len(b) for b in mesh.blocks])]).astype(np.int64)

    def set_mesh(self, mesh) -> None:
        """Frames from now on are of this mesh (adaptive refinement changes it during a run)."""
        self.mesh = mesh
        self._offsets = np.concatenate([[0], np.cumsum([len(b) for b in mesh.blocks])]).astype(np.int64)

    # -- paths ---------------------------------------------------------------------------------
    @property
    def pvd_path(self) -> Path:
        return self.out_dir / f"{self.name}.pvd"

    def frame_path(self, step: int) -> Path:
        return self.out_dir / f"{self.name}_{int(step):06d}.vtu"

    # -- writing ---------------------------------------------------------------------------------
    def write_frame(self, step, time, points, displacement, fields=None, cell_fields=None) -> Path:
        """Write one frame and update the .pvd; returns the frame's path.

        points: the coordinates to write, (n_points, dim) (None: the mesh's
        reference points); displacement: (n_points, dim). fields: name ->
        array with one row per point (point data) or, when the length differs,
        one row per cell in block order (cell data); cell_fields: always cell
        data. 2-component vectors of 2D meshes are padded with z = 0.
        """
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
                point_data[key] = self._pad(self._point_array(key, arr))
            elif arr.ndim >= 1 and arr.shape[0] == mesh.n_cells:
                cell_data[key] = self._cell_array(key, arr)
            else:
                raise TensormassError(f"field {key!r} has {arr.shape[0] if arr.ndim else 'no'} rows; expected "
                                      f"{n} (points) or {mesh.n_cells} (cells)")
        for key, value in (cell_fields or {}).items():
            cell_data[key] = self._cell_array(key, value)
        _check_finite("points", X)
        for key, arr in point_data.items():
            _check_finite(f"point field {key!r}", arr)
        for key, parts in cell_data.items():
            for part in parts:
                _check_finite(f"cell field {key!r}", part)

        import meshio

        from .mesh import to_meshio
        m = to_meshio(mesh, pad_to_3d=True)
        m.points = self._pad(X)
        m.point_data = point_data
        m.cell_data.update(cell_data)
        target = self.frame_path(step)
        self._make_dir()
        tmp = self.out_dir / f".{target.name}.tmp"
        try:
            meshio.write(tmp, m, file_format="vtu")
            os.replace(tmp, target)
        except BaseException as exc:
            _remove(tmp)
            self.discard()
            if isinstance(exc, Exception) and not isinstance(exc, TensormassError):
                raise TensormassError(f"could not write {target}: {type(exc).__name__}: {exc}") from exc
            raise
        self.frames = [f for f in self.frames if f[1] != target.name] + [(time, target.name)]
        self._write_pvd()
        return target

    def close(self) -> None:
        """Finish (idempotent): the .pvd is already up to date after every frame."""
        if not self.closed and self.frames:
            self._write_pvd()
        self.closed = True

    def discard(self) -> None:
        """After a failure: remove the output folder if this writer created it and it is empty."""
        if self.created_dir and not self.frames:
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
            self.closed = True
        else:
            self.close()
        return False

    # -- helpers -------------------------------------------------------------------------------
    def _make_dir(self) -> None:
        if not self.out_dir.is_dir():
            try:
                self.out_dir.mkdir(parents=True)
            except FileExistsError:
                pass
            except OSError as exc:
                raise TensormassError(f"cannot create output folder {self.out_dir}: {exc}") from None
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
        return [np.ascontiguousarray(arr[a:b]) for a, b in zip(self._offsets[:-1], self._offsets[1:])]

    def _pad(self, arr: np.ndarray) -> np.ndarray:
        """2D vectors -> 3 components (VTK's vectors and points have 3)."""
        if self.mesh.dim == 2 and arr.ndim == 2 and arr.shape[1] == 2:
            return np.column_stack([arr, np.zeros(len(arr), dtype=arr.dtype)])
        return arr

    def _write_pvd(self) -> None:
        rows = "\n".join(f'    <DataSet timestep="{t!r}" group="" part="0" file={quoteattr(f)}/>'
                         for t, f in self.frames)
        text = ('<?xml version="1.0"?>\n'
                '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">\n'
                '  <Collection>\n'
                f"{rows}\n"
                '  </Collection>\n'
                '</VTKFile>\n')
        write_text_atomic(self.pvd_path, text)
