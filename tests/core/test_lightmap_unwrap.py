"""xatlas layout: one page, charts apart by the padding, bad faces left out, results cached."""
import numpy as np
import pytest

import shapes
from radiosity_baker.core import device
from radiosity_baker.core.errors import BakeError
from radiosity_baker.core.lightmap import raster
from radiosity_baker.core.lightmap.unwrap import ChartMesh, unwrap


def _box(size=1.0):
    """Six 4×4-quad faces of a closed box (m), as separate faces sharing no vertices."""
    parts = []
    p, _, t = shapes.grid(size, 4, z=size / 2)
    for rot in ([0, 0, 0], [90, 0, 0], [180, 0, 0], [-90, 0, 0], [0, 90, 0], [0, -90, 0]):
        ax, ay = np.radians(rot[0]), np.radians(rot[1])
        rx = np.array([[1, 0, 0], [0, np.cos(ax), -np.sin(ax)], [0, np.sin(ax), np.cos(ax)]])
        ry = np.array([[np.cos(ay), 0, np.sin(ay)], [0, 1, 0], [-np.sin(ay), 0, np.cos(ay)]])
        parts.append(p @ (ry @ rx).T)
    pos = np.concatenate(parts).astype(np.float32)
    tris = np.concatenate([t + i * len(p) for i in range(6)]).astype(np.int32)
    return pos, tris


def _charts(tri_uv: np.ndarray) -> np.ndarray:
    """int[T] chart label of each triangle: triangles sharing a corner UV are in one chart."""
    keys = np.round(tri_uv.reshape(-1, 2) * 1e6).astype(np.int64)
    _, corner = np.unique(keys[:, 0] * (1 << 31) + keys[:, 1], return_inverse=True)
    corner = corner.reshape(-1, 3)
    label = np.arange(corner.max() + 1)
    while True:  # propagate the smallest label through triangles until nothing changes
        tri_min = label[corner].min(axis=1)
        new = label.copy()
        np.minimum.at(new, corner.ravel(), np.repeat(tri_min, 3))
        if np.array_equal(new, label):
            return label[corner[:, 0]]
        label = new


def test_charts_of_two_meshes_share_one_page_without_overlap_and_keep_the_padding(tmp_path):
    pos, tris = _box()
    padding = 3
    atlas, = unwrap([[ChartMesh("box", pos, tris), ChartMesh("box2", pos * 0.5, tris)]],
                    density=32.0, max_size=512, padding=padding, cache_dir=tmp_path)
    w, h = atlas.size
    assert 16 <= max(w, h) <= 512 and atlas.density == 32.0
    tri_uv = np.concatenate(atlas.tri_uv)
    assert np.isfinite(tri_uv).all() and tri_uv.min() >= 0.0 and tri_uv.max() <= 1.0
    labels = _charts(tri_uv)
    assert len(np.unique(labels)) >= 12
    dev = device.select("cpu")
    # Texels covered (conservatively) by different charts are more than `padding` texels apart
    # (Chebyshev distance), so dilating each chart by the padding never reaches another.
    owner = np.full((h, w), -1)
    for c in np.unique(labels):
        tx = raster.rasterize(tri_uv[labels == c], w, h, dev)
        ys, xs = np.divmod(tx.index, w)
        for dy in range(-padding, padding + 1):
            for dx in range(-padding, padding + 1):
                y, x = np.clip(ys + dy, 0, h - 1), np.clip(xs + dx, 0, w - 1)
                clash = (owner[y, x] >= 0) & (owner[y, x] != c)
                assert not clash.any(), f"charts overlap or lie within {padding} texels"
        owner[ys, xs] = c


def test_density_is_lowered_until_the_atlas_fits_one_page(tmp_path):
    pos, tris = _box(2.0)
    atlas, = unwrap([[ChartMesh("box", pos, tris)]], density=200.0, max_size=64, padding=2,
                    cache_dir=tmp_path)
    assert max(atlas.size) <= 64 and atlas.density < 200.0


def test_nan_and_zero_area_triangles_are_left_out(tmp_path):
    p, _, t = shapes.grid(1.0, 4)
    p = np.concatenate([p, [[np.nan, 0, 0]]]).astype(np.float32)
    t = np.concatenate([t, [[0, 1, len(p) - 1], [0, 0, 1]]]).astype(np.int32)
    atlas, = unwrap([[ChartMesh("plane", p, t)]], 16.0, 256, 2, cache_dir=tmp_path)
    ok = np.isfinite(atlas.tri_uv[0]).all(axis=(1, 2))
    assert ok[:-2].all() and not ok[-2:].any()


def test_a_mesh_without_area_is_an_error_naming_it(tmp_path):
    p = np.zeros((3, 3), np.float32)
    with pytest.raises(BakeError, match="Flat"):
        unwrap([[ChartMesh("Flat", p, np.array([[0, 1, 2]], np.int32))]], 16.0, 256, 2, cache_dir=tmp_path)


@pytest.mark.parametrize("density", [20.0, 1000.0, 1e5])
def test_millimetre_meshes_get_charts_and_texels_at_any_density(tmp_path, density):
    pos, tris = _box(0.002)  # 2 mm: xatlas alone drops every face of it
    atlas, = unwrap([[ChartMesh("screw", pos, tris), ChartMesh("nut", pos * 0.5 + 0.01, tris)]],
                    density, 1024, 2, cache_dir=tmp_path)
    w, h = atlas.size
    assert w > 0 and h > 0 and atlas.density == density
    dev = device.select("cpu")
    for tri_uv in atlas.tri_uv:
        assert np.isfinite(tri_uv).all() and tri_uv.min() >= 0.0 and tri_uv.max() <= 1.0
        assert raster.rasterize(tri_uv, w, h, dev).count > 0


def test_a_mesh_too_small_beside_the_others_of_its_page_is_an_error_naming_it(tmp_path):
    pos, tris = _box()
    with pytest.raises(BakeError, match="gave Speck no chart"):
        unwrap([[ChartMesh("box", pos, tris), ChartMesh("box2", pos + 3, tris),
                 ChartMesh("Speck", pos * 1e-4, tris)]], 16.0, 256, 2, cache_dir=tmp_path)


def test_results_are_cached_per_mesh_content(tmp_path):
    pos, tris = _box()
    first, = unwrap([[ChartMesh("box", pos, tris)]], 16.0, 256, 2, cache_dir=tmp_path)
    # A cache hit never starts the worker: a missing interpreter does not matter then.
    again, = unwrap([[ChartMesh("box", pos, tris)]], 16.0, 256, 2, python="/nonexistent/python",
                    cache_dir=tmp_path)
    np.testing.assert_array_equal(first.tri_uv[0], again.tri_uv[0])
    with pytest.raises(BakeError, match="cannot start the UV unwrapper"):
        unwrap([[ChartMesh("box", pos * 1.01, tris)]], 16.0, 256, 2, python="/nonexistent/python",
               cache_dir=tmp_path)
