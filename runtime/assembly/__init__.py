"""The assembly wing: the sparsity pattern, assembly of forces and stiffness over a mixed mesh, its
colouring, loads, masses, follower pressures and the locking-free volumetric couplings.
Below: base, mesh, kernels."""
