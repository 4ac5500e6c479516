"""What the accuracy report and its benchmarks (benchmarks.py, adaptive.py) share: the analytic
cantilever tip, one timed run of a scene, the result row (accuracy.COLUMNS) and the cells label.
Kept apart so that accuracy imports the benchmarks and the benchmarks import only this."""
from __future__ import annotations

import copy
import tracemalloc

from ...runtime.scene.scene import Scene

# The cantilever of the built-in `accuracy` benchmark (a steel-like bar under its own weight).
SIZE = (1.2, 0.2, 0.2)
E_MOD, NU, RHO, G = 1.0e8, 0.3, 800.0, 9.81


def analytic_tip(size=SIZE, E=E_MOD, nu=NU, rho=RHO, g=G) -> tuple:
    """(Euler-Bernoulli, Euler-Bernoulli + Timoshenko shear with kappa = 5/6) tip deflection."""
    L, b, h = size
    A, I = b * h, b * h ** 3 / 12.0
    eb = rho * g * A * L ** 4 / (8.0 * E * I)
    Gm = E / (2.0 * (1.0 + nu))
    return eb, eb + rho * g * A * L ** 2 / (2.0 * (5.0 / 6.0) * Gm * A)


def measure(scene, trace=True) -> tuple:
    """(Summary, tracemalloc peak in MB or nan, Simulation) of one run of a validated scene."""
    # deferred: the simulation stack (scipy.sparse, pyamg), 0.56 s skipped by `tensormass report --help` (0.7 s)
    from ...runtime.run.simulation import Simulation
    if trace:
        tracemalloc.start()
    try:
        sim = Simulation(scene, output=False)
        summary = sim.run()
        peak = tracemalloc.get_traced_memory()[1] / 1e6 if trace else float("nan")
    finally:
        if trace:
            tracemalloc.stop()
    return summary, peak, sim


def run_dict(data, trace=True) -> tuple:
    """(Summary, peak MB or nan, Simulation) of one run of a scene dict (left unchanged)."""
    return measure(Scene.from_dict(copy.deepcopy(data)), trace)


def cells_label(c) -> str:
    return "x".join(str(int(x)) for x in c)


def result_row(element, law, quadrature, cells, summary, peak, value, benchmark="cantilever", case="") -> dict:
    """One row of results.csv (accuracy.COLUMNS, plus main=True)."""
    t = summary.time
    return {"benchmark": benchmark, "element": element, "law": law, "quadrature": quadrature,
            "formulation": "displacement",
            "cells": cells_label(cells), "case": case, "main": True,
            "dofs": int(summary.n_free_dofs),
            "value": float(value), "error_analytic": float("nan"),
            "error_reference": float("nan"), "time_setup": float(t["setup"]),
            "time_assembly": float(t["assembly"]), "time_solve": float(t["linear_solve"]),
            "time_total": float(t["total"]), "peak_memory_mb": float(peak)}


def benchmark_row(bench, element, law, quad, cells, case, summary, peak, value) -> dict:
    """result_row of one of the extra benchmarks (its name and case filled in)."""
    return result_row(element, law, quad, cells, summary, peak, value, benchmark=bench, case=case)
