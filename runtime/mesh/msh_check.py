"""Checks of gmsh .msh files before meshio reads them: sections closed, counts as declared.

    from tensormass.runtime.mesh.msh_check import check_msh
    check_msh(path)          # MeshError naming the file and the broken part, or None

meshio reads what a header announces and stops there: a `$Elements` count that is too small gives
a mesh with fewer cells and no message, and most other damage ends in an exception about arrays
that says nothing of where the file is broken.  This module reads the section headers and counts
of MSH 2.2 and 4.1 files, ASCII and binary, and refuses a file whose content disagrees with them:

- every `$Section` is closed by its `$EndSection`, and `$MeshFormat`, `$Nodes`, `$Elements` exist;
- `$Nodes` / `$Elements`: the declared counts (per block in 4.1, and the totals) are what follows,
  every node line has its coordinates, every element line the node count of its type, and every
  node an element lists is defined in `$Nodes`;
- `$PhysicalNames` has as many names as it declares; MSH 4.1's `$Entities` as many points, curves,
  surfaces and volumes, each line with its counts of physical tags and bounding entities, and the
  node and element blocks refer to entities it defines;
- binary files are walked record by record with the same counts (ints of 4 bytes, MSH 4.1's
  size_t of the header's data size; a count larger than the bytes left is refused before anything
  is allocated); their other sections are only checked to be closed.

Other versions (MSH 3, 4.0) are left to meshio.  Messages name the section, the block and the line
(ASCII) or byte offset (binary), e.g. "$Nodes block 2: expected 40 nodes, found 38".
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from .container import MeshError

__all__ = ["check_msh"]


def _gmsh_types() -> dict:
    """gmsh element type number -> (name, number of nodes), from meshio's tables."""
    from meshio._common import num_nodes_per_cell
    from meshio.gmsh.common import _gmsh_to_meshio_type
    return {k: (v, num_nodes_per_cell[v]) for k, v in _gmsh_to_meshio_type.items() if v in num_nodes_per_cell}


class _Broken(Exception):
    """A problem found in the file: where (section, block) and what."""


def check_msh(path) -> None:
    """Raise MeshError when the .msh file's sections or counts are broken (see the module doc)."""
    path = Path(path)
    data = path.read_bytes()
    try:
        version, binary, size_t, body = _format(data)
        if version.startswith("2"):
            (_binary_v2 if binary else _ascii_v2)(data, body)
        elif version == "4.1":
            (_binary_v41 if binary else _ascii_v41)(data, body, size_t)
    except _Broken as exc:
        raise MeshError(f"{path}: broken .msh file: {exc}") from None


# ------------------------------------------------------------------------------------ the header

_FORMAT = re.compile(rb"\s*\$MeshFormat\r?\n\s*(\S+)\s+(\S+)\s+(\S+)[^\n]*\n")


def _format(data: bytes):
    """(version, binary, data size, offset after $EndMeshFormat)."""
    m = _FORMAT.match(data)
    if m is None:
        raise _Broken("$MeshFormat: the file must start with $MeshFormat and a line 'version file-type "
                      "data-size' (e.g. '4.1 0 8')")
    version, ftype, dsize = (x.decode("latin-1") for x in m.groups())
    if ftype not in ("0", "1") or not dsize.isdigit():
        raise _Broken(f"$MeshFormat: expected 'version file-type data-size' with file-type 0 (ASCII) or 1 "
                      f"(binary), found {m.group(0).strip().decode('latin-1')!r}")
    at = m.end()
    if ftype == "1":                      # binary: the integer 1 in the file's byte order, then a newline
        at += 4
    end = data.find(b"$EndMeshFormat", at)
    if end < 0 or data[at:end].strip():
        raise _Broken("$MeshFormat is not closed by $EndMeshFormat right after its header line")
    return version, ftype == "1", int(dsize), end + len(b"$EndMeshFormat")


# ------------------------------------------------------------------------------------- ASCII files

def _ascii_sections(text: str, first_line: int):
    """{name: (first content line number (1-based), content lines)}; the framing checked."""
    lines = text.splitlines()
    out, i = {}, 0
    while i < len(lines):
        line = lines[i].strip()
        if not line:
            i += 1
            continue
        if not line.startswith("$"):
            raise _Broken(f"line {first_line + i}: {line[:40]!r} outside any section")
        name = line[1:]
        if name.startswith("End"):
            raise _Broken(f"line {first_line + i}: ${name} without a ${name[3:]} before it")
        j = i + 1
        while j < len(lines) and not lines[j].startswith("$"):
            j += 1
        if j == len(lines):
            raise _Broken(f"${name} (line {first_line + i}) is never closed: the file ends inside it "
                          f"(truncated?)")
        if lines[j].strip() != f"$End{name}":
            raise _Broken(f"${name} (line {first_line + i}) is not closed: {lines[j].strip()[:40]} at line "
                          f"{first_line + j} comes before $End{name}")
        if name in out:
            raise _Broken(f"${name} appears twice (lines {out[name][0] - 1} and {first_line + i})")
        out[name] = (first_line + i + 1, lines[i + 1:j])
        i = j + 1
    for name in ("Nodes", "Elements"):
        if name not in out:
            raise _Broken(f"no ${name} section")
    return out


def _count(line: str, where: str) -> int:
    """The count a line starts with."""
    f = line.split()
    if not f:
        raise _Broken(f"{where}: expected a count, found an empty line")
    return _ints(f[:1], where)[0]


def _ints(tokens, where: str) -> list:
    try:
        return [int(t) for t in tokens]
    except ValueError:
        raise _Broken(f"{where}: expected integers, found {' '.join(tokens)[:60]!r}") from None


def _numbers(lines, start: int, width: int, what: str, where: str) -> np.ndarray:
    """(len(lines), width) floats; names the first line that does not hold `width` numbers."""
    rows = [ln.split() for ln in lines]
    for k, r in enumerate(rows):
        if len(r) != width:
            raise _Broken(f"{where}, line {start + k}: {what} needs {width} numbers, found {len(r)}")
    try:
        return np.array(rows, dtype=float).reshape(len(rows), width)
    except ValueError:
        for k, r in enumerate(rows):
            try:
                [float(t) for t in r]
            except ValueError:
                raise _Broken(f"{where}, line {start + k}: {' '.join(r)[:60]!r} is not all numbers") from None
        raise


def _ascii_v2(data: bytes, body: int) -> None:
    first_line = data[:body].count(b"\n") + 1
    sections = _ascii_sections(data[body:].decode("latin-1"), first_line)
    _physical_names(sections)
    start, lines = sections["Nodes"]
    if not lines:
        raise _Broken("$Nodes: no node count")
    n = _count(lines[0], f"$Nodes, line {start}")
    rows = lines[1:]
    if len(rows) != n:
        raise _Broken(f"$Nodes: expected {n} nodes, found {len(rows)} lines (line {start})")
    nodes = _numbers(rows, start + 1, 4, "a node (id x y z)", "$Nodes")
    tags = nodes[:, 0].astype(np.int64)
    _unique_tags(tags, "$Nodes")
    start, lines = sections["Elements"]
    if not lines:
        raise _Broken("$Elements: no element count")
    n = _count(lines[0], f"$Elements, line {start}")
    rows = lines[1:]
    if len(rows) != n:
        raise _Broken(f"$Elements: expected {n} elements, found {len(rows)} lines (line {start})")
    types, refs = _gmsh_types(), []
    for k, row in enumerate(rows):
        where = f"$Elements, line {start + 1 + k}"
        f = _ints(row.split(), where)
        if len(f) < 3:
            raise _Broken(f"{where}: an element line is 'id type ntags tags... nodes...', found {row.strip()!r}")
        if f[1] not in types:
            raise _Broken(f"{where}: unknown gmsh element type {f[1]}")
        name, nn = types[f[1]]
        if len(f) != 3 + f[2] + nn:
            raise _Broken(f"{where}: element {f[0]} ({name}) needs {nn} nodes after its {f[2]} tags, "
                          f"found {len(f) - 3 - f[2]}")
        refs.append(f[3 + f[2]:])
    _defined(np.concatenate([np.asarray(r, np.int64) for r in refs]) if refs else np.zeros(0, np.int64),
             tags, "$Elements")


def _ascii_v41(data: bytes, body: int, size_t: int) -> None:
    first_line = data[:body].count(b"\n") + 1
    sections = _ascii_sections(data[body:].decode("latin-1"), first_line)
    _physical_names(sections)
    entities = _ascii_v41_entities(*sections["Entities"]) if "Entities" in sections else None
    tags = _ascii_v41_nodes(*sections["Nodes"], entities)
    _ascii_v41_elements(*sections["Elements"], tags, entities)


def _physical_names(sections) -> None:
    """$PhysicalNames: a count, then that many lines 'dim tag "name"'."""
    if "PhysicalNames" not in sections:
        return
    start, lines = sections["PhysicalNames"]
    if not lines:
        raise _Broken("$PhysicalNames: no count")
    n = _count(lines[0], f"$PhysicalNames, line {start}")
    if len(lines) - 1 != n:
        raise _Broken(f"$PhysicalNames: expected {n} names, found {len(lines) - 1} lines (line {start})")
    for k, line in enumerate(lines[1:]):
        f = line.split(maxsplit=2)
        where = f"$PhysicalNames, line {start + 1 + k}"
        if len(f) != 3 or not f[2].startswith('"') or not f[2].rstrip().endswith('"') or len(f[2].strip()) < 2:
            raise _Broken(f"{where}: expected 'dimension tag \"name\"', found {line.strip()[:60]!r}")
        _ints(f[:2], where)


def _ascii_v41_entities(start, lines) -> set:
    """$Entities: the declared points, curves, surfaces and volumes, each line complete; the set of
    (dimension, tag) it defines."""
    counts = _header(lines, start, "$Entities", ("numPoints", "numCurves", "numSurfaces", "numVolumes"))
    names = ("point", "curve", "surface", "volume")
    at, out = 1, set()
    for dim, n in enumerate(counts):
        for j in range(n):
            where = f"$Entities, line {start + at}"
            if at >= len(lines):
                raise _Broken(f"$Entities: expected {n} {names[dim]} lines, found {j} (the section ends)")
            f = lines[at].split()
            lead = 4 if dim == 0 else 7                       # tag and its point or bounding box
            ok = len(f) > lead and f[lead].isdigit() and len(f) >= lead + 1 + int(f[lead])
            if ok and dim > 0:
                b = lead + 1 + int(f[lead])
                ok = len(f) > b and f[b].isdigit() and len(f) == b + 1 + int(f[b])
            elif ok:
                ok = len(f) == lead + 1 + int(f[lead])
            if not ok:
                raise _Broken(f"{where}: {names[dim]} {j + 1} of {n}: its fields do not match its counts of "
                              f"physical tags{'' if dim == 0 else ' and bounding entities'} (found "
                              f"{lines[at].strip()[:60]!r})")
            out.add((dim, _ints(f[:1], where)[0]))
            at += 1
    if at < len(lines):
        raise _Broken(f"$Entities: more lines than the {sum(counts)} declared entities (line {start + at})")
    return out


def _header(lines, start, section, names):
    if not lines:
        raise _Broken(f"{section}: no header line ({' '.join(names)})")
    h = _ints(lines[0].split(), f"{section}, line {start}")
    if len(h) != len(names):
        raise _Broken(f"{section}, line {start}: the header is '{' '.join(names)}', found {lines[0].strip()!r}")
    return h


def _run(split_rows, at: int, width, limit: int) -> int:
    """How many rows from `at` on (at most limit) have `width` fields (an int, or a set of ints)."""
    ok = {width} if isinstance(width, int) else width
    k = 0
    while k < limit and at + k < len(split_rows) and len(split_rows[at + k]) in ok:
        k += 1
    return k


def _known_entity(entities, dim, tag, where) -> None:
    if entities is not None and (dim, tag) not in entities:
        raise _Broken(f"{where}: entity dimension {dim}, tag {tag} is not in $Entities")


def _ascii_v41_nodes(start, lines, entities=None):
    n_blocks, n_nodes, _, _ = _header(lines, start, "$Nodes", ("numEntityBlocks", "numNodes", "minNodeTag",
                                                               "maxNodeTag"))
    rows = [ln.split() for ln in lines]
    at, tags = 1, []
    for b in range(1, n_blocks + 1):
        where = f"$Nodes block {b}"
        if at >= len(rows):
            raise _Broken(f"{where}: missing (the header declares {n_blocks} blocks, the section ends after "
                          f"{b - 1})")
        dim, ent, param, n = _block_header(rows, lines, at, start, where,
                                           "entityDim entityTag parametric numNodesInBlock")
        if param not in (0, 1):
            _bad_block_header(where, start + at, lines[at], "entityDim entityTag parametric numNodesInBlock")
        _known_entity(entities, dim, ent, f"{where}, line {start + at}")
        at += 1
        k = _run(rows, at, 1, n)
        if k < n:
            raise _Broken(f"{where}: expected {n} nodes, found {k} node tags (line {start + at})")
        block_tags = _ints([r[0] for r in rows[at:at + n]], where)
        at += n
        width = 3 + (dim if param else 0)
        k = _run(rows, at, width, n)
        if k < n:
            raise _Broken(f"{where}: expected {n} nodes, found {k} coordinate lines of {width} numbers "
                          f"(line {start + at})")
        _numbers(lines[at:at + n], start + at, width, "a node's coordinates", where)
        at += n
        tags += block_tags
    if at < len(rows):
        raise _Broken(f"$Nodes: more lines than the {n_blocks} declared blocks hold (line {start + at}: "
                      f"{lines[at].strip()[:40]!r})")
    if len(tags) != n_nodes:
        raise _Broken(f"$Nodes: the header declares {n_nodes} nodes, the blocks hold {len(tags)}")
    tags = np.asarray(tags, dtype=np.int64)
    _unique_tags(tags, "$Nodes")
    return tags


def _ascii_v41_elements(start, lines, node_tags, entities=None):
    n_blocks, n_elements, _, _ = _header(lines, start, "$Elements", ("numEntityBlocks", "numElements",
                                                                     "minElementTag", "maxElementTag"))
    rows = [ln.split() for ln in lines]
    types, at, total, refs = _gmsh_types(), 1, 0, []
    for b in range(1, n_blocks + 1):
        where = f"$Elements block {b}"
        if at >= len(rows):
            raise _Broken(f"{where}: missing (the header declares {n_blocks} blocks, the section ends after "
                          f"{b - 1})")
        dim, ent, etype, n = _block_header(rows, lines, at, start, where,
                                           "entityDim entityTag elementType numElementsInBlock")
        if etype not in types:
            _bad_block_header(where, start + at, lines[at], "entityDim entityTag elementType numElementsInBlock")
        _known_entity(entities, dim, ent, f"{where}, line {start + at}")
        name, nn = types[etype]
        at += 1
        k = _run(rows, at, 1 + nn, n)
        if k < n:
            found = f"line {start + at + k} has {len(rows[at + k]) - 1} nodes" if at + k < len(rows) else \
                "the section ends"
            raise _Broken(f"{where} ({name}, {nn} nodes each): expected {n} elements, found {k} ({found})")
        try:
            block = np.array(rows[at:at + n], dtype=np.int64).reshape(n, 1 + nn)
        except ValueError:
            block = np.asarray(_ints([t for r in rows[at:at + n] for t in r], where), np.int64).reshape(n, 1 + nn)
        refs.append(block[:, 1:].ravel())
        at += n
        total += n
    if at < len(rows):
        raise _Broken(f"$Elements: more lines than the {n_blocks} declared blocks hold (line {start + at}: "
                      f"{lines[at].strip()[:40]!r})")
    if total != n_elements:
        raise _Broken(f"$Elements: the header declares {n_elements} elements, the blocks hold {total}")
    _defined(np.concatenate(refs) if refs else np.zeros(0, np.int64), node_tags, "$Elements")


def _block_header(rows, lines, at, start, where, names):
    """The 4 integers of a 4.1 block header (entity dimension 0..3, a count >= 0), or _Broken."""
    ok = len(rows[at]) == 4 and all(t.lstrip("-").isdigit() for t in rows[at])
    h = [int(t) for t in rows[at]] if ok else None
    if h is None or not 0 <= h[0] <= 3 or h[3] < 0:
        _bad_block_header(where, start + at, lines[at], names)
    return h


def _bad_block_header(where, line, text, names):
    raise _Broken(f"{where}, line {line}: expected a block header '{names}', found {text.strip()[:60]!r} "
                  f"(a count above is wrong?)")


def _unique_tags(tags, section):
    u, counts = np.unique(tags, return_counts=True)
    if (counts > 1).any():
        raise _Broken(f"{section}: node tag {int(u[counts > 1][0])} is defined {int(counts[counts > 1][0])} times")


def _defined(refs, node_tags, section):
    missing = np.setdiff1d(refs, node_tags)
    if missing.size:
        head = ", ".join(str(int(t)) for t in missing[:5])
        raise _Broken(f"{section}: elements refer to node tag(s) {head}{' ...' if missing.size > 5 else ''} "
                      f"that $Nodes does not define ({missing.size} in all)")


# ------------------------------------------------------------------------------------ binary files

class _Reader:
    """Walks a binary .msh file: text lines, section markers and little-endian records."""

    def __init__(self, data: bytes, at: int):
        self.data, self.at = data, at

    def skip_space(self):
        while self.at < len(self.data) and self.data[self.at:self.at + 1].isspace():
            self.at += 1

    def marker(self):
        """The next $Name (None at the end of the file)."""
        self.skip_space()
        if self.at >= len(self.data):
            return None
        end = self.data.find(b"\n", self.at)
        end = len(self.data) if end < 0 else end
        word = self.data[self.at:end].strip().decode("latin-1")
        if not word.startswith("$"):
            raise _Broken(f"byte {self.at}: {word[:40]!r} where a $Section was expected")
        self.at = end + 1
        return word[1:]

    def line(self, what):
        self.skip_space()
        end = self.data.find(b"\n", self.at)
        if end < 0:
            raise _Broken(f"{what}: the file ends (truncated?)")
        text = self.data[self.at:end].decode("latin-1")
        self.at = end + 1
        return text

    def take(self, dtype, count, what):
        size = np.dtype(dtype).itemsize * count
        if self.at + size > len(self.data):
            raise _Broken(f"{what}: needs {size} bytes at byte {self.at}, the file has "
                          f"{len(self.data) - self.at} left (truncated, or a count is wrong)")
        out = np.frombuffer(self.data, dtype=dtype, count=count, offset=self.at)
        self.at += size
        return out

    def end(self, name):
        self.skip_space()
        if not self.data.startswith(f"$End{name}".encode(), self.at):
            got = self.data[self.at:self.at + 20]
            raise _Broken(f"${name}: expected $End{name} at byte {self.at} after the declared records, found "
                          f"{got!r} (a count is wrong, or the section is truncated)")
        self.at += len(f"$End{name}")

    def skip_section(self, name):
        end = self.data.find(f"$End{name}".encode(), self.at)
        if end < 0:
            raise _Broken(f"${name} is never closed: the file ends inside it (truncated?)")
        self.at = end + len(f"$End{name}")


def _binary_sections(data, body, handlers):
    r = _Reader(data, body)
    seen = set()
    while True:
        name = r.marker()
        if name is None:
            break
        if name.startswith("End"):
            raise _Broken(f"${name} without a ${name[3:]} before it (byte {r.at})")
        seen.add(name)
        if name in handlers:
            handlers[name](r)
            r.end(name)
        else:
            r.skip_section(name)
    for name in ("Nodes", "Elements"):
        if name not in seen:
            raise _Broken(f"no ${name} section")


def _binary_v2(data: bytes, body: int) -> None:
    state = {}

    def nodes(r):
        n = _count(r.line("$Nodes"), "$Nodes")
        rec = r.take(np.dtype([("id", "<i4"), ("x", "<f8", 3)]), n, f"$Nodes ({n} nodes declared)")
        state["tags"] = rec["id"].astype(np.int64)
        _unique_tags(state["tags"], "$Nodes")

    def elements(r):
        n = _count(r.line("$Elements"), "$Elements")
        types, done, refs, b = _gmsh_types(), 0, [], 0
        while done < n:
            b += 1
            etype, count, ntags = (int(v) for v in r.take("<i4", 3, f"$Elements group {b} header"))
            if etype not in types or count <= 0 or ntags < 0:
                raise _Broken(f"$Elements group {b} (byte {r.at - 12}): type {etype}, {count} elements, {ntags} "
                              f"tags is no valid group header ({done} of {n} elements read: a count is wrong?)")
            name, nn = types[etype]
            if done + count > n:
                raise _Broken(f"$Elements: expected {n} elements, group {b} brings the total to {done + count}")
            rec = r.take("<i4", count * (1 + ntags + nn), f"$Elements group {b} ({count} {name})")
            refs.append(rec.reshape(count, -1)[:, 1 + ntags:].ravel())
            done += count
        state["refs"] = np.concatenate(refs).astype(np.int64) if refs else np.zeros(0, np.int64)

    _binary_sections(data, body, {"Nodes": nodes, "Elements": elements})
    _defined(state["refs"], state["tags"], "$Elements")


def _binary_v41(data: bytes, body: int, size_t: int) -> None:
    st = {4: "<u4", 8: "<u8"}.get(size_t)
    if st is None:
        raise _Broken(f"$MeshFormat: data size {size_t} (size_t) is neither 4 nor 8")
    state = {}

    def entities(r):
        counts = [int(v) for v in r.take(st, 4, "$Entities header")]
        names = ("point", "curve", "surface", "volume")
        for dim, n in enumerate(counts):
            for j in range(1, n + 1):
                where = f"$Entities {names[dim]} {j} of {n}"
                r.take("<i4", 1, where)
                r.take("<f8", 3 if dim == 0 else 6, where)
                (k,) = (int(v) for v in r.take(st, 1, where))
                r.take("<i4", k, f"{where}: {k} physical tags")
                if dim:
                    (k,) = (int(v) for v in r.take(st, 1, where))
                    r.take("<i4", k, f"{where}: {k} bounding entities")

    def nodes(r):
        n_blocks, n_nodes, _, _ = (int(v) for v in r.take(st, 4, "$Nodes header"))
        tags = []
        for b in range(1, n_blocks + 1):
            where = f"$Nodes block {b}"
            dim, _, param = (int(v) for v in r.take("<i4", 3, where))
            (n,) = (int(v) for v in r.take(st, 1, where))
            if not 0 <= dim <= 3 or param not in (0, 1) or n > n_nodes:
                raise _Broken(f"{where} (byte {r.at - 12 - size_t}): entity dimension {dim}, parametric {param}, "
                              f"{n} nodes is no valid block header (a count above is wrong?)")
            tags.append(r.take(st, n, f"{where}: {n} node tags").astype(np.int64))
            r.take("<f8", n * (3 + (dim if param else 0)), f"{where}: coordinates of {n} nodes")
        tags = np.concatenate(tags) if tags else np.zeros(0, np.int64)
        if len(tags) != n_nodes:
            raise _Broken(f"$Nodes: the header declares {n_nodes} nodes, the blocks hold {len(tags)}")
        _unique_tags(tags, "$Nodes")
        state["tags"] = tags

    def elements(r):
        n_blocks, n_elements, _, _ = (int(v) for v in r.take(st, 4, "$Elements header"))
        types, total, refs = _gmsh_types(), 0, []
        for b in range(1, n_blocks + 1):
            where = f"$Elements block {b}"
            dim, _, etype = (int(v) for v in r.take("<i4", 3, where))
            (n,) = (int(v) for v in r.take(st, 1, where))
            if etype not in types or not 0 <= dim <= 3 or n > n_elements:
                raise _Broken(f"{where} (byte {r.at - 12 - size_t}): entity dimension {dim}, element type {etype}, "
                              f"{n} elements is no valid block header (a count above is wrong?)")
            name, nn = types[etype]
            rec = r.take(st, n * (1 + nn), f"{where}: {n} {name} elements")
            refs.append(rec.reshape(n, 1 + nn)[:, 1:].ravel().astype(np.int64))
            total += n
        if total != n_elements:
            raise _Broken(f"$Elements: the header declares {n_elements} elements, the blocks hold {total}")
        state["refs"] = np.concatenate(refs) if refs else np.zeros(0, np.int64)

    _binary_sections(data, body, {"Entities": entities, "Nodes": nodes, "Elements": elements})
    _defined(state["refs"], state["tags"], "$Elements")
