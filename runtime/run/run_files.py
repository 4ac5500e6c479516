"""What a run leaves on disk: the same files from Python and from the command line.

    files = RunFiles(scene, out=None, json_path=None, overwrite=False)
    files.prepare()                          # checks only (output folder, summary paths): nothing written
    sim = Simulation(scene, output=files)    # Simulation(scene) makes one itself from [output]
    data = files.finish(summary, stopped)    # the summary dict, written where asked

The output folder ([output] dir, or `out`: --out / Simulation(output=...)) receives the VTU
frames and their .pvd (runtime.run.output.Writer) and, beside them, ``summary.json``: the run summary
(also for a run that stopped, with its status and message) and ``summary.csv``: its per-step
history (runtime.run.history). ``json_path`` (--json F) writes one more copy elsewhere, with its
history beside it (F with .csv). On request ([output] picture / plot, run --picture / --plot):
``<field>.png``, the deformed body coloured by a field at the end of the run (runtime.run.picture;
not drawn for a run that stopped: its last state is not a result), and ``summary.png``, the
history curves (runtime.run.curves; the same picture as `tensormass plot summary.json`).
A run that ends before its first frame leaves no folder behind. The folder is locked from the
first frame until the summary is written (runtime.run.lock.FolderLock): a second run into the
same folder meanwhile is refused, naming the first one's pid.

Everything that can be refused is refused before the first step: in prepare(), before the model is built, an unwritable
folder, frames or a .pvd that an earlier run of ours did not write, a summary path that holds
anything but one of our summaries, a history/picture file in a folder whose summary.json is not
ours (all unless overwrite), a picture or plot asked without an output folder, a folder another
run is writing into, and two files of this run at one path (--json s.csv would be its own
history, --json onto the folder's history or a picture); in check_outputs(sim), once the model
is built (Simulation calls it before its first step), a picture field the kernels cannot give and
a mesh, view or clip the picture cannot draw (a picture of the rest state is rendered, not written).
The default field (von Mises) is not refused: where the kernels give no stress (co-rotational
shells) the displacement is drawn instead, and the summary says so.

The picture and the plot are optional: when one of them cannot be written after a run that
reached its end (a mesh changed by a cut, a full disk), the run keeps its exit code 0; the
summary has a warning of kind "output" naming the file and the reason (and "picture_error" /
"plot_error" in its "output"), and its status is "warnings". Exit code 2 means bad input found
before the first step, never a late failure of an optional file.
"""
from __future__ import annotations

import os
from pathlib import Path

from ..base.errors import EXIT_OK, TensormassError
from .curves import plot_history
from .history import write_history_csv
from .output import SUMMARY_FORMAT, Writer, check_summary_path, is_summary_file, write_summary
from ..physics.fields import check_available, has_stress
from ..scene.parser import PICTURE_DEFAULT
from . import picture as pictures

__all__ = ["RunFiles", "SUMMARY_NAME", "summary_mapping"]

SUMMARY_NAME = "summary.json"


class RunFiles:
    """The files of one run of `scene` (see the module docstring).

    out: a folder overriding scene.output.dir (None: the scene's); dir_from: how the folder was
    chosen, said in the summary (runtime/base/paths.py: scene paths are relative to the scene file,
    given ones to the working directory).
    """

    def __init__(self, scene, out=None, json_path=None, overwrite: bool = False, dir_from: str | None = None):
        self.scene = scene
        folder = out if out is not None else scene.output.dir      # the scene itself is left as it is
        self.out_dir = Path(folder) if folder else None
        self.dir_from = dir_from or ("[output] dir, relative to the scene file" if out is None else
                                     "given, relative to the working directory")
        self.json_path = json_path
        self.overwrite = overwrite
        self.mesh = scene.load_mesh()
        self.writer = Writer(self.out_dir, self.mesh, overwrite=overwrite) if self.out_dir is not None else None
        if self.writer is not None:
            self.writer.keep_lock = True         # the folder stays locked until finish() wrote the summary
        self.summary_path = None if self.out_dir is None else self.out_dir / SUMMARY_NAME
        self.picture = scene.output.picture              # a field name, or None
        self.picture_named = scene.output.picture_named  # named: drawn or refused, never replaced
        self.plot = scene.output.plot
        self.picture_note = None                         # why the default field was not drawn
        self.data = None
        self._prepared = False

    def prepare(self) -> None:
        """Every check before the run (idempotent); writes nothing."""
        if self._prepared:
            return
        scene = self.scene
        self.json_path = check_summary_path(self.json_path, scene_file=scene.source, writer=self.writer)
        self._check_collisions()
        if self.json_path is not None:
            self._check_beside(self.json_path, [self.json_path.with_suffix(".csv")])
        if (self.picture or self.plot) and self.out_dir is None:
            what = "output.picture" if self.picture else "output.plot"
            raise TensormassError(f"{what}: pictures go to the output folder; set [output] dir (or --out)")
        if self.writer is not None:
            self.writer.prepare()
            if self.out_dir.is_dir():        # else it is created with the first frame: nothing there yet
                self._check_folder_summary()
                self._check_folder_extras()
        self._prepared = True

    def check_outputs(self, sim) -> None:
        """The checks that need the model (Simulation calls this before its first step; writes
        nothing): the picture's field is one the kernels give, and the mesh is one the picture
        module can draw with the scene's view and clip (runtime.run.picture.check_picture: the rest
        state rendered in memory).

        The default field (picture = true, a bare --picture: von Mises) falls back to the
        displacement where a kernel gives no stress (co-rotational shells): the picture is then
        <dir>/displacement.png, and the summary's output says why (picture_note). A field the scene
        names (picture = "von_mises") is drawn or refused."""
        if not self.picture:
            return
        if self.picture == PICTURE_DEFAULT and not self.picture_named:
            bare = next((p for p in sim.model.parts if not has_stress(p.kernel)), None)
            if bare is not None:
                kernel = f"{bare.element}/{bare.law}/{bare.quadrature}"
                self._fall_back_to_displacement(f"{PICTURE_DEFAULT} needs the stress records of every kernel, "
                                                f"and the kernel for {kernel} gives none")
        field = self.picture
        refused = f"picture of {field!r} ([output] picture / --picture) cannot be drawn for this scene, refused " \
                  "before the first step: "
        if field not in ("displacement", "u"):
            try:
                check_available(sim.model, [field], sim._field_providers(), key="picture",
                                remedy="draw the displacement (--picture displacement)")
            except TensormassError as exc:
                raise TensormassError(f"{refused}{exc}") from None
        try:
            pictures.check_picture(sim.model)             # the scene's view and clip included
        except TensormassError as exc:       # the mesh, view or clip: no other field would help
            raise TensormassError(f"{refused}{exc}") from None

    def _fall_back_to_displacement(self, why: str) -> None:
        """The default picture field is not available: draw the displacement, its own file checked
        like the one it replaces (prepare())."""
        self.picture = "displacement"
        self.picture_note = f"the displacement is drawn: {why}"
        self._check_collisions()
        if self.writer is not None and self.out_dir.is_dir():
            self._check_folder_extras()

    @property
    def picture_path(self):
        return self.out_dir / f"{self.picture}.png" if self.picture else None

    @property
    def plot_path(self):
        return self.summary_path.with_suffix(".png") if self.plot else None

    def _extras(self) -> list:
        """The files beside the folder's summary: its history, and the pictures asked for."""
        return [p for p in (self.summary_path.with_suffix(".csv"), self.picture_path, self.plot_path) if p]

    def _check_collisions(self) -> None:
        """No two files of this run at one path; --json may name the folder's own summary.json
        (written once), nothing else of the folder's."""
        path = self.json_path
        if path is None:
            return
        history = path.with_suffix(".csv")
        if path.suffix.lower() == ".csv":
            raise TensormassError(f"--json {path}: the summary's per-step history is written beside it under "
                                  f"the same name with .csv ({history.name}), which is the summary itself; give "
                                  f"the summary another name (e.g. {path.with_suffix('.json').name})")
        if self.out_dir is None or _same_path(path, self.summary_path):
            return
        for mine in (path, history):
            for theirs in self._extras():
                if _same_path(mine, theirs):
                    what = "the summary" if mine == path else f"its history {history}"
                    raise TensormassError(f"--json {path}: {what} would be written over {theirs}, a file of "
                                          "this run in the output folder; give the summary another name")

    def _check_folder_extras(self) -> None:
        self._check_beside(self.summary_path, self._extras())

    def _check_beside(self, summary, paths) -> None:
        """History and pictures beside a summary replace earlier ones of ours (that summary is ours)."""
        ours = is_summary_file(summary)
        for path in paths:
            if _same_path(path, self.scene.source or ""):
                raise TensormassError(f"output file {path}: is the scene file; give the summary another name")
            if os.path.lexists(path) and not (self.overwrite or (ours and path.is_file() and not path.is_symlink())):
                raise TensormassError(f"output file {path}: exists and was not written by an earlier tensormass "
                                      f"run (no summary of ours beside it, {summary.name}); refusing to replace "
                                      "it (--overwrite / overwrite=True replaces it)")

    def _check_folder_summary(self) -> None:
        """summary.json in the folder: replaced when it is one of ours, or with overwrite (like frames)."""
        path = self.summary_path
        if self.overwrite and path.is_file() and not path.is_symlink():
            return
        try:
            check_summary_path(path, scene_file=self.scene.source, writer=self.writer, what="output file")
        except TensormassError as exc:
            raise TensormassError(f"{exc} (--overwrite / overwrite=True replaces it)") from None

    # -- after the run ---------------------------------------------------------------------------
    def abandon(self) -> None:
        """A run that failed outside the steps (bad input found late, a bug): no empty folder left."""
        if self.writer is not None:
            self.writer.close()
            self.writer.discard()
            self.writer.release_lock()

    def finish(self, summary, stopped=None, sim=None) -> dict:
        """Close the frames, write the summary (JSON, and its history as CSV) where asked, and the
        pictures asked for (from sim, the Simulation, at its final state); the summary dict.

        stopped: the RunStopped / RunInterrupted that ended the run, None for a result we stand
        behind. Raises the writer's OutputError when a frame could not be written (disk full).
        The folder's lock is released at the end, whatever happens.
        """
        try:
            return self._finish(summary, stopped, sim)
        finally:
            if self.writer is not None:
                self.writer.release_lock()

    def _finish(self, summary, stopped, sim) -> dict:
        writer = self.writer
        if writer is not None:
            writer.close()
            if writer.error is not None:
                raise writer.error
            if stopped is not None:
                if writer.stopped is None:
                    writer.mark_stopped(_steps_done(summary), f"run {stopped.status}: {stopped}")
                writer.discard()
        self.data = data = self.summary_data(summary, stopped)
        if data["output"] is not None and writer.frames:
            # the optional files first, so that the summary says which of them failed and why
            data["output"].update(self._pictures(data, stopped, sim))
            data["output"].update(self._plot(data))
        for path in self._summary_paths():
            write_summary(path, data)
            if data.get("per_step"):
                write_history_csv(path.with_suffix(".csv"), data["per_step"], data.get("units") or {})
        if self.json_path is not None:
            data["output_json"] = str(self.json_path)
        return data

    def _pictures(self, data, stopped, sim) -> dict:
        """The picture entries of data["output"] (its path; the picture drawn here). A picture that
        cannot be drawn after the run is a warning (_optional_failed), not an error."""
        out = {"picture": None}
        if not self.picture:
            return out
        if stopped is not None or sim is None:
            out["picture_skipped"] = ("the run stopped: its last state is not a result to picture" if stopped
                                      else "no simulation state to draw")
            return out
        path = self.picture_path
        try:
            pictures.picture_of_simulation(sim, path, self.picture, step=sim.step, time=sim.time)
        except (TensormassError, OSError) as exc:
            out["picture_error"] = _optional_failed(data, "picture", path, exc)
            return out
        out["picture"] = str(path)
        if self.picture_note:
            out["picture_note"] = self.picture_note
        return out

    def _plot(self, data) -> dict:
        """The plot entries of data["output"]: the history curves drawn (runtime.run.curves), or the
        warning saying why not."""
        if not self.plot or not data.get("per_step"):
            return {"plot": None}
        path = self.plot_path
        try:
            plot_history(data, path)
        except (TensormassError, OSError) as exc:
            return {"plot": None, "plot_error": _optional_failed(data, "plot", path, exc)}
        return {"plot": str(path)}

    def _summary_paths(self) -> list:
        """The folder's summary (when the folder holds frames of this run) and --json's, once each."""
        paths = []
        if self.writer is not None and self.writer.frames:
            paths.append(self.summary_path)
        if self.json_path is not None and not any(_same_path(self.json_path, p) for p in paths):
            paths.append(self.json_path)
        return paths

    def summary_data(self, summary, stopped) -> dict:
        """The summary dict: the runtime's Summary (when there is one), how the run ended, scene, output."""
        scene, writer = self.scene, self.writer
        output = None if writer is None else {
            "dir": str(self.out_dir), "pvd": str(writer.pvd_path) if writer.frames else None,
            "frames": len(writer.frames), "every": scene.output.every, "dir_from": self.dir_from,
            "summary": str(self.summary_path) if writer.frames else None}
        data = summary_mapping(summary, stopped, scene, self.mesh, output)
        if summary is not None and hasattr(summary, "attach"):
            summary.attach(data)             # the Summary reads like what summary.json holds
        return data


def summary_mapping(summary, stopped, scene, mesh, output=None) -> dict:
    """What summary.json holds (without a file): the runtime's Summary (when there is one), how the
    run ended (stopped: the RunStopped, None for a result we stand behind), the scene on its rest
    mesh (None without a scene), and the output entry (None: no output folder)."""
    data = {"format": SUMMARY_FORMAT}
    if summary is not None:
        data.update(summary.to_dict())
    if stopped is not None:
        data.update(status=stopped.status, message=str(stopped), exit_code=stopped.exit_code)
    else:
        data.setdefault("status", "ok")
        data.setdefault("message", None)
        data["exit_code"] = EXIT_OK
    data.setdefault("warnings", [])
    data["scene"] = None if scene is None else {
        "name": scene.name, "source": scene.source, "solver": scene.solver.kind, "nodes": mesh.n_points,
        "cells": {b: sum(len(x) for x in mesh.blocks if x.type == b) for b in mesh.cell_types()}}
    data["output"] = output
    return data


def _optional_failed(data, what, path, exc) -> str:
    """Record an optional file that could not be written after the run: a warning of kind "output"
    in the summary (the status "ok" becomes "warnings"; the exit code stays 0); returns the reason."""
    reason = f"{what} {path} not written: {exc}"
    data.setdefault("warnings", []).append({"step": data.get("steps_done"), "time": None, "kind": "output",
                                            "message": reason})
    if data.get("status") == "ok":
        data["status"] = "warnings"
    return reason


def _steps_done(summary) -> int:
    done = getattr(summary, "steps_done", None)
    return int(done or 0)


def _same_path(a, b) -> bool:
    return os.path.abspath(a) == os.path.abspath(b)
