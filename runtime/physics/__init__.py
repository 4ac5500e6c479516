"""The physics wing: Newton and the time integrators, run health, reactions, motions over time,
hanging-node constraints, volume preservation, locking-free formulations and output fields.
Below: base, mesh, kernels, assembly, solve."""
