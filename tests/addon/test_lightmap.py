"""Lightmaps through the add-on: files, UV maps, images, hook-up, clearing, failures, the CLI."""
import json

import bpy
import numpy as np
import pytest

from radiosity_baker.addon import cli
from radiosity_baker.addon.job import BakeJob
from radiosity_baker.addon.lightmap import IMAGE_TAG, NODE_PREFIX
from radiosity_baker.core import BakeCancelled
from radiosity_baker.core.lightmap import files
from radiosity_baker.core.lightmap.pages import bilinear

from scenes import GROUND, OCCLUDER, fast_settings, lit_ground, snapshot, vertex_colors


@pytest.fixture
def lit_scene(empty_scene, tmp_path):
    lit_ground(empty_scene)
    fast_settings(empty_scene, target="lightmap", output=str(tmp_path / "maps"), texel_density=8.0)
    return empty_scene


def _uv(mesh, name="Lightmap") -> np.ndarray:
    out = np.empty(len(mesh.loops) * 2, np.float32)
    mesh.uv_layers[name].uv.foreach_get("vector", out)
    return out.reshape(-1, 2)


def _pixels(image) -> np.ndarray:
    w, h = image.size
    px = np.empty(w * h * 4, np.float32)
    image.pixels.foreach_get(px)
    return px.reshape(h, w, 4)


@pytest.mark.parametrize("method", ["direct", "implicit", "antiradiance"])
def test_bake_writes_exr_preview_lightmap_uvs_and_a_linear_image(lit_scene, tmp_path, method):
    """From the panel (the operator), with direct light and with the two methods whose indirect
    light needs no rays (issue #11): both targets, and the lightmap agrees with the color
    attribute at the vertices. The occluder faces the ground: its light is all indirect."""
    lit_scene.radiosity_baker.method = method
    bpy.data.objects[OCCLUDER].data.flip_normals()
    ground = bpy.data.objects[GROUND].data
    user_uv = ground.uv_layers.new(name="UVMap")
    user_uv.uv.foreach_set("vector", np.linspace(0, 1, len(ground.loops) * 2, dtype=np.float32))
    before = _uv(ground, "UVMap")
    lit_scene.radiosity_baker.target = "both"
    assert bpy.ops.object.radiosity_bake(use_selected=False) == {'FINISHED'}

    maps = tmp_path / "maps"
    assert sorted(p.name for p in maps.iterdir()) == ["Lightmap.exr", "Lightmap.png"]
    assert [l.name for l in ground.uv_layers] == ["UVMap", "Lightmap"]
    assert ground.uv_layers.active.name == "UVMap" and ground.uv_layers["UVMap"].active_render
    np.testing.assert_array_equal(_uv(ground, "UVMap"), before)
    image = bpy.data.images["Lightmap"]
    assert image.get(IMAGE_TAG) == "Lightmap" and image.colorspace_settings.name == "Linear Rec.709"
    assert not image.packed_file
    # Blender reads the EXR as written (rows flipped back: row 0 at the bottom)
    exr = files.read_exr(maps / "Lightmap.exr")
    np.testing.assert_allclose(_pixels(image), exr, rtol=1e-3, atol=1e-6)
    # at the vertices the lightmap agrees with the color attribute baked alongside
    at_corners = bilinear(exr[..., :3], _uv(ground))
    corner_vert = np.empty(len(ground.loops), np.int32)
    ground.loops.foreach_get("vertex_index", corner_vert)
    per_vertex = vertex_colors(ground, "Lighting")[corner_vert, :3]
    lit = per_vertex.max(axis=1) > 0.2 * per_vertex.max()  # away from the shadow's edges
    error = np.abs(at_corners - per_vertex)[lit].max() / per_vertex.max()
    bounced = vertex_colors(bpy.data.objects[OCCLUDER].data, "Lighting")[:, :3].mean()
    print(f"\n{method}: lightmap against the attribute at the vertices {error:.4f}, the occluder's "
          f"light {bounced:.3f}")
    assert error < 0.05
    assert (bounced > 0.2) == (method != "direct")  # grey 0.8 ground lit about 1 to 3 below it


def test_a_cancelled_bake_adds_no_uv_map_image_or_file(lit_scene, tmp_path):
    before = snapshot()
    uv_before = {m.name: [l.name for l in m.uv_layers] for m in bpy.data.meshes}
    job = BakeJob(lit_scene.radiosity_baker.to_settings())
    job.cancel()
    with pytest.raises(BakeCancelled):
        job.run_sync(bpy.context)
    assert snapshot() == before and len(bpy.data.images) == 0
    assert {m.name: [l.name for l in m.uv_layers] for m in bpy.data.meshes} == uv_before
    assert not (tmp_path / "maps").exists()


def test_a_mesh_with_eight_uv_maps_is_an_error_naming_it(lit_scene):
    mesh = bpy.data.objects[GROUND].data
    for i in range(8):
        mesh.uv_layers.new(name=f"UV{i}")
    with pytest.raises(RuntimeError, match=f"mesh {GROUND}.*8 UV maps"):
        bpy.ops.object.radiosity_bake(use_selected=False)
    assert len(bpy.data.images) == 0 and "Lightmap" not in bpy.data.objects[OCCLUDER].data.uv_layers


def test_user_lightmap_uvs_are_reused_unchanged_unless_reunwrap(lit_scene):
    mesh = bpy.data.objects[GROUND].data
    layer = mesh.uv_layers.new(name="Lightmap")
    co = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", co)
    corner_vert = np.empty(len(mesh.loops), np.int32)
    mesh.loops.foreach_get("vertex_index", corner_vert)
    planar = (co.reshape(-1, 3)[corner_vert, :2] / 6.0 + 0.5) * 0.9 + 0.05  # the user's own layout
    layer.uv.foreach_set("vector", planar.astype(np.float32).ravel())
    bpy.ops.object.radiosity_bake(use_selected=False)
    np.testing.assert_array_equal(_uv(mesh), planar.astype(np.float32))
    # the ground keeps its own page; the occluder, unwrapped now, gets the atlas
    assert {im.name for im in bpy.data.images} == {"Lightmap", f"Lightmap_{GROUND}"}
    lit_scene.radiosity_baker.reunwrap = True
    bpy.ops.object.radiosity_bake(use_selected=False)
    assert not np.array_equal(_uv(mesh), planar.astype(np.float32))


def _material_with_linked_base_color():
    mat = bpy.data.materials.new("Painted")
    tree = mat.node_tree
    rgb = tree.nodes.new("ShaderNodeRGB")
    rgb.outputs[0].default_value = (0.2, 0.4, 0.6, 1.0)
    tree.links.new(rgb.outputs[0], tree.nodes["Principled BSDF"].inputs["Base Color"])
    return mat


def _links(mat):
    return sorted((l.from_node.name, l.from_socket.identifier, l.to_node.name, l.to_socket.identifier)
                  for l in mat.node_tree.links)


def test_hookup_multiply_then_clear_restores_materials_uvs_and_images(lit_scene):
    mat = _material_with_linked_base_color()
    for name in (GROUND, OCCLUDER):  # one material shared by both objects
        bpy.data.objects[name].data.materials.append(mat)
    nodes_before, links_before = sorted(n.name for n in mat.node_tree.nodes), _links(mat)
    lit_scene.radiosity_baker.hookup = "multiply"
    bpy.ops.object.radiosity_bake(use_selected=False)
    added = sorted(n.name for n in mat.node_tree.nodes if n.name.startswith(NODE_PREFIX))
    assert added == ["RB Lightmap", "RB Lightmap Multiply", "RB Lightmap UV"]
    base = mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"]
    assert base.links[0].from_node.name == "RB Lightmap Multiply"
    assert mat.node_tree.nodes["RB Lightmap"].image == bpy.data.images["Lightmap"]
    bpy.ops.object.radiosity_bake(use_selected=False)  # a rebake reuses the nodes and the image
    assert len(mat.node_tree.nodes) == len(nodes_before) + 3 and len(bpy.data.images) == 1

    assert bpy.ops.object.radiosity_bake_clear(use_selected=False) == {'FINISHED'}
    assert sorted(n.name for n in mat.node_tree.nodes) == nodes_before
    assert _links(mat) == links_before
    assert len(bpy.data.images) == 0
    assert all("Lightmap" not in m.uv_layers for m in bpy.data.meshes)


def test_hookup_node_adds_the_pair_without_rewiring(lit_scene):
    mat = _material_with_linked_base_color()
    bpy.data.objects[GROUND].data.materials.append(mat)
    links_before = _links(mat)
    lit_scene.radiosity_baker.hookup = "node"
    bpy.ops.object.radiosity_bake(use_selected=False)
    assert _links(mat) == sorted(links_before + [("RB Lightmap UV", "UV", "RB Lightmap", "Vector")])


def test_objects_whose_modifiers_change_topology_are_skipped_with_the_reason(lit_scene):
    bpy.data.objects[OCCLUDER].modifiers.new("Sub", "SUBSURF")
    job = BakeJob(lit_scene.radiosity_baker.to_settings())
    warnings = job.run_sync(bpy.context)
    assert any(OCCLUDER in w and "modifiers change the vertex count" in w for w in warnings)
    assert "Lightmap" not in bpy.data.objects[OCCLUDER].data.uv_layers
    assert bpy.data.images["Lightmap"].get(IMAGE_TAG) == "Lightmap"


def test_relative_output_of_an_unsaved_file_is_a_clear_error(lit_scene):
    lit_scene.radiosity_baker.output = "//maps"
    with pytest.raises(RuntimeError, match="not saved"):
        bpy.ops.object.radiosity_bake(use_selected=False)
    assert len(bpy.data.images) == 0


def test_cli_target_lightmap_writes_files_next_to_the_blend_and_packs(empty_scene, tmp_path):
    lit_ground(empty_scene)
    blend, out = tmp_path / "in.blend", tmp_path / "out.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    assert cli.main(["bake", str(blend), "--method", "direct", "--samples", "1", "--target",
                     "lightmap", "--texel-density", "8", "--max-size", "64", "--padding", "2",
                     "--pack-images", "--hookup", "--save", str(out), "--report",
                     str(tmp_path / "report.json")]) == 0
    exr = tmp_path / "lightmaps" / "Lightmap.exr"
    assert exr.is_file()
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["lightmaps"] == {"Lightmap": str(exr)} and report["counts"]["texels"] > 0
    bpy.ops.wm.open_mainfile(filepath=str(out))
    image = bpy.data.images["Lightmap"]
    assert image.packed_file is not None and max(image.size) <= 64
    assert "Lighting" not in bpy.data.objects[GROUND].data.attributes


def _crates(scene, count=5):
    """``count`` 1 m cubes in a row sharing one material, under a point lamp."""
    mat = bpy.data.materials.new("Crate")
    for k in range(count):
        bpy.ops.mesh.primitive_cube_add(size=1.0, location=(1.5 * k, 0.0, 0.5))
        ob = bpy.context.object
        ob.name = f"Crate{k}"
        ob.data.materials.append(mat)
    light = bpy.data.lights.new("Lamp", 'POINT')
    light.energy = 500.0
    lamp = bpy.data.objects.new("Lamp", light)
    lamp.location = (3.0, -2.0, 4.0)
    scene.collection.objects.link(lamp)
    return mat


def test_an_atlas_of_several_pages_is_one_udim_image_each_object_on_one_tile(empty_scene, tmp_path):
    mat = _crates(empty_scene)
    bpy.data.objects["Crate2"].radiosity_baker_texel_density = 10.0  # its own density, panel-set
    fast_settings(empty_scene, target="lightmap", output=str(tmp_path / "maps"), texel_density=16.0,
                  max_size=64, padding=2, hookup="node")
    job = BakeJob(empty_scene.radiosity_baker.to_settings())
    warnings = job.run_sync(bpy.context)
    pages = job.result["lightmap"].pages
    tiles = [p.tile for p in pages]
    assert len(pages) > 1 and tiles == list(range(1001, 1001 + len(pages)))
    assert sorted(p.name for p in (tmp_path / "maps").iterdir()) == sorted(
        f"Lightmap.{t}.{ext}" for t in tiles for ext in ("exr", "png"))
    image = bpy.data.images["Lightmap"]
    assert image.source == "TILED" and [t.number for t in image.tiles] == tiles
    assert image.get(IMAGE_TAG) == "Lightmap" and len(bpy.data.images) == 1
    # one material shows every page: the objects' UVs point into their tiles
    assert mat.node_tree.nodes[NODE_PREFIX].image == image
    assert not any("is used by objects on lightmaps" in w for w in warnings)
    for page in pages:
        for name in page.objects:
            uv = _uv(bpy.data.objects[name].data)
            assert (np.floor(uv[:, 0]) == page.tile - 1001).all() and (uv[:, 1] <= 1.0).all()
    density = job.result.counts["lightmap"]["density"]
    assert density["Crate2"] == {"asked": 10.0, "used": 10.0, "note": "as asked"}
    assert density["Crate0"] == {"asked": 16.0, "used": 16.0, "note": "as asked"}
    # a rebake reuses the tiles' UVs as they are
    again = BakeJob(empty_scene.radiosity_baker.to_settings())
    again.run_sync(bpy.context)
    assert [p.tile for p in again.result["lightmap"].pages] == tiles and again.result["lightmap"].uv == {}


def test_cli_bakes_a_multi_page_atlas_and_reports_the_density_used(empty_scene, tmp_path):
    _crates(empty_scene)
    blend = tmp_path / "in.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    args = ["bake", str(blend), "--method", "direct", "--samples", "1", "--target", "lightmap",
            "--texel-density", "16", "--max-size", "64", "--padding", "2"]
    assert cli.main(args + ["--report", str(tmp_path / "many.json")]) == 0
    report = json.loads((tmp_path / "many.json").read_text())
    assert len(report["lightmaps"]) > 1 and "Lightmap.1002" in report["lightmaps"]
    assert {d["note"] for d in report["counts"]["lightmap"]["density"].values()} == {"as asked"}
    assert cli.main(args + ["--atlas-pages", "one", "--output", str(tmp_path / "one"), "--report",
                            str(tmp_path / "one.json")]) == 0
    report = json.loads((tmp_path / "one.json").read_text())
    assert list(report["lightmaps"]) == ["Lightmap"]
    assert {d["note"] for d in report["counts"]["lightmap"]["density"].values()} == {"lowered"}
