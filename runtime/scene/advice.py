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

- body size: a body whose size, weight and stiffness disagree by orders of magnitude, the usual sign of
  a mesh in millimetres with SI values (mesh coordinates are read in metres): the sag under gravity
  estimated as rho g L^2 / E (L: the largest side of the bounding box) larger than L itself, or a
  tissue-like material (TISSUE_E, TISSUE_DENSITY) on a body outside BODY_SIZE. The line names the
  body's size and the material.

Only the element types a material actually models (its cells in this mesh) are considered.
"""
from __future__ import annotations

import numpy as np

from ... import laws
from ..physics.formulations import DEFAULT_FORMULATION, LINEAR_ELEMENTS, locking_free_choice
from ..kernels.hourglass import hourglass_message, spurious_modes
from ..mesh.regions import assign_materials

__all__ = ["scene_advice", "poisson_ratio", "young_modulus", "body_size_advice", "LOCKING_NU", "BODY_SIZE",
           "TISSUE_E", "TISSUE_DENSITY"]

# Bodies outside this size [m] with a tissue-like material are most likely meshes in other units
# (an organ is centimetres across: a mesh in millimetres read as metres is 1000 times too big)
BODY_SIZE = (1e-3, 10.0)
TISSUE_E = (1e2, 1e7)             # Pa: soft tissue and gels (fat 1 kPa ... cartilage 10 MPa)
TISSUE_DENSITY = (500.0, 3000.0)  # kg/m^3

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


def young_modulus(material) -> float | None:
    """E of a material: as given, or from its native shear modulus (mu; Mooney-Rivlin 2 (C10 + C01))
    and Poisson's ratio (E = 2 mu (1 + nu); nu unknown: 0.5); None when they do not say."""
    if material.E is not None:
        return float(material.E)
    p = {k: float(v) for k, v in (material.params or {}).items() if isinstance(v, (int, float))}
    mu = 2.0 * (p["C10"] + p["C01"]) if "C10" in p and "C01" in p else p.get("mu")
    if mu is None or mu <= 0:
        return None
    nu = poisson_ratio(material)
    return 2.0 * mu * (1.0 + (0.5 if nu is None else nu))


def body_size_advice(scene, mesh) -> str | None:
    """One line when the body's size, weight and stiffness disagree by orders of magnitude (see the
    module docstring), naming the size; None otherwise."""
    points = np.asarray(mesh.points, dtype=float)
    if points.size == 0 or not np.all(np.isfinite(points)):
        return None
    sides = points.max(axis=0) - points.min(axis=0)
    size = float(sides.max())
    if size <= 0:
        return None
    g = float(np.linalg.norm(getattr(scene.loads, "gravity", (0.0, 0.0, 0.0))))
    box = " x ".join(f"{x:.3g}" for x in sides)
    worst = None                              # (sag / size, key, E, density) of the material that sags most
    tissue = None
    for i, material in enumerate(scene.materials):
        E = None if laws.is_discrete(material.law) else young_modulus(material)
        if E is None or E <= 0:
            continue
        rho, key = float(material.density), f"material[{i}]"
        ratio = rho * g * size / E            # (rho g L^2 / E) / L
        if worst is None or ratio > worst[0]:
            worst = (ratio, key, E, rho)
        if tissue is None and TISSUE_E[0] <= E <= TISSUE_E[1] and TISSUE_DENSITY[0] <= rho <= TISSUE_DENSITY[1]:
            tissue = (key, E, rho)
    units = ("mesh coordinates are read in metres: a mesh in millimetres needs scaling by 0.001 "
             "(gmsh: Mesh.ScalingFactor = 0.001), or the values in the mesh's units")
    if worst is not None and worst[0] > 1.0:
        ratio, key, E, rho = worst
        return (f"the body is {size:.3g} m across (bounding box {box} m): under gravity ({g:.3g} m/s^2) {key} "
                f"(E = {E:.3g} Pa, density = {rho:.4g} kg/m^3) would sag by about rho g L^2 / E = "
                f"{ratio * size:.3g} m, {ratio:.3g} times its size; {units}")
    if tissue is not None and not BODY_SIZE[0] <= size <= BODY_SIZE[1]:
        key, E, rho = tissue
        return (f"the body is {size:.3g} m across (bounding box {box} m), with the tissue-like {key} (E = {E:.3g} Pa, "
                f"density = {rho:.4g} kg/m^3): a size outside {BODY_SIZE[0]:g} to {BODY_SIZE[1]:g} m is most likely a "
                f"mesh in other units; {units}")
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


def _locking(key, material, element, beside_shells: bool = False) -> str | None:
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
    fix = ("the locking-free formulations are not available beside shells: refine the mesh or use quadratic "
           "elements" if beside_shells else f"use formulation = \"{choice}\"" if choice is not None else
           "no locking-free formulation exists for it: refine the mesh or use quadratic elements")
    return (f"{key}: nu = {nu:.4g} on {element} with the displacement formulation locks (too stiff); {fix}")


def scene_advice(scene, mesh=None) -> list:
    """Advice lines for a scene on its mesh (default: scene.load_mesh()); [] when there is none."""
    mesh = scene.load_mesh() if mesh is None else mesh
    backend = getattr(scene.solver, "backend", "numba")
    advice = list(getattr(mesh, "notes", ()))        # what reading the mesh changed (shell windings)
    beside_shells = any(b.type == "shell" for b in mesh.blocks)
    for i, element_types in sorted(_modelled_elements(scene, mesh).items()):
        material, key = scene.materials[i], f"material[{i}]"
        if laws.is_discrete(material.law):
            continue        # springs: no locking, no quadrature; a singular lattice is refused by the solve check
        for element in element_types:
            text = _locking(key, material, element, beside_shells)
            if text is not None:
                advice.append(text)
            count = spurious_modes(element, material.law, material.quadrature, backend)
            if count:
                advice.append(f"{key}: {hourglass_message(element, material.quadrature, count)}")
    size = body_size_advice(scene, mesh)
    if size is not None:
        advice.append(size)
    for i, material in enumerate(scene.materials):
        text = _prony_times(f"material[{i}].viscous", material, scene.solver)
        if text is not None:
            advice.append(text)
    return advice


def _prony_times(key: str, material, solver) -> str | None:
    """Prony branches the run cannot see: every relaxation time far below the step (relaxed within a
    step: the law responds as if relaxed) or far beyond the run (never relaxes: stiffer, not slower)."""
    branches = getattr(material, "viscous", None)
    if not branches:
        return None
    dt = float(solver.dt)
    duration = dt * int(solver.steps)
    fast = [tau for tau, _ in branches if tau < dt / 100]
    slow = [tau for tau, _ in branches if tau > 100 * duration]
    if not fast and not slow:
        return None
    parts = []
    if fast:
        parts.append(f"tau = {', '.join(f'{t:g}' for t in fast)} s relax within a step of {dt:g} s (they add "
                     "nothing after it: lower dt to see them)")
    if slow:
        parts.append(f"tau = {', '.join(f'{t:g}' for t in slow)} s do not relax within the run's {duration:g} s "
                     "(they only stiffen the law: its instantaneous modulus)")
    return f"{key}: " + "; ".join(parts)
