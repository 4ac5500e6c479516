"""The time per step of the resource estimate (runtime.scene.resources): counted from the model."""
from __future__ import annotations


def test_the_time_counts_the_kernels_of_materials_chosen_by_mesh_group():
    """The organ's material is chosen by its group name ("organ"): its kernel's operations count
    (tetra10 neohookean gauss2, forces and stiffness, 4 Newton iterations of a static step)."""
    from pathlib import Path
    from tensormass.runtime.scene import resources as R
    from tensormass.runtime.scene.scene import Scene
    scene = Scene.from_toml(Path(__file__).parents[3] / "examples" / "organ" / "scene.toml")
    est = R.estimate(scene)
    ops = R._entry("tetra10", "neohookean", "gauss2")["ops"]["forces_and_stiffness"]
    kernels = est.cells["tetra10"] * ops * R.SECONDS_PER_OP * est.newton_iterations
    assert est.newton_iterations == 4 and est.seconds_per_step > kernels > 0
    # PARDISO's factor at its modelled rate is part of every iteration
    assert est.seconds_per_step > kernels + 4 * R.PARDISO_FLOPS_PER_N2 * est.dofs ** 2 / R.PARDISO_FLOPS
    assert "(4 Newton iterations assumed)" in est.describe()
