"""KernelIR: everything a template needs to emit one (element, law, quadrature) kernel.

Built once from the earlier stages (frozen: op counts, input hash and the kernel bodies are
computed before construction), language neutral (sympy expressions and names); a backend
only prints it. The algorithm of every kernel is data: `bodies`, the statement trees of
generator/kernel_body.py. The per-element constant vector D is laid out as
  [point 0: v, G_0_0 .. G_{n-1}_{dim-1}] [point 1: ...] ... [material constants]
so that the per-step code reads D and u only.
"""
from __future__ import annotations

import hashlib
import inspect
import sys
from functools import lru_cache
from types import SimpleNamespace

import sympy as sp

from .. import laws as laws_pkg
from . import GENERATOR_VERSION
from .constants import geometry_code, hoist
from .derivatives import law_derivatives
from .elements import element as get_element
from .kinematics import F_symbols
from .fragments import DEFAULT_MAX_OPS, Fragment, split
from .discrete import QUADRATURE as DISCRETE, build_discrete_ir
from .kernel_body import build_bodies, stress_record
from .kernel_ir import KernelIR
from .quadrature import QuadratureRule, rule as get_rule, rule_for_degree
from .shell import QUADRATURE as SHELL, build_shell_ir

EXACT = "exact"


def resolve_rule(element_name: str, law, quadrature: str) -> QuadratureRule:
    """The integration rule behind a quadrature name.

    "exact" integrates the polynomial integrand exactly: its degree is found
    symbolically (law degree in F times the degree of F in xi on an affine
    simplex) and a rule of at least that degree is used; the generated
    constants kernel refuses curved (non-affine) elements for it.
    """
    if quadrature != EXACT:
        return get_rule(element_name, quadrature)
    degree = exact_degree(element_name, law)
    if degree is None:
        raise ValueError(f"quadrature 'exact' needs a polynomial integrand: law {law.name!r} on "
                         f"{element_name!r} is not polynomial (use gauss1, gauss2, gauss3)")
    return rule_for_degree(element_name, degree)


@lru_cache(maxsize=None)       # laws are immutable (hashed by identity); scene validation asks per material
def law_degree(law) -> int | None:
    """Total degree of W in the entries of F, or None when W is not polynomial.

    W alone, not its derivatives: scene validation asks this of every material's law, and a
    run whose kernels are cached must not differentiate the law (seconds of sympy for Yeoh)."""
    F = F_symbols(3)
    flat = [s for row in F for s in row]
    W = law.W(sp.Matrix(F))
    if not W.is_polynomial(*flat):            # checked before expanding: ln J, J^(-2/3) are slow to expand
        return None
    return sp.Poly(sp.expand(W), *flat).total_degree()


def exact_degree(element_name: str, law) -> int | None:
    ref = get_element(element_name)
    if not ref.simplex:
        return None
    degree = law_degree(law)
    return None if degree is None else degree * (ref.order - 1)


CONSTANTS_MODES = ("precompute", "recompute")


def build_ir(element_name: str, law_name: str, quadrature: str, max_ops: int = DEFAULT_MAX_OPS,
             constants: str = "precompute") -> KernelIR:
    """The IR of one kernel.

    constants="precompute" (the catalogue) stores v = w det J and the shape gradients G of every
    integration point in D; "recompute" stores only the rest coordinates and recomputes them at
    every call: less memory traffic, more arithmetic (the kernel benchmark compares both).
    """
    if constants not in CONSTANTS_MODES:
        raise ValueError(f"unknown constants mode {constants!r}; use one of {', '.join(CONSTANTS_MODES)}")
    law = laws_pkg.kernel_law(law_name)
    if law.kind == "shell":                     # an energy in nodal displacements and rotations: generator/shell.py
        if quadrature != SHELL:
            raise ValueError(f"law {law_name!r} is a shell law: its kernels have quadrature {SHELL!r}, not {quadrature!r}")
        return build_shell_ir(element_name, law_name, max_ops, constants)
    if law.kind == "discrete":                  # an element energy in nodal positions: generator/discrete.py
        if quadrature != DISCRETE:
            raise ValueError(f"law {law_name!r} is discrete: its kernels have quadrature {DISCRETE!r}, not {quadrature!r}")
        return build_discrete_ir(element_name, law_name, max_ops, constants)
    recompute = constants == "recompute"
    ref = get_element(element_name)
    rule = resolve_rule(element_name, law, quadrature)
    dim, n = ref.dim, ref.n_nodes
    deriv = law_derivatives(law, dim)

    dN_table, names = _shape_gradient_table(ref, rule, law.point_inputs)
    geo_temps, geo_G = geometry_code(dim)
    law_code, material, J = _law_code(deriv, law, max_ops)
    if law.point_inputs and recompute:
        raise ValueError(f"law {law_name!r} has inputs per point (its history): it needs constants='precompute'")
    point_inputs = tuple(law.point_inputs)
    stride = 1 + n * dim + len(point_inputs)
    material_names = tuple(name for name, _ in material.outputs)
    if recompute:
        names = [f"X[{i}][{k}]" for i in range(n) for k in range(dim)]
    fields = dict(
        name=f"{element_name}_{law_name}_{quadrature}" + ("_recompute" if recompute else ""),
        element=element_name, law=law_name, quadrature=quadrature,
        dim=dim, n_nodes=n, n_points=rule.n_points,
        parameters=tuple(law.inputs),
        requires_positive_J=law.requires_positive_J,
        quadratic_energy=law_name in laws_pkg.names() and laws_pkg.is_quadratic(law_name),
        affine_edges=midside_triples(ref) if quadrature == EXACT else (),
        point_stride=0 if recompute else stride,
        material_offset=len(names),
        material_names=material_names,
        constant_names=tuple(names) + material_names,
        geometry=Fragment(tuple(geo_temps), ()),
        geometry_G=tuple(geo_G),
        dN_table=dN_table,
        weights=tuple(float(sp.N(w, 30)) for w in rule.weights),
        material=material,
        law_code=law_code,
        J=J,
        chain=_chain_rule(deriv),
        rule_points=tuple(tuple(float(x) for x in p) for p in rule.points),
        rule_weights=tuple(float(w) for w in rule.weights),
        recompute=recompute,
        stress_record=stress_record(dim),
        point_inputs=point_inputs,
    )
    # Everything derived is computed before the IR exists: it is never patched afterwards.
    draft = SimpleNamespace(**fields, n_dofs=n * dim, dofs_per_node=dim)
    return KernelIR(**fields, ops=_op_counts(draft), input_hash=_input_hash(ref, rule, law),
                    bodies=build_bodies(draft))


def _shape_gradient_table(ref, rule, point_inputs=()):
    """dN_i/dxi_k at every point as floats, and the names of the D columns they lead to (with the
    law's point inputs after G)."""
    dN_symbolic = ref.gradients()
    table, names = [], []
    for q, point in enumerate(rule.points):
        dN = dN_symbolic.subs(dict(zip(ref.xi, point)))
        table.append(tuple(tuple(float(sp.N(dN[i, k], 30)) for k in range(ref.dim)) for i in range(ref.n_nodes)))
        names += [f"v[{q}]"] + [f"G[{q}][{i}][{b}]" for i in range(ref.n_nodes) for b in range(ref.dim)]
        names += [f"{name}[{q}]" for name, _ in point_inputs]
    return tuple(table), names


def _law_code(deriv, law, max_ops):
    dim = deriv.dim
    P = [(f"P{a}{b}", deriv.P[a][b]) for a in range(dim) for b in range(dim)]
    A = [(f"A{i}_{j}", e) for (i, j), e in sorted(deriv.A.items())]
    # 2D: the out-of-plane stress P33 (named P22, 0-based) of plane strain, for the stress kernel;
    # last in the list, so that the constants it hoists come after every earlier one.
    out_of_plane = [("P22", deriv.P33)] if deriv.P33 is not None else []
    everything = [("W", deriv.W)] + P + A + out_of_plane
    # Hoist parameter-only subexpressions once, over every output, so all
    # variants share one set of material constants.
    hoisted, constants = hoist([e for _, e in everything], set(deriv.params))
    named = dict(zip([name for name, _ in everything], hoisted))
    Pn = [(name, named[name]) for name, _ in P]
    An = [(name, named[name]) for name, _ in A]
    variants = {
        "energy": [("W", named["W"])],
        "gradient": Pn,
        "tangent": An,
        "gradient_tangent": Pn + An,
        # the stress kernel's record: W, P (and P33 in 2D) at one point, in one fragment
        "stress": [("W", named["W"])] + Pn + [(name, named[name]) for name, _ in out_of_plane],
    }
    law_code = {k: split(v, f"t_{k[0]}", max_ops) for k, v in variants.items()}
    # Material constants: the raw parameters the code still reads, then the hoisted ones.
    used = set().union(*(e.free_symbols for e in hoisted))
    raw = [(str(p), p) for p in deriv.params if p in used]
    material = Fragment((), tuple(raw + [(str(c), e) for c, e in constants]))
    J = deriv.J if law.requires_positive_J else None
    return law_code, material, J


def _chain_rule(deriv):
    """f_i = -sum_q v P g_i ; K_ij = sum_q v g_i A g_j, written with symbols for one node pair."""
    dim = deriv.dim
    v = sp.Symbol("v", real=True)
    gi = [sp.Symbol(f"gi{b}", real=True) for b in range(dim)]
    gj = [sp.Symbol(f"gj{b}", real=True) for b in range(dim)]
    P = [[sp.Symbol(f"P{a}{b}", real=True) for b in range(dim)] for a in range(dim)]

    def A(a, b, c, d):
        i, j = a * dim + b, c * dim + d
        return sp.Symbol(f"A{min(i, j)}_{max(i, j)}", real=True)

    forces = [(a, v * sum(P[a][b] * gi[b] for b in range(dim))) for a in range(dim)]
    H = [(f"h{a}{c}{d}", v * sum(A(a, b, c, d) * gi[b] for b in range(dim)))
         for a in range(dim) for c in range(dim) for d in range(dim)]
    h = {(a, c, d): sp.Symbol(f"h{a}{c}{d}", real=True) for a in range(dim) for c in range(dim) for d in range(dim)}
    K = [(a, c, sum(h[a, c, d] * gj[d] for d in range(dim))) for a in range(dim) for c in range(dim)]
    return {"forces": forces, "H": H, "K": K}


def midside_triples(ref):
    """(midside node, corner a, corner b) with a < b, from the element table."""
    t = ref.type
    return tuple((t.n_corners + m, min(e), max(e)) for m, e in enumerate(t.midside_edges))


def _op_counts(ir) -> dict:
    """Floating-point operations per element, per kernel (sympy's count_ops of the emitted code);
    ir: the IR's fields (before construction)."""
    n, dim, nq = ir.n_nodes, ir.dim, ir.n_points
    law = {k: sum(f.ops for f in v) for k, v in ir.law_code.items()}
    F = 2 * n * dim * dim
    forces = n * (2 * dim + 1) * dim                 # f_a = v sum_b P_ab g_b, per node
    H = n * dim**3 * 2 * dim
    pairs = n * (n + 1) // 2
    K = pairs * dim * dim * 2 * dim
    J = 14 if ir.J is not None else 0
    geometry = 2 * n * dim * dim + ir.geometry.ops + 1 + n * dim * (2 * dim - 1)
    F += geometry if ir.recompute else 0
    return {
        "constants": nq * geometry + ir.material.ops,
        "energy": nq * (F + J + law["energy"] + 2),
        "forces": nq * (F + J + law["gradient"] + forces),
        "stiffness": nq * (F + J + law["tangent"] + H + K),
        "forces_and_stiffness": nq * (F + J + law["gradient_tangent"] + forces + H + K),
        "stress": nq * (F + J + law["stress"]),
    }


def _input_hash(ref, rule, law) -> str:
    """A hash of everything the generated text depends on (templates are added by the backend)."""
    h = hashlib.sha256()
    h.update(GENERATOR_VERSION.encode())
    h.update(repr((ref.name, ref.nodes, [str(s) for s in ref.shape_functions])).encode())
    h.update(repr((rule.name, [tuple(str(x) for x in p) for p in rule.points], [str(w) for w in rule.weights])).encode())
    h.update(inspect.getsource(inspect.getmodule(law.energy)).encode())
    for module in law.sources:                 # a derived law (laws/viscous.py): its base law's file too
        h.update(inspect.getsource(sys.modules[module]).encode())
    return h.hexdigest()[:16]
