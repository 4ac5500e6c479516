"""The generator's stages: kinematics, exact integration, hoisting, determinism, the CLI."""
from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest
import sympy as sp

import tensormass as tm
from tensormass import laws
from tensormass.generator import kinematics
from tensormass.generator.catalogue import entries
from tensormass.apps.cli import committed_dir, main
from tensormass.generator.constants import hoist
from tensormass.generator.elements import element
from tensormass.generator.ir import build_ir, exact_degree, law_degree

from helpers import relative_error

t, X1, X2 = sp.symbols("t X1 X2", real=True)
MOTION = sp.Matrix([(18 * t + 4 * X1 + 6 * t * X2) / 4, (14 * t + (4 + 2 * t) * X2) / 4])


def test_brief_kinematics_check_symbolic():
    """Brief 1.5: x1 = (18t + 4X1 + 6tX2)/4, x2 = (14t + (4+2t)X2)/4."""
    F = MOTION.jacobian([X1, X2])
    assert sp.simplify(F - sp.Matrix([[2, 3 * t], [0, 2 + t]]) / 2) == sp.zeros(2)
    E = kinematics.green_lagrange(F.subs(t, 1))
    assert E == sp.Matrix([[0, 3], [3, 7]]) / 4


def test_brief_kinematics_check_through_shape_functions():
    """The same motion interpolated on a quad: F from shape gradients, and the StVK kernel energy."""
    ref = element("quad")
    nodes = sp.Matrix([[0, 0], [2, 0], [2, 1], [0, 1]])          # a 2 x 1 rectangle
    # Rest-geometry gradients at the centre: G = dN J^-1.
    dN = ref.gradients().subs({ref.xi[0]: 0, ref.xi[1]: 0})
    G = dN * (nodes.T * dN).inv()
    at_1 = MOTION.subs(t, 1)
    u = sp.Matrix([[at_1[a].subs({X1: nodes[i, 0], X2: nodes[i, 1]}) - nodes[i, a] for a in range(2)] for i in range(4)])
    F = kinematics.deformation_gradient(u, G)
    assert F == sp.Matrix([[2, 3], [0, 3]]) / 2
    # The kernel's energy equals area x W_stvk(E) with the brief's E (plane strain, E33 = 0).
    k = tm.load_kernel("quad", "stvk", "gauss2")
    X = np.array(nodes.tolist(), dtype=float)[None]
    D = k.constants(X, lam=2.0, mu=3.0)
    E = np.array([[0, 3], [3, 7]]) / 4
    expected = 2.0 * (2.0 / 2 * np.trace(E) ** 2 + 3.0 * np.sum(E * E))
    assert relative_error(k.energy(D, np.array(u.tolist(), dtype=float)[None]), expected) < 1e-14


def test_law_degrees_and_exact_rules():
    assert law_degree(laws.get("hooke")) == 2
    assert law_degree(laws.get("stvk")) == 4
    assert law_degree(laws.get("neohookean")) is None
    assert exact_degree("tetra10", laws.get("stvk")) == 4
    assert exact_degree("hexahedron", laws.get("stvk")) is None
    with pytest.raises(ValueError, match="polynomial"):
        build_ir("tetra10", "neohookean", "exact")


def test_exact_quadrature_equals_symbolic_integration():
    """triangle6 + StVK 'exact' against sympy's integration of W over the reference triangle."""
    ref = element("triangle6")
    xi, eta = ref.xi
    # Small exact rationals keep sympy's integration quick.
    corners = [[0, 0], [sp.Rational(6, 5), sp.Rational(1, 10)], [sp.Rational(1, 5), sp.Rational(9, 10)]]
    mids = [[(corners[a][k] + corners[b][k]) / 2 for k in range(2)] for a, b in ((0, 1), (1, 2), (2, 0))]
    Xs = sp.Matrix(corners + mids)                                                   # straight edges
    us = sp.Matrix(6, 2, lambda i, k: sp.Rational((7 * i + 3 * k) % 5 - 2, 20))
    X, u = np.array(Xs.tolist(), dtype=float), np.array(us.tolist(), dtype=float)
    lam, mu = sp.Rational(3, 2), sp.Rational(1, 1)
    dN = ref.gradients()
    J = Xs.T * dN
    G = dN * J.inv()
    F = kinematics.embed_plane_strain((sp.eye(2) + us.T * G).tolist())
    W = laws.get("stvk").energy(F, lam=lam, mu=mu) * J.det()
    exact = sp.integrate(sp.integrate(sp.expand(W), (eta, 0, 1 - xi)), (xi, 0, 1))
    k = tm.load_kernel("triangle6", "stvk", "exact")
    got = k.energy(k.constants(X[None], lam=1.5, mu=1.0), u[None])[0]
    assert abs(got - float(exact)) < 1e-13 * abs(float(exact))
    # A rule of lower degree does not reproduce it: the test can tell.
    k2 = tm.load_kernel("triangle6", "stvk", "gauss2")
    assert abs(k2.energy(k2.constants(X[None], lam=1.5, mu=1.0), u[None])[0] - float(exact)) > 1e-8


def test_exact_quadrature_refuses_curved_elements():
    k = tm.load_kernel("triangle6", "stvk", "exact")            # any quadratic element: the quick pool's
    X = np.array([[float(c) for c in n] for n in element("triangle6").nodes])
    X[3] += [0.0, 0.05]                          # bend edge 0-1
    with pytest.raises(tm.DegenerateElementError, match="straight"):
        k.constants(X[None], E=1.0, nu=0.3)


def test_hoisting_groups_parameter_only_factors():
    mu, lam, x, y = sp.symbols("mu lam x y", real=True)
    exprs, constants = hoist([mu / 2 * x * y + (lam + 2 * mu) * x, sp.log(lam) * y], {mu, lam})
    values = dict(constants)
    assert set(values.values()) == {mu / 2, lam + 2 * mu, sp.log(lam)}
    for e in exprs:
        assert not (e.free_symbols & {mu, lam})


def test_ir_records_counts_and_layout():
    ir = build_ir("hexahedron", "stvk", "gauss2")
    assert ir.n_points == 8 and ir.point_stride == 1 + 8 * 3
    assert ir.n_constants == 8 * 25 + len(ir.material_names)
    assert set(ir.ops) == {"constants", "energy", "forces", "stiffness", "forces_and_stiffness", "stress"}
    assert ir.ops["forces"] < ir.ops["forces_and_stiffness"]


def _generate(tmp, seed):
    code = ("from tensormass.generator.pipeline import generate_all;"
            "from tensormass.generator.catalogue import entries;"
            f"generate_all(entries(['wedge'], ['mooney_rivlin'], ['gauss2']), ['numba'], {str(tmp)!r}, progress=None)")
    env = {**os.environ, "PYTHONHASHSEED": str(seed)}
    subprocess.run([sys.executable, "-c", code], check=True, env=env)
    return {p.relative_to(tmp): p.read_bytes() for p in sorted(tmp.rglob("*")) if p.is_file()}


@pytest.mark.heavy          # ~20 s of sympy in two processes; CI's generate --check also compares bytes
def test_generation_is_deterministic_across_processes(tmp_path):
    a = _generate(tmp_path / "a", 1)
    b = _generate(tmp_path / "b", 12345)
    assert a and a == b


def test_committed_kernels_match_a_regeneration(tmp_path, capsys):
    """A sample of generated/ regenerated in-process (the full diff is the CI's `generate --check` step)."""
    from tensormass.generator.pipeline import generate_all
    sample = entries(["tetra", "quad"], ["neohookean"], ["gauss2"])
    generate_all(sample, ["numba"], tmp_path, progress=None)
    for e in sample:
        assert (tmp_path / "numba" / f"{e.name}.py").read_bytes() == (committed_dir() / "numba" / f"{e.name}.py").read_bytes()
    text = (committed_dir() / "numba" / "tetra_neohookean_gauss2.py").read_text().splitlines()[0]
    assert text.startswith("# generated by tensormass") and "inputs" in text


# numba: the generate command compiles the new module (5 to 8 s, in a fresh folder each run)
@pytest.mark.parametrize("backend", ["c", pytest.param("numba", marks=pytest.mark.heavy)])
def test_cli_generate_list_and_errors(tmp_path, capsys, backend):
    assert main(["generate", "--element", "triangle", "--law", "hooke", "--quadrature", "gauss1",
                 "--backend", backend, "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "triangle_hooke_gauss1" in out
    if backend == "numba":
        assert "numba first call (compile)" in out
    suffix = {"numba": ".py", "c": ".c"}[backend]
    assert (tmp_path / backend / f"triangle_hooke_gauss1{suffix}").exists()
    assert (tmp_path / "manifest.json").exists()
    assert main(["list"]) == 0
    assert "hexahedron_stvk_gauss2" in capsys.readouterr().out
    assert main(["generate", "--law", "rubber", "--out", str(tmp_path)]) == 2
    assert "unknown law rubber" in capsys.readouterr().err
    assert main(["generate", "--element", "tetra", "--quadrature", "gauss9", "--out", str(tmp_path)]) == 2


# Each case compiles a kernel of its own (the recompute variant): with C, the 2D quadratic one in
# the quick suite; the hexahedron and numba in CI's catalogue step.
@pytest.mark.parametrize("name, law, quadrature, backend", [
    pytest.param(*case, backend, marks=() if backend == "c" and case[0] == "triangle6" else pytest.mark.heavy)
    for case in [("hexahedron", "neohookean", "gauss2"), ("triangle6", "stvk", "gauss2")] for backend in ("numba", "c")])
def test_recompute_constants_mode_matches_precompute(name, law, quadrature, backend):
    """The generator option constants="recompute" (rest coordinates in D) computes the same
    energy, forces and stiffness as the catalogue's precomputed shape gradients."""
    from tensormass.runtime.kernels.kernels import load_recompute_kernel
    from helpers import random_elements
    variant = load_recompute_kernel(name, law, quadrature, backend)
    reference = tm.load_kernel(name, law, quadrature, backend)
    X = random_elements(name, 6, seed=2)
    u = 0.03 * np.random.default_rng(0).standard_normal((6, variant.n_dofs))
    Dv, Dr = variant.constants(X, E=2.0, nu=0.3), reference.constants(X, E=2.0, nu=0.3)
    assert Dv.shape[1] < Dr.shape[1]                  # rest coordinates instead of G and v per point
    fv, Kv = variant.forces_and_stiffness(Dv, u)
    fr, Kr = reference.forces_and_stiffness(Dr, u)
    assert relative_error(fv, fr) < 1e-12 and relative_error(Kv, Kr) < 1e-12
    assert relative_error(variant.energy(Dv, u), reference.energy(Dr, u)) < 1e-12
    with pytest.raises(tm.TensormassError, match="precompute"):
        variant.inverted(Dv, u)
