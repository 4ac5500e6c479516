"""Setup-time advice (runtime.scene.advice) and rank-deficient elements (runtime.kernels.hourglass).

Advice never changes a run's status; a static run whose stiffness is singular because of hourglass
modes is refused before its first step. The bending case: a hexahedral cantilever, one element
through the thickness, one-point (gauss1) against 2x2x2 (gauss2) quadrature.
"""
from __future__ import annotations

import numpy as np
import pytest

from tensormass import laws
from tensormass.runtime.scene import advice as adv
from tensormass.runtime.kernels import hourglass
from tensormass.runtime.base.errors import TensormassError
from tensormass.runtime.scene.types import Material
from tensormass.runtime.scene.scene import Scene
from tensormass.runtime.run.simulation import Simulation


# The count comes from the kernel's stiffness, the same on both backends: C where other tests compile
# these kernels too, the default (numba) on the one numba kernel other tests compile.
@pytest.mark.parametrize("element, quadrature, spurious, backend", [
    ("hexahedron", "gauss1", 12, "c"), ("quad", "gauss1", 2, "c"),           # flagged
    ("hexahedron", "gauss2", 0, "c"), ("quad", "gauss2", 0, "c"), ("tetra", "gauss1", 0, None),
])
def test_spurious_modes_come_from_the_kernel(element, quadrature, spurious, backend):
    given = {} if backend is None else {"backend": backend}
    assert hourglass.spurious_modes(element, "hooke", quadrature, **given) == spurious


def test_unknown_kernels_get_no_verdict():
    assert hourglass.spurious_modes("hexahedron", "no_such_law", "gauss1") is None


def test_poisson_ratio_from_native_parameters():
    for law in ("hooke", "mooney_rivlin"):
        native = {k: float(v) for k, v in laws.get(law).native_parameters(E=2.0, nu=0.49).items()}
        assert adv.poisson_ratio(Material(law=law, params=native)) == pytest.approx(0.49, rel=1e-12)
    assert adv.poisson_ratio(Material(E=1.0, nu=0.3)) == 0.3
    assert adv.poisson_ratio(Material(params={"mu": 1.0, "kappa": 1.0})) == pytest.approx(1 / 8)
    assert adv.poisson_ratio(Material(params={"C10": 1.0})) is None


BAR = """
[mesh]
generate = "bar"
size = {size}
cells = {cells}
element = "{element}"
[[material]]
region = "{region}"
law = "hooke"
quadrature = "{quadrature}"
{elastic}
{more}
[[fixed]]
box = [[-1, -1, -1], [0.0, 1, 1]]
[[loads.force]]
box = [[1.0, -1, -1], [1.0, 1, 1]]
value = [0.0, 0.0, -0.1]
[[probe]]
name = "tip"
box = [[1.0, -1, -1], [1.0, 1, 1]]
"""


def bar(element="tetra", quadrature="gauss1", elastic="E = 1.0e6\nnu = 0.49", cells="[2, 1, 1]", region="all",
        more="", size="[1.0, 0.1, 0.1]"):
    return Scene.from_string(BAR.format(element=element, quadrature=quadrature, elastic=elastic, cells=cells,
                                        region=region, more=more, size=size))


def test_locking_advice_names_the_locking_free_choice():
    assert adv.scene_advice(bar()) == ['material[0]: nu = 0.49 on tetra with the displacement formulation locks '
                                       '(too stiff); use formulation = "nodal_pressure"']
    lam_mu = bar(elastic="lam = 4.9\nmu = 0.1")                  # nu = lam / (2 (lam + mu)) = 0.49
    assert adv.scene_advice(lam_mu) == adv.scene_advice(bar())
    assert adv.scene_advice(bar(elastic="E = 1.0e6\nnu = 0.449")) == []
    assert adv.scene_advice(bar(more='formulation = "nodal_pressure"')) == []
    hexa = adv.scene_advice(bar("hexahedron", "gauss2"))
    assert hexa == ['material[0]: nu = 0.49 on hexahedron with the displacement formulation locks (too stiff); '
                    'use formulation = "mean_dilatation"']


def test_pyramid_has_no_locking_free_choice():
    text = adv._locking("material[1]", Material(E=1.0, nu=0.499), "pyramid")
    assert text == ("material[1]: nu = 0.499 on pyramid with the displacement formulation locks (too stiff); no "
                    "locking-free formulation exists for it: refine the mesh or use quadratic elements")


def test_only_the_elements_a_material_models_are_advised():
    """A mixed bar: material[0] on its hexahedra only (nu = 0.3, gauss1: hourglass), material[1] (nu = 0.49)
    on the rest; no advice names material[0] with another element, none names material[1] with a hexahedron."""
    scene = Scene.from_string(BAR.format(element="mixed", quadrature="gauss1", elastic="E = 1.0e6\nnu = 0.3",
                                         cells="[4, 1, 1]", region="hexahedron", size="[1.0, 0.1, 0.1]", more="""
[[material]]
region = "all"
law = "hooke"
quadrature = "gauss2"
E = 1.0e6
nu = 0.49
formulation = "displacement"
"""), load_mesh=True)
    lines = adv.scene_advice(scene)
    assert lines[0] == ("material[0]: hexahedron with quadrature 'gauss1' has 12 spurious zero-energy (hourglass) "
                        "mode(s) per element beyond the rigid motions, and no hourglass control: deformations that "
                        "cost no energy; use quadrature = \"gauss2\"")
    assert [line.split(" on ")[1].split(" ")[0] for line in lines[1:]] == ["wedge", "pyramid", "tetra"]
    assert all(line.startswith("material[1]: nu = 0.49 on ") for line in lines[1:])


def test_advice_does_not_change_the_status():
    summary = Simulation(bar(), output=False).run()
    assert summary.status == "ok" and summary.warnings == []
    assert summary.advice == adv.scene_advice(bar()) and len(summary.advice) == 1
    assert summary.to_dict()["advice"] == summary.advice


def euler_bernoulli(scene) -> float:
    L, b, h = scene.mesh.size
    return 0.1 * L ** 3 / (3.0 * scene.materials[0].E * b * h ** 3 / 12.0)


def test_hourglass_on_a_bending_cantilever():
    """10 x 1 x 1 hexahedra, end load 0.1 N, E = 1 MPa, nu = 0.3. gauss2: a unique answer, too stiff
    (shear locking of one element through the thickness: 0.648 x Euler-Bernoulli). gauss1: every
    element's bending is one of its 12 zero-energy modes, the clamped bar keeps free ones (its stiffness
    has a null space): the static run is refused before its first step, naming the element and gauss2."""
    stiff = bar("hexahedron", "gauss2", elastic="E = 1.0e6\nnu = 0.3", cells="[10, 1, 1]")
    assert Simulation(stiff, output=False).advice == []
    w = -Simulation(stiff, output=False).run().probes["tip"][2]
    ratio = w / euler_bernoulli(stiff)
    assert 0.64 < ratio < 0.66, ratio

    soft = bar("hexahedron", "gauss1", elastic="E = 1.0e6\nnu = 0.3", cells="[10, 1, 1]")
    sim = Simulation(soft, output=False)
    assert len(sim.advice) == 1 and "12 spurious zero-energy (hourglass) mode(s)" in sim.advice[0]
    # the null space of the clamped bar's stiffness: zero-energy deformations that the constraints leave free
    K = sim.model.parts[0].kernel
    free = sim.model.free_dofs
    from tensormass.runtime.physics.newton import Context
    ctx = Context(sim.model)
    ctx.model.warm_up()
    ctx.asm.warm_up()
    Kf = ctx.asm.matrix(ctx.asm.stiffness(np.zeros(sim.model.n_dofs)))[free][:, free].toarray()
    eig = np.linalg.eigvalsh(Kf)
    # 120 free dofs, but one-point quadrature sees only the 6 constant strains of each of the 10 elements
    assert K.quadrature == "gauss1" and Kf.shape == (120, 120) and np.count_nonzero(eig < 1e-8 * eig.max()) == 60
    with pytest.raises(TensormassError, match=r"^static solve refused: the stiffness at rest is singular, hexahedron "
                                              r"with quadrature 'gauss1' has 12 spurious .* use quadrature = \"gauss2\""):
        sim.run()


def test_static_runs_go_on_where_the_constraints_hold_every_hourglass_mode():
    """2D quads with gauss1, two elements through the thickness: rank-deficient elements (advice), but
    the clamped mesh's stiffness is not singular, so the static answer is unique and the run goes on."""
    scene = Scene.from_string("""
[mesh]
generate = "bar"
size = [1.0, 0.1]
cells = [10, 2]
element = "quad"
[[material]]
law = "hooke"
quadrature = "gauss1"
E = 1.0e6
nu = 0.3
[[fixed]]
box = [[-1, -1], [0.0, 1]]
[[loads.force]]
box = [[1.0, -1], [1.0, 1]]
value = [0.0, -0.1]
""")
    summary = Simulation(scene, output=False).run()
    assert summary.status == "ok" and len(summary.advice) == 1 and "quad with quadrature 'gauss1' has 2" in summary.advice[0]

