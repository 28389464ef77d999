"""The benchmark level (sample_blends/make_level.py), made small: what it holds, and that it bakes
into a multi-page lightmap atlas from the panel's operator."""

import bpy
import numpy as np

from radiosity_baker.addon.lightmap import IMAGE_TAG

from scenes import script


def test_the_level_holds_objects_lamps_and_emitters_and_bakes_into_a_udim_atlas(empty_scene, tmp_path):
    counts = script("sample_blends/make_level.py").build(detail=0.05)
    assert counts["objects"] >= 100 and counts["emissive_objects"] >= 8
    kinds = sorted({ob.data.type for ob in empty_scene.objects if ob.type == "LIGHT"})
    assert kinds == ["AREA", "POINT", "SUN"]
    assert tuple(empty_scene.world.color) == (0.0, 0.0, 0.0)
    s = empty_scene.radiosity_baker  # as the panel sets it
    s.method, s.target, s.light_samples = "direct", "lightmap", 4
    s.texel_density, s.max_size, s.padding = 2.0, 128, 2
    s.output = str(tmp_path / "maps")
    assert bpy.ops.object.radiosity_bake(use_selected=False) == {'FINISHED'}
    image = next(im for im in bpy.data.images if im.get(IMAGE_TAG) == "Lightmap")
    assert image.source == "TILED" and len(image.tiles) >= 2
    files = sorted(p.name for p in (tmp_path / "maps").glob("Lightmap.*.exr"))
    assert files == [f"Lightmap.{t.number}.exr" for t in image.tiles]
    ground = bpy.data.objects["Ground"].data
    uv = np.empty(len(ground.loops) * 2, np.float32)
    ground.uv_layers["Lightmap"].uv.foreach_get("vector", uv)
    assert len(np.unique(np.floor(uv[0::2]))) == 1  # the whole object on one tile
