"""Directional lightmaps (``--directional sh``): each texel's L1 points where its light comes from,
L0 is the plain lightmap, and L0 + L1 · (n' − n) is the lighting a tilted surface gets."""
import dataclasses
import math

import numpy as np
import pytest

import shapes
from radiosity_baker.core import Settings, bake, directional, receivers, targets
from radiosity_baker.core.lightmap import LightmapObject, LightmapRequest
from radiosity_baker.core.scene import LAMP_POINT, LAMP_SUN, Lamps

LUMINANCE = np.array([0.2126, 0.7152, 0.0722])


def _planar(sc, parts, tmp_path) -> LightmapRequest:
    """Every part lightmapped through its own planar UVs (x, y over the 2 m square; no unwrap)."""
    objects, t0 = [], 0
    for k, part in enumerate(parts):
        nt = part[2].shape[0]
        corners = sc.triangles[t0:t0 + nt].ravel()
        p = sc.positions[corners]
        uv = (p[:, :2] / 2.0 + 0.5) if abs(part[1][0, 2]) > 0.5 else (p[:, 1:] / 2.0 + 0.5)
        objects.append(LightmapObject(f"part{k}", f"part{k}", corner_vert=(corners - corners.min()).astype(np.int32),
                                      corner_triangles=np.arange(3 * nt, dtype=np.int32).reshape(nt, 3),
                                      triangle_offset=t0, corner_uv=uv.astype(np.float32)))
        t0 += nt
    return LightmapRequest(objects[:1], cache_dir=tmp_path)


def _suns(*directions) -> Lamps:
    lamps = [shapes.lamp(LAMP_SUN, direction=d, power=(3.0,) * 3) for d in directions]
    return Lamps(**{f: np.concatenate([getattr(l, f) for l in lamps]) if f != "names" else
                    [f"Sun{k}" for k in range(len(lamps))] for f in vars(lamps[0])})


def _floor_under(lamps, tmp_path, directional="sh"):
    p, n, t = shapes.grid(2.0, 6)
    parts = [(p, n, t, (0.5, 0.5, 0.5), (0,) * 3)]
    sc = shapes.scene(parts, lamps)
    settings = Settings(method="direct", device="cpu", light_samples=4, texel_density=8.0, padding=2,
                        directional=directional)
    return bake(sc, settings, targets=[targets.make("lightmap", _planar(sc, parts, tmp_path))])["lightmap"]


def _covered_l1(page):
    """float64[T,3] luminance L1 and float64[T] luminance L0 of a page's covered texels."""
    l1 = page.l1[page.covered].reshape(-1, 3, 3).astype(np.float64)  # [T, xyz, rgb]
    return l1 @ LUMINANCE, page.rgb[page.covered].astype(np.float64) @ LUMINANCE


def test_l1_points_at_a_distant_lamp(tmp_path):
    towards = np.array([math.sin(math.radians(35)), 0.0, math.cos(math.radians(35))])
    page = _floor_under(_suns(-towards), tmp_path).pages[0]
    l1, l0 = _covered_l1(page)
    angle = np.degrees(np.arccos(np.clip(l1 @ towards / np.linalg.norm(l1, axis=1), -1, 1)))
    print(f"direction error: largest {angle.max():.3f}°, mean {angle.mean():.3f}°; "
          f"|L1|/L0 {np.median(np.linalg.norm(l1, axis=1) / l0):.4f}")
    assert angle.max() < 5.0
    # the L1 of one sun at 35° is the light over cos 35° along its direction
    np.testing.assert_allclose(np.linalg.norm(l1, axis=1), l0 / math.cos(math.radians(35)), rtol=1e-3)


def test_l0_is_the_plain_lightmap(tmp_path):
    lamps = _suns((-0.3, 0.2, -1.0))
    plain = _floor_under(lamps, tmp_path / "plain", directional="none").pages[0]
    sh = _floor_under(lamps, tmp_path / "sh").pages[0]
    assert plain.l1 is None and sh.l1.shape == plain.rgb.shape[:2] + (9,)
    np.testing.assert_array_equal(sh.rgb, plain.rgb)


def test_light_from_two_opposite_sides_leaves_no_direction_along_the_floor(tmp_path):
    a = np.array([math.sin(math.radians(40)), 0.0, math.cos(math.radians(40))])
    b = a * np.array([-1.0, 1.0, 1.0])
    page = _floor_under(_suns(-a, -b), tmp_path).pages[0]
    l1, l0 = _covered_l1(page)
    along = np.linalg.norm(l1[:, :2], axis=1) / l0
    one = _covered_l1(_floor_under(_suns(-a), tmp_path / "one").pages[0])
    one_along = np.linalg.norm(one[0][:, :2], axis=1) / one[1]
    print(f"L1 along the floor / L0: two opposite suns {along.max():.2e}, one sun {one_along.mean():.4f}")
    assert along.max() < 0.01 and one_along.min() > 0.8  # tan 40° = 0.84




def _tilted(tmp_path):
    """A black floor beside a lit grey wall (x = −1, facing +x) under a point lamp: direct light from
    above, bounce light from the −x side. Per floor texel: the lighting L0 + L1 · (n' − n) predicts
    at a normal n' tilted 30° towards the wall, and the lighting baked there."""
    from radiosity_baker.core.targets import lightmap

    tilt = math.radians(30)
    tilted_normal = np.array([-math.sin(tilt), 0.0, math.cos(tilt)], np.float32)

    class Tilted(lightmap.Target):
        def finish(self, problem, at, light):
            l1 = directional.texel_l1(problem, at, light)
            predicted = light.output + np.einsum("rcj,j->rc", l1, tilted_normal - at.normals[0])
            grid = dataclasses.replace(at, normals=np.tile(tilted_normal, (len(at), 1)), grids=None,
                                       label="tilted")
            baked = receivers.light_at(problem, *light.solved, grid)
            return predicted, baked.output, light

    fp, fn, ft = shapes.grid(2.0, 8)
    wp_, wn, wt = shapes.grid(2.0, 8)
    rot = np.array([[0, 0, 1], [0, 1, 0], [-1, 0, 0]], np.float32)  # +z → +x
    wp_, wn = wp_ @ rot.T + np.array([-1.0, 0.0, 1.0], np.float32), wn @ rot.T
    parts = [(fp, fn, ft, (0.0, 0.0, 0.0), (0,) * 3), (wp_, wn, wt, (0.8, 0.8, 0.8), (0,) * 3)]
    sc = shapes.scene(parts, shapes.lamp(LAMP_POINT, (0.3, 0.2, 1.2), power=(200.0,) * 3))
    settings = Settings(method="reference", device="cpu", light_samples=4, visibility_rays=4,
                        texel_density=8.0, padding=2, directional="sh")
    target = Tilted(_planar(sc, parts, tmp_path))
    target.name = "tilted"
    return bake(sc, settings, targets=[target])["tilted"]


def test_l1_predicts_the_lighting_of_a_tilted_surface(tmp_path):
    predicted, baked, light = _tilted(tmp_path)
    lum_p, lum_b = predicted @ LUMINANCE, baked @ LUMINANCE
    error = np.sqrt(np.mean((lum_p - lum_b) ** 2)) / np.mean(lum_b)
    flat = np.sqrt(np.mean((light.output @ LUMINANCE - lum_b) ** 2)) / np.mean(lum_b)
    share = np.mean(light.indirect @ LUMINANCE) / np.mean(light.output @ LUMINANCE)
    print(f"tilted 30°: relative RMS error {error:.4f} (the plain lightmap's: {flat:.4f}); "
          f"indirect share {share:.3f}")
    assert error < 0.03 and flat > 3 * error


def test_the_directional_exr_holds_l0_and_l1_channels(tmp_path):
    from radiosity_baker.core.lightmap import files

    page = _floor_under(_suns((-0.3, 0.2, -1.0)), tmp_path).pages[0]
    path = tmp_path / "Lightmap.sh.exr"
    files.write_directional_exr(path, page.rgb, page.l1, "float")
    import OpenImageIO as oiio
    spec = oiio.ImageInput.open(str(path)).spec()
    assert tuple(spec.channelnames) == files.DIRECTIONAL_CHANNELS
    back = files.read_exr(path)
    np.testing.assert_array_equal(back[..., :3], page.rgb)
    np.testing.assert_array_equal(back[..., 3:], page.l1)


def test_engine_layouts_decode_to_l0_at_the_texel_normal_and_half_the_l1_tilt_beside_it():
    rng = np.random.default_rng(3)
    n = rng.normal(size=(4, 5, 3))
    n /= np.linalg.norm(n, axis=2, keepdims=True)
    l0 = rng.uniform(0.1, 2.0, size=(4, 5, 3)).astype(np.float32)
    # L1 per channel: l0 along n plus any part across n (L1 · n = L0)
    across = rng.normal(size=(4, 5, 3, 3)) * 0.3
    across -= np.einsum("hwcj,hwj->hwc", across, n)[..., None] * n[:, :, None, :]
    l1_rgb = l0[..., None] * n[:, :, None, :] + across  # [H,W,channel,axis]
    l1 = l1_rgb.transpose(0, 1, 3, 2).reshape(4, 5, 9).astype(np.float32)
    tilted = n + rng.normal(size=n.shape) * 0.3
    tilted /= np.linalg.norm(tilted, axis=2, keepdims=True)

    t = directional.godot_layers(l0, l1)
    for normal, expected in ((n, l0), (tilted, 0.5 * l0 + 0.5 * np.einsum("hwcj,hwj->hwc", l1_rgb, tilted))):
        g = sum((t[k] - 0.5) * 2.0 * normal[..., axis, None] for k, axis in ((1, 1), (2, 2), (3, 0)))
        np.testing.assert_allclose(t[0] + 4.0 * t[0] * g, expected, rtol=1e-5, atol=1e-6)

    d = directional.unity_direction(l0, l1)
    assert d.min() >= 0.0 and d.max() <= 1.0
    half_lambert = np.einsum("hwj,hwj->hw", d[..., :3] - 0.5, n) + 0.5
    np.testing.assert_allclose(l0 * (half_lambert / d[..., 3])[..., None], l0, rtol=1e-5)
