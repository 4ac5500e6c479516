"""What a run leaves on disk: the same files from Python and from the command line.

    files = RunFiles(scene, out=None, json_path=None, overwrite=False)
    files.prepare()                          # checks only (output folder, summary paths): nothing written
    sim = Simulation(scene, output=files)    # Simulation(scene) makes one itself from [output]
    data = files.finish(summary, stopped)    # the summary dict, written where asked

The output folder ([output] dir, or `out`: --out / Simulation(output=...)) receives the VTU
frames and their .pvd (runtime.output.Writer) and, beside them, ``summary.json``: the run summary
(also for a run that stopped, with its status and message). ``json_path`` (--json) writes one more
copy elsewhere. A run that ends before its first frame leaves no folder behind.

Everything that can be refused is refused in prepare(), before the model is built: an unwritable
folder, frames or a .pvd that an earlier run of ours did not write (unless overwrite), a summary
path that holds anything but one of our summaries.
"""
from __future__ import annotations

import os
from pathlib import Path

from .errors import EXIT_OK, TensormassError
from .output import SUMMARY_FORMAT, Writer, check_summary_path, write_summary

__all__ = ["RunFiles", "SUMMARY_NAME"]

SUMMARY_NAME = "summary.json"


class RunFiles:
    """The files of one run of `scene` (see the module docstring).

    out: a folder overriding scene.output.dir (None: the scene's); dir_from: how the folder was
    chosen, said in the summary (runtime/paths.py: scene paths are relative to the scene file,
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
        self.summary_path = None if self.out_dir is None else self.out_dir / SUMMARY_NAME
        self.data = None
        self._prepared = False

    def prepare(self) -> None:
        """Every check before the run (idempotent); writes nothing."""
        if self._prepared:
            return
        scene = self.scene
        self.json_path = check_summary_path(self.json_path, scene_file=scene.source, writer=self.writer)
        if self.writer is not None:
            self.writer.prepare()
            if self.out_dir.is_dir():        # else it is created with the first frame: nothing there yet
                self._check_folder_summary()
        self._prepared = True

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

    def finish(self, summary, stopped=None) -> dict:
        """Close the frames, write the summary (JSON) where asked; the summary dict.

        stopped: the RunStopped / RunInterrupted that ended the run, None for a result we stand
        behind. Raises the writer's OutputError when a frame could not be written (disk full).
        """
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
        for path in self._summary_paths():
            write_summary(path, data)
        if self.json_path is not None:
            data["output_json"] = str(self.json_path)
        return data

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
        scene, mesh, writer = self.scene, self.mesh, self.writer
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
        data["scene"] = {"name": scene.name, "source": scene.source, "solver": scene.solver.kind,
                         "nodes": mesh.n_points,
                         "cells": {b: sum(len(x) for x in mesh.blocks if x.type == b) for b in mesh.cell_types()}}
        data["output"] = None if writer is None else {
            "dir": str(self.out_dir), "pvd": str(writer.pvd_path) if writer.frames else None,
            "frames": len(writer.frames), "every": scene.output.every, "dir_from": self.dir_from,
            "summary": str(self.summary_path) if writer.frames else None}
        return data


def _steps_done(summary) -> int:
    done = getattr(summary, "steps_done", None)
    return int(done or 0)


def _same_path(a, b) -> bool:
    return os.path.abspath(a) == os.path.abspath(b)
