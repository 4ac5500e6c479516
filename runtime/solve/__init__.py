"""The solve wing: linear solvers (band Cholesky, CG, multigrid, PARDISO, SuperLU) and their choice.
Below: base, mesh, kernels, assembly."""
