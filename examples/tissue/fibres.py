"""Fibre directions of examples/tissue/myocardium_strip.toml: in the x-y plane of the strip, their
angle to the x axis turning from -60 to +60 degrees through the thickness (z), as in the wall of a
heart ventricle."""
import numpy as np

THICKNESS = 0.01        # m: the strip's size along z in the scene


def helical(centroids):
    """(n, 3) unit vectors for the cells' rest centroids (n, 3)."""
    angle = np.radians(-60.0 + 120.0 * centroids[:, 2] / THICKNESS)
    return np.column_stack([np.cos(angle), np.sin(angle), np.zeros(len(centroids))])
