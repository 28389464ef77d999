"""Directional lightmaps and light probes baked from the command line and the panel's operator:
the files beside the pages, Probes.json, the probes shown in the viewport (replaced by a rebake,
removed by Clear), a Light Probe Volume's box, and the directional textures in the glTF export."""
import json

import bpy
import numpy as np
import pytest

from radiosity_baker.addon import cli, probes
from radiosity_baker.addon.tags import PROBES_TAG
from radiosity_baker.core.lightmap import files

from scenes import lit_ground
from test_gltf import image_bytes, read_glb

FAST = ["--method", "direct", "--samples", "4", "--target", "lightmap", "--texel-density", "6"]
# A closed cube beside the occluder: of the 6×6×2 probes over the scene (1 m apart), the one at
# (2.5, 2.5, 0.375) lies inside it.
CUBE = dict(size=1.0, location=(2.4, 2.4, 0.6))
INSIDE = (2.5, 2.5, 0.375)


@pytest.fixture
def scene_with_cube(empty_scene):
    lit_ground(empty_scene)
    bpy.ops.mesh.primitive_cube_add(**CUBE)
    bpy.context.view_layer.update()
    return empty_scene


@pytest.fixture
def blend(scene_with_cube, tmp_path):
    path = tmp_path / "in.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    return path


def _probe_objects() -> list:
    return [ob for ob in bpy.data.objects if ob.get(PROBES_TAG)]


def check_sh_page_and_probes(maps) -> None:
    """The directional page's L0 is the plain page; Probes.json holds the grid with one probe
    inside the cube; the viewport shows it: one tagged object, a sphere per probe, magenta inside."""
    sh = files.read_exr(maps / "Lightmap.sh.exr")
    assert sh.shape[2] == len(files.DIRECTIONAL_CHANNELS)
    plain = files.read_exr(maps / "Lightmap.exr")[..., :3]
    np.testing.assert_array_equal(sh[..., :3], plain)
    assert np.abs(sh[..., 3:]).max() > 0
    doc = json.loads((maps / "Probes.json").read_text())
    points, valid = np.array(doc["points"]), np.array(doc["valid"])
    assert doc["shape"] == [6, 6, 2] and len(points) == 72 and np.array(doc["sh"]).shape == (72, 9, 3)
    (inside,) = np.flatnonzero(~valid)
    np.testing.assert_allclose(points[inside], INSIDE, atol=1e-5)
    (shown,) = _probe_objects()
    mesh = shown.data
    assert len(mesh.vertices) == 72 * 12 and shown.hide_render
    colours = np.empty(len(mesh.vertices) * 4, np.float32)
    mesh.color_attributes[probes.ATTRIBUTE].data.foreach_get("color", colours)
    colours = colours.reshape(72, 12, 4)[:, 0, :3]
    np.testing.assert_array_equal(colours[inside], probes.INVALID)
    assert (colours[valid] > 0).all()


def test_cli_bakes_a_directional_lightmap_and_probes_shown_in_the_saved_file(blend, tmp_path):
    maps, saved = tmp_path / "maps", tmp_path / "out.blend"
    assert cli.main(["bake", str(blend), *FAST, "--directional", "sh", "--probes", "grid",
                     "--output", str(maps), "--save", str(saved)]) == 0
    bpy.ops.wm.open_mainfile(filepath=str(saved))
    check_sh_page_and_probes(maps)


def test_operator_bakes_them_a_rebake_replaces_the_probes_and_clear_removes_only_ours(scene_with_cube, tmp_path):
    s = scene_with_cube.radiosity_baker
    s.method, s.light_samples, s.target, s.texel_density = "direct", 4, "lightmap", 6.0
    s.output, s.directional, s.probes, s.probe_spacing = str(tmp_path / "maps"), "sh", "grid", 1.0
    assert bpy.ops.object.radiosity_bake() == {'FINISHED'}
    check_sh_page_and_probes(tmp_path / "maps")
    assert bpy.ops.object.radiosity_bake() == {'FINISHED'}
    assert len(_probe_objects()) == 1
    user = sorted(ob.name for ob in bpy.data.objects if not ob.get(PROBES_TAG))
    assert bpy.ops.object.radiosity_bake_clear(use_selected=False) == {'FINISHED'}
    assert _probe_objects() == [] and not any(m.get(PROBES_TAG) for m in bpy.data.meshes)
    assert not any(m.get(PROBES_TAG) for m in bpy.data.materials)
    assert sorted(ob.name for ob in bpy.data.objects) == user


def test_a_light_probe_volume_gives_the_grid_its_box_and_resolution(scene_with_cube, tmp_path):
    volume = bpy.data.objects.new("Volume", bpy.data.lightprobes.new("Volume", 'VOLUME'))
    volume.location, volume.scale = (0.0, 0.0, 1.0), (1.0, 0.5, 0.5)
    volume.data.resolution_x, volume.data.resolution_y, volume.data.resolution_z = 4, 2, 3
    scene_with_cube.collection.objects.link(volume)
    s = scene_with_cube.radiosity_baker
    s.method, s.light_samples, s.target = "direct", 4, "vertex_colors"
    s.output, s.probes, s.probe_spacing = str(tmp_path / "maps"), "grid", 1.0
    assert bpy.ops.object.radiosity_bake() == {'FINISHED'}
    doc = json.loads((tmp_path / "maps" / "Probes.json").read_text())
    assert doc["shape"] == [4, 2, 3]
    np.testing.assert_allclose(doc["spacing"], [0.5, 0.5, 1 / 3], rtol=1e-5)
    points = np.array(doc["points"])
    np.testing.assert_allclose(points.min(axis=0), [-0.75, -0.25, 0.5 + 1 / 6], atol=1e-5)
    np.testing.assert_allclose(points.max(axis=0), [0.75, 0.25, 1.5 - 1 / 6], atol=1e-5)


def test_engine_layouts_are_written_beside_the_page_and_carried_by_the_gltf_export(empty_scene, tmp_path):
    lit_ground(empty_scene)  # every surface faces +z
    mat = bpy.data.materials.new("Grey")  # MOZ_lightmap goes on the materials
    for ob in empty_scene.objects:
        if ob.type == "MESH":
            ob.data.materials.append(mat)
    blend = tmp_path / "in.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    maps = tmp_path / "godot"
    assert cli.main(["bake", str(blend), *FAST, "--directional", "godot", "--output", str(maps)]) == 0
    plain = files.read_exr(maps / "Lightmap.exr")[..., :3]
    layers = files.read_exr(maps / "Lightmap.godot.exr")[..., :3]
    h = plain.shape[0]
    t0, t_z = layers[3 * h:], layers[h:2 * h]  # layer 0 on top: the last rows (row 0 at the bottom)
    # Godot's decoding at the ground's normal +z gives the plain page (half precision)
    up = t0 + 4.0 * t0 * (t_z - 0.5) * 2.0
    np.testing.assert_allclose(up, plain, rtol=4e-3, atol=1e-4)

    maps, glb = tmp_path / "unity", tmp_path / "out.glb"
    assert cli.main(["bake", str(blend), *FAST, "--directional", "unity", "--output", str(maps),
                     "--gltf", str(glb)]) == 0
    direction = maps / "Lightmap.dir.png"
    doc, binary = read_glb(glb)
    for material in doc["materials"]:
        extras = material["extensions"]["MOZ_lightmap"]["extras"]
        assert extras["directional"]["layout"] == "unity"
        source = doc["textures"][extras["directional"]["texture"]]["source"]
        assert doc["images"][source]["mimeType"] == "image/png"
        assert image_bytes(doc, binary, source) == direction.read_bytes()
    # Unity's decoding at the ground's normal gives the colour map, the plain page
    dirmap = files.read_exr(direction)  # 8-bit read as [0, 1]
    up = (dirmap[..., 2] - 0.5) + 0.5  # d·n·0.5 + 0.5 with n = +z
    covered = plain.max(axis=2) > 0
    np.testing.assert_allclose((up / dirmap[..., 3])[covered], 1.0, atol=0.02)
