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


def _overlap_free(tri_uv: np.ndarray, w: int, h: int, padding: int) -> None:
    """Texels covered (conservatively) by different charts of one page are more than ``padding``
    texels apart (Chebyshev distance), so dilating each chart by the padding never reaches another."""
    labels = _charts(tri_uv)
    dev = device.select("cpu")
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


def test_charts_of_two_meshes_share_one_page_without_overlap_and_keep_the_padding(tmp_path):
    pos, tris = _box()
    padding = 3
    layout, = unwrap([[ChartMesh("box", pos, tris, 32.0), ChartMesh("box2", pos * 0.5, tris, 32.0)]],
                     max_size=512, padding=padding, cache_dir=tmp_path)
    (w, h), = layout.sizes
    assert 16 <= max(w, h) <= 512 and layout.density == [32.0, 32.0] and layout.page == [0, 0]
    tri_uv = np.concatenate(layout.tri_uv)
    assert np.isfinite(tri_uv).all() and tri_uv.min() >= 0.0 and tri_uv.max() <= 1.0
    assert len(np.unique(_charts(tri_uv))) >= 12
    _overlap_free(tri_uv, w, h, padding)


def test_charts_that_do_not_fit_one_page_go_onto_more_each_mesh_whole_at_its_density(tmp_path):
    pos, tris = _box()
    meshes = [ChartMesh(f"box{k}", pos * (0.6 + 0.05 * k), tris, 40.0 if k % 2 else 30.0) for k in range(8)]
    layout, = unwrap([meshes], max_size=128, padding=2, cache_dir=tmp_path)
    assert len(layout.sizes) > 1 and all(size == (128, 128) for size in layout.sizes)
    assert layout.density == [m.density for m in meshes]  # as asked, each its own
    assert sorted(set(layout.page)) == list(range(len(layout.sizes)))
    for page, (w, h) in enumerate(layout.sizes):
        on = [uv for uv, k in zip(layout.tri_uv, layout.page) if k == page]
        tri_uv = np.concatenate(on)
        assert tri_uv.min() >= 0.0 and tri_uv.max() <= 1.0
        _overlap_free(tri_uv, w, h, 2)
        # a page holds what it can: at most the last page is far from full
        texels = sum(0.5 * np.abs(np.cross(uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0])).sum() for uv in on) * w * h
        assert page == len(layout.sizes) - 1 or texels > 0.25 * w * h


def test_a_mesh_too_large_for_a_page_is_scaled_down_onto_one_alone(tmp_path):
    pos, tris = _box()
    layout, = unwrap([[ChartMesh("small", pos * 0.3, tris, 20.0), ChartMesh("huge", pos * 4.0, tris, 20.0)]],
                     max_size=128, padding=2, cache_dir=tmp_path)
    assert layout.density[0] == 20.0 and layout.density[1] < 20.0
    assert all(max(size) <= 128 for size in layout.sizes)


def test_one_page_lowers_the_density_until_everything_fits(tmp_path):
    pos, tris = _box(2.0)
    layout, = unwrap([[ChartMesh("box", pos, tris, 200.0), ChartMesh("box2", pos * 0.5, tris, 200.0)]],
                     max_size=64, padding=2, many=False, cache_dir=tmp_path)
    (w, h), = layout.sizes
    assert max(w, h) <= 64 and layout.page == [0, 0]
    assert layout.density[0] == layout.density[1] < 200.0


def _wobbly_torus():
    """A torus of quads bent in and out five times round (m): xatlas cuts some of its quads by a
    seam. (positions, triangles, face corners of each triangle: a quad's two share two)."""
    pos, nrm, tris = shapes.torus(around=32, tube=16, inward=False)
    pos = pos + 0.15 * nrm * np.sin(5 * np.arctan2(pos[:, 1], pos[:, 0]))[:, None]
    q = np.arange(len(tris) // 2)[:, None] * 4
    return pos, tris, np.concatenate([q + [0, 1, 2], q + [0, 2, 3]])


def _cut(tri_uv: np.ndarray, corners: np.ndarray) -> int:
    """How many triangles disagree with another of their polygon on a shared corner's UV."""
    uv = np.zeros((corners.max() + 1, 2))
    uv[corners.ravel()] = tri_uv.reshape(-1, 2)
    return int((np.abs(uv[corners] - tri_uv) > 1e-6).any(axis=(1, 2)).sum())


def test_a_polygon_cut_by_a_chart_seam_is_kept_whole_in_one_chart_without_overlap(tmp_path):
    pos, tris, corners = _wobbly_torus()
    density, padding = 20.0, 2
    apart, = unwrap([[ChartMesh("torus", pos, tris, density)]], 256, padding, cache_dir=tmp_path)
    assert _cut(apart.tri_uv[0], corners) > 0  # xatlas alone cuts quads: the case is met
    layout, = unwrap([[ChartMesh("torus", pos, tris, density, corners)]], 256, padding, cache_dir=tmp_path)
    (w, h), = layout.sizes
    tri_uv = layout.tri_uv[0]
    assert _cut(tri_uv, corners) == 0  # one UV per face corner: what Blender's UV map holds
    _overlap_free(tri_uv, w, h, padding)
    # the moved triangles are laid flat beside their chart, not stretched across the page
    uv = tri_uv.astype(np.float64) * (w, h)
    p = pos.astype(np.float64)[tris]
    stretch = (np.linalg.norm(uv - np.roll(uv, 1, axis=1), axis=2).max(axis=1)
               / (density * np.linalg.norm(p - np.roll(p, 1, axis=1), axis=2).max(axis=1)))
    assert stretch.max() < 2.0
    signed = np.cross(uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0])
    labels = _charts(tri_uv)
    for c in np.unique(labels):  # a chart may be mirrored as a whole, no triangle within it
        assert len(np.unique(np.sign(signed[labels == c]))) == 1


def test_one_page_too_small_for_the_charts_at_any_scale_is_an_error_not_charts_laid_over_each_other(tmp_path):
    pos, tris = _box()
    meshes = [ChartMesh(f"box{k}", pos + np.float32(2 * k), tris, 8.0) for k in range(30)]  # 180 charts
    with pytest.raises(BakeError, match="180 charts 2 texels apart do not fit a page of 64 texels"):
        unwrap([meshes], max_size=64, padding=2, many=False, cache_dir=tmp_path)
    layout, = unwrap([meshes], max_size=96, padding=2, many=False, cache_dir=tmp_path)
    (w, h), = layout.sizes
    _overlap_free(np.concatenate(layout.tri_uv), w, h, 2)


def _one_triangle_charts(count: int) -> tuple:
    """A worker's UV mesh of ``count`` one-triangle charts of a texel each (texels)."""
    uv = (np.arange(3 * count)[:, None] // 3 * 2.0 + np.tile([[0, 0], [1, 0], [0, 1]], (count, 1))).astype(np.float32)
    return uv, np.arange(3 * count, dtype=np.uint32).reshape(count, 3), np.repeat(np.arange(count), 3).astype(np.int32)


class _Atlas:
    """What ``_one_page`` reads of an xatlas atlas: one page of ``side`` texels holding
    ``charts`` charts of one sound triangle."""

    def __init__(self, charts: int, side: int):
        self.chart_count, self.atlas_count, self.width, self.height = charts, 1, side, side

    def __getitem__(self, k):
        return None, np.array([[0, 1, 2]], np.uint32), np.array([[0, 0], [1, 0], [0, 1]], np.float32)


def test_charts_that_cannot_each_keep_a_texel_and_their_padding_are_refused_before_packing(monkeypatch):
    from radiosity_baker.core.lightmap import _xatlas_worker as worker

    mesh = _one_triangle_charts(851)  # the level's charts on a 128 page
    assert worker._below_floor([mesh], 128, 2) and not worker._below_floor([mesh], 128, 1)

    def never(*args):
        raise AssertionError("packed although no scale fits")

    monkeypatch.setattr(worker, "_layout", never)
    assert worker._one_page([mesh], [1.0], 128, 2) is None
    assert worker._fits_alone(mesh, 128, 2) is None


def test_a_layout_whose_charts_xatlas_drops_while_shrinking_them_is_refused(monkeypatch):
    from radiosity_baker.core.lightmap import _xatlas_worker as worker

    tries = iter([_Atlas(10, 300), _Atlas(6, 100)])  # too large, then fits: with 4 charts dropped
    monkeypatch.setattr(worker, "_layout", lambda *args: next(tries))
    assert worker._one_page([_one_triangle_charts(10)], [1.0], 128, 2) is None
    tries = iter([_Atlas(10, 300), _Atlas(10, 100)])  # the same charts all kept: it fits
    monkeypatch.setattr(worker, "_layout", lambda *args: next(tries))
    atlas, scale = worker._one_page([_one_triangle_charts(10)], [1.0], 128, 2)
    assert atlas.chart_count == 10 and scale < 1.0


def test_nan_and_zero_area_triangles_are_left_out(tmp_path):
    p, _, t = shapes.grid(1.0, 4)
    p = np.concatenate([p, [[np.nan, 0, 0]]]).astype(np.float32)
    t = np.concatenate([t, [[0, 1, len(p) - 1], [0, 0, 1]]]).astype(np.int32)
    layout, = unwrap([[ChartMesh("plane", p, t, 16.0)]], 256, 2, cache_dir=tmp_path)
    ok = np.isfinite(layout.tri_uv[0]).all(axis=(1, 2))
    assert ok[:-2].all() and not ok[-2:].any()


def test_a_mesh_without_area_is_an_error_naming_it(tmp_path):
    p = np.zeros((3, 3), np.float32)
    with pytest.raises(BakeError, match="Flat"):
        unwrap([[ChartMesh("Flat", p, np.array([[0, 1, 2]], np.int32), 16.0)]], 256, 2, cache_dir=tmp_path)


@pytest.mark.parametrize("density", [20.0, 1000.0, 1e5])
def test_millimetre_meshes_get_charts_and_texels_at_any_density(tmp_path, density):
    pos, tris = _box(0.002)  # 2 mm: xatlas alone drops every face of it
    layout, = unwrap([[ChartMesh("screw", pos, tris, density), ChartMesh("nut", pos * 0.5 + 0.01, tris, density)]],
                     1024, 2, cache_dir=tmp_path)
    dev = device.select("cpu")
    for tri_uv, page in zip(layout.tri_uv, layout.page):
        w, h = layout.sizes[page]
        assert np.isfinite(tri_uv).all() and tri_uv.min() >= 0.0 and tri_uv.max() <= 1.0
        assert raster.rasterize(tri_uv, w, h, dev).count > 0


def test_a_mesh_far_smaller_than_the_others_of_its_page_still_gets_texels(tmp_path):
    pos, tris = _box()
    layout, = unwrap([[ChartMesh("box", pos, tris, 16.0), ChartMesh("box2", pos + 3, tris, 16.0),
                       ChartMesh("Speck", pos * 1e-4, tris, 16.0)]], 256, 2, cache_dir=tmp_path)
    w, h = layout.sizes[layout.page[2]]
    assert raster.rasterize(layout.tri_uv[2], w, h, device.select("cpu")).count > 0


def test_results_are_cached_per_mesh_content(tmp_path):
    pos, tris = _box()
    first, = unwrap([[ChartMesh("box", pos, tris, 16.0)]], 256, 2, cache_dir=tmp_path)
    # A cache hit never starts the worker: a missing interpreter does not matter then.
    again, = unwrap([[ChartMesh("box", pos, tris, 16.0)]], 256, 2, python="/nonexistent/python",
                    cache_dir=tmp_path)
    np.testing.assert_array_equal(first.tri_uv[0], again.tri_uv[0])
    with pytest.raises(BakeError, match="cannot start the UV unwrapper"):
        unwrap([[ChartMesh("box", pos * 1.01, tris, 16.0)]], 256, 2, python="/nonexistent/python",
               cache_dir=tmp_path)


def test_pages_too_large_for_memory_stop_before_unwrapping_with_a_density_that_fits(monkeypatch):
    """A 2 m × 2 m floor at 10⁴ texels/m would take 4·10⁸ texels; with 1 GB to use the check says
    which density fits, and that density passes (while a tenth more does not)."""
    from radiosity_baker.core import Settings
    from radiosity_baker.core.errors import SettingsError
    from radiosity_baker.core.lightmap import LightmapObject, budget

    p, n, t = shapes.grid(2.0, 4)
    scene = shapes.scene([(p, n, t, (0.5,) * 3, (0,) * 3)])
    target = LightmapObject("floor", "floor", corner_vert=t.ravel().astype(np.int32),
                            corner_triangles=np.arange(t.size, dtype=np.int32).reshape(-1, 3),
                            triangle_offset=0)
    monkeypatch.setattr(budget, "memory_budget", lambda: 1 << 30)
    settings = Settings(target="lightmap", texel_density=1e4, max_size=16384)
    with pytest.raises(SettingsError, match="texel density of") as info:
        budget.check([target], scene, settings)
    fits = float(str(info.value).rsplit("texel density of ", 1)[1].split()[0])
    assert 100 < fits < 1e4
    settings.texel_density = fits
    assert budget.check([target], scene, settings) * budget.BYTES_PER_TEXEL <= 1 << 30
    settings.texel_density = 1.1 * fits
    with pytest.raises(SettingsError):
        budget.check([target], scene, settings)


@pytest.mark.parametrize("many", [True, False])
def test_a_page_too_small_for_the_padding_names_the_mesh_and_the_padding_that_fits(tmp_path, many):
    pos, tris = _box()
    meshes = [ChartMesh("crate", pos, tris, 20.0), ChartMesh("lid", pos * 0.5, tris, 20.0)]
    with pytest.raises(BakeError, match="padding of") as info:
        unwrap([meshes], max_size=16, padding=4, many=many, cache_dir=tmp_path)
    message = str(info.value)
    assert "crate" in message and ("lid" in message) != many  # the mesh, or all on the one page
    padding = int(message.rsplit("--padding ", 1)[1].split(")")[0])
    assert 1 <= padding < 4
    layout, = unwrap([meshes], max_size=16, padding=padding, many=many, cache_dir=tmp_path)
    assert all(max(size) <= 16 for size in layout.sizes)


def _hanging_python(tmp_path, hangs: int) -> str:
    """An interpreter for the workers whose first ``hangs`` runs never end (as xatlas now and then
    does) and whose later runs are this Python's; each run leaves a line in ``runs``."""
    import sys

    script = tmp_path / "python"
    script.write_text(f"#!/bin/sh\necho run >> {tmp_path / 'runs'}\n"
                      f"if [ $(wc -l < {tmp_path / 'runs'}) -le {hangs} ]; then exec sleep 600; fi\n"
                      f"exec {sys.executable} \"$@\"\n")
    script.chmod(0o755)
    return str(script)


def test_a_worker_that_hangs_is_killed_and_started_again_and_its_layout_is_the_same(tmp_path, monkeypatch):
    from radiosity_baker.core.lightmap import unwrap as module

    monkeypatch.setattr(module, "WORKER_SECONDS", 2.0)
    monkeypatch.setattr(module, "WORKER_SECONDS_PER_TRIANGLE", 0.0)
    p, _, t = shapes.grid(1.0, 4)
    mesh = [[ChartMesh("plane", p, t, 16.0)]]
    expected, = unwrap(mesh, 64, 2, cache_dir=tmp_path / "a")
    got, = unwrap(mesh, 64, 2, cache_dir=tmp_path / "b", python=_hanging_python(tmp_path, 1))
    assert (tmp_path / "runs").read_text().count("run") == 3  # charts: hung, then again; pack
    assert got.sizes == expected.sizes
    np.testing.assert_array_equal(got.tri_uv[0], expected.tri_uv[0])


def test_a_worker_that_hangs_every_time_is_an_error_naming_the_time_limit(tmp_path, monkeypatch):
    import time

    from radiosity_baker.core.lightmap import unwrap as module

    monkeypatch.setattr(module, "WORKER_SECONDS", 1.0)
    monkeypatch.setattr(module, "WORKER_SECONDS_PER_TRIANGLE", 0.0)
    p, _, t = shapes.grid(1.0, 4)
    start = time.monotonic()
    with pytest.raises(BakeError, match=r"did not finish within 1 s, 2 times, for 1 mesh: xatlas hung"):
        unwrap([[ChartMesh("plane", p, t, 16.0)]], 64, 2, cache_dir=tmp_path / "c",
               python=_hanging_python(tmp_path, 10))
    assert time.monotonic() - start < 30
    assert (tmp_path / "runs").read_text().count("run") == 2
    assert not list((tmp_path / "c").glob("rb-xatlas-*"))  # its temporary folder is gone
