"""The thresholds by which the linear solvers are chosen, light (no numba, no scipy): runtime.solve
uses them to choose, and the resource estimate (runtime.scene.resources) to predict the choice
before anything is built."""

# Below this many unknowns "auto" takes the band Cholesky, no cost model needed.
AUTO_DIRECT_BELOW = 3_000
# Modelled band seconds past which PARDISO's analysis is worth running.
PARDISO_ANALYSE_ABOVE = 0.05
# PARDISO's single-precision factor rate (flop/s; double: half).
PARDISO_FLOPS = 30e9
# Without MKL: "auto" takes the band Cholesky while n kd^2 <= AUTO_BAND_WORK_PER_NNZ x nnz,
# IC(0)-CG beyond (CG-IC(0) costs about nnz x 1.2-1.7e-7 s).
AUTO_BAND_WORK_PER_NNZ = 6_000.0
# Above this many unknowns "auto" never factorises.
DIRECT_LIMIT = 2_000_000
# The band factor is refused (SuperLU instead) beyond this many float64 band entries (2 GiB).
BAND_MAX_ENTRIES = 2**28
