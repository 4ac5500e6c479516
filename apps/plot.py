"""`tensormass plot`: history curves of a run summary as a PNG.

    tensormass plot run.json                      -> run.png beside it
    tensormass plot run.json -o curves.png --what probes,energy

The summary is the JSON a run writes (`tensormass run SCENE --json run.json`); its per-step
history is drawn by runtime.run.curves.plot_history (a panel per group: probes, energy, reactions,
solver). A file that is not a tensormass summary, a missing file, or one without per-step data
is refused (exit 2) and nothing is written.
"""
from __future__ import annotations

import json
from pathlib import Path

from ..runtime.base.errors import TensormassError
from ..runtime.run.output import SUMMARY_FORMAT, check_png_path, is_summary_file
from ..runtime.run.curves import plot_history

__all__ = ["add_plot_command", "cmd_plot"]


def cmd_plot(args) -> int:
    source = Path(args.summary)
    if not source.exists():
        raise TensormassError(f"plot {source}: no such file")
    if source.is_dir():
        raise TensormassError(f"plot {source}: is a folder; give a run summary (.json)")
    if not is_summary_file(source):
        raise TensormassError(f"plot {source}: not a tensormass run summary (no \"format\": \"{SUMMARY_FORMAT}\"; "
                              "write one with `tensormass run SCENE --json SUMMARY.json`)")
    try:
        summary = json.loads(source.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise TensormassError(f"plot {source}: cannot read the summary ({exc})") from None
    out = Path(args.out) if args.out else source.with_suffix(".png")
    check_png_path(out, "-o")
    if out.resolve() == source.resolve():
        raise TensormassError(f"-o {out}: is the summary itself")
    if not out.parent.is_dir():
        raise TensormassError(f"-o {out}: folder {out.parent} does not exist")
    panels = plot_history(summary, out, what=args.what)
    if not args.quiet:
        print(f"wrote {out} ({', '.join(panels)})")
    return 0


def add_plot_command(subparsers) -> None:
    """Add `plot` to an argparse subparsers object."""
    p = subparsers.add_parser("plot", help="draw the per-step history of a run summary (JSON) as a PNG")
    p.add_argument("summary", help="run summary written by `tensormass run SCENE --json SUMMARY.json`")
    p.add_argument("-o", "--out", metavar="PNG", help="output picture (default: the summary's name with .png)")
    p.add_argument("--what", metavar="GROUPS",
                   help="comma-separated groups to draw: probes, energy, reactions, solver (default: all there are)")
    p.add_argument("--quiet", action="store_true", help="print nothing on success")
    p.set_defaults(run=cmd_plot)
