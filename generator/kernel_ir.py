"""KernelIR: the frozen intermediate representation of one kernel, what every backend's templates
read.  The builders (ir.py for laws W(F), discrete.py for energies in nodal positions, shell.py for
shells) fill it; nothing here depends on how."""
from __future__ import annotations

from dataclasses import dataclass

import sympy as sp

from .fragments import Fragment


@dataclass(frozen=True)
class KernelIR:
    name: str
    element: str
    law: str
    quadrature: str
    dim: int
    n_nodes: int
    n_points: int
    parameters: tuple            # native law parameters: inputs of the constants kernel
    requires_positive_J: bool
    affine_edges: tuple          # (mid, a, b) node triples checked for straight edges ("exact" only)
    point_stride: int
    material_offset: int
    material_names: tuple        # material constants stored after the geometry
    constant_names: tuple        # names of every column of D
    geometry: Fragment           # det J and J^-1 from J (same code at every point)
    geometry_G: tuple            # ((b, G_b from dn and J^-1), ...) for one node
    dN_table: tuple              # [point][node][k] reference shape gradients at the points
    weights: tuple               # quadrature weights
    material: Fragment           # material constants from the parameters
    law_code: dict               # variant -> list[Fragment]: energy, gradient, tangent, gradient_tangent, stress
    J: sp.Expr | None            # det F from the F symbols, for the inversion check
    chain: dict                  # chain-rule statements (forces, tangent H, stiffness K)
    rule_points: tuple
    rule_weights: tuple
    recompute: bool              # D holds rest coordinates; G and det J are recomputed every call
    ops: dict                    # floating-point operations per element, per kernel
    input_hash: str              # hash of element, rule, law source, generator version
    bodies: dict                 # kind -> statement tree of one element (generator/kernel_body.py)
    stress_record: dict          # layout of the stress kernel's per-point record (kernel_body.stress_record)
    source: str = "continuum"    # the energy: a law's W(F), "discrete" (generator/discrete.py: nodal positions)
    #                              or "shell" (generator/shell.py: nodal displacements and rotations)
    dofs: int = 0                # unknowns per node; 0: the space dimension (solids)
    quadratic_energy: bool = False   # W homogeneous quadratic in grad u: K constant and f = -K u
    point_inputs: tuple = ()     # ((name, value at rest), ...) stored per point after G (laws.Law.point_inputs)

    @property
    def dofs_per_node(self) -> int:
        return self.dofs or self.dim

    @property
    def point_fields(self) -> dict:
        """Where each point's fields start in its block of D: v (weight x det J; a discrete kernel's
        rest measure), G (shape gradients: not for recompute or discrete kernels) and the point inputs."""
        if self.recompute:
            return {}
        if self.source in ("discrete", "shell"):
            return {"v": 0}
        fields = {"v": 0, "G": 1}
        if self.point_inputs:                  # what the runtime writes per point (a viscous law's history)
            fields["inputs"] = 1 + self.n_nodes * self.dim
        return fields

    @property
    def n_dofs(self) -> int:
        return self.n_nodes * self.dofs_per_node

    @property
    def n_constants(self) -> int:
        return len(self.constant_names)
