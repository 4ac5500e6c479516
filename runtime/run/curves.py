"""History curves of a run: one PNG with a panel per group of the summary's per-step history.

    summary = json.loads(Path("run.json").read_text())
    plot_history(summary, "run.png")                          # every group the summary has
    plot_history(summary, "run.png", what=["probes", "energy"])

Groups (GROUPS), each drawn when the summary has it (summary["per_step"], see the README's
"Histories"): probes (every displacement component of every probe), energy (elastic, kinetic,
external work), reactions (force components per region; the moments in a panel of their own),
solver (Newton and linear iterations per step). The x axis is the time [s] of a dynamic run and
the load step of a static one (summary["solver"] == "static"). Units come from summary["units"]
(the keys of runtime.run.history.units: "probes", "elastic", "reactions.force", ...), with SI
defaults for summaries written before it existed. A value that was not evaluated (None / null)
is left out of its curve, never drawn as zero; runs of at most MARKER_LIMIT points get markers
so that a single-step run still shows its point. The title is the scene name.

Errors (TensormassError, nothing written): no per-step history, lists whose lengths differ
from "step", an unknown group in `what`, nothing to draw of the groups asked for, a path that
is not *.png or cannot be written. The PNG is written atomically.
"""
from __future__ import annotations

import io

import numpy as np

from ..base.errors import TensormassError
from .output import OutputError, check_png_path
from ..base.files import write_bytes_atomic

__all__ = ["plot_history", "render_history", "history_panels", "history_groups", "GROUPS"]

GROUPS = ("probes", "energy", "reactions", "solver")
MARKER_LIMIT = 40
_DEFAULT_UNITS = {"time": "s", "elastic": "J", "kinetic": "J", "external_work": "J", "probes": "m",
                  "reactions.force": "N", "reactions.moment": "N m"}
_ENERGY = (("elastic", "elastic"), ("kinetic", "kinetic"), ("external_work", "external work"))
_SOLVER = (("newton", "Newton iterations"), ("linear", "linear iterations"))
_AXES = "xyz"


def plot_history(summary: dict, path, what=None, size=(1000, None)) -> list:
    """Write the history curves of a run summary as a PNG; returns the panels drawn (titles).

    what: None (every group the summary has), a list of GROUPS names, or a comma-separated
    string of them. size: (width, height) in pixels; height None: 250 per panel + the title."""
    target = check_png_path(path, "plot")
    png, panels = render_history(summary, what=what, size=size)
    try:
        write_bytes_atomic(target, png)
    except OSError as exc:
        raise OutputError(f"cannot write the plot {target}: {exc.strerror or exc}") from None
    return panels


def history_groups(summary: dict) -> list:
    """The GROUPS that the summary's per-step history has data for, in GROUPS order."""
    return [p["group"] for p in _panels(summary, GROUPS)] if _per_step(summary) else []


def history_panels(summary: dict, what=None) -> tuple:
    """What plot_history draws: (x values, x label, [{group, title, ylabel, curves: [(label, y)]}]).

    y has NaN where the summary has None (not evaluated); those points are left out."""
    groups = _groups(what)
    panels = _panels(summary, groups)
    if not panels:
        have = history_groups(summary)
        raise TensormassError(f"nothing to plot: the summary's per-step history has no {', '.join(groups)} "
                              f"data (it has: {', '.join(have) or 'none'})")
    x, xlabel = _x_axis(summary)
    return x, xlabel, panels


def render_history(summary: dict, what=None, size=(1000, None)) -> tuple:
    """(PNG bytes, panel titles): plot_history without the file."""
    x, xlabel, panels = history_panels(summary, what)
    return _draw(summary, x, xlabel, panels, size), [p["title"] for p in panels]


# ============================================================================== reading the summary


def _groups(what) -> list:
    if what is None:
        return list(GROUPS)
    names = [w.strip() for w in (what.split(",") if isinstance(what, str) else what)]
    names = [w for w in names if w]
    unknown = [w for w in names if w not in GROUPS]
    if unknown or not names:
        raise TensormassError(f"unknown plot group(s) {', '.join(unknown) or '(none given)'}; "
                              f"known: {', '.join(GROUPS)}")
    return list(dict.fromkeys(names))


def _per_step(summary) -> dict:
    if not isinstance(summary, dict):
        raise TensormassError("not a run summary (expected a JSON object)")
    per = summary.get("per_step")
    if not isinstance(per, dict) or not isinstance(per.get("step"), list) or not per["step"]:
        raise TensormassError("the summary has no per-step history (\"per_step\" with a \"step\" list); "
                              "it was written by a run that stopped before its first step, or is not a run summary")
    return per


def _floats(values, n: int, key: str) -> np.ndarray:
    """A list of numbers or None (n long) as floats, NaN where None."""
    if not isinstance(values, list) or len(values) != n:
        got = len(values) if isinstance(values, list) else type(values).__name__
        raise TensormassError(f"per_step.{key}: {got} entries for {n} steps")
    out = np.full(n, np.nan)
    for i, v in enumerate(values):
        if v is None:
            continue
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise TensormassError(f"per_step.{key}[{i}]: {v!r} is not a number")
        out[i] = float(v)
    return out


def _rows(values, n: int, key: str) -> np.ndarray:
    """A list of vectors or None (n long) as an (n, k) float array, NaN rows where None."""
    if not isinstance(values, list) or len(values) != n:
        got = len(values) if isinstance(values, list) else type(values).__name__
        raise TensormassError(f"per_step.{key}: {got} entries for {n} steps")
    width = max((len(v) for v in values if isinstance(v, list)), default=0)
    out = np.full((n, width), np.nan)
    for i, v in enumerate(values):
        if v is None:
            continue
        if not isinstance(v, list) or len(v) != width:
            raise TensormassError(f"per_step.{key}[{i}]: expected a list of {width} numbers or null, got {v!r}")
        out[i] = [np.nan if c is None else float(c) for c in v]
    return out


def _unit(summary, key: str) -> str:
    units = summary.get("units")
    unit = units.get(key) if isinstance(units, dict) else None
    return str(unit) if unit is not None else _DEFAULT_UNITS.get(key, "")


def _curve(label: str, y: np.ndarray):
    return (label, y) if np.isfinite(y).any() else None


def _components(width: int) -> list:
    return [_AXES[c] for c in range(width)] if width <= 3 else [str(c) for c in range(width)]


def _panels(summary, groups) -> list:
    """[{group, title, ylabel, curves [(label, y)]}] of the groups with data, in order."""
    per = _per_step(summary)
    n = len(per["step"])
    panels = []
    for group in groups:
        if group == "probes" and isinstance(per.get("probes"), dict) and per["probes"]:
            curves = []
            for name, values in per["probes"].items():
                arr = _rows(values, n, f"probes.{name}")
                for c, axis in enumerate(_components(arr.shape[1])):
                    curves.append(_curve(f"{name} u{axis}", arr[:, c]))
            _add(panels, group, "probe displacements", f"displacement [{_unit(summary, 'probes')}]", curves)
        elif group == "energy":
            curves = [_curve(label, _floats(per[key], n, key)) for key, label in _ENERGY if key in per]
            _add(panels, group, "energies", f"energy [{_unit(summary, 'elastic')}]", curves)
        elif group == "reactions" and isinstance(per.get("reactions"), dict) and per["reactions"]:
            forces, moments = [], []
            for name, parts in per["reactions"].items():
                if not isinstance(parts, dict):
                    raise TensormassError(f"per_step.reactions.{name}: expected {{\"force\": ..., \"moment\": ...}}")
                if "force" in parts:
                    arr = _rows(parts["force"], n, f"reactions.{name}.force")
                    forces += [_curve(f"{name} F{a}", arr[:, c]) for c, a in enumerate(_components(arr.shape[1]))]
                if "moment" in parts:
                    arr = _rows(parts["moment"], n, f"reactions.{name}.moment")
                    axes = ["z"] if arr.shape[1] == 1 else _components(arr.shape[1])
                    moments += [_curve(f"{name} M{a}", arr[:, c]) for c, a in enumerate(axes)]
            _add(panels, group, "reaction forces", f"force [{_unit(summary, 'reactions.force')}]", forces)
            _add(panels, group, "reaction moments", f"moment [{_unit(summary, 'reactions.moment')}]", moments)
        elif group == "solver":
            curves = [_curve(label, _floats(per[key], n, key)) for key, label in _SOLVER if key in per]
            _add(panels, group, "solver", "iterations per step", curves)
    return panels


def _add(panels, group, title, ylabel, curves) -> None:
    curves = [c for c in curves if c is not None]
    if curves:
        panels.append(dict(group=group, title=title, ylabel=ylabel, curves=curves))


def _x_axis(summary) -> tuple:
    per = _per_step(summary)
    n = len(per["step"])
    if summary.get("solver") == "static" or "time" not in per:
        return _floats(per["step"], n, "step"), "load step"
    x = _floats(per["time"], n, "time")
    if not np.isfinite(x).all():
        return _floats(per["step"], n, "step"), "step"
    return x, f"time [{_unit(summary, 'time')}]"


def _name(summary) -> str:
    name = summary.get("name")
    if not name and isinstance(summary.get("scene"), dict):
        name = summary["scene"].get("name")
    return str(name) if name else "run"


# ============================================================================== drawing


def _draw(summary, x, xlabel, panels, size) -> bytes:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    width = int(size[0])
    height = int(size[1]) if size[1] is not None else 115 + 250 * len(panels)
    if not (200 <= width <= 8000 and 200 <= height <= 20000):
        raise TensormassError(f"plot: size {width} x {height} pixels is out of range")
    fig = Figure(figsize=(width / 100.0, height / 100.0), dpi=100, facecolor="white")
    FigureCanvasAgg(fig)
    # fixed margins (pixels): a layout engine costs seconds for five panels; room on the right
    # for the legends, at the bottom for the x label, at the top for the title
    fig.subplots_adjust(left=110 / width, right=1 - 190 / width, top=1 - 75 / height, bottom=55 / height,
                        hspace=0.3)
    axes = fig.subplots(len(panels), 1, sharex=True, squeeze=False)[:, 0]
    marker = "o" if len(x) <= MARKER_LIMIT else None
    for ax, panel in zip(axes, panels):
        for label, y in panel["curves"]:
            ok = np.isfinite(y)
            # None entries are gaps: the curve joins the evaluated points only
            ax.plot(x[ok], y[ok], marker=marker, markersize=3.5, linewidth=1.3, label=label)
        ax.set_title(panel["title"], fontsize=10, loc="left")
        ax.set_ylabel(panel["ylabel"])
        ax.ticklabel_format(axis="y", style="sci", scilimits=(-3, 4), useMathText=True)   # short tick labels
        ax.grid(True, linewidth=0.4, alpha=0.5)
        ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
        if panel["group"] == "solver":
            ax.yaxis.get_major_locator().set_params(integer=True)
    axes[-1].set_xlabel(xlabel)
    if xlabel == "load step":
        axes[-1].xaxis.get_major_locator().set_params(integer=True)
    status = summary.get("status")
    extra = f" ({status})" if status not in (None, "ok") else ""
    stride = _per_step(summary).get("stride")
    kept = f" (every {stride}th step kept)" if isinstance(stride, int) and stride > 1 else ""
    fig.suptitle(f"{_name(summary)}{extra}: {len(x)} steps{kept}", fontsize=12)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100, facecolor="white", metadata={"Software": None})
    return buf.getvalue()
