"""The orchestrator: validation, progress, cancellation, clear errors, content."""
import threading

import numpy as np
import pytest

import shapes
from radiosity_baker.core import BakeCancelled, BakeError, Settings, bake
from radiosity_baker.core.scene import LAMP_POINT, Lamps


def lit_plane(albedo=(0.5, 0.25, 0.1), emission=(0.0, 0.0, 0.0)):
    p, n, t = shapes.grid(2.0, 6)
    return shapes.scene([(p, n, t, albedo, emission)], shapes.lamp(LAMP_POINT, (0, 0, 1), power=(100,) * 3))


@pytest.mark.parametrize("field, value", [("method", "magic"), ("content", "nope"), ("light_samples", 0),
                                          ("tolerance", 0.0), ("attribute", " ")])
def test_bad_settings_are_rejected_with_the_setting_named(field, value):
    with pytest.raises(ValueError, match=field if field != "attribute" else "attribute"):
        Settings(**{field: value}).validate()


def test_scene_without_triangles_is_a_clear_error():
    sc = lit_plane()
    sc.triangles = sc.triangles[:0]
    sc.tri_object, sc.albedo, sc.emission = sc.tri_object[:0], sc.albedo[:0], sc.emission[:0]
    sc.corner_normals = sc.corner_normals[:0]
    with pytest.raises(BakeError, match="no triangles"):
        bake(sc, Settings())


def test_nan_geometry_is_an_error_naming_the_object():
    sc = lit_plane()
    sc.positions[3] = np.nan
    with pytest.raises(BakeError, match="part0"):
        bake(sc, Settings())


def test_zero_area_triangles_are_ignored_with_a_warning():
    sc = lit_plane()
    sc.triangles = np.concatenate([sc.triangles, [[0, 0, 1]]]).astype(np.int32)
    sc.tri_object = np.append(sc.tri_object, 0).astype(np.int32)
    sc.albedo = np.concatenate([sc.albedo, sc.albedo[:1]])
    sc.emission = np.concatenate([sc.emission, sc.emission[:1]])
    sc.corner_normals = np.concatenate([sc.corner_normals, sc.corner_normals[:1]])
    r = bake(sc, Settings(method="direct"))
    assert any("zero-area" in w and "part0" in w for w in r.warnings)
    assert np.isfinite(r.lighting).all()


def test_progress_is_reported_per_stage_and_timings_returned():
    seen = []
    r = bake(lit_plane(), Settings(method="reference"), progress=lambda s, f: seen.append((s, f)))
    stages = [s for s, _ in seen]
    for stage in ("elements", "direct", "solve"):
        assert stage in stages and stage in r.timings
    assert all(0.0 <= f <= 1.0 for _, f in seen)
    assert r.counts["elements"] == 49 and r.counts["rays"] > 0


def test_cancel_stops_the_bake():
    cancel = threading.Event()

    def progress(stage, f):
        if stage == "direct":
            cancel.set()

    with pytest.raises(BakeCancelled):
        bake(lit_plane(), Settings(), progress=progress, cancel=cancel)


def test_combined_is_emission_plus_albedo_times_lighting():
    sc = lit_plane(albedo=(0.5, 0.25, 0.1), emission=(0.3, 0.0, 0.0))
    lighting = bake(sc, Settings(method="direct")).output
    combined = bake(sc, Settings(method="direct", content="combined")).output
    np.testing.assert_allclose(combined, np.array([0.3, 0, 0]) + np.array([0.5, 0.25, 0.1]) * lighting, rtol=1e-5)


def test_a_first_bake_says_it_compiles_kernels_and_later_ones_do_not(monkeypatch):
    from radiosity_baker.core import device as device_mod

    def stages_of():
        seen = []
        bake(lit_plane(), Settings(method="direct", device="cpu"), progress=lambda s, f: seen.append(s))
        return seen

    assert not any(s.startswith("compiling kernels") for s in stages_of())  # cached by now
    monkeypatch.setattr(device_mod, "_cached", lambda module, device: False)  # as on a fresh install
    assert sum(s.startswith("compiling kernels") for s in stages_of()) == 1


def banner_lit(below: bool, above: bool):
    """A 1 m plane "Banner" facing +Z with a "Wall" beside it facing it, and a point lamp under the
    banner (its back) and/or over it (its front)."""
    banner = shapes.grid(1.0, 4)
    wall = shapes.quad([(0.6, -0.5, -1), (0.6, 0.5, -1), (0.6, 0.5, 1), (0.6, -0.5, 1)], 4, 4, (0, 0, 0))
    lamps = [shapes.lamp(LAMP_POINT, (0, 0, z), power=(50,) * 3) for z, on in ((-1, below), (1, above)) if on]
    scene = shapes.scene([(*banner, (0.8,) * 3, (0,) * 3), (*wall, (0.8,) * 3, (0,) * 3)],
                         Lamps.concat(lamps))
    scene.object_names = ["Banner", "Wall"]
    return scene


def backs_left_dark(result) -> list:
    return [w for w in result.warnings if "back of" in w]


@pytest.mark.parametrize("below, above", [(True, False), (True, True)])
def test_a_surface_without_thickness_lit_from_behind_is_named_as_left_dark_there(below, above):
    warned = backs_left_dark(bake(banner_lit(below, above), Settings(method="reference", device="cpu")))
    assert len(warned) == 1 and "Banner" in warned[0] and "Wall" not in warned[0], warned


def test_surfaces_lit_only_from_the_front_or_baked_without_bounces_are_not_warned_about():
    assert not backs_left_dark(bake(banner_lit(False, True), Settings(method="reference", device="cpu")))
    assert not backs_left_dark(bake(banner_lit(True, False), Settings(method="direct", device="cpu")))
