"""The committed sample scenes hold what sample_blends/make_samples.py says they hold."""
from pathlib import Path

import bpy
import numpy as np
import pytest

from scenes import script


make_samples = script("sample_blends/make_samples.py")


@pytest.fixture
def open_blend():
    """Open a sample file; leave an empty file behind for the next test."""
    def _open(path: Path):
        assert path.is_file(), f"{path} missing: run .venv/bin/python sample_blends/make_samples.py"
        bpy.ops.wm.open_mainfile(filepath=str(path))
        return bpy.context.scene

    yield _open
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)


def _principled(ob):
    return ob.active_material.node_tree.nodes["Principled BSDF"]


def _vertex_total(scene) -> int:
    return sum(len(ob.data.vertices) for ob in scene.objects if ob.type == "MESH")


def test_cornell_box_matches_script(open_blend):
    scene = open_blend(make_samples.CORNELL_PATH)
    for name, material in make_samples.CORNELL_OBJECTS.items():
        ob = scene.objects[name]
        assert ob.type == "MESH" and not ob.modifiers, name
        assert ob.active_material.name == material, name
        bsdf = _principled(ob)
        assert bsdf.inputs["Specular IOR Level"].default_value == 0.0
        assert bsdf.inputs["Roughness"].default_value == 1.0
    lo, hi = make_samples.CORNELL_VERTEX_RANGE
    assert lo <= _vertex_total(scene) <= hi
    assert tuple(_principled(scene.objects["Floor"]).inputs["Base Color"].default_value)[:3] == \
        pytest.approx(make_samples.WHITE)
    assert tuple(_principled(scene.objects["RedWall"]).inputs["Base Color"].default_value)[:3] == \
        pytest.approx(make_samples.RED)
    light = _principled(scene.objects["Light"])
    assert light.inputs["Emission Strength"].default_value == pytest.approx(
        make_samples.CORNELL_LIGHT_STRENGTH)
    # The light faces down, just under the ceiling, inside the box's footprint.
    me = scene.objects["Light"].data
    assert all(p.normal.z < -0.99 for p in me.polygons)
    light_z = max(v.co.z for v in me.vertices)
    ceiling_z = min(v.co.z for v in scene.objects["Ceiling"].data.vertices)
    assert 0.0 < ceiling_z - light_z < 0.01
    # Walls face into the box: the floor up, the ceiling down.
    assert all(p.normal.z > 0.99 for p in scene.objects["Floor"].data.polygons)
    assert all(p.normal.z < -0.99 for p in scene.objects["Ceiling"].data.polygons)
    assert scene.camera is not None
    assert tuple(scene.world.color) == (0.0, 0.0, 0.0)


def test_cornell_box_is_in_metres(open_blend):
    scene = open_blend(make_samples.CORNELL_PATH)
    co = np.array([v.co[:] for ob in scene.objects if ob.type == "MESH" for v in ob.data.vertices])
    size = co.max(axis=0) - co.min(axis=0)
    np.testing.assert_allclose(size, [0.556, 0.5592, 0.5488], atol=1e-3)


def test_lamp_scene_matches_script(open_blend):
    scene = open_blend(make_samples.LAMP_SCENE_PATH)
    for name, kind in make_samples.LAMP_SCENE_LAMPS.items():
        ob = scene.objects[name]
        assert ob.type == "LIGHT" and ob.data.type == kind and ob.data.energy > 0, name
    for name in make_samples.LAMP_SCENE_MESHES:
        assert scene.objects[name].type == "MESH" and not scene.objects[name].modifiers, name
    lo, hi = make_samples.LAMP_SCENE_VERTEX_RANGE
    assert lo <= _vertex_total(scene) <= hi
    assert scene.camera is not None
