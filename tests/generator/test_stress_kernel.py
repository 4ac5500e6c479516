"""The generated stress kernel: C = numba, and its record holds what its layout says.

The record (generator.kernel_body.stress_record, exported as metadata "stress_record") is checked
against quantities computed here from the other kernel outputs: v against point_volumes(D),
F = I + sum_i u_i (x) G_i from point_gradients(D), the volume-weighted W against energy(), and
the chain rule f_i = -sum_q v P G_i against forces(): so the layout, F, P and W cannot drift
apart from the kernels the solver uses. The analytic values per law (P33 of plane strain
included) are in tests/runtime/physics/test_fields.py."""
from __future__ import annotations


import numpy as np
import pytest

import tensormass as tm
from tensormass.generator.kernel_body import stress_record

from helpers import FULL_CATALOGUE, catalogue_elements, catalogue_parameters, relative_error

pytestmark = pytest.mark.catalogue

# 3D and 2D, one and eight points, three laws, from the numba kernels the quick suite loads anyway
# (helpers.QUICK_NUMBA_KERNELS). The stress kernels share one template per backend: CI's catalogue
# step (TENSORMASS_FULL_CATALOGUE=1) adds one entry per element type and law rather than all 217
# (numba compiles each stress function for 3 to 10 s), a quadratic element among them.
ENTRIES = [("hexahedron", "neohookean", "gauss2"), ("triangle", "mooney_rivlin", "gauss1"),
           ("tetra", "hooke", "gauss1")]
SELECTED = ENTRIES + ([("tetra10", "hooke", "gauss1"), ("tetra", "stvk", "gauss1"), ("wedge", "stable_neohookean", "gauss1"),
                       ("pyramid", "hooke", "gauss1"), ("quad", "neohookean", "gauss2"),
                       ("triangle6", "stvk", "gauss2"), ("hexahedron", "mooney_rivlin", "gauss1")]
                      if FULL_CATALOGUE else [])


def _state(kernel, n=11, seed=3):
    X = catalogue_elements(kernel.element, kernel.law, kernel.quadrature, n, seed=seed)
    D = kernel.constants(X, **catalogue_parameters(kernel.law))
    u = 0.04 * np.random.default_rng(seed).standard_normal((n, kernel.n_nodes, kernel.dofs_per_node))
    return D, u


@pytest.mark.parametrize("entry", SELECTED, ids=["_".join(e) for e in SELECTED])
def test_stress_c_equals_numba(entry):
    numba = tm.load_kernel(*entry, backend="numba")
    c = tm.load_kernel(*entry, backend="c")
    D, u = _state(numba)
    Sn, Sc = numba.stress(D, u), c.stress(D, u)
    assert Sn.shape == (len(D), numba.n_points, numba.stress_record["size"])
    assert relative_error(Sc, Sn) < 1e-12


@pytest.mark.parametrize("entry", ENTRIES, ids=["_".join(e) for e in ENTRIES])
def test_record_matches_the_other_kernels(entry):
    k = tm.load_kernel(*entry, backend="numba")
    d = k.dim
    assert k.stress_record == stress_record(d)
    assert ("P33" in k.stress_record["offsets"]) == (d == 2)
    at = k.stress_record["offsets"]
    D, u = _state(k)
    S = k.stress(D, u)
    v = S[..., at["v"]]
    assert relative_error(v, k.point_volumes(D)) < 1e-14
    G = k.point_gradients(D)                                        # (n, q, nodes, dim)
    F = np.eye(d) + np.einsum("nia,nqib->nqab", u, G)
    assert relative_error(S[..., at["F"]:at["F"] + d * d].reshape(F.shape), F) < 1e-13
    assert relative_error((v * S[..., at["W"]]).sum(axis=1), k.energy(D, u)) < 1e-12
    P = S[..., at["P"]:at["P"] + d * d].reshape(F.shape)
    f = -np.einsum("nq,nqab,nqib->nia", v, P, G).reshape(len(D), -1)
    assert relative_error(f, k.forces(D, u)) < 1e-12

