"""The model wing: the Model a scene builds (parts, kernels, constants, loads, constraints, probes).
Below: base ... scene."""
