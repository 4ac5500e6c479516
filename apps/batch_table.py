"""The table of a batch study: its CSV (and Parquet) text, written atomically in task order, the
partial rows appended as tasks finish, and the rules for where --out may write (never an input
scene, a folder, a link, or a file batch did not write)."""
from __future__ import annotations

import contextlib
import csv
import io
import json
import math
import os
import stat
import sys
from pathlib import Path

from ..runtime.base.errors import TensormassError
from ..runtime.base.files import check_writable, write_bytes_atomic, write_text_atomic

# A table of ours: a CSV whose header starts with these columns and has these too.
PARQUET_KEY, PARQUET_VALUE = b"tensormass", b"batch-table/1"
PARTIAL_FORMAT = "tensormass-batch-rows/1"
TABLE_FIRST = ("task", "scene")
TABLE_COLUMNS = {"status", "exit_code", "error"}


# ============================================================================== the table


def _columns(rows) -> list:
    cols: dict = {}
    for r in rows:
        for k in r:
            cols.setdefault(k, None)
    return list(cols)


def _cell(value) -> str:
    if value is None:
        return ""
    if isinstance(value, bool):
        return str(value)
    if isinstance(value, float):
        return repr(value) if math.isfinite(value) else str(value)
    return str(value)


def csv_text(rows) -> str:
    cols = _columns(rows)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(cols)
    for r in rows:
        w.writerow([_cell(r.get(c)) for c in cols])
    return buf.getvalue()


def write_table(rows, out) -> list:
    """out (CSV) and, with pyarrow, out with .parquet (its schema marked as ours), each atomically;
    the paths written (a note on stderr when pyarrow is missing)."""
    out = Path(out)
    write_text_atomic(out, csv_text(rows))
    written = [out]
    pa, pq = _pyarrow()
    if pa is None:
        print("batch: pyarrow is not installed: wrote the CSV only (pip install pyarrow for Parquet)",
              file=sys.stderr)
        return written
    columns = {}
    for c in _columns(rows):
        values = [r.get(c) for r in rows]
        try:
            columns[c] = pa.array(values)
        except (pa.ArrowInvalid, pa.ArrowTypeError):
            columns[c] = pa.array([None if v is None else _cell(v) for v in values], type=pa.string())
    buf = pa.BufferOutputStream()
    pq.write_table(pa.table(columns).replace_schema_metadata({PARQUET_KEY: PARQUET_VALUE}), buf)
    parquet = out.with_suffix(".parquet")
    write_bytes_atomic(parquet, buf.getvalue().to_pybytes())
    return written + [parquet]


def _pyarrow():
    """(pyarrow, pyarrow.parquet), or (None, None) without pyarrow."""
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        return None, None
    return pa, pq


# ============================================================================== the table's files


def partial_path(out) -> Path:
    """The rows of a study in progress: <out>.partial (see the module docstring)."""
    out = Path(out)
    return out.with_name(out.name + ".partial")


def _first_bytes(path, n: int = 65536) -> bytes | None:
    """The first n bytes of a regular file (not a link), None for anything else."""
    try:
        if not stat.S_ISREG(os.lstat(path).st_mode):
            return None
        with open(path, "rb") as handle:
            return handle.read(n)
    except OSError:
        return None


def is_batch_table(path) -> bool:
    """A CSV written by tensormass batch: its header starts with task,scene and has status,
    exit_code and error (the columns every row of ours has)."""
    head = _first_bytes(path)
    if not head:
        return False
    line = head.split(b"\n", 1)[0].decode("utf-8", "replace")
    try:
        header = next(csv.reader([line]))
    except (csv.Error, StopIteration):
        return False
    return tuple(header[:2]) == TABLE_FIRST and TABLE_COLUMNS <= set(header)


def _is_partial(path) -> bool:
    head = _first_bytes(path, 4096)
    if not head:
        return False
    try:
        first = json.loads(head.split(b"\n", 1)[0])
    except ValueError:
        return False
    return isinstance(first, dict) and first.get("format") == PARTIAL_FORMAT


def _is_our_parquet(path) -> bool:
    pa, pq = _pyarrow()
    if _first_bytes(path, 4) != b"PAR1":
        return False
    try:
        metadata = pq.read_schema(path).metadata or {}
    except Exception:              # noqa: BLE001 - a file pyarrow cannot read is not ours
        return False
    return metadata.get(PARQUET_KEY) == PARQUET_VALUE


def _same_path(a, b) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return os.path.abspath(a) == os.path.abspath(b)


def check_table_path(out, scenes=()) -> Path:
    """--out, checked before the study (the rules of run --json): refused are a .parquet name (the
    Parquet copy goes beside the CSV), a folder, a missing folder, an input scene, a link, a device,
    an existing file that tensormass batch did not write (the table, its .partial rows, its .parquet
    copy when pyarrow writes one), and a folder this process cannot write in."""
    out = Path(out)
    if out.suffix.lower() == ".parquet":
        raise TensormassError(f"--out {out}: give the CSV table's name (e.g. {out.with_suffix('.csv').name}); "
                              "the Parquet copy is written beside it")
    if out.is_dir():
        raise TensormassError(f"--out {out}: is a folder; give a file name (e.g. {out / 'batch.csv'})")
    if not out.parent.is_dir():
        raise TensormassError(f"--out {out}: folder {out.parent} does not exist")
    files = [(out, is_batch_table, "a table of tensormass batch"),
             (partial_path(out), _is_partial, "rows of tensormass batch")]
    if _pyarrow()[0] is not None:
        files.append((out.with_suffix(".parquet"), _is_our_parquet, "a table of tensormass batch"))
    for path, ours, what in files:
        for scene in scenes:
            if _same_path(path, scene):
                raise TensormassError(f"--out {out}: {path} is an input scene file; give the table another name")
        _check_replaceable(out, path, ours, what)
    check_writable(out.parent, f"--out {out}: folder")
    return out


def _check_replaceable(out: Path, path: Path, ours, what: str) -> None:
    """An existing file at path may only be replaced when it is one of ours."""
    try:
        info = os.lstat(path)
    except FileNotFoundError:
        return
    except OSError as exc:
        raise TensormassError(f"--out {out}: {path}: {exc.strerror or exc}") from None
    if stat.S_ISLNK(info.st_mode):
        raise TensormassError(f"--out {out}: {path} is a symbolic link; refusing to replace it, give another name")
    if not stat.S_ISREG(info.st_mode):
        raise TensormassError(f"--out {out}: {path} exists and is not a regular file; refusing to write there")
    if not ours(path):
        raise TensormassError(f"--out {out}: {path} exists and is not {what}; refusing to replace it, "
                              "remove it or give another name")


def _jsonable(value):
    """A row's value for a JSON line: NaN and infinities as text (JSON has none)."""
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    return value


class PartialRows:
    """<out>.partial: a header line, then one JSON row per finished task, flushed per row."""

    def __init__(self, out: Path, n_tasks: int):
        self.path = partial_path(out)
        self.count = 0
        self.handle = open(self.path, "w", encoding="utf-8")
        self._line({"format": PARTIAL_FORMAT, "tasks": n_tasks, "table": str(out),
                    "note": "rows in the order the tasks finished; the table is written in task order at the end"})

    def _line(self, data) -> None:
        self.handle.write(json.dumps({k: _jsonable(v) for k, v in data.items()}, default=str) + "\n")
        self.handle.flush()

    def add(self, row: dict) -> None:
        self._line(row)
        self.count += 1

    def close(self, remove: bool) -> None:
        self.handle.close()
        if remove:
            with contextlib.suppress(FileNotFoundError):
                os.remove(self.path)
