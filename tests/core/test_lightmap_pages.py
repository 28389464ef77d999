"""Per-texel lighting against the per-vertex solution, coverage, dilation, seams, EXR, layouts."""
import numpy as np
import pytest

import shapes
from radiosity_baker.core import Settings, bake
from harness import metrics
from radiosity_baker.core.lightmap import LightmapRequest, LightmapObject, files
from radiosity_baker.core.lightmap.pages import bilinear, dilate
from radiosity_baker.core.scene import LAMP_POINT


def _targets(sc, parts, names=None, mesh_names=None, corner_uv=None):
    """A LightmapObject per part of a shapes.scene (each triangle corner its own face corner)."""
    out, t0 = [], 0
    for k, part in enumerate(parts):
        nt = part[2].shape[0]
        vertex = sc.triangles[t0:t0 + nt].ravel().astype(np.int32)
        name = names[k] if names else f"part{k}"
        out.append(LightmapObject(name, mesh_names[k] if mesh_names else name,
                                  corner_vert=(vertex - vertex.min()).astype(np.int32),
                                  corner_triangles=np.arange(3 * nt, dtype=np.int32).reshape(nt, 3),
                                  triangle_offset=t0,
                                  corner_uv=None if corner_uv is None else corner_uv[k]))
        t0 += nt
    return out


def _corner_values(result, target):
    """float32[C,3]: the bake's per-vertex output at each face corner of ``target`` (_targets)."""
    nt = target.corner_triangles.shape[0]
    return result.output[result.shading.corner[target.triangle_offset:target.triangle_offset + nt].ravel()]


def _room():
    """A 2 m floor and a 2 m wall at its −x edge facing +x, lit by a point lamp: direct light and
    one bounce of indirect light on both."""
    fp, fn, ft = shapes.grid(2.0, 8)
    wp_, wn, wt = shapes.grid(2.0, 8)
    rot = np.array([[0, 0, 1], [0, 1, 0], [-1, 0, 0]], np.float32)  # +z → +x
    wp_ = wp_ @ rot.T + np.array([-1.0, 0.0, 1.0], np.float32)
    wn = wn @ rot.T
    parts = [(fp, fn, ft, (0.8, 0.6, 0.4), (0, 0, 0)), (wp_, wn, wt, (0.5, 0.5, 0.5), (0, 0, 0))]
    sc = shapes.scene(parts, shapes.lamp(LAMP_POINT, (0.3, 0.2, 1.2), power=(200.0,) * 3))
    return sc, parts


@pytest.fixture(scope="module")
def room_bake(tmp_path_factory):
    sc, parts = _room()
    # interpolation alone: texels then hold exactly the solution at the vertices (the final
    # gather's detail is tested below)
    settings = Settings(method="reference", light_samples=1, visibility_rays=4, texel_density=24.0,
                        padding=3, device="cpu", texel_indirect="interpolate")
    request = LightmapRequest(_targets(sc, parts), cache_dir=tmp_path_factory.mktemp("cache"))
    return sc, parts, bake(sc, settings, targets=shapes.with_lightmap(request))


def test_lightmap_matches_the_per_vertex_solution_at_the_vertices(room_bake):
    sc, parts, r = room_bake
    page, = r["lightmap"].pages
    assert page.objects == ["part0", "part1"] and r.counts["texels"] == page.covered.sum()
    assert {"unwrap", "raster", "texel direct"} <= set(r.timings)
    assert r.indirect.max() > 0.05 * r.lighting.max()  # the wall and floor light each other
    for k, name in enumerate(page.objects):
        target = _targets(sc, parts)[k]
        at_vertices = bilinear(page.rgb, r["lightmap"].uv[name])
        expected = _corner_values(r, target)
        error = np.abs(at_vertices - expected).max() / expected.max()
        assert error < 0.01, (name, error)


def test_every_covered_texel_is_finite_and_non_negative_and_padding_is_filled(room_bake):
    _, _, r = room_bake
    page, = r["lightmap"].pages
    assert np.isfinite(page.rgb).all() and (page.rgb >= 0).all()
    lit = page.rgb.max(axis=2) > 0
    assert page.covered.any() and (lit | ~page.covered).all()
    # every texel within the padding (3) of a chart was dilated: 8-neighbours of covered texels
    grown = np.zeros_like(page.covered)
    h, w = grown.shape
    ys, xs = np.nonzero(page.covered)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            grown[np.clip(ys + dy, 0, h - 1), np.clip(xs + dx, 0, w - 1)] = True
    assert lit[grown].all()


def test_combined_is_emission_plus_albedo_times_lighting_per_texel(tmp_path):
    sc, parts = _room()
    common = dict(method="direct", light_samples=1, texel_density=16.0, device="cpu")
    pages = {}
    for content in ("lighting", "combined"):
        req = LightmapRequest(_targets(sc, parts)[:1], cache_dir=tmp_path)
        pages[content] = bake(sc, Settings(content=content, **common), targets=shapes.with_lightmap(req))["lightmap"].pages[0]
    cov = pages["lighting"].covered
    np.testing.assert_allclose(pages["combined"].rgb[cov], pages["lighting"].rgb[cov] * (0.8, 0.6, 0.4),
                               rtol=1e-5, atol=1e-7)


def test_dilation_grows_charts_ring_by_ring_with_the_mean_of_their_neighbours():
    rgb = np.zeros((9, 9, 3), np.float32)
    covered = np.zeros((9, 9), bool)
    covered[4, 2:7] = True
    rgb[4, 2:7] = np.arange(1, 6)[:, None]
    out = dilate(rgb, covered, 2)
    assert out[3, 4, 0] == pytest.approx(3.0)             # above the middle: mean of 2, 3, 4
    assert out[4, 1, 0] == pytest.approx(1.0)             # left end
    assert out[2, 4, 0] > 0 and out[1, 4, 0] == 0.0       # two rings, no more
    np.testing.assert_array_equal(out[covered], rgb[covered])


@pytest.mark.parametrize("precision, dtype", [("half", np.float16), ("float", np.float32)])
def test_exr_round_trip_is_exact_at_the_stored_precision(tmp_path, precision, dtype):
    rng = np.random.default_rng(3)
    rgb = (rng.random((13, 17, 3)) * 20.0).astype(np.float32)
    path = tmp_path / "page.exr"
    files.write_exr(path, rgb, precision)
    back = files.read_exr(path)
    np.testing.assert_array_equal(back[..., :3], rgb.astype(dtype).astype(np.float32))
    assert (back[..., 3] == 1.0).all()
    files.write_preview(tmp_path / "page.png", rgb)
    png = files.read_exr(tmp_path / "page.png")
    assert png.shape == (13, 17, 3) and 0.0 <= png.min() and png.max() <= 1.0


# Smooth UV seams on a lit sphere: both sides of a seam edge sampled bilinearly differ by less
# than this fraction of the brightest texel (texel centres on the two sides sit up to ~0.7 texel
# apart on the surface, so the lighting gradient sets the scale).
SEAM_BOUND = 0.05


def test_both_sides_of_smooth_uv_seams_agree(tmp_path):
    p, n, t = shapes.icosphere(0.5, 3, inward=False)
    parts = [(p, n, t, (0.5,) * 3, (0,) * 3)]
    sc = shapes.scene(parts, shapes.lamp(LAMP_POINT, (0.0, 0.4, 1.5), power=(100.0,) * 3))
    settings = Settings(method="direct", light_samples=1, texel_density=64.0, device="cpu")
    r = bake(sc, settings, targets=shapes.with_lightmap(LightmapRequest(_targets(sc, parts), cache_dir=tmp_path)))
    print(f"largest seam difference: {r['lightmap'].seam_error:.4f} of the brightest texel")
    assert 0.0 < r["lightmap"].seam_error < SEAM_BOUND


def test_layouts_shared_meshes_and_reused_uvs(tmp_path):
    sc, parts = _room()
    common = dict(method="direct", light_samples=1, texel_density=16.0, device="cpu")
    # two objects sharing one mesh: in an atlas only the first, per object one page each
    shared = _targets(sc, parts[:1], names=["A"]) + _targets(sc, parts[:1], names=["B"], mesh_names=["A"])
    r = bake(sc, Settings(**common), targets=shapes.with_lightmap(LightmapRequest(shared, cache_dir=tmp_path)))
    assert [p.objects for p in r["lightmap"].pages] == [["A"]]
    assert any("shared by A, B" in w for w in r.warnings)
    r = bake(sc, Settings(layout="per_object", **common),
             targets=shapes.with_lightmap(LightmapRequest(shared, cache_dir=tmp_path)))
    assert [p.name for p in r["lightmap"].pages] == ["Lightmap_A", "Lightmap_B"]
    assert list(r["lightmap"].uv) == ["A"]
    np.testing.assert_array_equal(r["lightmap"].pages[0].rgb, r["lightmap"].pages[1].rgb)
    # existing UVs are kept (nothing new to write) and sized by the density
    uv = r["lightmap"].uv["A"]
    kept = _targets(sc, parts[:1], corner_uv=[uv])
    r2 = bake(sc, Settings(**common), targets=shapes.with_lightmap(LightmapRequest(kept, cache_dir=tmp_path)))
    assert r2["lightmap"].uv == {} and r2["lightmap"].pages[0].name == "Lightmap"
    assert abs(r2["lightmap"].pages[0].density - 16.0) / 16.0 < 0.15
    r3 = bake(sc, Settings(reunwrap=True, **common), targets=shapes.with_lightmap(LightmapRequest(kept, cache_dir=tmp_path)))
    assert list(r3["lightmap"].uv) == ["part0"]


def test_supersampling_keeps_the_page_and_the_values(tmp_path):
    sc, parts = _room()
    common = dict(method="direct", light_samples=1, texel_density=16.0, device="cpu")
    pages = [bake(sc, Settings(supersample=s, **common),
                  targets=shapes.with_lightmap(LightmapRequest(_targets(sc, parts)[:1], cache_dir=tmp_path)))["lightmap"].pages[0]
             for s in (1, 3)]
    assert pages[0].size == pages[1].size
    inner = pages[0].covered & pages[1].covered
    diff = np.abs(pages[0].rgb[inner] - pages[1].rgb[inner]).max() / pages[0].rgb.max()
    assert diff < 0.05


def test_ao_lightmap_matches_per_vertex_ao_at_the_vertices(tmp_path):
    sc, parts = _room()
    settings = Settings(method="direct", content="ao", ao_distance=1.0, texel_density=16.0, device="cpu")
    r = bake(sc, settings, targets=shapes.with_lightmap(LightmapRequest(_targets(sc, parts), cache_dir=tmp_path)))
    page, = r["lightmap"].pages
    assert "texel ao" in r.timings and "texel direct" not in r.timings
    cov = page.rgb[page.covered]
    assert (cov >= 0).all() and (cov <= 1.0 + 1e-5).all() and cov.min() < 0.9
    target = _targets(sc, parts)[0]
    at_vertices = bilinear(page.rgb, r["lightmap"].uv["part0"])
    error = np.abs(at_vertices - _corner_values(r, target))
    # AO falls to 0.5 in the crease where floor meets wall, within a texel: vertices on the crease
    # differ most from the texel centres next to it.
    assert error.mean() < 0.005 and error.max() < 0.15


def _wall_and_floor(floor_quads: int):
    """A bright 2 m wall at x = −1 facing +x, lit by a point lamp near it, over a 2 m floor of
    ``floor_quads``² quads: the floor's indirect light falls off steeply away from the wall."""
    fp, fn, ft = shapes.grid(2.0, floor_quads)
    wp_, wn, wt = shapes.grid(2.0, 8)
    rot = np.array([[0, 0, 1], [0, 1, 0], [-1, 0, 0]], np.float32)  # +z → +x
    wp_ = wp_ @ rot.T + np.array([-1.0, 0.0, 1.0], np.float32)
    parts = [(fp, fn, ft, (0.5, 0.5, 0.5), (0, 0, 0)), (wp_, wn @ rot.T, wt, (0.9, 0.9, 0.9), (0, 0, 0))]
    return shapes.scene(parts, shapes.lamp(LAMP_POINT, (-0.7, 0.0, 1.0), power=(300.0,) * 3)), parts


def _floor_texels_at(points_xy, floor_pos, floor_tris, page, corner_uv):
    """The lightmap's values (bilinear, as a GPU samples) at floor points float[N,2]: each point
    is carried to the UVs through its triangle's barycentric coordinates."""
    a, b, c = (floor_pos[floor_tris[:, k], :2].astype(np.float64) for k in range(3))
    e1, e2, rel = b - a, c - a, points_xy[:, None, :] - a[None]
    det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    u = (rel[..., 0] * e2[:, 1] - rel[..., 1] * e2[:, 0]) / det
    v = (e1[:, 0] * rel[..., 1] - e1[:, 1] * rel[..., 0]) / det
    inside = (u >= -1e-9) & (v >= -1e-9) & (u + v <= 1 + 1e-9)
    t = inside.argmax(axis=1)
    k = np.arange(len(points_xy))
    u, v = u[k, t], v[k, t]
    uv = corner_uv.reshape(-1, 3, 2)[t].astype(np.float64)
    at = (1 - u - v)[:, None] * uv[:, 0] + u[:, None] * uv[:, 1] + v[:, None] * uv[:, 2]
    return bilinear(page.rgb, at)


def test_final_gather_brings_indirect_detail_finer_than_the_mesh_into_texels(tmp_path):
    """A floor of 2×2 quads cannot hold the steep fall-off of the wall's bounce light in its 9
    vertices; the texels' final gather over the hierarchy restores it. Truth: the reference
    solver's per-vertex indirect light on the same floor made of 24×24 quads."""
    fine, fine_parts = _wall_and_floor(24)
    settings = Settings(method="reference", content="indirect", light_samples=4, texel_density=32.0,
                        padding=2, device="cpu")
    truth = bake(fine, settings).output[:len(fine_parts[0][0])]
    inner = np.all(np.abs(fine_parts[0][0][:, :2]) < 0.9, axis=1)  # away from the floor's border
    points, truth = fine_parts[0][0][inner, :2], truth[inner]

    coarse, parts = _wall_and_floor(2)
    errors = {}
    for mode in ("interpolate", "gather"):
        s = Settings(**{**settings.as_dict(), "texel_indirect": mode, "target": "lightmap"})
        r = bake(coarse, s, targets=shapes.with_lightmap(LightmapRequest(_targets(coarse, parts),
                                                     cache_dir=tmp_path / "cache")))
        assert ("texel gather" in r.timings) == (mode == "gather")
        page, = r["lightmap"].pages
        ours = _floor_texels_at(points, parts[0][0], parts[0][2], page, r["lightmap"].uv["part0"])
        errors[mode] = metrics.relative_rmse(ours, truth)
    print(f"\nfloor indirect vs the fine reference, relative RMSE: {errors}")
    assert errors["interpolate"] > 0.1  # the coarse mesh really misses it
    assert errors["gather"] < 0.5 * errors["interpolate"]


def test_an_atlas_too_large_for_one_page_becomes_a_udim_tile_set_each_object_on_one_tile(tmp_path):
    sc, targets = shapes.crates()
    targets[1].density = 36.0  # an object with its own density
    settings = Settings(method="direct", light_samples=1, texel_density=30.0, max_size=128, padding=2,
                        device="cpu")
    r = bake(sc, settings, targets=shapes.with_lightmap(LightmapRequest(targets, cache_dir=tmp_path)))
    pages = r["lightmap"].pages
    assert len(pages) > 1 and {p.name for p in pages} == {"Lightmap"}
    assert [p.tile for p in pages] == list(range(1001, 1001 + len(pages)))
    assert [p.stem for p in pages][:2] == ["Lightmap.1001", "Lightmap.1002"]
    assert sorted(o for p in pages for o in p.objects) == sorted(t.object_name for t in targets)
    for page in pages:
        assert page.size == (128, 128)
        for name in page.objects:  # its UVs lie in its tile: u in [k, k + 1)
            uv = r["lightmap"].uv[name]
            assert np.floor(uv[:, 0].min()) == np.floor(uv[:, 0].max() - 1e-6) == page.tile - 1001
            assert 0.0 <= uv[:, 1].min() and uv[:, 1].max() <= 1.0
        assert page.covered.any() and (page.rgb[page.covered] > 0).any()
    report = r.counts["lightmap"]
    assert report["density"]["crate1"] == {"asked": 36.0, "used": 36.0, "note": "as asked"}
    assert all(d["note"] == "as asked" for d in report["density"].values())
    assert [p["tile"] for p in report["pages"]] == [p.tile for p in pages]


def test_one_page_lowers_the_density_and_says_so(tmp_path):
    sc, targets = shapes.crates()
    settings = Settings(method="direct", light_samples=1, texel_density=32.0, max_size=128, padding=2,
                        atlas_pages="one", device="cpu")
    r = bake(sc, settings, targets=shapes.with_lightmap(LightmapRequest(targets, cache_dir=tmp_path)))
    page, = r["lightmap"].pages
    assert page.tile is None and max(page.size) <= 128 and page.density < 32.0
    assert {d["note"] for d in r.counts["lightmap"]["density"].values()} == {"lowered"}
    assert any("would not fit 128² texels with the others" in w for w in r.warnings)
