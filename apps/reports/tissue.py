"""Tissue laws against closed forms (`tensormass report accuracy --benchmark tissue`).

Cases (the `case` column), each run through a scene like a user's, `error_analytic` the largest
relative difference from its reference over the times or stretches listed:
- relaxation / creep: a unit cube of neo-Hookean tetrahedra with Prony branches (laws/viscous.py)
  in uniaxial stress (rollers on three faces), a strain or a traction reached in the first 20 ms
  step and held for 1 s, against the linear Prony model's closed forms (relaxation modulus; the
  standard linear solid's creep compliance). Normalised by the elastic run's force or strain at the
  same load, so that what is compared is the viscous response alone (0.1 % strain).
- lbmc ORGAN rate R: the thesis' LBMC power law of the organ (laws/prony.py, Table 7.7) as a Prony
  fit, a cube in homogeneous simple shear at the shear rate R for 2 s; the shear stress at 0.5, 1
  and 2 s against the power law's K R t^(1-n) / Gamma(2 - n). In simple shear neo-Hookean's shear
  stress is linear in the shear at any strain, so this is exact up to the fit and the time steps.
- b22 rate R: the thesis' B22 block (liver, 10 x 10 x 30 cubes of 1 mm, the 30 x 10 mm face sheared
  along its length, bottom clamped, E = 1000 Pa instantaneous in the thesis: here the fit of the
  power law) at t = 1 s: force over the top area against the power law. The block's free faces make
  it bend as well as shear, so the difference is the geometry's, as in the thesis (qualitative).
- hgo along / across: a cube of fibre-reinforced tetrahedra (laws/hgo.py) stretched 25 % along and
  across its fibres against the principal-stretch solution of the same energy (numpy, by hand).
- incompressible uniaxial ELEMENT: formulation "mixed" at nu = 0.5 (runtime.assembly.mixed), a cube of
  2 x 2 x 2 cells stretched 50 % with rollers, against neo-Hookean's incompressible P = mu (l - 1/l^2).
- cook ELEMENT FORMULATION nu NU: Cook's membrane extruded one cell thick, plane strain (u_z = 0),
  Hooke with E = 1, the vertical shear of cook.py; the corner's deflection against the mixed run at
  nu = 0.5 on the same mesh (error_analytic: the relative difference from it).  The mixed runs at
  0.4999 and 0.49999 converge to it; the displacement formulation at 0.4999 shows the locking.
- organ ELEMENT nu NU: the organ of `bench organ` (gmsh tetra10, h = 8 mm, liver-sized, with P2-P1;
  without gmsh or with --quick the committed small tetra organ with the stabilised P1-P1), two static
  load steps of its gravity and traction, against the same at nu = 0.5: the top pole's displacement.
"""
from __future__ import annotations

import math
import tempfile
import time
from pathlib import Path

import numpy as np

from ...laws import prony
from .common import benchmark_row as _row
from .common import measure

__all__ = ["tissue"]

E, NU = 3000.0, 0.3
H = 0.02                                   # s: the relaxation / creep step
BRANCHES = ((0.5, 2.0), (0.05, 1.0))       # (tau, beta) of the relaxation case
SLS = (0.2, 1.5)                            # the creep case's one branch
HGO = {"E": 3000.0, "nu": 0.45, "k1": 2000.0, "k2": 1.5, "dispersion": 0.1}
TISSUE_FULL = {"organs": ["liver", "kidney", "spleen"], "b22": True, "steps": 100, "cook_cells": 16,
               "cook_elements": ["hexahedron", "tetra10", "tetra"], "organ": "tetra10"}
TISSUE_QUICK = {"organs": ["liver"], "b22": False, "steps": 50, "cook_cells": 4, "cook_elements": ["tetra"],
                "organ": "tetra"}
NUS = (0.4999, 0.49999, 0.5)               # the mixed runs converging to nu = 0.5
MIXED_QUADRATURE = {"tetra": "gauss1", "tetra10": "gauss2", "hexahedron": "gauss2"}


# -- scenes ------------------------------------------------------------------------------------------
def _rollers() -> list:
    return [{"box": [[-1.0] * a + [-0.01] + [-1.0] * (2 - a), [2.0] * a + [0.01] + [2.0] * (2 - a)], "components": [a]}
            for a in range(3)]


def _cube(material: dict, extra: dict, steps: int, dt: float, cells=(1, 1, 1)) -> dict:
    data = {"name": "tissue_cube", "mesh": {"generate": "bar", "size": [1.0, 1.0, 1.0], "cells": list(cells),
                                            "element": "tetra"},
            "material": [{"law": "neohookean", "quadrature": "gauss1", "E": E, "nu": NU, **material}],
            "fixed": _rollers(), "solver": {"kind": "static", "steps": steps, "dt": dt}}
    for key, value in extra.items():
        data[key] = data.get(key, []) + value if isinstance(value, list) else value
    return data


def _viscous(branches) -> dict:
    return {"viscous": [{"tau": t, "beta": b} for t, b in branches]} if branches else {}


_HOLD = {"amplitude": [{"name": "hold", "factor": [0.0, H, 1.0], "value": [0.0, 1.0, 1.0]}]}


def _relaxation_scene(branches) -> dict:
    pull = {"name": "pulled", "box": [[0.99, -1, -1], [1.01, 2, 2]], "components": [0],
            "displacement": [1e-3, 0.0, 0.0], "amplitude": "hold"}
    return _cube(_viscous(branches), {**_HOLD, "fixed": [pull]}, int(round(1 / H)), H)


def _creep_scene(branches) -> dict:
    traction = {"box": [[0.99, -1, -1], [1.01, 2, 2]], "value": [3.0, 0.0, 0.0], "amplitude": "hold"}
    return _cube(_viscous(branches), {**_HOLD, "loads": {"traction": [traction]},
                                      "probe": [{"name": "face", "point": [1.0, 0.0, 0.0]}]}, int(round(1 / H)), H)


def _shear_scene(G_inf: float, branches, rate: float, steps: int) -> dict:
    """Homogeneous simple shear u_x = rate t y of a one-cell cube: every node prescribed, for 2 s."""
    return {"name": "tissue_shear", "mesh": {"generate": "bar", "size": [1.0, 1.0, 1.0], "cells": [1, 1, 1],
                                             "element": "tetra"},
            "material": [{"law": "neohookean", "quadrature": "gauss1", "E": 2 * G_inf * (1 + NU), "nu": NU,
                          **_viscous(branches)}],
            "fixed": [{"name": "bottom", "box": [[-1, -0.01, -1], [2, 0.01, 2]]},
                      {"name": "top", "box": [[-1, 0.99, -1], [2, 1.01, 2]], "displacement": [2.0 * rate, 0.0, 0.0]}],
            "solver": {"kind": "static", "steps": steps, "dt": 2.0 / steps}}


def _b22_scene(G_inf: float, branches, rate: float, steps: int) -> dict:
    """The thesis' B22 block: 30 x 10 mm top face, 10 mm high, 1 mm hexahedra, top moved along x."""
    size = [0.030, 0.010, 0.010]
    return {"name": "tissue_b22", "mesh": {"generate": "bar", "size": size, "cells": [30, 10, 10],
                                           "element": "hexahedron"},
            "material": [{"law": "neohookean", "quadrature": "gauss2", "E": 2 * G_inf * (1 + 0.499), "nu": 0.499,
                          "formulation": "mean_dilatation", **_viscous(branches)}],
            "fixed": [{"name": "bottom", "box": [[-1, -1, -1e-9], [1, 1, 1e-9]]},
                      {"name": "top", "box": [[-1, -1, 0.010 - 1e-9], [1, 1, 1]],
                       "displacement": [0.010 * rate * 1.0, 0.0, 0.0]}],
            "solver": {"kind": "static", "steps": steps, "dt": 1.0 / steps}}


def _hgo_scene(axis: int) -> dict:
    pull = [0.0, 0.0, 0.0]
    pull[axis] = 0.25
    box = [[-1.0, -1.0, -1.0], [2.0, 2.0, 2.0]]
    box[0][axis], box[1][axis] = 0.99, 1.01
    material = {"law": "hgo", "quadrature": "gauss1", **HGO, "fibres": [1.0, 0.0, 0.0]}
    data = _cube({}, {"fixed": [{"name": "pulled", "box": box, "components": [axis], "displacement": pull}]}, 4, 1.0)
    data["material"] = [material]
    return data


def _uniaxial_incompressible_scene(element: str, stretch: float) -> dict:
    material = {"quadrature": MIXED_QUADRATURE[element], "nu": 0.5, "formulation": "mixed"}
    data = _cube(material, {"fixed": [{"name": "pulled", "box": [[-1, -1, 0.99], [2, 2, 1.01]], "components": [2],
                                       "displacement": [0.0, 0.0, stretch - 1.0]}]}, 3, 1.0, cells=(2, 2, 2))
    data["mesh"]["element"] = element
    return data


def cook_mesh_3d(element: str, n: int, thickness: float = 1.0):
    """Cook's panel extruded one cell thick (z in [0, thickness]): hexahedra, Kuhn tetrahedra, or those
    with straight-sided midside nodes; a meshio mesh."""
    import meshio
    from ...runtime.mesh.bars import generate_bar
    from ...runtime.mesh.container import CellBlock, Mesh
    from ...runtime.mesh.uniform import to_quadratic
    from .cook import _map
    bar = generate_bar((1.0, 1.0, thickness), (n, n, 1), "hexahedron" if element == "hexahedron" else "tetra")
    x, y = _map(bar.points[:, 0], bar.points[:, 1])
    mesh = Mesh(np.column_stack([x, y, bar.points[:, 2]]), [CellBlock(b.type, b.cells) for b in bar.blocks])
    if element == "tetra10":
        mesh = to_quadratic(mesh)
    return meshio.Mesh(mesh.points, [(b.type, np.asarray(b.cells)) for b in mesh.blocks])


def _cook_scene(path, element: str, nu: float, formulation: str) -> dict:
    from .cook import COOK_CORNERS, COOK_LOAD, cook_scene
    data = cook_scene(path, element, nu, MIXED_QUADRATURE[element], formulation)
    x_load, height = COOK_CORNERS[1][0], COOK_CORNERS[2][1] - COOK_CORNERS[1][1]
    data["fixed"] = [{"box": [[-1e-9, -1.0, -1.0], [1e-9, 100.0, 2.0]]},
                     {"box": [[-1.0, -1.0, -1.0], [100.0, 100.0, 2.0]], "components": [2]}]      # plane strain
    data["loads"] = {"traction": [{"box": [[x_load - 1e-9, -1.0, -1.0], [x_load + 1e-9, 100.0, 2.0]],
                                   "value": [0.0, COOK_LOAD / height, 0.0]}]}
    data["probe"] = [{"name": "corner", "point": [*COOK_CORNERS[2], 0.0]}]
    return data


def _organ_scene(element: str, nu: float) -> str:
    """The organ of `bench organ` with formulation "mixed" (TOML text), its top pole probed."""
    from .. import bench_organ as bo
    from .dynamics import QUICK_MESH
    # the committed small organ is the same shape at scale 1 (apps/reports/dynamics.py)
    case = bo.Case("tissue_organ", "organ", element, "static", 2, size=0.008,
                   scale=1.0 if element == "tetra" else bo.ORGAN_SCALE)
    path = QUICK_MESH if element == "tetra" else bo.organ_mesh(case)[0]
    text = bo.organ_scene_text(case, path, nu, "mixed")
    return text + f"[[probe]]\nname = \"pole\"\npoint = {list(bo.probe_point(case))}\n"


# -- references ----------------------------------------------------------------------------------------
def relaxation(t, strain=1e-3):
    """Uniaxial stress of the linear Prony model for a strain ramp over the first step, then held."""
    rate = strain / H
    if t <= H * (1 + 1e-9):
        return E * rate * (t + sum(b * tau * (1 - math.exp(-t / tau)) for tau, b in BRANCHES))
    return E * strain + E * rate * sum(b * tau * (math.exp(-(t - H) / tau) - math.exp(-t / tau)) for tau, b in BRANCHES)


def creep(t):
    """Strain over the elastic strain of the standard linear solid, the load ramped over the first step."""
    tau, beta = SLS
    tc = tau * (1 + beta)
    if t <= H * (1 + 1e-9):
        return (t - beta / (1 + beta) * tc * (1 - math.exp(-t / tc))) / H
    return (H - beta / (1 + beta) * tc * math.exp(-t / tc) * (math.exp(H / tc) - 1)) / H


def hgo_stress(stretch: float, axis: int) -> float:
    """Nominal stress of HGO (fibres along x) pulled along `axis`, the other two stress-free."""
    from scipy.optimize import fsolve
    mu, kappa = HGO["E"] / (2 * (1 + HGO["nu"])), HGO["E"] / (3 * (1 - 2 * HGO["nu"]))
    k1, k2, d = HGO["k1"], HGO["k2"], HGO["dispersion"]

    def stress(lam):
        lam = np.asarray(lam, dtype=float)
        J, I1 = lam.prod(), (lam ** 2).sum()
        Ef = d * (I1 - 3) + (1 - 3 * d) * (lam[0] ** 2 - 1)
        dE = 2 * d * lam
        dE[0] += 2 * (1 - 3 * d) * lam[0]
        matrix = mu / 2 * (-2 / 3 * J ** (-2 / 3) * I1 / lam + 2 * J ** (-2 / 3) * lam) + kappa / 2 * (J - 1 / J) * J / lam
        return matrix + k1 * max(Ef, 0.0) * math.exp(k2 * max(Ef, 0.0) ** 2) * dE

    free = [a for a in range(3) if a != axis]

    def residual(s):
        lam = np.empty(3)
        lam[axis], lam[free] = stretch, s
        return stress(lam)[free]
    s = fsolve(residual, [1.0, 1.0], xtol=1e-13)
    lam = np.empty(3)
    lam[axis], lam[free] = stretch, s
    return float(stress(lam)[axis])


# -- the benchmark -----------------------------------------------------------------------------------
def _run(data):
    from ...runtime.scene.scene import Scene
    scene = Scene.from_string(data) if isinstance(data, str) else Scene.from_dict(data)
    summary, peak, sim = measure(scene)
    if summary.status != "ok":
        raise RuntimeError(f"tissue: {scene.name} ended {summary.status}: {summary.message}")
    return summary, peak, sim


def _series(summary, name, component=0):
    rows = summary.per_step
    return np.array(rows["time"]), np.array(rows["reactions"][name]["force"])[:, component]


def _add(rows, case, law, element, summary, peak, value, error, cells="1x1x1", quadrature="gauss1"):
    row = _row("tissue", element, law, quadrature, tuple(int(c) for c in cells.split("x")), case, summary, peak, value)
    row["error_analytic"] = float(error)
    rows.append(row)


def tissue(quick, progress, sweep=None) -> dict:
    cfg = dict(TISSUE_QUICK if quick else TISSUE_FULL)
    cfg.update(sweep or {})
    progress("tissue: Prony relaxation and creep, the LBMC power laws in simple shear, HGO tension")
    rows, notes, compile_s = [], [], {}
    t0 = time.perf_counter()
    _run(_relaxation_scene(BRANCHES[:1]))                          # warm-up: the viscous kernel
    compile_s[("tetra", "neohookean_viscous", "gauss1")] = time.perf_counter() - t0

    # relaxation and creep: the viscous response over the elastic one at the same load
    summary, peak, _ = _run(_relaxation_scene(BRANCHES))
    t, F = _series(summary, "pulled")
    elastic = _series(_run(_relaxation_scene(()))[0], "pulled")[1][-1]
    expected = np.array([relaxation(x) for x in t]) / (E * 1e-3)
    _add(rows, "relaxation", "neohookean_viscous", "tetra", summary, peak, F[-1] / elastic,
         np.abs(F / elastic / expected - 1).max())
    summary, peak, _ = _run(_creep_scene([SLS]))
    ux = np.array(summary.per_step["probes"]["face"])[:, 0]
    t = np.array(summary.per_step["time"])
    elastic = np.array(_run(_creep_scene(()))[0].per_step["probes"]["face"])[-1, 0]
    expected = np.array([creep(x) for x in t])
    _add(rows, "creep", "neohookean_viscous", "tetra", summary, peak, ux[-1] / elastic,
         np.abs(ux / elastic / expected - 1).max())

    # the LBMC power laws as Prony fits, in homogeneous simple shear
    checked = (0.5, 1.0, 2.0)
    for organ in cfg["organs"]:
        K, n = prony.LBMC[organ]
        G_inf, branches = prony.prony_fit(K, n)
        notes.append(f"- {organ}: K = {K:g} Pa s^n, n = {n:g}; Prony fit over 1 ms to 10 s: G_inf = {G_inf:.4g} Pa, "
                     + ", ".join(f"(tau {tau:.3g} s, beta {beta:.3g})" for tau, beta in branches))
        for rate in prony.RATES:
            summary, peak, _ = _run(_shear_scene(G_inf, branches, rate, cfg["steps"]))
            t, F = _series(summary, "top")
            at = [int(np.argmin(np.abs(t - x))) for x in checked]
            analytic = prony.constant_rate_stress(t[at], rate, K, n)
            _add(rows, f"lbmc {organ} rate {rate:g}", "neohookean_viscous", "tetra", summary, peak, F[at[1]],
                 np.abs(F[at] / analytic - 1).max())
    if cfg["b22"]:
        K, n = prony.LBMC["liver"]
        G_inf, branches = prony.prony_fit(K, n)
        for rate in prony.RATES:
            summary, peak, _ = _run(_b22_scene(G_inf, branches, rate, 50))
            t, F = _series(summary, "top")
            stress = F[-1] / (0.030 * 0.010)
            analytic = float(prony.constant_rate_stress(1.0, rate, K, n))
            _add(rows, f"b22 rate {rate:g}", "neohookean_viscous", "hexahedron", summary, peak, stress,
                 stress / analytic - 1, cells="30x10x10", quadrature="gauss2")

    # HGO: tension along and across the fibres
    for axis, case in ((0, "hgo along"), (1, "hgo across")):
        summary, peak, sim = _run(_hgo_scene(axis))
        force = float(sim.reactions()["pulled"]["force"][axis])
        _add(rows, case, "hgo", "tetra", summary, peak, force, force / hgo_stress(1.25, axis) - 1)
    _incompressible(cfg, rows, notes, progress)
    for r in rows:
        progress(f"  {r['case']:<28} value {r['value']:.6g}  error {r['error_analytic']:+.3g}")
    reference = {"subject": "tissue laws: Prony relaxation and creep, LBMC power laws as Prony fits, HGO tension, "
                            "exact incompressibility",
                 "numerical": "the mixed formulation at nu = 0.5 on the same mesh (cook and organ rows)",
                 "analytic": "closed forms of the linear Prony model, the LBMC power law K rate t^(1-n) / Gamma(2-n), "
                             "HGO's principal-stretch solution, incompressible neo-Hookean uniaxial tension"}
    return {"rows": rows, "reference": reference, "compile_s": compile_s, "notes": notes}


def _incompressible(cfg, rows, notes, progress) -> None:
    """The mixed formulation's rows: the closed form at nu = 0.5, then Cook's membrane and the organ
    converging to their nu = 0.5 runs (module docstring)."""
    _uniaxial_rows(rows)
    _cook_rows(rows, notes, int(cfg["cook_cells"]), cfg["cook_elements"])
    _organ_rows(rows, notes, cfg["organ"])


def _uniaxial_rows(rows, stretch: float = 1.5) -> None:
    for element in ("tetra", "tetra10", "hexahedron"):
        summary, peak, sim = _run(_uniaxial_incompressible_scene(element, stretch))
        force = float(sim.reactions()["pulled"]["force"][2])
        exact = E / 3 * (stretch - stretch ** -2)
        _add(rows, f"incompressible uniaxial {element}", "neohookean", element, summary, peak, force, force / exact - 1,
             cells="2x2x2", quadrature=MIXED_QUADRATURE[element])


def _cook_rows(rows, notes, n: int, elements) -> None:
    import meshio
    with tempfile.TemporaryDirectory() as folder:
        for element in elements:
            path = Path(folder) / f"cook3d_{element}_{n}.vtu"
            meshio.write(path, cook_mesh_3d(element, n))
            results = {}
            for formulation, nu in [("mixed", nu) for nu in NUS] + [("displacement", NUS[0])]:
                summary, peak, _ = _run(_cook_scene(path, element, nu, formulation))
                results[(formulation, nu)] = (summary, peak, float(summary.probes["corner"][1]))
            limit = results[("mixed", 0.5)][2]
            for (formulation, nu), (summary, peak, value) in results.items():
                _add(rows, f"cook {element} {formulation} nu {nu:g}", "hooke", element, summary, peak, value,
                     value / limit - 1, cells=f"{n}x{n}x1", quadrature=MIXED_QUADRATURE[element])
    notes.append("- cook: the 2D panel at nu = 0.4999 converges to 19.419 (P2-P0 on 64 x 64, `--benchmark cook`)")


def _organ_rows(rows, notes, element: str) -> None:
    if element == "tetra10":
        from .. import bench_organ as bo
        try:
            bo.require_gmsh()
        except bo.GmshMissing as why:
            notes.append(f"- organ at nu = 0.5: {why}; the small committed tetra organ instead")
            element = "tetra"
    results = {}
    for nu in NUS:
        summary, peak, sim = _run(_organ_scene(element, nu))
        results[nu] = (summary, peak, float(summary.probes["pole"][2]), sim.ctx.pressures.volume_change(sim.ctx.u))
    limit = results[0.5][2]
    for nu, (summary, peak, value, _) in results.items():
        _add(rows, f"organ {element} nu {nu:g}", "neohookean", element, summary, peak, value, value / limit - 1,
             cells=str(summary.n_elements), quadrature=MIXED_QUADRATURE[element])
    notes.append(f"- organ ({element}) at nu = 0.5: volume change {results[0.5][3]:.2g} of the body")
