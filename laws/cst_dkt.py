"""The flat CST-DKT shell triangle (thesis chapter 6): membrane + Kirchhoff plate bending + drilling.

The energy of one triangle in its 18 world dofs u = (u, v, w, theta_x, theta_y, theta_z) per node,
small strains and small rotations (the co-rotational runtime kernel, runtime/corotational.py,
applies it in the current element frame for large rotations):

  frame      e0 along the edge from node 0 to node 1, e2 the unit normal (right-handed winding),
             e1 = e2 x e0 (right-handed: the printed e0 x e2 of the thesis is left-handed);
             node coordinates in it: (0, 0), (l, 0), (p, q).  Local dofs: u_bar = T0^T u per node.
  membrane   CST: W_m = 1/2 h A eps^T C eps, eps = (u_x, v_y, u_y + v_x) (engineering shear),
             C = E / (1 - nu^2) [[1, nu, 0], [nu, 1, 0], [0, 0, (1 - nu) / 2]] (plane stress; the
             printed (1 - nu) shear entry doubles the shear stiffness).
  bending    DKT (Batoz, Bathe & Ho 1980), derived here from its hypotheses, not transcribed: the
             normal's rotations beta = (theta_y, -theta_x) (u = z beta_x, v = z beta_y, so the
             Kirchhoff constraint is beta = -grad w) are quadratic (six-node shape functions);
             at the corners they are the nodal dofs; at each midside the tangential component
             is -dw/ds of the cubic w along the edge (Hermite from the corner values and slopes)
             and the normal component the mean of the corners'.  W_b = 1/2 (h^3 / 12) int k^T C k,
             k = (beta_x,x, beta_y,y, beta_x,y + beta_y,x), integrated exactly (three midside points:
             the integrand is quadratic).
  drilling   the in-plane rotations theta_z get a small stiffness so that K is regular:
             W_d = 1/2 k_d sum_i (theta_z_i - omega)^2 with omega = (v_x - u_y) / 2 the membrane's
             in-plane rotation (so a rigid in-plane rotation costs nothing) and
             k_d = DRILLING x E h A: 1/1000 of the membrane's stiffness against an in-plane rotation
             of the element (the thesis' "minimum diagonal entry / 1000", made smooth).
Parameters: E, nu, thickness (h).  The option `corotational` (default 1) is the runtime's: 1 wraps
the kernel in the co-rotational formulation, 0 uses it as it is (small rotations: linear plates).
"""
from dataclasses import dataclass
from fractions import Fraction
from typing import Callable

from . import sympy_lazy as sp
from .base import DiscreteLaw, LawError

DRILLING = Fraction(1, 1000)      # exact: sympy reads it as Rational(1, 1000)
ELEMENT = "shell"


def _cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def _dot(a, b):
    return sum(x * y for x, y in zip(a, b))


def rest_frame(X):
    """(e0, e1, e2), l, p, q of the rest triangle X (3 x 3 rows = nodes): the frame's axes as
    lists of world components and the node coordinates (0, 0), (l, 0), (p, q) in it."""
    d1 = [X[1, k] - X[0, k] for k in range(3)]
    d2 = [X[2, k] - X[0, k] for k in range(3)]
    l = sp.sqrt(_dot(d1, d1))
    n = _cross(d1, d2)
    twice_area = sp.sqrt(_dot(n, n))
    e0 = [c / l for c in d1]
    e2 = [c / twice_area for c in n]
    e1 = _cross(e2, e0)
    return (e0, e1, e2), l, _dot(d2, e0), twice_area / l


def plane_stress(E, nu):
    return E / (1 - nu**2) * sp.Matrix([[1, nu, 0], [nu, 1, 0], [0, 0, (1 - nu) / 2]])


def _map(P):
    """Reference (s, t) -> local (x, y) of the triangle with local corners P, and the gradient
    operator d/d(x, y) of functions of (s, t) (the map is affine)."""
    s, t = sp.symbols("s t", real=True)
    J = sp.Matrix([[P[1][0] - P[0][0], P[2][0] - P[0][0]], [P[1][1] - P[0][1], P[2][1] - P[0][1]]])   # dx/d(s,t)
    Jinv = J.inv()

    def grad(f):
        g = sp.Matrix([[sp.diff(f, s), sp.diff(f, t)]]) * Jinv
        return g[0], g[1]
    return s, t, J.det(), grad


def membrane(P, ubar):
    """CST strain eps = (u_x, v_y, u_y + v_x), the in-plane rotation omega = (v_x - u_y) / 2 of
    the local in-plane displacements, and the area."""
    s, t, detJ, grad = _map(P)
    N = [1 - s - t, s, t]
    u = sum(N[i] * ubar[i][0] for i in range(3))
    v = sum(N[i] * ubar[i][1] for i in range(3))
    (ux, uy), (vx, vy) = grad(u), grad(v)
    return sp.Matrix([ux, vy, uy + vx]), (vx - uy) / 2, detJ / 2


def dkt_rotations(P, w, beta):
    """The DKT rotation field beta(s, t) = (beta_x, beta_y) from corner deflections w[i] and corner
    rotations beta[i] (local): quadratic, constrained at the midsides as the module says."""
    s, t = sp.symbols("s t", real=True)
    L = [1 - s - t, s, t]
    out = [sum(L[i] * (2 * L[i] - 1) * beta[i][c] for i in range(3)) for c in range(2)]
    for i, j in ((1, 2), (2, 0), (0, 1)):
        dx, dy = P[j][0] - P[i][0], P[j][1] - P[i][1]
        length = sp.sqrt(dx**2 + dy**2)
        tangent = (dx / length, dy / length)
        normal = (tangent[1], -tangent[0])
        bs = [beta[k][0] * tangent[0] + beta[k][1] * tangent[1] for k in (i, j)]
        bn = [beta[k][0] * normal[0] + beta[k][1] * normal[1] for k in (i, j)]
        # w cubic along the edge: its midside slope is 3 (w_j - w_i) / (2 length) - (w_s,i + w_s,j) / 4
        # with w_s = -beta_s at the corners; the midside beta_s is minus that slope
        mid_s = -sp.Rational(3, 2) * (w[j] - w[i]) / length - (bs[0] + bs[1]) / 4
        mid_n = (bn[0] + bn[1]) / 2
        mid = (mid_s * tangent[0] + mid_n * normal[0], mid_s * tangent[1] + mid_n * normal[1])
        bubble = 4 * L[i] * L[j]
        out = [out[c] + bubble * mid[c] for c in range(2)]
    return out


def bending(P, ubar, h):
    """DKT curvature terms: (weight, kappa) at the three midside points, which integrate the
    quadratic density kappa^T C kappa exactly (weight = (h^3 / 12) x area / 3)."""
    s, t, detJ, grad = _map(P)
    w = [ubar[i][2] for i in range(3)]
    beta = [(ubar[i][4], -ubar[i][3]) for i in range(3)]          # (theta_y, -theta_x)
    bx, by = dkt_rotations(P, w, beta)
    (bxx, bxy), (byx, byy) = grad(bx), grad(by)
    kappa = sp.Matrix([bxx, byy, bxy + byx])
    points = ((sp.Rational(1, 2), 0), (sp.Rational(1, 2), sp.Rational(1, 2)), (0, sp.Rational(1, 2)))
    return [(h**3 / 12 * detJ / 6, kappa.subs({s: a, t: b}, simultaneous=True)) for a, b in points]


def local_dofs(u, frame):
    """Per node: the world dofs (u, theta) in the frame's axes."""
    out = []
    for i in range(3):
        trans = [u[i, k] for k in range(3)]
        rot = [u[i, 3 + k] for k in range(3)]
        out.append([_dot(trans, e) for e in frame] + [_dot(rot, e) for e in frame])
    return out


def frame(element, X):
    """The rest frame's axes (e0, e1, e2) and the local corner coordinates ((0, 0), (l, 0), (p, q))."""
    axes, l, p, q = rest_frame(X)
    return axes, ((0, 0), (l, 0), (p, q))


def local_strains(element, ubar, P, E, nu, thickness):
    """The energy as a sum of quadratic forms of strains linear in the local dofs ubar[i] =
    (u, v, w, theta_x, theta_y, theta_z) of node i (frame axes) of the flat triangle with local
    corners P: [(weight, D, eps)], W = sum of weight / 2 eps^T D eps."""
    C = plane_stress(E, nu)
    eps, omega, area = membrane(P, ubar)
    out = [(thickness * area, C, eps)]
    out += [(weight, C, kappa) for weight, kappa in bending(P, ubar, thickness)]
    drill = sp.Matrix([ubar[i][5] - omega for i in range(3)])
    out.append((DRILLING * E * thickness * area, sp.eye(3), drill))
    return out


def local_energy(element, ubar, P, E, nu, thickness):
    """The energy in the local dofs (the sum of local_strains' quadratic forms)."""
    return sum(weight * (eps.T * D * eps)[0, 0] / 2
               for weight, D, eps in local_strains(element, ubar, P, E, nu, thickness))


def energy(element, u, X, E, nu, thickness):
    """The element energy in its world dofs u (3 x 6) at rest positions X (3 x 3)."""
    axes, P = frame(element, X)
    return local_energy(element, local_dofs(u, axes), P, E, nu, thickness)


def measure(element, X):
    """The rest area (the runtime multiplies by the thickness for the mass: see point volume)."""
    _, l, _, q = rest_frame(X)
    return l * q / 2


def checks(element, X):
    return []


@dataclass(frozen=True, eq=False)
class ShellLaw(DiscreteLaw):
    """A structural element energy in nodal displacements and rotations (kind "shell"), quadratic
    (small strains, small rotations in its frame).  Besides DiscreteLaw's fields:
      frame(element, X) -> ((e0, e1, e2), P): the rest frame's axes (world components) and the
          local 2D corner coordinates P;
      local_strains(element, ubar, P, **params) -> [(weight, D, eps)]: the energy
          sum weight / 2 eps^T D eps, eps linear in the local dofs ubar (per node: the frame
          components of the displacement and of the rotation vector).
    generator/shell.py differentiates the strains (the B matrices), hoists them and forms the
    local stiffness sum weight B^T D B, rotated into world axes; element_energy (world dofs) is
    the same energy, for the tests."""
    frame: Callable = None
    local_strains: Callable = None
    kind = "shell"

    def native_parameters(self, E=None, nu=None, **options) -> dict:
        if options.get("thickness") is None:
            raise LawError(f"law {self.name!r} needs the shell thickness: thickness = ... (m) in the material")
        return super().native_parameters(E, nu, **options)


LAW = ShellLaw(
    name="cst_dkt",
    parameters=("E", "nu", "thickness"),
    element_energy=energy,
    frame=frame,
    local_strains=local_strains,
    rest_measure=measure,
    rest_checks=checks,
    elements=(ELEMENT,),
    options=(("thickness", None, (1e-300, float("inf"))), ("corotational", 1.0, (0.0, 1.0))),
    description="flat shell triangle: CST membrane + DKT bending + drilling stiffness, linear elastic, "
                "co-rotational for large rotations",
    validity="thin shells (h << element size is fine: DKT has no shear locking), small strains, "
             "large rotations with corotational = 1",
)
