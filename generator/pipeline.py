"""Generate kernels to disk: IR per entry, text per backend, a manifest, deterministically.

Files are written to a temporary name and renamed, so an interrupted run never
leaves a half-written kernel; the manifest lists entries in sorted order and
holds no timestamps, so regenerating the same inputs gives identical bytes.
"""
from __future__ import annotations

import json
import time
from pathlib import Path

from . import GENERATOR_VERSION
from ..runtime.base.files import write_atomic
from ..backends import BACKENDS, get as get_backend
from .catalogue import Entry
from .ir import build_ir

MANIFEST = "manifest.json"


def backend_dir(out: Path, backend: str) -> Path:
    return Path(out) / backend


def generate_entry(entry: Entry, backends, out: Path, constants: str = "precompute") -> dict:
    """Generate one entry for the given backends; returns its manifest record."""
    ir = build_ir(entry.element, entry.law, entry.quadrature, constants=constants)
    record = {
        "name": ir.name, "element": ir.element, "law": ir.law, "quadrature": ir.quadrature,
        "dim": ir.dim, "nodes": ir.n_nodes, "points": ir.n_points,
        "constants": ir.n_constants, "ops": dict(sorted(ir.ops.items())),
        "files": {}, "inputs": {},
    }
    for name in sorted(backends):
        backend = get_backend(name)
        path = backend_dir(out, name) / backend.file_name(ir)
        write_atomic(path, backend.render(ir))
        record["files"][name] = f"{name}/{path.name}"
        record["inputs"][name] = backend.input_hash(ir)
    return record


def update_manifest(out: Path, records: list[dict]) -> None:
    """Merge records into out/manifest.json (entries keyed and sorted by name)."""
    path = Path(out) / MANIFEST
    manifest = {"generator": GENERATOR_VERSION, "entries": {}}
    if path.exists():
        manifest["entries"] = json.loads(path.read_text())["entries"]
    for r in records:
        key = r["name"]
        old = manifest["entries"].get(key, {})
        # Keep files of other backends generated earlier for the same entry.
        r = {**r, "files": {**old.get("files", {}), **r["files"]}, "inputs": {**old.get("inputs", {}), **r["inputs"]}}
        r["files"] = dict(sorted(r["files"].items()))
        r["inputs"] = dict(sorted(r["inputs"].items()))
        manifest["entries"][key] = r
    manifest["entries"] = dict(sorted(manifest["entries"].items()))
    write_atomic(path, json.dumps(manifest, indent=1, sort_keys=True) + "\n")


def generate_all(entries, backends=BACKENDS, out: Path = None, progress=print, constants: str = "precompute") -> list[dict]:
    """Generate every entry; prints progress and the time each one took.

    constants: "precompute" (G and det J of every point stored in D, the catalogue) or
    "recompute" (D holds rest coordinates; files are named <entry>_recompute)."""
    out = Path(out)
    records, start = [], time.perf_counter()
    for k, entry in enumerate(entries, 1):
        t0 = time.perf_counter()
        record = generate_entry(entry, backends, out, constants)
        record_time = time.perf_counter() - t0
        records.append(record)
        if progress:
            progress(f"[{k}/{len(entries)}] {entry.name}: {record_time:.2f} s "
                     f"({record['constants']} constants, {record['ops']['forces_and_stiffness']} ops f+K)")
    update_manifest(out, records)
    if progress:
        progress(f"generated {len(entries)} entr{'y' if len(entries) == 1 else 'ies'} "
                 f"for {', '.join(sorted(backends))} in {time.perf_counter() - start:.1f} s into {out}")
    return records
