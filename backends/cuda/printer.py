"""CUDA printing: the C backend's scalar statements (CUDA C++ device code has C's arithmetic and the
double overloads of <math.h>), laid out by kernel.cu.j2 as one element per thread."""
from __future__ import annotations

from ..c.loader import METADATA_TAG
from ..c.printer import CStatements
from ..render import environment, metadata_json, tables


def render(ir, backend) -> str:
    # One thread evaluates one element, so only the scalar statements are printed (the C backend's
    # 4-element vector variant has no use here: a warp is the GPU's vector).
    bodies = {kind: CStatements(ir).text(body, 2) for kind, body in ir.bodies.items() if kind != "constants"}
    bodies["constants"] = CStatements(ir, writes_D=True).text(ir.bodies["constants"], 2)
    return environment(backend).get_template("kernel.cu.j2").render(
        ir=ir, header=backend.header(ir), metadata=metadata_json(ir, backend), metadata_tag=METADATA_TAG,
        body=bodies, **tables(ir))
