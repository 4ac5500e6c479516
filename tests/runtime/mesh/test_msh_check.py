"""Broken gmsh .msh files are refused naming the file and the broken part (runtime.mesh.msh_check), never
read in part and never with meshio's own exception."""
import re
from pathlib import Path

import pytest

from tensormass.runtime.mesh.container import MeshError
from tensormass.runtime.mesh.io import read_mesh
from tensormass.runtime.mesh.msh_check import check_msh

DATA = Path(__file__).parents[1] / "data" / "msh"


def _lines(name):
    return (DATA / name).read_text().splitlines()


def _at(lines, marker, after=1):
    return lines.index(marker) + after


def _edit(name, change):
    lines = _lines(name)
    change(lines)
    return "\n".join(lines) + "\n"


def _set(i, text):
    def f(lines):
        lines[i(lines)] = text(lines[i(lines)])
    return f


def _drop(i, count=1):
    def f(lines):
        del lines[i(lines):i(lines) + count]
    return f


def _node_block_2(lines):
    """Line of the header of $Nodes block 2 of tetra_v41.msh."""
    start = _at(lines, "$Nodes", 2)
    n = int(lines[start].split()[3])
    return start + 1 + 2 * n


ASCII = {
    # MSH 2.2, hex_wedge_v22.msh: 36 elements, 52 nodes
    "v22 $Elements count too small": ("hex_wedge_v22.msh", _set(lambda L: _at(L, "$Elements"), lambda s: "12"),
                                      r"\$Elements: expected 12 elements, found 36"),
    "v22 $Elements count too large": ("hex_wedge_v22.msh", _set(lambda L: _at(L, "$Elements"), lambda s: "40"),
                                      r"\$Elements: expected 40 elements, found 36"),
    "v22 $Nodes count too small": ("hex_wedge_v22.msh", _set(lambda L: _at(L, "$Nodes"), lambda s: "50"),
                                   r"\$Nodes: expected 50 nodes, found 51 lines \(line 10\)"),
    "v22 node without z": ("hex_wedge_v22.msh", _set(lambda L: _at(L, "$Nodes", 3), lambda s: " ".join(s.split()[:3])),
                           r"\$Nodes, line 12: a node \(id x y z\) needs 4 numbers, found 3"),
    "v22 node not a number": ("hex_wedge_v22.msh", _set(lambda L: _at(L, "$Nodes", 3), lambda s: s + "x")
                              , r"\$Nodes, line 12: .* is not all numbers"),
    "v22 element short of a node": ("hex_wedge_v22.msh", _set(lambda L: _at(L, "$Elements", 2),
                                                              lambda s: " ".join(s.split()[:-1])),
                                    r"\$Elements, line 65: element 1 \(quad\) needs 4 nodes after its 2 tags, found 3"),
    "v22 undefined node": ("hex_wedge_v22.msh", _set(lambda L: _at(L, "$Elements", 2),
                                                     lambda s: " ".join(s.split()[:-1] + ["999"])),
                           r"\$Elements: elements refer to node tag\(s\) 999 that \$Nodes does not define"),
    "v22 no $EndElements": ("hex_wedge_v22.msh", _drop(lambda L: _at(L, "$EndElements", 0)),
                            r"\$Elements \(line 63\) is never closed: the file ends inside it"),
    "v22 no $EndNodes": ("hex_wedge_v22.msh", _drop(lambda L: _at(L, "$EndNodes", 0)),
                         r"\$Nodes \(line 9\) is not closed: \$Elements at line 62 comes before \$EndNodes"),
    # MSH 4.1, tetra_v41.msh: 21 node blocks, 2 element blocks
    "v41 $Nodes block 2 short of a node": ("tetra_v41.msh", lambda L: (_drop(lambda L: _node_block_2(L) + 1)(L),
                                                                       _drop(lambda L: _node_block_2(L) + 1)(L)),
                                           r"\$Nodes block 2: expected 1 nodes, found 0 node tags"),
    "v41 $Nodes header total": ("tetra_v41.msh", _set(lambda L: _at(L, "$Nodes"), lambda s: "21 23 1 24"),
                                r"\$Nodes: the header declares 23 nodes, the blocks hold 24"),
    "v41 $Nodes too few blocks": ("tetra_v41.msh", _set(lambda L: _at(L, "$Nodes"), lambda s: "20 24 1 24"),
                                  r"\$Nodes: more lines than the 20 declared blocks hold"),
    "v41 $Elements block count too small": ("tetra_v41.msh", _set(lambda L: _at(L, "$Elements", 2),
                                                                  lambda s: " ".join(s.split()[:3] + ["5"])),
                                            r"\$Elements block 2, line 119: expected a block header 'entityDim entityTag elementType "
                                            r"numElementsInBlock', found '6 .*' \(a count above is wrong\?\)"),
    "v41 $Elements header total": ("tetra_v41.msh", _set(lambda L: _at(L, "$Elements"), lambda s: "2 49 1 50"),
                                   r"\$Elements: the header declares 49 elements, the blocks hold 50"),
    "v41 element short of a node": ("tetra_v41.msh", _set(lambda L: _at(L, "$Elements", 3),
                                                          lambda s: " ".join(s.split()[:-1])),
                                    r"\$Elements block 1 \(triangle, 3 nodes each\): expected 8 elements, found 0"),
    "v41 $PhysicalNames count": ("tetra_v41.msh", _set(lambda L: _at(L, "$PhysicalNames"), lambda s: "3"),
                                 r"\$PhysicalNames: expected 3 names, found 2 lines"),
    "v41 $Entities line short": ("tetra_v41.msh", _set(lambda L: _at(L, "$Entities", 10),
                                                       lambda s: " ".join(s.split()[:-1])),
                                 r"\$Entities, line 19: curve \d+ of \d+: its fields do not match its counts"),
    "v41 truncated": ("tetra_v41.msh", lambda L: L.__delitem__(slice(len(L) * 4 // 5, None)),
                      r"\$Elements \(line 111\) is never closed: the file ends inside it \(truncated\?\)"),
}


@pytest.mark.parametrize("case", sorted(ASCII))
def test_a_broken_ascii_file_is_refused_naming_the_broken_part(case, tmp_path):
    name, change, message = ASCII[case]
    path = tmp_path / f"broken_{name}"
    path.write_text(_edit(name, change))
    with pytest.raises(MeshError, match=re.escape(str(path)) + r": broken \.msh file: " + message):
        read_mesh(path)


def _binary_cases():
    b22, b41 = (DATA / "tetra_v22b.msh").read_bytes(), (DATA / "hex_wedge_v41b.msh").read_bytes()
    e22 = b22.index(b"$Elements\n") + len(b"$Elements\n")
    n22 = int(b22[e22:b22.index(b"\n", e22)])
    return {
        "v22b truncated": (b22[:len(b22) * 2 // 3], r"(needs \d+ bytes|never closed|truncated)"),
        "v22b $Elements count too small": (b22[:e22] + str(n22 - 5).encode() + b22[b22.index(b"\n", e22):],
                                           r"\$Elements: expected \$EndElements at byte \d+ after the declared records"),
        "v22b $Elements count too large": (b22[:e22] + str(n22 + 5).encode() + b22[b22.index(b"\n", e22):],
                                           r"\$Elements"),
        "v41b truncated": (b41[:len(b41) // 2], r"(needs \d+ bytes|never closed|truncated)"),
        "v41b no $EndElements": (b41.replace(b"$EndElements", b""), r"\$Elements: expected \$EndElements"),
    }


def test_a_broken_binary_file_is_refused_naming_the_broken_part(tmp_path):
    for case, (data, message) in _binary_cases().items():
        path = tmp_path / (case.replace(" ", "_").replace("$", "") + ".msh")
        path.write_bytes(data)
        with pytest.raises(MeshError, match=re.escape(str(path)) + r": broken \.msh file: .*" + message):
            read_mesh(path)


def test_every_gmsh_fixture_passes_the_check():
    for path in sorted(DATA.glob("*.msh")):
        check_msh(path)
