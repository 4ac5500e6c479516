"""The second energy source: discrete laws, an element energy written in nodal positions.

    ir = build_discrete_ir("hexahedron", "hybmss")      # a KernelIR for the same backends

Stages (the continuum pipeline's, with the element energy in place of W(F) and the chain rule):
  energy      the law's element_energy(element, x, X, params) with x = X + u
  rest frame  the kernels store rest positions relative to node 0, R_i = X_i - X_0 (translation
              invariance, checked here): the per-step code reads D and u only, like the FEM kernels
  hoisting    every subexpression of rest positions and parameters (rest lengths, volumes, the
              stiffness rules) becomes a per-element constant, computed once by constants()
  derivatives f = -dW/du and K = d2W/du2 directly (node blocks j >= i, mirrored by the kernel)
  fragments   CSE and splitting, as for the laws
The result is a KernelIR with one "point" (n_points = 1, its v the element's rest measure) and
the same kernel functions and signatures as every generated kernel, so the backends print it with
their own templates and the runtime loads and assembles it like any other.  Its stress record
holds homogenised values: F the least-squares deformation gradient of the nodes (exact for an
affine motion), W the energy per rest measure and P = (1/V) sum_a (dW/dx_a) (X_a - X_c)^T, the
virial stress, which is the average first Piola-Kirchhoff stress of a finite element.
"""
from __future__ import annotations

import hashlib
import inspect
import random
from types import SimpleNamespace

import sympy as sp

from .. import laws as laws_pkg
from . import GENERATOR_VERSION
from .kernel_ir import KernelIR
from .constants import hoist
from .elements import element as get_element
from .fragments import DEFAULT_MAX_OPS, Fragment, count_ops, eliminate, split
from .kernel_body import (ARRAYS, FUSED_ARRAYS, KINDS, Assign, Comment, Declare, Flag, FlagIf, BodyBuilder, ref,
                          stress_record)

QUADRATURE = "discrete"          # the quadrature name of every discrete kernel: no integration points


def _s(name):
    return sp.Symbol(name, real=True)


def build_discrete_ir(element_name: str, law_name: str, max_ops: int = DEFAULT_MAX_OPS, constants="precompute"):
    """The IR of a discrete law's kernel on one element type (quadrature "discrete")."""
    if constants != "precompute":
        raise ValueError("discrete kernels store their rest geometry as constants: only constants='precompute'")
    law = laws_pkg.get(law_name)
    if element_name not in law.elements:
        raise ValueError(f"law {law_name!r} is defined on {', '.join(law.elements)}, not {element_name!r}")
    ref_el = get_element(element_name)
    n, dim = ref_el.n_nodes, ref_el.dim
    parts = _derive(element_name, law, n, dim, max_ops)
    stride = 1 + (n - 1) * dim
    material_names = tuple(name for name, _ in parts.material.outputs)
    names = ["v[0]"] + [f"R[{i}][{k}]" for i in range(1, n) for k in range(dim)]
    fields = dict(
        name=f"{element_name}_{law_name}_{QUADRATURE}", element=element_name, law=law_name, quadrature=QUADRATURE,
        dim=dim, n_nodes=n, n_points=1, parameters=tuple(law.parameters), requires_positive_J=False,
        affine_edges=(), point_stride=stride, material_offset=stride, material_names=material_names,
        constant_names=tuple(names) + material_names, geometry=Fragment((), ()), geometry_G=(),
        dN_table=(tuple(tuple(0.0 for _ in range(dim)) for _ in range(n)),), weights=(1.0,),
        material=parts.material, law_code=parts.code, J=None, chain={}, rule_points=((0.0,) * dim,),
        rule_weights=(1.0,), recompute=False, stress_record=stress_record(dim), source="discrete",
    )
    draft = SimpleNamespace(**fields, n_dofs=n * dim, dofs_per_node=dim, parts=parts)
    ops = {k: sum(f.ops for f in v) for k, v in parts.code.items()}
    ops = {"constants": parts.material.ops + parts.rest.ops, "energy": ops["energy"], "forces": ops["forces"],
           "stiffness": ops["stiffness"], "forces_and_stiffness": ops["forces_and_stiffness"],
           "stress": ops["stress"] + sum(count_ops(e) for _, e in parts.record_rest)}
    return KernelIR(**fields, ops=ops, input_hash=_input_hash(ref_el, law), bodies=_DiscreteBuilder(draft).bodies())


def _derive(element_name, law, n, dim, max_ops):
    """Energy, forces, stiffness and stress record as fragments over R (rest positions relative to
    node 0), u and the hoisted per-element constants."""
    R = sp.Matrix(n, dim, lambda i, k: 0 if i == 0 else _s(f"R{i}_{k}"))
    u = sp.Matrix(n, dim, lambda i, k: _s(f"u{i}_{k}"))
    params = law.symbols()
    _check_translation(law, element_name, n, dim)
    W = law.element_energy(element_name, R + u, R, **params)
    measure = sp.sympify(law.rest_measure(element_name, R))
    checks = [(sp.sympify(a), sp.sympify(b), flag) for a, b, flag, _ in law.rest_checks(element_name, R)]
    uflat = list(u)
    grad = [sp.diff(W, s) for s in uflat]
    forces = [(f"f{r}", -g) for r, g in enumerate(grad)]
    stiffness = [(f"K{r}_{s}", sp.diff(grad[r], uflat[s]))
                 for i in range(n) for j in range(i, n) for r in range(i * dim, (i + 1) * dim)
                 for s in range(j * dim, (j + 1) * dim)]
    everything = [("W", W)] + forces + stiffness
    rest = {s for s in R if s != 0} | set(params.values()) | {_s("v")}
    hoisted, constants = hoist([e for _, e in everything], rest, prefix="k")
    W_out = [("W", hoisted[0])]
    f_out = [(name, e) for (name, _), e in zip(forces, hoisted[1:1 + len(forces)])]
    K_out = [(name, e) for (name, _), e in zip(stiffness, hoisted[1 + len(forces):])]
    # The stress record runs once per frame: what it needs beyond the energy and forces is computed
    # there from R (not stored), with S = sum_a dX_a dX_a^T as named temporaries (inverted in closed form).
    F, P, S_code = _homogenised(R, u, n, dim)
    v = _s("v")
    virial = [(f"rec_P{a}{b}", P[a, b] / v) for a in range(dim) for b in range(dim)]
    record = [("rec_W", _s("W") / v)] + [(f"rec_F{a}{b}", F[a, b]) for a in range(dim) for b in range(dim)] + virial
    code = {"energy": split(W_out, "t_e", max_ops), "forces": split(f_out, "t_f", max_ops),
            "stiffness": split(K_out, "t_s", max_ops),
            "forces_and_stiffness": split(f_out + K_out, "t_g", max_ops),
            "stress": split(W_out + f_out, "t_e", max_ops) + [eliminate(record, "t_r")]}
    material = eliminate([(str(c), e) for c, e in constants], "m")
    rest_code = eliminate([("v", measure)] + [(f"check{k}", a) for k, (a, _, _) in enumerate(checks)], "r")
    return SimpleNamespace(code=code, material=material, rest=rest_code, checks=checks, record_rest=S_code)


def _homogenised(R, u, n, dim):
    """The least-squares F of the nodes and the virial sum_a (dW/dx_a) (X_a - X_c)^T, in terms of the
    force symbols f{r} = -dW/du_r and of symbols S{a}{b} for S = sum_a dX_a dX_a^T; S_code computes
    S from R (the stress kernel declares it first)."""
    centre = [sum(R[i, k] for i in range(n)) / n for k in range(dim)]
    dX = sp.Matrix(n, dim, lambda i, k: R[i, k] - centre[k])
    S_full = dX.T * dX
    S = sp.Matrix(dim, dim, lambda a, b: _s(f"S{min(a, b)}{max(a, b)}"))
    S_code = [(f"S{a}{b}", sp.expand(S_full[a, b])) for a in range(dim) for b in range(a, dim)]
    B = dX * (S.adjugate() / _s("detS"))
    S_code.append(("detS", S.det()))
    x = R + u
    F = sp.zeros(dim, dim)
    P = sp.zeros(dim, dim)
    for a in range(n):
        for r in range(dim):
            for c in range(dim):
                F[r, c] += x[a, r] * B[a, c]
                P[r, c] -= _s(f"f{a * dim + r}") * dX[a, c]
    return F, P, S_code


def _check_translation(law, element_name, n, dim):
    """The kernels drop X_0: refuse a law whose element energy changes under a translation."""
    rnd = random.Random(7)
    X = sp.Matrix(n, dim, lambda i, k: sp.Float(rnd.uniform(-1, 1)))
    u = sp.Matrix(n, dim, lambda i, k: sp.Float(0.1 * rnd.uniform(-1, 1)))
    shift = sp.Matrix(n, dim, lambda i, k: sp.Float([0.3, -0.7, 0.5][k]))
    numbers = {p: sp.Float(0.3) for p in law.parameters}
    a = float(law.element_energy(element_name, X + u, X, **numbers))
    b = float(law.element_energy(element_name, X + u + shift, X + shift, **numbers))
    if abs(a - b) > 1e-9 * (1 + abs(a)):
        raise ValueError(f"discrete law {law.name!r}: the element energy of {element_name} is not invariant "
                         "under a translation")


def _input_hash(ref_el, law) -> str:
    h = hashlib.sha256()
    h.update(GENERATOR_VERSION.encode())
    h.update(repr((ref_el.name, ref_el.nodes, "discrete")).encode())
    for module in sorted({inspect.getmodule(law.element_energy), inspect.getmodule(law.rest_measure),
                          inspect.getmodule(laws_pkg.springs)}, key=lambda m: m.__name__):
        h.update(inspect.getsource(module).encode())
    return h.hexdigest()[:16]


class _DiscreteBuilder(BodyBuilder):
    """The statement trees of a discrete kernel: straight-line code per element, no point loop."""

    def __init__(self, ir):
        super().__init__(ir)
        self.parts = ir.parts

    def read_rest(self):
        d = self.dim
        return [Declare(f"R{i}_{k}", ref("D", 1 + (i - 1) * d + k)) for i in range(1, self.n) for k in range(d)]

    def read_u(self):
        return [Declare(f"u{i}_{k}", self.arr("u", i, k)) for i in range(self.n) for k in range(self.dim)]

    def prologue(self):
        return ([Declare("v", ref("D", 0))] + self.read_rest() + self.material() + self.read_u())

    def write_forces(self):
        return [Assign(self.arr("f", r), _s(f"f{r}")) for r in range(self.n_dofs)]

    def write_stiffness(self):
        d, out = self.dim, []
        for i in range(self.n):
            for j in range(i, self.n):
                out += [Assign(self.arr("K", r, s), _s(f"K{r}_{s}")) for r in range(i * d, (i + 1) * d)
                        for s in range(j * d, (j + 1) * d)]
        return out + self.mirror_stiffness()

    def constants(self):
        d, ir = self.dim, self.ir
        out = [Declare(f"R{i}_{k}", ref("X", i, k) - ref("X", 0, k)) for i in range(1, self.n) for k in range(d)]
        out += [Assign(ref("D", 1 + (i - 1) * d + k), _s(f"R{i}_{k}")) for i in range(1, self.n) for k in range(d)]
        out += [Declare(p, ref("params", k)) for k, p in enumerate(ir.parameters)]
        rest = self.parts.rest
        out += [Declare(str(sym), e) for sym, e in rest.temporaries]
        out += [Declare(name, e) for name, e in rest.outputs]
        out.append(Assign(ref("D", 0), _s("v")))
        out.append(Flag(_s("v"), 1))
        out += [FlagIf(_s(f"check{k}"), bound, flag) for k, (_, bound, flag) in enumerate(self.parts.checks)]
        out += [Declare(str(sym), e) for sym, e in ir.material.temporaries]
        out += [Assign(ref("D", ir.material_offset + k), e) for k, (_, e) in enumerate(ir.material.outputs)]
        return tuple(out)

    def kernel(self, kind):
        if kind == "constants":
            return self.constants()
        if kind == "forces_and_stiffness_scatter":
            self.names = FUSED_ARRAYS
            try:
                return tuple(self.gather_u()) + self.kernel("forces_and_stiffness") + tuple(self.scatter())
            finally:
                self.names = ARRAYS
        out = self.prologue()
        if kind == "stress":
            out += [Declare(name, e) for name, e in self.parts.record_rest]
        out += self.law(kind)               # the fragments of law_code[kind], as for the continuum kernels
        if kind == "energy":
            out.append(Assign(ref("out"), _s("W")))
        if kind in ("forces", "forces_and_stiffness"):
            out += self.write_forces()
        if kind in ("stiffness", "forces_and_stiffness"):
            out += self.write_stiffness()
        if kind == "stress":
            out += self.write_record()
        return tuple(out)

    def write_record(self):
        d, layout = self.dim, stress_record(self.dim)["offsets"]
        out = [Comment("The homogenised record of the element (one point: v, W per v, F, P).")]
        out.append(Assign(ref("S", 0, layout["v"]), _s("v")))
        out.append(Assign(ref("S", 0, layout["W"]), _s("rec_W")))
        out += [Assign(ref("S", 0, layout[name] + a * d + b), _s(f"rec_{name}{a}{b}"))
                for name in ("F", "P") for a in range(d) for b in range(d)]
        if d == 2:
            out.append(Assign(ref("S", 0, layout["P33"]), sp.Integer(0)))
        return out

    def bodies(self) -> dict:
        return {kind: self.kernel(kind) for kind in KINDS}
