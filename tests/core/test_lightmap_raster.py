"""Texel rasterisation: conservative coverage, the triangle under the centre wins, leak guard."""
import numpy as np
import pytest

import shapes
from radiosity_baker.core import Settings, device
from radiosity_baker.core.problem import Problem
from radiosity_baker.core.lightmap import raster


@pytest.fixture(scope="module")
def dev():
    return device.select("cpu")


def _centres(tx):
    y, x = np.divmod(tx.index, tx.width)
    return np.stack([x + 0.5, y + 0.5], axis=1)


def test_a_sliver_thinner_than_a_texel_gets_a_texel_in_every_row_it_crosses(dev):
    uv = np.array([[[0.50, 0.1], [0.502, 0.9], [0.504, 0.1]]], np.float32)  # 0.13 texels wide
    tx = raster.rasterize(uv, 64, 64, dev)
    rows = np.unique(tx.index // 64)
    assert set(range(7, 57)) <= set(rows.tolist())
    assert (tx.triangle == 0).all()


def test_the_triangle_covering_a_texel_centre_samples_it_at_the_centre(dev):
    # two triangles of a square split along its diagonal, plus an empty (NaN) one
    uv = np.array([[[0.1, 0.1], [0.9, 0.1], [0.9, 0.9]], [[0.1, 0.1], [0.9, 0.9], [0.1, 0.9]],
                   [[np.nan, np.nan]] * 3], np.float32)
    tx = raster.rasterize(uv, 20, 20, dev)
    c = _centres(tx) / 20.0
    inside = (c > 0.1).all(axis=1) & (c < 0.9).all(axis=1)
    above = c[:, 1] > c[:, 0]
    on_diagonal = np.isclose(c[:, 1], c[:, 0])
    sel = inside & ~on_diagonal
    np.testing.assert_array_equal(tx.triangle[sel], above[sel].astype(np.int32))
    # sample point = texel centre inside; barycentrics valid everywhere
    p = np.einsum("nk,nkc->nc", tx.bary, uv[tx.triangle])
    np.testing.assert_allclose(p[inside], c[inside], atol=1e-5)
    assert (tx.bary >= -1e-6).all() and np.allclose(tx.bary.sum(axis=1), 1.0, atol=1e-5)
    # conservative: the border ring of texels the square only partly covers is included
    assert tx.count == 18 * 18
    assert not (tx.triangle == 2).any()


def test_a_floor_texel_behind_a_wall_moves_in_front_of_it(dev):
    # floor z = 0 (2 m), wall x = 0 facing −x standing on it; a texel sample at x = +0.01 m lies
    # behind the wall and must move to its front (x < 0); one at x = −0.3 m stays.
    fp, fn, ft = shapes.grid(2.0, 1)
    wp_ = np.array([[0, -1, 0], [0, 1, 0], [0, 1, 1], [0, -1, 1]], np.float32)
    wn = np.tile([[-1, 0, 0]], (4, 1)).astype(np.float32)
    wt = np.array([[0, 2, 1], [0, 3, 2]], np.int32)
    sc = shapes.scene([(fp, fn, ft, (0.5,) * 3, (0,) * 3), (wp_, wn, wt, (0.5,) * 3, (0,) * 3)])
    problem = Problem(sc, Settings(device="cpu"))
    origin = problem.scene.origin.astype(np.float32)  # the problem's frame
    tri_pos = np.array([[[-1, -1, 0], [1, -1, 0], [1, 1, 0]]] * 2, np.float32)
    tri_nrm = np.tile([0, 0, 1], (2, 3, 1)).astype(np.float32)
    # barycentrics of (0.01, 0.01) and (−0.3, −0.3) in the triangle (−1,−1), (1,−1), (1,1)
    bary = np.array([[0.495, 0.0, 0.505], [0.65, 0.0, 0.35]], np.float32)
    tx = raster.Texels(np.array([0, 1]), np.array([0, 1], np.int32), bary, 2, 1)
    points, normals = raster.surface_points(tx, tri_pos - origin, tri_nrm, np.full(2, 0.05, np.float32),
                                            problem)
    points = points + origin
    assert points[0, 0] < 0.0 and abs(points[0, 0]) < 1e-3
    assert points[1, 0] == pytest.approx(-0.3, abs=2e-3)
    np.testing.assert_allclose(normals, [[0, 0, 1]] * 2, atol=1e-6)
