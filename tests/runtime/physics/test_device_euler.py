"""[solver] device = "cuda" through the whole run, on the host shim (the integrator's device system on numpy
arrays with the cuda backend's files compiled as C) and, where present, the GPU: the run follows the CPU's
implicit Euler (direct solves) with damping, a moving boundary, gravity and a nodal force, on one part and
on four parts sharing nodes. Scenes it does not take are refused naming solver.device."""
from __future__ import annotations

import numpy as np
import pytest

import tensormass as tm
from tensormass.runtime.base.errors import SceneError, TensormassError
from tensormass.runtime.physics.device_euler import DeviceImplicitEuler
from tensormass.runtime.scene.parser import DEVICES
from tensormass.runtime.solve import device as device_module

from helpers import device_params

SCENE = """
[mesh]
generate = "bar"
size = [2.0, 0.5, 0.5]
cells = [4, 2, 2]
element = "{element}"

[[material]]
law = "neohookean"
quadrature = "{quadrature}"
E = 2e4
nu = 0.3
density = 1000.0

[[fixed]]
box = [[-0.01, -1, -1], [0.01, 1, 1]]
displacement = [0.05, 0.0, 0.0]

[loads]
gravity = [0.0, 0.0, -9.81]
[[loads.force]]
box = [[1.99, -1, -1], [2.01, 1, 1]]
value = [0.0, 20.0, 0.0]

[solver]
kind = "implicit_euler"
dt = 0.01
steps = 8
rayleigh = [0.5, 0.001]
mass = "{mass}"
{extra}

[[probe]]
name = "tip"
point = [2.0, 0.25, 0.25]
"""


def _run(device, mass="lumped", extra="", element="tetra"):
    quadrature = "gauss1" if element == "tetra" else "gauss2"
    text = SCENE.format(element=element, quadrature=quadrature, mass=mass, extra=extra + (f'\ndevice = "{device}"' if device else ""))
    sim = tm.Simulation(tm.Scene.from_string(text), output=False)
    summary = sim.run()
    assert summary.status == "ok", summary.message
    return sim, summary


@pytest.mark.parametrize("make_device", device_params())
@pytest.mark.parametrize("mass,element", [("lumped", "tetra"), ("consistent", "tetra"),
                                          pytest.param("lumped", "mixed", marks=pytest.mark.heavy)])
def test_device_run_follows_the_cpu_run(monkeypatch, mass, element, make_device):
    """mixed: hexahedron, wedge, pyramid and tetra parts sharing nodes."""
    device = make_device()
    monkeypatch.setattr(DeviceImplicitEuler, "device_factory", staticmethod(lambda name: device))
    cpu, s_cpu = _run(None, mass, 'linear = "direct"', element)
    dev, s_dev = _run("cuda", mass, "cg_tolerance = 1e-13\ncg_max_iterations = 5000", element)
    u = cpu.displacement
    assert np.abs(u).max() > 1e-3
    np.testing.assert_allclose(dev.displacement, u, rtol=0, atol=1e-8 * np.abs(u).max())
    for name, r in s_cpu.reactions.items():
        np.testing.assert_allclose(s_dev.reactions[name]["force"], r["force"], rtol=0,
                                   atol=1e-6 * np.abs(r["force"]).max())
    assert s_dev.iterations["linear_solvers"] == {"device-cg": 8}
    assert s_dev.iterations["linear"] > 8


def test_devices_agree_with_the_parser():
    assert DEVICES == device_module.DEVICES


@pytest.mark.parametrize("extra,message", [
    ('kind = "explicit"', r'runs kind = "implicit_euler"'),
    ('mode = "interactive"', r"solves every step exactly"),
    ('linear = "pardiso"', r"solves with its own Jacobi-preconditioned CG"),
    ('project_psd = true', r"takes the kernels' stiffness as it is"),
])
def test_scenes_the_device_does_not_take_are_refused(extra, message):
    text = SCENE.format(element="tetra", quadrature="gauss1", mass="lumped", extra='device = "cuda"').replace(
        'kind = "implicit_euler"', "") + ""
    text = text.replace("[solver]\n", "[solver]\n" + extra + "\n")
    if "kind" not in extra:
        text = text.replace("[solver]\n", '[solver]\nkind = "implicit_euler"\n')
    with pytest.raises(SceneError, match=r"solver\.device: \"cuda\" " + message):
        tm.Scene.from_string(text)


def test_without_a_gpu_the_device_is_a_clear_error():
    try:
        device_module.get_device("cuda")
    except TensormassError as error:
        assert "solver.device = \"cuda\"" in str(error) and "cuda" in str(error)
    else:
        pytest.skip("CuPy and a CUDA device are present")
