"""Setup-time advice: what a scene's choices will cost in accuracy, said before the run.

    for line in scene_advice(scene, mesh):   # [] when there is nothing to say
        print("advice:", line)

Advice never changes a run's status (health warnings do: runtime.physics.health); it is printed by
`tensormass run` before the first step and kept in the summary as "advice" (Simulation.advice).
Each line names the material (``material[i]``), the element it concerns and what to change:

- locking: a displacement formulation with Poisson's ratio >= LOCKING_NU on linear elements
  (runtime.physics.formulations.LINEAR_ELEMENTS) is too stiff; the locking-free formulation is named
  (runtime.physics.formulations.locking_free_choice), or, where there is none, a finer or quadratic mesh.
  A formulation that an element accepts but that does not cure its locking (NOT_CURED: mean
  dilatation on wedges) is advised against the same way.
- hourglass: an element x quadrature whose stiffness at rest has more zero-energy modes than rigid
  motions (runtime.kernels.hourglass.spurious_modes, decided from the kernel itself).

Only the element types a material actually models (its cells in this mesh) are considered.
"""
from __future__ import annotations

import numpy as np

from ... import laws
from ..physics.formulations import DEFAULT_FORMULATION, LINEAR_ELEMENTS, locking_free_choice
from ..kernels.hourglass import hourglass_message, spurious_modes
from ..mesh.regions import assign_materials

__all__ = ["scene_advice", "poisson_ratio", "LOCKING_NU"]

# Nearly incompressible from here on: linear displacement elements lock (issue 15: tissue is 0.45-0.499)
LOCKING_NU = 0.45


def poisson_ratio(material) -> float | None:
    """nu of a material: as given, or from its native parameters (lam and mu; mu and kappa; Mooney-Rivlin
    C10, C01 and kappa, with mu = 2 (C10 + C01)); None when they do not say."""
    if material.nu is not None:
        return float(material.nu)
    p = {k: float(v) for k, v in (material.params or {}).items()}
    if "lam" in p and "mu" in p and p["lam"] + p["mu"] != 0:
        return p["lam"] / (2.0 * (p["lam"] + p["mu"]))
    mu = 2.0 * (p["C10"] + p["C01"]) if "C10" in p and "C01" in p else p.get("mu")
    kappa = p.get("kappa")
    if mu is not None and kappa is not None and 3.0 * kappa + mu != 0:
        return (3.0 * kappa - 2.0 * mu) / (2.0 * (3.0 * kappa + mu))
    return None


def _modelled_elements(scene, mesh) -> dict:
    """material index -> the element types of the cells it models, in mesh order."""
    which = assign_materials(mesh, scene.materials)
    out: dict = {}
    for block, w in zip(mesh.blocks, which):
        for i in np.unique(w):
            if i >= 0 and block.type not in out.setdefault(int(i), []):
                out[int(i)].append(block.type)
    return out


# (formulation, element) that a scene may choose but that does not cure the element's locking: why
NOT_CURED = {("mean_dilatation", "wedge"): "under a load in the plane of prism layers a linear prism's dilatation "
                                           "is already constant per cell, so the cell mean changes nothing "
                                           "(P1/P0 triangles' one volume constraint per cell)"}


def _locking(key, material, element) -> str | None:
    formulation = getattr(material, "formulation", DEFAULT_FORMULATION)
    nu = poisson_ratio(material)
    if element not in LINEAR_ELEMENTS or nu is None or nu < LOCKING_NU:
        return None
    choice = locking_free_choice(element)
    if (formulation, element) in NOT_CURED:
        return (f"{key}: nu = {nu:.4g} on {element} with {formulation} still locks (too stiff) in layers loaded in "
                f"their plane: {NOT_CURED[formulation, element]}; use formulation = \"{choice}\"")
    if formulation != "displacement":
        return None
    fix = (f"use formulation = \"{choice}\"" if choice is not None else
           "no locking-free formulation exists for it: refine the mesh or use quadratic elements")
    return (f"{key}: nu = {nu:.4g} on {element} with the displacement formulation locks (too stiff); {fix}")


def scene_advice(scene, mesh=None) -> list:
    """Advice lines for a scene on its mesh (default: scene.load_mesh()); [] when there is none."""
    mesh = scene.load_mesh() if mesh is None else mesh
    backend = getattr(scene.solver, "backend", "numba")
    advice = list(getattr(mesh, "notes", ()))        # what reading the mesh changed (shell windings)
    for i, element_types in sorted(_modelled_elements(scene, mesh).items()):
        material, key = scene.materials[i], f"material[{i}]"
        if laws.is_discrete(material.law):
            continue        # springs: no locking, no quadrature; a singular lattice is refused by the solve check
        for element in element_types:
            text = _locking(key, material, element)
            if text is not None:
                advice.append(text)
            count = spurious_modes(element, material.law, material.quadrature, backend)
            if count:
                advice.append(f"{key}: {hourglass_message(element, material.quadrature, count)}")
    return advice
