"""Shared test helpers: random well-shaped elements and finite differences."""
from __future__ import annotations

import os

import numpy as np
import pytest

from tensormass.generator.elements import element as reference
from tensormass.runtime.base.samples import random_elements

__all__ = ["random_elements", "reference_nodes", "fd_gradient", "relative_error", "FULL_CATALOGUE",
           "catalogue_selection", "QUICK_KERNELS", "QUICK_NUMBA_KERNELS", "quick", "law_inputs"]

# The checks that run over the catalogue (finite differences, patch tests, C = numba, ...) take a
# sample covering every element type, law and quadrature; CI's catalogue step sets
# TENSORMASS_FULL_CATALOGUE=1 and runs them on every entry (pytest -m catalogue).
FULL_CATALOGUE = os.environ.get("TENSORMASS_FULL_CATALOGUE") == "1"


# The kernels the quick suite compiles. A cold run pays gcc -O3 (1.5 to 8 s) once per distinct C
# kernel and a numba compile once per generated numba module, so a test that needs "some kernel of
# this element / law / quadrature" picks its kernel from this one pool and each kernel is compiled
# once for the whole suite. The scene default (gauss2) for the three common laws on every element;
# the gauss1 tetrahedra (the cheapest 3D kernels); mooney_rivlin and stable_neohookean only where
# they are cheap (mooney_rivlin on 3D elements takes 4 to 8 s per build); one gauss3 and the exact
# rules on one 2D quadratic element (with their Hooke tangents); the formulations' measure kernels
# at the scene default (and gauss1 on tetrahedra). Other instances: pytest.mark.catalogue or heavy.
_ELEMENTS = ("tetra", "tetra10", "hexahedron", "wedge", "pyramid", "triangle", "triangle6", "quad")
QUICK_KERNELS = frozenset(
    [f"{e}_{law}_gauss2" for e in _ELEMENTS for law in ("hooke", "stvk", "neohookean")]
    + [f"tetra_{law}_gauss1" for law in ("hooke", "stvk", "neohookean", "stable_neohookean")]
    + ["triangle_mooney_rivlin_gauss1", "triangle_hooke_gauss1",      # triangle_hooke_gauss1: the tangent
       "quad_hooke_gauss3", "triangle6_stvk_exact", "triangle6_hooke_exact"]   # at rest of the one before
    + [f"{e}_measure_{m}_gauss2" for e in _ELEMENTS for m in ("volume", "dilatation", "green_dilatation")]
    + [f"tetra_measure_{m}_gauss1" for m in ("volume", "dilatation", "green_dilatation")]
    + ["triangle_measure_volume_gauss1"]         # the one-point triangle mooney_rivlin's nodal pressure
    + ["tetra_mss_discrete", "triangle_mss_discrete"]           # the lattice laws on their cheap elements
    + ["tetra_hgo_gauss1", "tetra_hgo2_gauss1"])               # fibres: the cheapest of their kernels
# Generated numba modules (5 to 30 s of numba compile each, cold): the tests about numba itself
# (C = numba, the numba backend's own behaviour, the benchmarks that time both backends) load
# these; every other test runs the default backend (C).
QUICK_NUMBA_KERNELS = frozenset(["tetra_hooke_gauss1", "tetra_stvk_gauss1", "triangle_mooney_rivlin_gauss1",
                                 "hexahedron_neohookean_gauss2"])


def has_c_compiler() -> bool:
    """Whether the C backend finds a compiler here (tests of C builds skip without one)."""
    from tensormass.backends.c import loader
    try:
        loader.compiler()
    except Exception:                                        # noqa: BLE001 - any failure: no compiler
        return False
    return True


def quick(name: str, backend: str = "c") -> bool:
    """Whether the quick suite may load the kernel `name` with `backend` (the pools above)."""
    return name in (QUICK_NUMBA_KERNELS if backend == "numba" else QUICK_KERNELS)


def catalogue_selection(entries, sample) -> list:
    """Every entry with TENSORMASS_FULL_CATALOGUE=1, else those named in sample (all of which exist)."""
    entries = list(entries)
    if FULL_CATALOGUE:
        return entries
    chosen = [e for e in entries if e.name in sample]
    missing = sorted(set(sample) - {e.name for e in chosen})
    assert not missing, f"sample entries not in the catalogue: {missing}"
    return chosen


def reference_nodes(name: str) -> np.ndarray:
    return np.array([[float(x) for x in node] for node in reference(name).nodes])


def fd_gradient(fun, u: np.ndarray, h: float) -> np.ndarray:
    """Central differences of a batched fun(u) -> (n_elem, ...) with respect to each dof of u (n_elem, n_dofs)."""
    n, m = u.shape
    cols = []
    for k in range(m):
        up, um = u.copy(), u.copy()
        up[:, k] += h
        um[:, k] -= h
        cols.append((fun(up) - fun(um)) / (2 * h))
    return np.stack(cols, axis=-1)


def relative_error(a, b) -> float:
    a, b = np.asarray(a), np.asarray(b)
    scale = max(np.abs(b).max(), 1e-300)
    return float(np.abs(a - b).max() / scale)


def random_cubes(n: int, seed: int = 0, edge=(0.3, 2.0)) -> np.ndarray:
    """(n, 8, 3) hexahedra that are cubes (the discrete lattice laws refuse others): the reference
    cube scaled to a random edge, rotated at random and moved."""
    from tensormass import elements
    rng = np.random.default_rng(seed)
    ref = np.array(elements.get("hexahedron").nodes, dtype=float) / 2
    out = np.empty((n, 8, 3))
    for e in range(n):
        Q, R = np.linalg.qr(rng.standard_normal((3, 3)))
        Q = Q * np.sign(np.diag(R))
        if np.linalg.det(Q) < 0:
            Q[:, 0] = -Q[:, 0]
        out[e] = rng.uniform(*edge) * ref @ Q.T + rng.standard_normal(3)
    return out


def catalogue_parameters(law: str) -> dict:
    """Material parameters every catalogue entry of `law` accepts (a shell needs its thickness)."""
    from tensormass import laws
    return {"E": 2.0, "nu": 0.3, **({"thickness": 0.1} if laws.is_shell(law) else {}), **law_inputs(law)}


# Fibre directions in the plane z = 0 (2D elements take in-plane fibres) whose squared length is 1
# in floating point: at rest the fibre strain is then exactly 0 and the fibres carry nothing.
FIBRE = (0.6, 0.8, 0.0)
FIBRES = (FIBRE, (-0.8, 0.6, 0.0))          # a law's first and second direction


def law_inputs(law: str) -> dict:
    """What a law takes beyond E and nu for the kernel checks: its options (fibre stiffness k1 of
    the order of E, k2, a dispersion that involves every term) and its directions (FIBRE)."""
    from tensormass import laws
    the_law = laws.kernel_law(law)
    if the_law.kind != "continuum":
        return {}
    values = {"k1": 2.0, "k2": 1.5, "dispersion": 0.1}
    out = {name: values.get(name, default) for name, default, _ in the_law.options}
    out.update({f"{d}_{c}": x for d, fibre in zip(the_law.directions, FIBRES) for c, x in zip("xyz", fibre)})
    return out


def catalogue_elements(element: str, law: str, quadrature: str, n: int, seed: int = 0) -> np.ndarray:
    """Random rest elements a catalogue entry accepts: cubes for the lattice (discrete) laws on
    hexahedra, straight edges for quadrature 'exact', random curved elements otherwise."""
    from tensormass import laws
    if laws.is_discrete(law) and element == "hexahedron":
        return random_cubes(n, seed=seed)
    if element == "shell":                  # triangles in 3D: a random 2D one, tilted and moved
        rng = np.random.default_rng(seed)
        flat = random_elements("triangle", n, seed=seed, straight=True)
        X = np.concatenate([flat, np.zeros((n, 3, 1))], axis=2)
        Q, _ = np.linalg.qr(rng.standard_normal((3, 3)))
        return X @ Q.T + rng.standard_normal(3)
    return random_elements(element, n, seed=seed, straight=quadrature == "exact")


# A unit cube of tetrahedra in uniaxial stress (the tissue tests): its mesh, and rollers on the faces
# x = 0, y = 0 and z = 0 (each holds its normal component only), as scene TOML.
UNIT_CUBE_TOML = """
[mesh]
generate = "bar"
size = [1.0, 1.0, 1.0]
cells = [1, 1, 1]
element = "tetra"
"""
ROLLERS_TOML = "".join(f"""
[[fixed]]
box = {[[-1] * a + [-0.01] + [-1] * (2 - a), [2] * a + [0.01] + [2] * (2 - a)]}
components = [{a}]
""" for a in range(3))



def _cuda_device_present() -> bool:
    from tensormass.runtime.base.errors import TensormassError
    from tensormass.runtime.solve.device import get_device
    try:
        get_device("cuda")
    except TensormassError:
        return False
    return True


def device_params() -> list:
    """The array devices the device tests run on: the host shim (numpy, the CUDA files compiled as C;
    needs a C compiler) always, and the GPU (CuPy) where one is present."""
    from tensormass.runtime.solve.device import get_device, host_device
    return [pytest.param(host_device, id="host-shim",
                         marks=pytest.mark.skipif(not has_c_compiler(), reason="the host shim needs a C compiler")),
            pytest.param(lambda: get_device("cuda"), id="cuda",
                         marks=pytest.mark.skipif(not _cuda_device_present(), reason="needs CuPy and a CUDA device"))]


def to_host(a) -> np.ndarray:
    """A numpy copy of a numpy or CuPy array."""
    return np.asarray(a.get() if hasattr(a, "get") else a)


# The organ stepped live (examples/organ/live.toml: tetra10, budgeted implicit Euler) and its pole.
LIVE_SCENE = __import__("pathlib").Path(__file__).resolve().parents[1] / "examples" / "organ" / "live.toml"
LIVE_POLE = np.array([0.0, 0.0, 0.03])


def live_scene(path=LIVE_SCENE, **solver):
    """The live organ's Scene (or another scene file's), with these [solver] keys changed."""
    from tensormass.runtime.scene.scene import Scene
    scene = Scene.from_toml(str(path))
    for key, value in solver.items():
        setattr(scene.solver, key, value)
    return scene
