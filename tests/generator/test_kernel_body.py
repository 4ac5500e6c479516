"""The frozen IR and the kernel algorithm as data (generator/kernel_body.py)."""
from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from tensormass import backends
from tensormass.generator import kernel_body as kb
from tensormass.generator.ir import build_ir


def walk(statements):
    for st in statements:
        yield st
        if isinstance(st, kb.Loop):
            yield from walk(st.body)


def test_ir_is_frozen():
    ir = build_ir("tetra", "stvk", "gauss1")
    with pytest.raises(dataclasses.FrozenInstanceError):
        ir.ops = {}
    assert ir.ops["forces_and_stiffness"] > 0 and len(ir.input_hash) == 16
    assert set(ir.bodies) == set(kb.KINDS)


def test_bodies_hold_the_algorithm():
    ir = build_ir("hexahedron", "neohookean", "gauss2")
    fk = list(walk(ir.bodies["forces_and_stiffness"]))
    loops = {st.var: st for st in fk if isinstance(st, kb.Loop)}
    assert loops["q"].stop == ir.n_points
    assert str(loops["j"].start) == "i" and loops["j"].stop == ir.n_nodes      # node pairs j >= i
    flags = [st for st in fk if isinstance(st, kb.Flag)]
    assert len(flags) == 1 and flags[0].leave                                 # det F check, neo-Hookean
    forces = [st for st in fk if isinstance(st, kb.Accumulate) and isinstance(st.target, kb.Ref)
              and str(st.target.args[0]) == "f"]
    assert len(forces) == ir.dim and all(st.sign == -1 for st in forces)      # f_i -= v P g_i
    mirror = [st for st in fk if isinstance(st, kb.Assign) and isinstance(st.target, kb.Ref) and str(st.target.args[0]) == "K"
              and st.value.func is kb.Ref]
    assert len(mirror) == 1
    # StVK needs no det F check; the exact rule on a quadratic simplex checks straight edges.
    assert not any(isinstance(st, kb.Flag) and st.leave
                   for st in walk(build_ir("tetra", "stvk", "gauss1").bodies["forces"]))
    t6 = build_ir("triangle6", "hooke", "exact")
    assert sum(isinstance(st, kb.FlagIf) for st in walk(t6.bodies["constants"])) == 1


def test_recompute_bodies_read_rest_coordinates():
    ir = build_ir("tetra", "stvk", "gauss1", constants="recompute")
    arrays = {str(st.target.args[0]) for st in walk(ir.bodies["forces"])
              if isinstance(st, kb.Assign) and isinstance(st.target, kb.Ref)}
    assert "Gq" in arrays                      # shape gradients recomputed per call
    assert ir.point_stride == 0


def test_templates_only_lay_out_functions():
    """No template spells the algorithm: no accumulation, no node or point loop, no F."""
    for name in backends.BACKENDS:
        for path in backends.get(name).templates_dir().glob("*.j2"):
            text = Path(path).read_text()
            for marker in ("F00", "range({{ ir.n_points", "q < {{ ir.n_points", "chain.", "law["):
                assert marker not in text, f"{name}/{path.name}: {marker}"


def test_int_div():
    i = kb._i("i")
    assert kb.IntDiv(7, 3) == 2
    assert kb.IntDiv(i, 3).func is kb.IntDiv
