"""The third energy source: structural elements, an energy in nodal displacements and rotations.

    ir = build_shell_ir("shell", "cst_dkt")          # a KernelIR for the same backends

Stages (a shell law is quadratic in its local dofs: small strains, small rotations in its frame):
  frame       the law's rest frame (axes e0, e1, e2) and local corner coordinates of the element
  energy      the law's local_energy in symbolic local dofs, differentiated twice: the local
              stiffness K_bar, a function of the local coordinates and the parameters only
  rotation    K = T K_bar T^T with T the block diagonal of the axes (one block per displacement
              and per rotation of each node): the stiffness in world dofs
  hoisting    the world K (upper node blocks), the axes, the shape gradients and the plane-stress
              constants are per-element constants computed once by constants(); per step the
              kernel is f = -K u, W = -f.u / 2 and K itself
  stress      one "point" (the element) with v = area x thickness, W per v, F = I + grad u of the
              mid-surface (in-plane gradients, world axes) and P the membrane stress (plane
              stress, world axes) at the mid-surface
The co-rotational formulation for large rotations is the runtime's (runtime/kernels/corotational.py): it
applies this kernel's K_bar in the current element frame.
"""
from __future__ import annotations

import hashlib
import inspect
from types import SimpleNamespace

import sympy as sp

from .. import laws as laws_pkg
from . import GENERATOR_VERSION
from .kernel_ir import KernelIR
from .discrete import _DiscreteBuilder
from .fragments import DEFAULT_MAX_OPS, Fragment, count_ops, eliminate, split
from .kernel_body import Assign, Declare, Flag, ref, stress_record

QUADRATURE = "exact"              # the shell kernels integrate their (polynomial) energies exactly
DOFS = 6                          # per node: u, v, w, theta_x, theta_y, theta_z (world components)
N_NODES, DIM = 3, 3


def _s(name):
    return sp.Symbol(name, real=True)


def build_shell_ir(element_name: str, law_name: str, max_ops: int = DEFAULT_MAX_OPS, constants="precompute"):
    """The IR of a shell law's kernel on its element type (quadrature "exact")."""
    if constants != "precompute":
        raise ValueError("shell kernels store their stiffness as constants: only constants='precompute'")
    law = laws_pkg.get(law_name)
    if element_name not in law.elements:
        raise ValueError(f"law {law_name!r} is defined on {', '.join(law.elements)}, not {element_name!r}")
    parts = _derive(element_name, law, max_ops)
    material_names = tuple(name for name, _ in parts.material.outputs)
    fields = dict(
        name=f"{element_name}_{law_name}_{QUADRATURE}", element=element_name, law=law_name, quadrature=QUADRATURE,
        dim=DIM, n_nodes=N_NODES, n_points=1, parameters=tuple(law.parameters), requires_positive_J=False,
        affine_edges=(), point_stride=1, material_offset=1, material_names=material_names,
        constant_names=("v[0]",) + material_names, geometry=Fragment((), ()), geometry_G=(),
        dN_table=(tuple(tuple(0.0 for _ in range(DIM)) for _ in range(N_NODES)),), weights=(1.0,),
        material=parts.material, law_code=parts.code, J=None, chain={}, rule_points=((0.0,) * DIM,),
        rule_weights=(1.0,), recompute=False, stress_record=stress_record(DIM), source="shell", dofs=DOFS,
    )
    draft = SimpleNamespace(**fields, n_dofs=N_NODES * DOFS, dofs_per_node=DOFS, parts=parts)
    ops = {k: sum(f.ops for f in v) for k, v in parts.code.items()}
    ops = {"constants": parts.material.ops + parts.rest.ops, "energy": ops["energy"], "forces": ops["forces"],
           "stiffness": ops["stiffness"], "forces_and_stiffness": ops["forces_and_stiffness"],
           "stress": ops["stress"]}
    return KernelIR(**fields, ops=ops, input_hash=_input_hash(law), bodies=_ShellBuilder(draft).bodies())


def local_stiffness(element_name, law, P, params):
    """K_bar = sum weight B^T D B (18 x 18) of the law's strains on local corners P, as a Fragment:
    temporaries define the B, D and weight entries (CSE), then each nonzero K_bar entry kb{r}_{s}
    (r <= s) as a plain sum of products of them.  Returns (fragment, kb) with kb(r, s) the entry's
    symbol or 0 where K_bar is structurally zero."""
    ubar = [[_s(f"ub{i}_{k}") for k in range(DOFS)] for i in range(N_NODES)]
    flat = [s for row in ubar for s in row]
    terms = law.local_strains(element_name, ubar, P, **params)
    named, blocks = [], []
    for g, (weight, D, eps) in enumerate(terms):
        B = eps.jacobian(flat)
        if any(sp.diff(B[c, r], x) != 0 for c in range(B.rows) for r in range(B.cols) for x in flat if B[c, r] != 0):
            raise ValueError(f"shell law {law.name!r}: its strains must be linear in the local dofs")
        B_sym = sp.zeros(*B.shape)
        for c in range(B.rows):
            for r in range(B.cols):
                if B[c, r] != 0:
                    B_sym[c, r] = _s(f"b{g}_{c}_{r}")
                    named.append((str(B_sym[c, r]), B[c, r]))
        D_sym = sp.zeros(*D.shape)
        for c in range(D.rows):
            for d in range(c, D.cols):
                if D[c, d] != 0:
                    D_sym[c, d] = D_sym[d, c] = _s(f"d{g}_{c}_{d}")
                    named.append((str(D_sym[c, d]), weight * D[c, d]))
        blocks.append((B_sym, D_sym))
    stage = eliminate(named, "q")
    temps = list(stage.temporaries) + [(_s(name), e) for name, e in stage.outputs]
    n = N_NODES * DOFS
    entries = {}
    for r in range(n):
        for c in range(r, n):
            total = sum((B[a, r] * D[a, b] * B[b, c] for B, D in blocks
                         for a in range(B.rows) for b in range(B.rows)), sp.Integer(0))
            if total != 0:
                entries[(r, c)] = _s(f"kb{r}_{c}")
                temps.append((entries[(r, c)], total))
    return temps, lambda r, c: entries.get((min(r, c), max(r, c)), 0)


def _derive(element_name, law, max_ops):
    R = sp.Matrix(N_NODES, DIM, lambda i, k: 0 if i == 0 else _s(f"R{i}_{k}"))
    params = law.symbols()
    axes, P = law.frame(element_name, R)
    # K_bar in corner-coordinate symbols (compact expressions), then those symbols defined from R
    local = [(0, 0), (_s("l_1"), 0), (_s("p_2"), _s("q_2"))]
    temps, kb = local_stiffness(element_name, law, local, params)
    e = sp.Matrix(DIM, DIM, lambda k, a: _s(f"e{a}_{k}"))          # column a: the frame axis a (stored)
    # world K = T K_bar T^T, T block diagonal of e (one block per displacement and per rotation)
    def world(r, c):
        I, a, J, b = r // 3, r % 3, c // 3, c % 3
        return sum(e[a, x] * kb(3 * I + x, 3 * J + y) * e[b, y] for x in range(DIM) for y in range(DIM))
    n = N_NODES * DOFS
    upper = [(r, s) for i in range(N_NODES) for j in range(i, N_NODES)
             for r in range(i * DOFS, (i + 1) * DOFS) for s in range(j * DOFS, (j + 1) * DOFS)]
    # the mid-surface in-plane gradients of the linear shape functions (world axes): G_a = e0 dN_a/dx + e1 dN_a/dy
    grads = _shape_gradients(local)
    corner = {_s("l_1"): P[1][0], _s("p_2"): P[2][0], _s("q_2"): P[2][1]}
    area = _s("l_1") * _s("q_2") / 2
    E, nu, h = params["E"], params["nu"], params["thickness"]
    rest = [(f"e{a}_{k}", axes[a][k]) for a in range(DIM) for k in range(DIM)]
    rest += [(str(c), v) for c, v in corner.items()]
    consts = [(f"k{r}_{s}", world(r, s)) for r, s in upper]
    consts += [(f"g{a}_{k}", sum(grads[a][c] * e[k, c] for c in range(2))) for a in range(N_NODES) for k in range(DIM)]
    consts += [("c11", E / (1 - nu**2)), ("c12", E * nu / (1 - nu**2))]
    consts += [(f"e{a}_{k}", e[k, a]) for a in range(2) for k in range(DIM)]      # the stress record's axes
    # constants() computes the frame and corner symbols from R first, then the stored constants
    rest_code = eliminate(rest + [("v", area * h)], "r")
    material = Fragment(tuple(temps), tuple(consts))
    # per step: f = -K u (K symmetric: the stored upper blocks), W = -f.u / 2
    u = [_s(f"u{i}_{k}") for i in range(N_NODES) for k in range(DOFS)]
    k = lambda r, s: _s(f"k{min(r, s)}_{max(r, s)}")          # symmetric: the upper triangle is stored
    forces = [(f"f{r}", -sum(k(r, s) * u[s] for s in range(n))) for r in range(n)]
    W = [("W", -sum(_s(f"f{r}") * u[r] for r in range(n)) / 2)]
    stiffness = [(f"K{r}_{s}", _s(f"k{r}_{s}")) for r, s in upper]
    record = _record(u, e)
    code = {"energy": split(forces, "t_f", max_ops) + [eliminate(W, "t_e")],
            "forces": split(forces, "t_f", max_ops),
            "stiffness": split(stiffness, "t_s", max_ops),
            "forces_and_stiffness": split(forces + stiffness, "t_g", max_ops),
            "stress": split(forces, "t_f", max_ops) + [eliminate(W, "t_e"), eliminate(record, "t_r")]}
    return SimpleNamespace(code=code, material=material, rest=rest_code, record_rest=())


def _shape_gradients(P):
    """d N_a / d(x, y) of the linear triangle with local corners P (constant)."""
    (x0, y0), (x1, y1), (x2, y2) = P
    twice = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
    return [((y1 - y2) / twice, (x2 - x1) / twice), ((y2 - y0) / twice, (x0 - x2) / twice),
            ((y0 - y1) / twice, (x1 - x0) / twice)]


def _record(u, e):
    """W per v, F = I + sum_a u_a (x) G_a and the plane-stress membrane P = sigma in world axes."""
    H = sp.Matrix(DIM, DIM, lambda r, c: sum(u[a * DOFS + r] * _s(f"g{a}_{c}") for a in range(N_NODES)))
    F = sp.eye(DIM) + H
    axis = [[e[k, a] for k in range(DIM)] for a in range(2)]
    strain = lambda a, b: sum(axis[a][r] * H[r, c] * axis[b][c] for r in range(DIM) for c in range(DIM))
    exx, eyy, gxy = strain(0, 0), strain(1, 1), strain(0, 1) + strain(1, 0)
    c11, c12 = _s("c11"), _s("c12")
    sxx, syy, sxy = c11 * exx + c12 * eyy, c12 * exx + c11 * eyy, (c11 - c12) / 2 * gxy
    P = sp.Matrix(DIM, DIM, lambda r, c: sxx * axis[0][r] * axis[0][c] + syy * axis[1][r] * axis[1][c]
                  + sxy * (axis[0][r] * axis[1][c] + axis[1][r] * axis[0][c]))
    out = [("rec_W", _s("W") / _s("v"))]
    out += [(f"rec_F{a}{b}", F[a, b]) for a in range(DIM) for b in range(DIM)]
    out += [(f"rec_P{a}{b}", P[a, b]) for a in range(DIM) for b in range(DIM)]
    return out


def _input_hash(law) -> str:
    h = hashlib.sha256()
    h.update(GENERATOR_VERSION.encode())
    h.update(b"shell")
    h.update(inspect.getsource(inspect.getmodule(law.local_strains)).encode())
    h.update(inspect.getsource(inspect.getmodule(_derive)).encode())
    return h.hexdigest()[:16]


class _ShellBuilder(_DiscreteBuilder):
    """The statement trees of a shell kernel: D = (v, the hoisted constants), u with 6 dofs per node."""

    def read_rest(self):
        return []

    def read_u(self):
        return [Declare(f"u{i}_{k}", self.arr("u", i, k)) for i in range(self.n) for k in range(self.dofs)]

    def write_stiffness(self):
        p, out = self.dofs, []
        for i in range(self.n):
            for j in range(i, self.n):
                out += [Assign(self.arr("K", r, s), _s(f"K{r}_{s}")) for r in range(i * p, (i + 1) * p)
                        for s in range(j * p, (j + 1) * p)]
        return out + self.mirror_stiffness()

    def constants(self):
        ir = self.ir
        out = [Declare(f"R{i}_{k}", ref("X", i, k) - ref("X", 0, k)) for i in range(1, self.n) for k in range(self.dim)]
        out += [Declare(p, ref("params", k)) for k, p in enumerate(ir.parameters)]
        rest = self.parts.rest
        out += [Declare(str(sym), e) for sym, e in rest.temporaries]
        out += [Declare(name, e) for name, e in rest.outputs]
        out.append(Assign(ref("D", 0), _s("v")))
        out.append(Flag(_s("v"), 1))                     # a degenerate triangle: zero area (or thickness)
        # ... or collinear corners up to rounding: twice the area / l^2 (dimensionless) below 1e-12
        out.append(Flag(_s("q_2") / _s("l_1") - sp.Float(1e-12), 1))
        out += [Declare(str(sym), e) for sym, e in ir.material.temporaries]
        out += [Assign(ref("D", ir.material_offset + k), e) for k, (_, e) in enumerate(ir.material.outputs)]
        return tuple(out)
