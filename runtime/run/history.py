"""Per-step histories of a run: bounded in memory, JSON-ready, and as CSV.

    h = History(limit=4096)
    h.add({"step": 1, "time": 0.01, "newton": 3, "linear": 3, "wall": 0.02, "elastic": 1.5,
           "kinetic": 0.1, "external_work": 1.7, "probes": {"tip": [ux, uy, uz]},
           "reactions": {"clamp": {"force": [Fx, Fy, Fz], "moment": [Mx, My, Mz]}}})
    h.to_dict()                       # summary["per_step"]: equally long lists + "stride"
    write_history_csv(path, summary["per_step"], summary["units"])

Bounded: a row is kept when its step is a multiple of `stride`; past `limit` rows the stride
doubles and every row whose step is not a multiple of the new stride is dropped, so a run of
any length keeps between limit/2 and limit rows, evenly spaced, and every list (the nested
probe and reaction lists too) stays aligned with `step`.  `keeps(step)` says beforehand whether
a row will be kept (so costly values are evaluated for kept rows only).

The keys (summary["per_step"]; units in summary["units"], see `units`):

    step, time [s] (statics: the load factor), newton, linear (iterations of that step),
    wall [s] (the step's wall time), elastic, kinetic, external_work [J] (None: not evaluated),
    probes {name: [[ux, uy(, uz)], ...]} [m], reactions {name: {"force": [[Fx, Fy(, Fz)], ...] [N],
    "moment": [[Mx, My, Mz], ...] [N m] (2D: [[Mz], ...])}}, stride; with contact (runtime.contact)
    also contact {"pairs", "min_distance" [m], "ccd_fraction", "penetration" [m]: [...]} and
    obstacles {name: {"force": [[Fx, Fy, Fz], ...] [N], "moment": [...] [N m]}}: the force each
    obstacle receives from the body, its moment about the obstacle's centre.

CSV (write_history_csv): one header line, then one line per kept step; columns step, time [s],
newton, linear, wall [s], elastic [J], kinetic [J], external_work [J], then per probe
``probe.<name>.ux [m]`` (uy, uz), per reaction ``reaction.<name>.Fx [N]`` (Fy, Fz) and
``reaction.<name>.Mx [N m]`` (My, Mz; 2D: Mz only), then ``contact.<key>`` and
``obstacle.<name>.Fx [N]`` .. ``obstacle.<name>.Mz [N m]`` with contact.  Floats as repr (round-trips exactly),
empty where a value was not evaluated; written atomically.
"""
from __future__ import annotations

import csv
import io

from ..base.files import write_text_atomic

__all__ = ["History", "SCALAR_KEYS", "units", "write_history_csv", "csv_columns"]

SCALAR_KEYS = ("step", "time", "newton", "linear", "wall", "elastic", "kinetic", "external_work")
# runtime.contact's record per step (scenes with contact): summary["per_step"]["contact"][key]
_CONTACT_KEYS = ("pairs", "min_distance", "ccd_fraction", "penetration")
_COMPONENTS = ("x", "y", "z")


def units(dim: int = 3, static: bool = False, contact: bool = False) -> dict:
    """summary["units"]: the unit of every per_step key (2D: per unit thickness; contact: its keys too)."""
    thick = "" if dim == 3 else "/m"
    energy = f"J{thick}"
    out = {"step": "1", "time": "1" if static else "s", "newton": "1", "linear": "1", "wall": "s",
           "elastic": energy, "kinetic": energy, "external_work": energy, "probes": "m",
           "reactions.force": f"N{thick}", "reactions.moment": f"N m{thick}"}
    if contact:
        out.update({"contact.pairs": "1", "contact.min_distance": "m", "contact.ccd_fraction": "1",
                    "contact.penetration": "m", "obstacles.force": "N", "obstacles.moment": "N m"})
    return out


class History:
    """Per-step rows, bounded: those of the steps that are multiples of `stride` (plus running totals)."""

    def __init__(self, limit: int = 4096):
        self.limit = int(limit)
        self.columns: dict = {k: [] for k in SCALAR_KEYS}   # flat key (tuple) or scalar name -> list
        self.stride = 1
        self.wall_total = 0.0
        self.first_wall = None
        self.last = {}

    @property
    def rows(self) -> dict:
        """The scalar columns (step, time, ...)."""
        return {k: self.columns[k] for k in SCALAR_KEYS}

    def keeps(self, step: int) -> bool:
        """Whether a row for this step would be kept now."""
        return step % self.stride == 0

    def add(self, row: dict) -> None:
        self.wall_total += row["wall"]
        if self.first_wall is None:
            self.first_wall = row["wall"]
        self.last = row
        if not self.keeps(row["step"]):
            return
        n = len(self.columns["step"])
        flat = _flatten(row)
        for key in flat:
            if key not in self.columns:                 # a probe or reaction first seen now
                self.columns[key] = [None] * n
        try:
            for key, values in self.columns.items():
                values.append(flat.get(key))
        finally:
            # Ctrl-C (KeyboardInterrupt) between two appends would leave columns of different
            # lengths in the interrupted run's summary: the row is dropped whole instead
            if any(len(values) != n + 1 for values in self.columns.values()):
                for values in self.columns.values():
                    del values[n:]
        if n + 1 > self.limit:
            keep = [i for i, k in enumerate(self.columns["step"]) if k % (2 * self.stride) == 0]
            self.columns = {key: [values[i] for i in keep] for key, values in self.columns.items()}
            self.stride *= 2

    def to_dict(self) -> dict:
        out = {k: list(self.columns[k]) for k in SCALAR_KEYS}
        out["probes"], out["reactions"] = {}, {}
        for key, values in self.columns.items():
            if key in SCALAR_KEYS:
                continue
            if key[0] == "probes":
                out["probes"][key[1]] = list(values)
            elif key[0] == "contact":
                out.setdefault("contact", {})[key[1]] = list(values)
            elif key[0] == "obstacles":
                out.setdefault("obstacles", {}).setdefault(key[1], {})[key[2]] = list(values)
            else:
                out["reactions"].setdefault(key[1], {})[key[2]] = list(values)
        out["stride"] = self.stride
        return out


def _vector(x):
    if x is None:
        return None
    try:
        return [float(v) for v in x]
    except TypeError:                  # a scalar (a 2D moment)
        return [float(x)]


def _flatten(row: dict) -> dict:
    flat = {k: row.get(k) for k in SCALAR_KEYS}
    for name, value in (row.get("probes") or {}).items():
        flat[("probes", name)] = _vector(value)
    for name, value in (row.get("reactions") or {}).items():
        flat[("reactions", name, "force")] = _vector(value.get("force"))
        flat[("reactions", name, "moment")] = _vector(value.get("moment"))
    contact = row.get("contact")
    if contact:
        for key in _CONTACT_KEYS:
            flat[("contact", key)] = contact.get(key)
        for name, value in contact.get("obstacles", {}).items():
            flat[("obstacles", name, "force")] = _vector(value.get("force"))
            flat[("obstacles", name, "moment")] = _vector(value.get("moment"))
    return flat


# --------------------------------------------------------------------------- CSV


def _width(values) -> int:
    return max((len(v) for v in values if v is not None), default=0)


def csv_columns(per_step: dict, unit: dict) -> list:
    """[(header, getter(i))] of every CSV column, in order."""
    unit = unit or {}

    def label(name, key):
        u = unit.get(key)
        return name if u in (None, "1", "") else f"{name} [{u}]"

    cols = [(label(k, k), (lambda k: lambda i: per_step[k][i])(k)) for k in SCALAR_KEYS if k in per_step]
    for name, values in (per_step.get("probes") or {}).items():
        for c in range(_width(values)):
            cols.append((label(f"probe.{name}.u{_COMPONENTS[c]}", "probes"), _getter(values, c)))
    for name, parts in (per_step.get("reactions") or {}).items():
        force, moment = parts.get("force", []), parts.get("moment", [])
        for c in range(_width(force)):
            cols.append((label(f"reaction.{name}.F{_COMPONENTS[c]}", "reactions.force"), _getter(force, c)))
        m = _width(moment)
        for c in range(m):
            axis = "z" if m == 1 else _COMPONENTS[c]
            cols.append((label(f"reaction.{name}.M{axis}", "reactions.moment"), _getter(moment, c)))
    for key, values in (per_step.get("contact") or {}).items():
        cols.append((label(f"contact.{key}", f"contact.{key}"), (lambda v: lambda i: v[i])(values)))
    for name, parts in (per_step.get("obstacles") or {}).items():
        for part, letter, unit_key in (("force", "F", "obstacles.force"), ("moment", "M", "obstacles.moment")):
            values = parts.get(part, [])
            for c in range(_width(values)):
                cols.append((label(f"obstacle.{name}.{letter}{_COMPONENTS[c]}", unit_key), _getter(values, c)))
    return cols


def _getter(values, c):
    return lambda i: None if values[i] is None else values[i][c]


def _cell(x) -> str:
    if x is None:
        return ""
    if isinstance(x, bool):
        return str(int(x))
    if isinstance(x, int):
        return str(x)
    return repr(float(x))


def write_history_csv(path, per_step: dict, units: dict) -> None:
    """The per-step history as CSV (see the module doc), written atomically."""
    cols = csv_columns(per_step, units)
    n = len(per_step.get("step", []))
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow([h for h, _ in cols])
    for i in range(n):
        writer.writerow([_cell(get(i)) for _, get in cols])
    write_text_atomic(path, buf.getvalue())
