"""The kernel algorithm as data: a small language-neutral statement tree, built once per IR.

Each kernel function (constants, energy, forces, stiffness, forces_and_stiffness, stress) is the
body of a loop over elements, given here as statements over sympy expressions:

    Loop(var, start, stop, body)       for var in [start, stop)
    Declare(name, value)               a new local (mutable when it is accumulated later;
                                       uniform when it is the same for every element: a table value;
                                       integer: an index, e.g. a node id read from cells)
    Assign(target, value)              target = value
    Accumulate(target, value, sign)    target += value (sign -1: -=)
    Flag(value, flag, leave)           if not (value > 0): flags = flag (and leave the point loop)
    FlagIf(left, right, flag)          if left > right: flags = flag
    Comment(text)

Array elements are Ref(array, index, ...) sympy functions over the loop variables; the arrays
are the kernel arguments of the current element (X, params, D, u, f, K, out, S: the stress kernel's
records (n_points, stress_record size), and cells, pos of the fused kernel), the global arrays of the fused kernel (U: nodal displacements (n_points, dim),
fg: global forces, data: global CSR values), the tables (DN, WEIGHTS) and per-call scratch
(Gq of recompute kernels; ul, fl, Kl: one element's u, f and K in the fused kernel).

forces_and_stiffness_scatter (the fused evaluation and scatter) is forces_and_stiffness with
u gathered from U through cells into the one-element scratch ul, f and K computed into the
scratch fl and Kl, then added into fg (dof = node * dim + component) and data (pos[e, r, j]:
the CSR index of row dof r, first column dof of node j: a node's dofs are consecutive in a
CSR row, so the dim entries of a node block are data[pos[e, r, j] + c]). Elements are added
one after the other in element order with the same values as the element-buffer path, so
the result is bit-identical to forces_and_stiffness followed by a serial scatter. A backend's printer prints the
statements in its language (the C vector variant prints the same tree on 4 elements at once);
templates only lay out the functions around them.
"""
from __future__ import annotations

from dataclasses import dataclass

import sympy as sp


class Ref(sp.Function):
    """Array element Ref(name, i0, i1, ...): name a Symbol naming the array, indices integer expressions."""

    @classmethod
    def eval(cls, *args):
        return None

    def _eval_is_real(self):
        return True


class IntDiv(sp.Function):
    """Integer division a // b (both non-negative) in an index or loop bound."""

    @classmethod
    def eval(cls, a, b):
        if a.is_Integer and b.is_Integer:
            return sp.Integer(int(a) // int(b))
        return None


@dataclass(frozen=True)
class Comment:
    text: str


@dataclass(frozen=True)
class Declare:
    name: str
    value: sp.Expr
    mutable: bool = False
    uniform: bool = False
    integer: bool = False


@dataclass(frozen=True)
class Assign:
    target: sp.Expr
    value: sp.Expr


@dataclass(frozen=True)
class Accumulate:
    target: sp.Expr
    value: sp.Expr
    sign: int = 1


@dataclass(frozen=True)
class Loop:
    var: str
    start: sp.Expr
    stop: sp.Expr
    body: tuple


@dataclass(frozen=True)
class Flag:
    value: sp.Expr
    flag: int
    leave: bool = False


@dataclass(frozen=True)
class FlagIf:
    left: sp.Expr
    right: sp.Expr
    flag: int


KINDS = ("constants", "energy", "forces", "stiffness", "forces_and_stiffness", "forces_and_stiffness_scatter",
         "stress")
LAW_VARIANT = {"energy": "energy", "forces": "gradient", "stiffness": "tangent",
               "forces_and_stiffness": "gradient_tangent", "forces_and_stiffness_scatter": "gradient_tangent",
               "stress": "stress"}


def stress_record(dim: int) -> dict:
    """The layout of one record of the stress kernel: what it writes per element and point.

    S[e, q, offsets[name] + k] for name in
      v    the point's rest volume w det J (m^3; area x unit thickness in 2D)
      W    the energy density per rest volume (J/m^3)
      F    the deformation gradient, dim x dim row-major (F[a][b] at + a * dim + b)
      P    the first Piola-Kirchhoff stress dW/dF, dim x dim row-major (Pa)
      P33  2D only (plane strain, F33 = 1): the out-of-plane stress dW/dF33 (Pa)
    Every stress and strain field follows from these, law-independently (runtime/physics/fields.py).
    The generated files export this dict in their metadata ("stress_record"); the runtime reads
    it from there, never from here (loading a kernel imports no generator)."""
    offsets, at = {}, 0
    for name, size in (("v", 1), ("W", 1), ("F", dim * dim), ("P", dim * dim)) + ((("P33", 1),) if dim == 2 else ()):
        offsets[name] = at
        at += size
    return {"size": at, "offsets": offsets}
# The arrays u, f, K of each kernel: the element's rows of the arguments, or (fused) one-element scratch.
ARRAYS = {"u": "u", "f": "f", "K": "K"}
FUSED_ARRAYS = {"u": "ul", "f": "fl", "K": "Kl"}


def _s(name: str) -> sp.Symbol:
    return sp.Symbol(name, real=True)


def _i(name: str) -> sp.Symbol:
    return sp.Symbol(name, integer=True, nonnegative=True)


def ref(array: str, *indices) -> Ref:
    return Ref(sp.Symbol(array), *[sp.sympify(i) for i in indices])


q, i, j, r, s, c_ = (_i(n) for n in ("q", "i", "j", "r", "s", "c"))
node, base = _i("node"), _i("base")


class BodyBuilder:
    """Statement lists of one IR (see build_bodies)."""

    def __init__(self, ir):
        self.ir = ir
        self.dim, self.n = ir.dim, ir.n_nodes
        self.dofs = ir.dofs_per_node           # = dim for solids; 6 for shells (u, f, K rows per node)
        self.n_dofs = ir.n_dofs
        self.names = ARRAYS

    def arr(self, name, *indices):
        """Element of u, f or K of the kernel being built (argument rows or fused scratch)."""
        return ref(self.names[name], *indices)

    # -- pieces -------------------------------------------------------------------------------
    def G(self, node, b):
        """Shape gradient b of node at point q: stored in D, or recomputed into Gq."""
        if self.ir.recompute:
            return ref("Gq", node, b)
        return ref("D", q * self.ir.point_stride + 1 + node * self.dim + b)

    def rest_jacobian(self, coordinate):
        """J = sum_i x_i (x) dN_i at point q, then det J and J^-1 (the geometry temporaries)."""
        d = self.dim
        out = [Declare(f"J{a}{k}", sp.Integer(0), mutable=True) for a in range(d) for k in range(d)]
        out.append(Loop("i", 0, self.n, tuple(
            Accumulate(_s(f"J{a}{k}"), coordinate(i, a) * ref("DN", q, i, k)) for a in range(d) for k in range(d))))
        out += [Declare(str(sym), e) for sym, e in self.ir.geometry.temporaries]
        return out

    def geometry_G(self, target):
        """The shape gradients of every node at point q, from det J and J^-1, written to target(i, b)."""
        body = [Declare(f"dn{k}", ref("DN", q, i, k), uniform=True) for k in range(self.dim)]
        body += [Assign(target(i, b), e) for b, e in self.ir.geometry_G]
        return Loop("i", 0, self.n, tuple(body))

    def deformation_gradient(self):
        d, ir = self.dim, self.ir
        out = []
        if ir.recompute:
            out.append(Comment("Rest geometry recomputed from the rest coordinates stored in D (no G in memory)."))
            out += self.rest_jacobian(lambda node, a: ref("D", node * d + a))
            out.append(Declare("v", ref("WEIGHTS", q) * _s("detJ")))
            out.append(self.geometry_G(lambda node, b: ref("Gq", node, b)))
        else:
            out.append(Declare("v", ref("D", q * ir.point_stride)))
        start = 1 + self.n * d                 # the law's point inputs (its history) follow G
        out += [Declare(name, ref("D", q * ir.point_stride + start + k)) for k, (name, _) in enumerate(ir.point_inputs)]
        out += [Declare(f"F{a}{b}", sp.Integer(1 if a == b else 0), mutable=True) for a in range(d) for b in range(d)]
        body = [Declare(f"gi{b}", self.G(i, b)) for b in range(d)]
        body += [Declare(f"u{a}", self.arr("u", i, a)) for a in range(d)]
        body += [Accumulate(_s(f"F{a}{b}"), _s(f"u{a}") * _s(f"gi{b}")) for a in range(d) for b in range(d)]
        out.append(Loop("i", 0, self.n, tuple(body)))
        if ir.J is not None:
            out.append(Declare("J", ir.J))
            out.append(Flag(_s("J"), 1, leave=True))
        return out

    def law(self, variant):
        out = []
        for k, fragment in enumerate(self.ir.law_code[variant]):
            out.append(Comment(f"law fragment {k}"))
            out += [Declare(str(sym), e) for sym, e in fragment.temporaries]
            out += [Declare(name, e) for name, e in fragment.outputs]
        return out

    def material(self):
        return [Declare(name, ref("D", self.ir.material_offset + k)) for k, name in enumerate(self.ir.material_names)]

    def add_forces(self):
        d = self.dim
        body = [Declare(f"gi{b}", self.G(i, b)) for b in range(d)]
        body += [Accumulate(self.arr("f", i * d + a), e, -1) for a, e in self.ir.chain["forces"]]
        return [Loop("i", 0, self.n, tuple(body))]

    def add_stiffness(self):
        d = self.dim
        inner = [Declare(f"gj{b}", self.G(j, b)) for b in range(d)]
        inner += [Accumulate(self.arr("K", i * d + a, j * d + c), e) for a, c, e in self.ir.chain["K"]]
        body = [Declare(f"gi{b}", self.G(i, b)) for b in range(d)]
        body += [Declare(name, e) for name, e in self.ir.chain["H"]]
        body.append(Loop("j", i, self.n, tuple(inner)))
        return [Loop("i", 0, self.n, tuple(body))]

    def zero_forces(self):
        return [Loop("r", 0, self.n_dofs, (Assign(self.arr("f", r), sp.Integer(0)),))]

    def zero_stiffness(self):
        return [Loop("r", 0, self.n_dofs, (Loop("s", 0, self.n_dofs, (Assign(self.arr("K", r, s), sp.Integer(0)),)),))]

    def mirror_stiffness(self):
        return [Comment("Only node blocks j >= i were accumulated: copy them below the diagonal."),
                Loop("r", 0, self.n_dofs, (Loop("s", 0, IntDiv(r, self.dofs) * self.dofs,
                                                 (Assign(self.arr("K", r, s), self.arr("K", s, r)),)),))]

    def gather_u(self):
        """ul[i, a] = U[cells[e, i], a]: the element's displacements read from the global array."""
        return [Loop("i", 0, self.n, (Declare("node", ref("cells", i), integer=True),)
                     + tuple(Assign(ref("ul", i, a), ref("U", node, a)) for a in range(self.dofs)))]

    def scatter(self):
        """fl into fg, then Kl into data node block by node block, through cells and pos."""
        d = self.dofs
        forces = Loop("i", 0, self.n, (Declare("node", ref("cells", i), integer=True),)
                      + tuple(Accumulate(ref("fg", node * d + a), ref("fl", i * d + a)) for a in range(d)))
        blocks = Loop("r", 0, self.n_dofs, (Loop("j", 0, self.n, (
            Declare("base", ref("pos", r, j), integer=True),
            Loop("c", 0, d, (Accumulate(ref("data", base + c_), ref("Kl", r, j * d + c_)),)))),))
        return [Comment("Add the element into the global forces and CSR values (element order)."), forces, blocks]

    # -- kernels ------------------------------------------------------------------------------
    def constants(self):
        ir, d = self.ir, self.dim
        point = self.rest_jacobian(lambda node, a: ref("X", node, a))
        point.append(Flag(_s("detJ"), 1))
        if not ir.recompute:
            point.append(Assign(ref("D", q * ir.point_stride), ref("WEIGHTS", q) * _s("detJ")))
            point.append(self.geometry_G(lambda node, b: ref("D", q * ir.point_stride + 1 + node * d + b)))
            point += [Assign(ref("D", q * ir.point_stride + 1 + self.n * d + k), sp.Float(value))
                      for k, (_, value) in enumerate(ir.point_inputs)]
        out = [Loop("q", 0, ir.n_points, tuple(point))]
        if ir.recompute:
            out.append(Loop("i", 0, self.n, tuple(Assign(ref("D", i * d + k), ref("X", i, k)) for k in range(d))))
        if ir.affine_edges:
            out += [Declare("deviation", sp.Integer(0), mutable=True), Declare("scale", sp.Integer(0), mutable=True)]
            for m, a, b in ir.affine_edges:
                for k in range(d):
                    mid = ref("X", m, k) - sp.Rational(1, 2) * (ref("X", a, k) + ref("X", b, k))
                    out.append(Accumulate(_s("deviation"), mid ** 2))
                    out.append(Accumulate(_s("scale"), (ref("X", a, k) - ref("X", b, k)) ** 2))
            out.append(FlagIf(_s("deviation"), sp.Float(1e-16) * _s("scale"), 2))
        out += [Declare(p, ref("params", k)) for k, p in enumerate(ir.parameters)]
        out += [Assign(ref("D", ir.material_offset + k), e) for k, (_, e) in enumerate(ir.material.outputs)]
        return tuple(out)

    def stress(self):
        """Per point, the record of stress_record(dim) into S[e, q, :]: no forces, no stiffness."""
        d, layout = self.dim, stress_record(self.dim)["offsets"]
        values = [("v", [_s("v")]), ("W", [_s("W")]),
                  ("F", [_s(f"F{a}{b}") for a in range(d) for b in range(d)]),
                  ("P", [_s(f"P{a}{b}") for a in range(d) for b in range(d)])]
        if d == 2:
            values.append(("P33", [_s("P22")]))
        record = [Comment("The stress record of this point (generator/kernel_body.stress_record).")]
        record += [Assign(ref("S", q, layout[name] + k), value) for name, column in values
                   for k, value in enumerate(column)]
        body = self.deformation_gradient() + self.law("stress") + record
        return tuple(self.material()) + (Loop("q", 0, self.ir.n_points, tuple(body)),)

    def point_loop(self, kind):
        body = self.deformation_gradient() + self.law(LAW_VARIANT[kind])
        if kind == "energy":
            body.append(Accumulate(_s("acc"), _s("v") * _s("W")))
        if kind in ("forces", "forces_and_stiffness"):
            body += self.add_forces()
        if kind in ("stiffness", "forces_and_stiffness"):
            body += self.add_stiffness()
        return Loop("q", 0, self.ir.n_points, tuple(body))

    def kernel(self, kind):
        if kind == "constants":
            return self.constants()
        if kind == "stress":
            return self.stress()
        if kind == "forces_and_stiffness_scatter":
            self.names = FUSED_ARRAYS
            try:
                return tuple(self.gather_u()) + self.kernel("forces_and_stiffness") + tuple(self.scatter())
            finally:
                self.names = ARRAYS
        out = []
        if kind in ("forces", "forces_and_stiffness"):
            out += self.zero_forces()
        if kind in ("stiffness", "forces_and_stiffness"):
            out += self.zero_stiffness()
        out += self.material()
        if kind == "energy":
            out.append(Declare("acc", sp.Integer(0), mutable=True))
        out.append(self.point_loop(kind))
        if kind == "energy":
            out.append(Assign(ref("out"), _s("acc")))
        if kind in ("stiffness", "forces_and_stiffness"):
            out += self.mirror_stiffness()
        return tuple(out)


def build_bodies(ir) -> dict:
    """kind -> the statements of one element (the body of the element loop) for every kernel."""
    builder = BodyBuilder(ir)
    return {kind: builder.kernel(kind) for kind in KINDS}
