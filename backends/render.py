"""What every backend's printer shares: the Jinja environment, the metadata dict and the
reference tables as literals. Rendering only (imports jinja2; the
loaders never import this module)."""
from __future__ import annotations

import json

import jinja2

from .printing import float_literal


def environment(backend) -> jinja2.Environment:
    return jinja2.Environment(
        loader=jinja2.FileSystemLoader(str(backend.templates_dir())),
        undefined=jinja2.StrictUndefined,
        keep_trailing_newline=True,
        trim_blocks=True,
        lstrip_blocks=True,
    )


def metadata(ir, backend) -> dict:
    """What the runtime needs to know about a kernel; the same keys for every backend
    (backends.METADATA_KEYS), including the layout of the per-element constants D:
    per point q, D[q * point_stride + point_fields[f]] starts field f (v: the weight x det J,
    G: the shape gradients, node-major, G[i][b] at + i * dim + b); the material
    constants start at material_offset. Recompute kernels store rest coordinates instead
    (point_stride 0, no point fields); discrete kernels (springs) their rest measure v and the rest
    positions relative to node 0 (no G). quadratic_energy: W is a homogeneous quadratic in grad u
    (K constant, f = -K u: the runtime assembles K once). stress_record: the layout of the stress kernel's
    per-point record ({"size", "offsets": {v, W, F, P(, P33)}}, generator.kernel_body)."""
    return {
        "name": ir.name,
        "element": ir.element,
        "law": ir.law,
        "quadrature": ir.quadrature,
        "dim": ir.dim,
        "n_nodes": ir.n_nodes,
        "n_points": ir.n_points,
        "n_constants": ir.n_constants,
        "n_dofs": ir.n_dofs,
        "dofs_per_node": ir.dofs_per_node,
        "point_stride": ir.point_stride,
        "point_fields": ir.point_fields,
        "material_offset": ir.material_offset,
        "parameters": list(ir.parameters),
        "requires_positive_J": bool(ir.requires_positive_J),
        "quadratic_energy": bool(ir.quadratic_energy),
        "recompute": bool(ir.recompute),
        "ops": dict(sorted(ir.ops.items())),
        "templates": backend.templates_hash()[:16],
        "stress_record": ir.stress_record,
    }


def metadata_json(ir, backend) -> str:
    """The metadata as one line of JSON (sorted keys): the text both C and numba files carry."""
    return json.dumps(metadata(ir, backend), sort_keys=True)


def tables(ir) -> dict:
    """The reference tables every generated file holds, as exact double literals."""
    return {
        "dN_table": [[[float_literal(x) for x in node] for node in point] for point in ir.dN_table],
        "weights": [float_literal(w) for w in ir.weights],
    }
