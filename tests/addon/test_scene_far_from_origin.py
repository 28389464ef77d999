"""A Blender scene placed kilometres from the world origin bakes the values it bakes at the origin
(extraction keeps positions relative to the scene's centre, in double precision)."""
import bpy
import numpy as np
import pytest

from harness import metrics

from scenes import GROUND, OCCLUDER, fast_settings, lit_ground, vertex_colors


def bake_ground(scene, offset: float, method: str) -> np.ndarray:
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = bpy.context.scene
    lit_ground(scene)
    sun = bpy.data.lights.new("Sun", "SUN")
    sun.energy, sun.angle = 3.0, 0.05
    sun_ob = bpy.data.objects.new("Sun", sun)
    sun_ob.rotation_euler = (0.6, 0.3, 0.0)
    scene.collection.objects.link(sun_ob)
    for ob in scene.objects:
        ob.location.x += offset
        ob.location.y += offset
    bpy.context.view_layer.update()
    fast_settings(scene, method=method, light_samples=16)
    assert bpy.ops.object.radiosity_bake(use_selected=False) == {'FINISHED'}
    return np.concatenate([vertex_colors(bpy.data.objects[n].data, "Lighting")[:, :3] for n in (GROUND, OCCLUDER)])


@pytest.mark.parametrize("method", ["direct", "reference"])
def test_a_scene_kilometres_from_the_origin_bakes_as_at_the_origin(empty_scene, method):
    near = bake_ground(empty_scene, 0.0, method)
    for offset in (1e3, 1e4, 1e5):
        far = bake_ground(empty_scene, offset, method)
        assert metrics.relative_rmse(far, near) <= 0.005, offset
        assert abs(metrics.mean_bias(far, near)) <= 0.005, offset
