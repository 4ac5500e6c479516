"""The spring models' cases of `tensormass report stability` (thesis chapters 3 and 7).

compression instability   a cube lattice squeezed 20 % between clamped plates (implicit Euler, the
                          top plate ramped down over the run) from a rest state nudged by 1e-4 of a
                          cell (a fixed seed): MSS-Baudet and HybMSS-FD (A = 0) buckle, the state
                          loses its mirror symmetry; HybMSS (A = 1, face diagonals) stays symmetric
                          (thesis Fig. 7.3 / 7.6).  The asymmetry is max |u(x) - M u(M x)| / max |u|
                          for the mirror M across the mid-plane x = L/2: the nudge's size when the
                          lattice holds, of the order of the displacement itself when it buckles.
springs stiff / extreme   MSS and HybMSS under the brief's cases where they apply: E from 1 kPa to
                          10 GPa with implicit Euler at dt = 1/60 and 0.1 s, and explicit steps at
                          0.5x and 2x the estimated stable step (a cantilever of cubes).
"""
from __future__ import annotations

import numpy as np

from .stability_runs import BAR, DIVERGED, GRAVITY, INVALID, STABLE, Run, outcome_in, scene_dict, stable_dt
from ...runtime.mesh.bars import generate_bar

__all__ = ["case_spring_compression", "case_spring_extremes", "BUCKLED", "asymmetry"]

BUCKLED = "buckled (detected by the report)"
CELL = 0.05
SYMMETRIC = 0.05          # asymmetry below this: the lattice held (the nudge is 1e-4 of a cell)
MODELS = (("mss", None, "buckles: the lattice has no face diagonals", (BUCKLED, DIVERGED, INVALID)),
          ("hybmss", 0.0, "buckles: HybMSS-FD (A = 0)", (BUCKLED, DIVERGED, INVALID)),
          ("hybmss", 1.0, "stable and symmetric: the face diagonals hold it", (STABLE,)))


def _spring_material(data, law, A):
    m = data["material"][0]
    m["quadrature"] = "discrete"
    if A is not None:
        m["A"] = float(A)
    return data


def compression_scene(law, A, n, steps, dt):
    L = round(n * CELL, 12)
    data = scene_dict(law, "implicit_euler", dt, steps, E=1e4, nu=0.3, size=(L, L, L), cells=(n, n, n),
                       gravity=False, fixed="bottom", rayleigh=(0.0, 0.01), quadrature="discrete")
    data["fixed"].append({"box": [[-1.0, -1.0, L - 1e-9 * L], [2 * L, 2 * L, 2 * L]],
                          "displacement": [0.0, 0.0, -0.2 * L]})
    data["solver"]["backend"] = "c"
    return _spring_material(data, law, A)


def asymmetry(points, u, length) -> float:
    """max |u(x) - M u(M x)| / max |u| for the mirror M: x -> L - x (u_x changes sign)."""
    index = {tuple(np.round(p, 9)): i for i, p in enumerate(points)}
    mirror = np.array([index[tuple(np.round([length - p[0], p[1], p[2]], 9))] for p in points])
    mirrored = u[mirror] * np.array([-1.0, 1.0, 1.0])
    return float(np.abs(u - mirrored).max() / max(np.abs(u).max(), 1e-300))


def case_spring_compression(quick):
    """10. the compression instability of the lattices without face diagonals (chapter 3.5, 7.6)."""
    n, steps, dt = (4, 20, 0.1) if quick else (6, 40, 0.05)
    rows = []
    for law, A, expected, allowed in MODELS:
        name = law if A is None else f"{law} A={A:g}"
        data = compression_scene(law, A, n, steps, dt)
        L = n * CELL
        points = generate_bar((L, L, L), (n, n, n), "hexahedron").points
        u0 = 1e-4 * CELL * np.random.default_rng(0).standard_normal(points.shape)
        run = Run(f"spring compression 20 % {n}^3", name, "implicit_euler", dt, expected, outcome_in(*allowed))

        def judge(sim, summary, points=points, L=L):
            a = asymmetry(points, sim.displacement, L)
            outcome = STABLE if a < SYMMETRIC else BUCKLED
            return outcome, f"asymmetry {a:.3g} (symmetric below {SYMMETRIC:g}; the nudge is 1e-4 of a cell)"
        rows.append(run.execute(data, u0=u0, judge=judge))
    return rows


def _cantilever(law, kind, dt, steps, E, A=None):
    data = scene_dict(law, kind, dt, steps, E=E, cells=(5, 1, 1), quadrature="discrete")   # 0.2 m cubes
    data["solver"]["backend"] = "c"
    return _spring_material(data, law, A)


def case_spring_extremes(quick):
    """11. MSS and HybMSS under the stiffness sweep and explicit steps around the stable one."""
    Es = (1e3, 1e6, 1e10) if quick else (1e3, 1e4, 1e6, 1e8, 1e10)
    steps = 6 if quick else 12
    rows = []
    for law, A in (("mss", None), ("hybmss", 1.0)):
        name = law if A is None else f"{law} A={A:g}"
        for E in Es:
            for dt in (1.0 / 60, 0.1):
                bound = GRAVITY * (dt * steps) ** 2 + 10.0 * max(BAR)
                soft = 1000.0 * GRAVITY * BAR[0] / E > 0.5
                allowed = outcome_in(STABLE, INVALID, DIVERGED) if soft else outcome_in(STABLE)
                expected = ("too soft to carry its weight: stable, invalid or diverged (detected)" if soft else
                            f"stable: all finite, max|u| <= {bound:.3g}")
                run = Run(f"springs stiffness E={E:.0e}", name, "implicit_euler", dt, expected, allowed)

                def judge(sim, summary, bound=bound, run=run):
                    return (STABLE if run.max_u <= bound else DIVERGED,
                            f"max|u| = {run.max_u:.3g} m (bound {bound:.3g}); tip z = {summary.probes['tip'][2]:.4g} m")
                rows.append(run.execute(_cantilever(law, "implicit_euler", dt, steps, E, A), judge=judge))
        crit = stable_dt(_cantilever(law, "explicit", 1e-3, 1, 1e6, A))
        for factor, expected, allowed in ((0.5, "stable", outcome_in(STABLE)), (2.0, "diverged (detected)", outcome_in(DIVERGED))):
            dt = factor * crit
            run = Run(f"springs explicit {factor:g}x stable dt", name, "explicit", dt, expected, allowed)
            run.extra.append(f"estimated stable dt {crit:.4g} s")
            rows.append(run.execute(_cantilever(law, "explicit", dt, 150 if quick else 400, 1e6, A)))
    return rows
