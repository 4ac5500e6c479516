"""The mesh checks' neighbour search (runtime.mesh.checks._within)."""
import numpy as np

from tensormass.runtime.mesh.checks import _within


def test_within_finds_every_point_in_every_ball():
    """The overlapping-face check's neighbour search against all pairs, on scattered points and balls of
    very different radii, in 2D and 3D."""
    rng = np.random.default_rng(3)
    for dim in (2, 3):
        points = rng.random((300, dim))
        centres = points[rng.permutation(300)] + 0.01 * rng.normal(size=(300, dim))
        radii = rng.choice([1e-3, 0.05, 0.3], size=300)
        d2 = ((points[:, None, :] - centres[None, :, :]) ** 2).sum(axis=2)
        j_all, i_all = np.nonzero(d2.T <= radii[:, None] ** 2)
        i, j = _within(points, centres, radii)
        assert (i.tolist(), j.tolist()) == (i_all.tolist(), j_all.tolist())
