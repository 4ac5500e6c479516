"""`tensormass report accuracy|stability`: what a setting costs and whether it survives.

accuracy   sweeps element x law x quadrature x resolution over benchmarks with known answers
           (cantilever, beam2d, volume, mixed, large_deflection, shear, torsion, adaptive_beam,
           refinement, cook, block) or a user scene, and writes
           results.csv, error_vs_time.png (Pareto front), convergence.png, report.md
stability  runs the stiff and extreme cases of the brief and writes a table and report.md
squeeze    the thesis' ball squeezed between two planes: volume lost by shells, FEM and MSS
contact    contact against closed forms: Hertz, friction on an incline, frictionless impact
"""
from __future__ import annotations

from .accuracy import add_accuracy_command
from .contact import add_contact_command
from .squeeze import add_squeeze_command
from .stability import add_stability_command


def add_report_command(subparsers) -> None:
    report = subparsers.add_parser("report", help="accuracy against run time; stability on stiff and extreme cases")
    sub = report.add_subparsers(dest="report_command", required=True)
    add_accuracy_command(sub)
    add_stability_command(sub)
    add_squeeze_command(sub)
    add_contact_command(sub)
