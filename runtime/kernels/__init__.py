"""The kernels wing: loading generated and custom kernels (C or numba) and what runs them per element
(fused scatter, the co-rotational wrapper, hourglass-mode counts). Below: base, mesh."""
