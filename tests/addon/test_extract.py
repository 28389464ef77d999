"""extract_scene: the depsgraph's view of a scene as SceneData, with render visibility and materials."""
import math

import bpy
import numpy as np
import pytest

from radiosity_baker.addon.extract import ExtractionError, extract_scene, realize_copy
from radiosity_baker.core.scene import (LAMP_AREA, LAMP_POINT, LAMP_SPOT, LAMP_SUN, SHAPE_ELLIPSE,
                                        SHAPE_RECTANGLE)

pytestmark = pytest.mark.usefixtures("empty_scene")

QUAD = [(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)]


def mesh_object(name, verts=QUAD, faces=((0, 1, 2, 3),), collection=None):
    me = bpy.data.meshes.new(name)
    me.from_pydata(list(verts), [], [list(f) for f in faces])
    ob = bpy.data.objects.new(name, me)
    (collection or bpy.context.scene.collection).objects.link(ob)
    return ob


def extract(receivers=None):
    return extract_scene(bpy.context.evaluated_depsgraph_get(), receivers)


def object_vertices(ex, name):
    """float64[N,3]: world positions of the vertices used by the triangles of object ``name``."""
    s = ex.scene
    idx = [i for i, n in enumerate(s.object_names) if n == name]
    tris = s.triangles[np.isin(s.tri_object, idx)]
    return s.positions[np.unique(tris)] + s.origin


def object_albedo(ex, name):
    s = ex.scene
    return s.albedo[s.tri_object == s.object_names.index(name)]


def material(name, shader="ShaderNodeBsdfPrincipled", **inputs):
    mat = bpy.data.materials.new(name)
    tree = mat.node_tree
    tree.nodes.clear()
    out = tree.nodes.new("ShaderNodeOutputMaterial")
    node = tree.nodes.new(shader)
    tree.links.new(node.outputs[0], out.inputs["Surface"])
    for key, value in inputs.items():
        node.inputs[key].default_value = value
    return mat


def test_modifiers_give_evaluated_positions():
    plane = mesh_object("Plane")
    mod = plane.modifiers.new("d", "DISPLACE")
    mod.strength, mod.mid_level = 2.0, 0.0
    cube = mesh_object("Cube", [(x, y, z) for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)],
                       [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4),
                        (1, 5, 7, 3)])
    cube.location = (5, 0, 0)
    cube.modifiers.new("s", "SUBSURF").levels = 1
    ex = extract()
    np.testing.assert_allclose(object_vertices(ex, "Plane")[:, 2], 2.0)
    cube_target = next(t for t in ex.targets if t.object_name == "Cube")
    assert cube_target.num_vertices == 26 and cube_target.topology_changed
    local = object_vertices(ex, "Cube") - (5, 0, 0)
    assert len(local) > 8 and np.abs(local).max() < 1.0  # smoothed inside the cage
    assert not next(t for t in ex.targets if t.object_name == "Plane").topology_changed


def test_modifier_settings_differing_from_render_are_reported():
    ob = mesh_object("Plane")
    ob.modifiers.new("Smooth", "SUBSURF").render_levels = 3
    ob.modifiers.new("Bend", "SIMPLE_DEFORM").show_render = False
    ex = extract()
    assert ex.warnings[:2] == [
        "Plane: modifier Smooth has 1 viewport levels and 3 render levels: baked with the viewport's",
        "Plane: modifier Bend is on in the viewport but not in renders: baked as the viewport shows it"]


def test_armature_pose_gives_posed_positions():
    arm = bpy.data.armatures.new("Arm")
    rig = bpy.data.objects.new("Rig", arm)
    bpy.context.scene.collection.objects.link(rig)
    bpy.context.view_layer.objects.active = rig
    bpy.ops.object.mode_set(mode="EDIT")
    bone = arm.edit_bones.new("Bone")
    bone.head, bone.tail = (0, 0, 0), (0, 0, 1)
    bpy.ops.object.mode_set(mode="OBJECT")
    ob = mesh_object("Skin")
    ob.vertex_groups.new(name="Bone").add(range(4), 1.0, "REPLACE")
    ob.modifiers.new("arm", "ARMATURE").object = rig
    rig.pose.bones["Bone"].location = (0, 2, 0)  # bone space: along the bone, i.e. world +Z
    np.testing.assert_allclose(object_vertices(extract(), "Skin")[:, 2], 2.0, atol=1e-6)


def test_shape_key_value_moves_vertices():
    ob = mesh_object("Keyed")
    ob.shape_key_add(name="Basis")
    key = ob.shape_key_add(name="Up")
    for point in key.data:
        point.co.z = 1.0
    key.value = 0.25
    np.testing.assert_allclose(object_vertices(extract(), "Keyed")[:, 2], 0.25)


def test_collection_instances_repeat_geometry_with_their_matrices():
    coll = bpy.data.collections.new("Prop")
    mesh_object("Tile", collection=coll)
    for name, loc in (("A", (10, 0, 0)), ("B", (0, 10, 0))):
        empty = bpy.data.objects.new(name, None)
        empty.instance_type, empty.instance_collection = "COLLECTION", coll
        empty.location = loc
        empty.rotation_euler = (math.pi / 2, 0, 0) if name == "B" else (0, 0, 0)
        bpy.context.scene.collection.objects.link(empty)
    ex = extract()
    assert sorted(ex.scene.object_names) == ["A/Tile", "B/Tile"]
    assert ex.scene.num_triangles == 4 and ex.targets == []
    a, b = object_vertices(ex, "A/Tile"), object_vertices(ex, "B/Tile")
    np.testing.assert_allclose(a.mean(axis=0), (10, 0, 0), atol=1e-6)
    np.testing.assert_allclose(b.mean(axis=0), (0, 10, 0), atol=1e-6)
    np.testing.assert_allclose(np.ptp(b, axis=0), (2, 0, 2), atol=1e-6)  # rotated upright
    b_normals = ex.scene.corner_normals[ex.scene.tri_object == ex.scene.object_names.index("B/Tile")]
    np.testing.assert_allclose(b_normals.reshape(-1, 3), [[0, -1, 0]] * 6, atol=1e-6)


def test_text_and_beveled_curve_are_converted_to_triangles():
    text = bpy.data.objects.new("Label", bpy.data.curves.new("Label", "FONT"))
    text.data.body = "Hi"
    curve_data = bpy.data.curves.new("Ring", "CURVE")
    curve_data.bevel_depth = 0.1
    spline = curve_data.splines.new("POLY")
    spline.points.add(3)
    spline.points.foreach_set("co", [0, 0, 0, 1, 1, 0, 0, 1, 1, 1, 0, 1, 0, 1, 0, 1])
    spline.use_cyclic_u = True
    curve = bpy.data.objects.new("Ring", curve_data)
    for ob in (text, curve):
        bpy.context.scene.collection.objects.link(ob)
    ex = extract(receivers=[text])
    counts = {n: int((ex.scene.tri_object == i).sum()) for i, n in enumerate(ex.scene.object_names)}
    assert counts["Label"] > 0 and counts["Ring"] > 0
    assert "Label is not a mesh: its results cannot be written" in ex.warnings
    assert ex.targets == []
    # baking everything, they still take no results: said, not silent (before: no word)
    everything = extract()
    said = [w for w in everything.warnings if "cast light and shadow but take no results" in w]
    assert len(said) == 1 and "2 curve, text" in said[0] and "Label" in said[0] and "Ring" in said[0]
    assert "Convert › Mesh" in said[0]


def test_ten_thousand_objects_without_a_material_make_one_warning_with_the_count():
    mesh = bpy.data.meshes.new("Tile")
    mesh.from_pydata([(0, 0, 0), (1, 0, 0), (0, 1, 0)], [], [(0, 1, 2)])
    for i in range(10_000):
        ob = bpy.data.objects.new(f"Tile{i:05d}", mesh)
        ob.location.x = 2 * i
        bpy.context.scene.collection.objects.link(ob)
    warnings = extract().warnings
    assert warnings == ["10,000 objects have no material: grey 0.8 used (Tile00000, Tile00001, "
                        "Tile00002, Tile00003, Tile00004 and 9,995 more)"]


def test_hide_render_objects_collections_and_instancers_are_excluded():
    mesh_object("Shown")
    mesh_object("Hidden").hide_render = True
    coll = bpy.data.collections.new("Off")
    bpy.context.scene.collection.children.link(coll)
    coll.hide_render = True
    mesh_object("InHiddenCollection", collection=coll)
    prop = bpy.data.collections.new("Prop")
    mesh_object("Tile", collection=prop)
    empty = bpy.data.objects.new("Instancer", None)
    empty.instance_type, empty.instance_collection = "COLLECTION", prop
    empty.hide_render = True
    bpy.context.scene.collection.objects.link(empty)
    bpy.context.scene.collection.objects.link(bpy.data.objects.new("HiddenLamp",
                                                                     bpy.data.lights.new("L", "POINT")))
    bpy.data.objects["HiddenLamp"].hide_render = True
    ex = extract()
    assert ex.scene.object_names == ["Shown"]
    assert [t.object_name for t in ex.targets] == ["Shown"]
    assert len(ex.scene.lamps) == 0


def test_object_hidden_in_viewport_but_rendered_is_reported():
    mesh_object("Shown")
    mesh_object("EyeHidden").hide_set(True)
    ex = extract()
    assert any(w.startswith("EyeHidden renders but is hidden in the viewport") for w in ex.warnings)


def test_principled_diffuse_emission_and_missing_materials_give_albedo_and_emission():
    specs = {
        "Principled": material("P", **{"Base Color": (0.2, 0.4, 0.6, 1), "Emission Color": (1, 0.5, 0, 1),
                                       "Emission Strength": 3.0}),
        "Diffuse": material("D", "ShaderNodeBsdfDiffuse", Color=(0.1, 0.2, 0.3, 1)),
        "Emitter": material("E", "ShaderNodeEmission", Color=(0.5, 1, 1, 1), Strength=4.0),
    }
    for i, (name, mat) in enumerate(specs.items()):
        mesh_object(name).data.materials.append(mat)
        bpy.data.objects[name].location.x = 3 * i
    mesh_object("Bare").location.x = 10
    ex = extract()
    s = ex.scene

    def first(array, name):
        return array[s.tri_object == s.object_names.index(name)][0]

    np.testing.assert_allclose(first(s.albedo, "Principled"), (0.2, 0.4, 0.6), rtol=1e-6)
    np.testing.assert_allclose(first(s.emission, "Principled"), (3, 1.5, 0), rtol=1e-6)
    np.testing.assert_allclose(first(s.albedo, "Diffuse"), (0.1, 0.2, 0.3), rtol=1e-6)
    np.testing.assert_allclose(first(s.emission, "Diffuse"), 0)
    np.testing.assert_allclose(first(s.albedo, "Emitter"), 0)
    np.testing.assert_allclose(first(s.emission, "Emitter"), (2, 4, 4), rtol=1e-6)
    np.testing.assert_allclose(first(s.albedo, "Bare"), 0.8, rtol=1e-6)
    assert ex.warnings.count("object Bare has no material: grey 0.8 used") == 1


def test_material_per_polygon_follows_material_index():
    ob = mesh_object("Two", [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (2, 0, 0), (2, 1, 0)],
                     [(0, 1, 2, 3), (1, 4, 5, 2)])
    ob.data.materials.append(material("Red", **{"Base Color": (1, 0, 0, 1)}))
    ob.data.materials.append(material("Blue", **{"Base Color": (0, 0, 1, 1)}))
    ob.data.polygons[1].material_index = 1
    s = extract().scene
    centre_x = s.positions[s.triangles].mean(axis=1)[:, 0] + s.origin[0]
    np.testing.assert_allclose(s.albedo[centre_x < 1], [[1, 0, 0]] * 2)
    np.testing.assert_allclose(s.albedo[centre_x > 1], [[0, 0, 1]] * 2)


def test_image_texture_on_base_color_gives_the_texel_colours_under_each_triangle():
    # 2×1 float image: left half red, right half green; the quad's two UV halves map onto them.
    image = bpy.data.images.new("Tex", 2, 1, float_buffer=True)
    image.pixels.foreach_set(np.array([1, 0, 0, 1, 0, 1, 0, 1], np.float32))
    mat = material("Textured")
    tex = mat.node_tree.nodes.new("ShaderNodeTexImage")
    tex.image = image
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    mat.node_tree.links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
    ob = mesh_object("Pic", [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (2, 0, 0), (2, 1, 0)],
                     [(0, 1, 2, 3), (1, 4, 5, 2)])
    ob.data.materials.append(mat)
    uv = ob.data.uv_layers.new(name="UVMap")
    corner_uv = np.array([[0, 0], [0.5, 0], [0.5, 1], [0, 1], [0.5, 0], [1, 0], [1, 1], [0.5, 1]],
                         np.float32)
    uv.uv.foreach_set("vector", corner_uv.ravel())
    s = extract().scene
    centre_x = s.positions[s.triangles].mean(axis=1)[:, 0] + s.origin[0]
    np.testing.assert_allclose(s.albedo[centre_x < 1], [[1, 0, 0]] * 2)
    np.testing.assert_allclose(s.albedo[centre_x > 1], [[0, 1, 0]] * 2)


def test_byte_srgb_image_without_uvs_gives_its_linear_mean_colour():
    image = bpy.data.images.new("Byte", 2, 2)  # 8-bit, sRGB
    image.pixels.foreach_set(np.tile(np.array([0.5, 0.5, 0.5, 1], np.float32), 4))
    mat = material("Textured")
    tex = mat.node_tree.nodes.new("ShaderNodeTexImage")
    tex.image = image
    mat.node_tree.links.new(tex.outputs["Color"], mat.node_tree.nodes["Principled BSDF"].inputs[0])
    mesh_object("Plain").data.materials.append(mat)
    ex = extract()
    stored = round(0.5 * 255) / 255  # the byte the image keeps
    np.testing.assert_allclose(ex.scene.albedo, ((stored + 0.055) / 1.055) ** 2.4, rtol=1e-5)
    assert "object Plain has no UV map: the image's mean colour is used" in ex.warnings


def lamp(name, kind, **props):
    light = bpy.data.lights.new(name, kind)
    for key, value in props.items():
        setattr(light, key, value)
    ob = bpy.data.objects.new(name, light)
    bpy.context.scene.collection.objects.link(ob)
    return ob


def test_lamps_convert_kind_power_size_and_direction():
    mesh_object("Floor")
    lamp("Point", "POINT", energy=100.0, color=(1, 0.5, 0.25), shadow_soft_size=0.3).location = (0, 0, 2)
    spot = lamp("Spot", "SPOT", energy=50.0, spot_size=1.0, spot_blend=0.2)
    spot.rotation_euler = (math.pi / 2, 0, 0)  # −Z turned to +Y
    lamp("Sun", "SUN", energy=3.0, angle=0.1)
    rect = lamp("Rect", "AREA", energy=20.0, shape="RECTANGLE", size=1.0, size_y=0.5)
    rect.scale = (2, 3, 1)
    lamp("Disk", "AREA", energy=10.0, shape="DISK", size=0.4)
    lamps = extract().scene.lamps
    i = {n: k for k, n in enumerate(lamps.names)}
    assert [lamps.kind[i[n]] for n in ("Point", "Spot", "Sun", "Rect", "Disk")] == [
        LAMP_POINT, LAMP_SPOT, LAMP_SUN, LAMP_AREA, LAMP_AREA]
    np.testing.assert_allclose(lamps.power[i["Point"]], (100, 50, 25))
    np.testing.assert_allclose(lamps.position[i["Point"]], (0, 0, 2))
    np.testing.assert_allclose(lamps.size[i["Point"], 0], 0.3, rtol=1e-6)
    np.testing.assert_allclose(lamps.direction[i["Spot"]], (0, 1, 0), atol=1e-6)
    np.testing.assert_allclose([lamps.spot_size[i["Spot"]], lamps.spot_blend[i["Spot"]]], (1.0, 0.2),
                               rtol=1e-6)
    np.testing.assert_allclose(lamps.direction[i["Sun"]], (0, 0, -1), atol=1e-6)
    np.testing.assert_allclose(lamps.power[i["Sun"]], (3, 3, 3))
    np.testing.assert_allclose(lamps.size[i["Sun"], 0], 0.1, rtol=1e-6)
    np.testing.assert_allclose(lamps.size[i["Rect"]], (2.0, 1.5), rtol=1e-6)
    assert lamps.shape[i["Rect"]] == SHAPE_RECTANGLE and lamps.shape[i["Disk"]] == SHAPE_ELLIPSE
    np.testing.assert_allclose(lamps.size[i["Disk"]], (0.4, 0.4), rtol=1e-6)
    np.testing.assert_allclose(lamps.axis_u[i["Rect"]], (1, 0, 0), atol=1e-6)
    np.testing.assert_allclose(lamps.axis_v[i["Rect"]], (0, 1, 0), atol=1e-6)


def test_hard_edged_cube_splits_vertices_with_face_normals_and_smooth_sphere_does_not():
    bpy.ops.mesh.primitive_cube_add()
    bpy.ops.mesh.primitive_uv_sphere_add(location=(4, 0, 0))
    bpy.ops.object.shade_smooth()
    ex = extract()
    s = ex.scene
    cube = next(t for t in ex.targets if t.object_name == "Cube")
    sphere = next(t for t in ex.targets if t.object_name == "Sphere")
    cube_ids = np.unique(cube.corner_shading)
    assert len(cube_ids) == 24
    n = ex.shading.normal[cube_ids]
    np.testing.assert_allclose(np.sort(np.abs(n), axis=1), [[0, 0, 1]] * 24, atol=1e-6)
    sphere_ids = np.unique(sphere.corner_shading)
    assert len(sphere_ids) == len(bpy.data.objects["Sphere"].data.vertices)
    radial = ex.shading.position[sphere_ids] + s.origin - (4, 0, 0)
    radial /= np.linalg.norm(radial, axis=1, keepdims=True)
    assert np.einsum("ij,ij->i", radial, ex.shading.normal[sphere_ids]).min() > 0.99


def test_triangles_are_ccw_seen_from_their_normals_also_under_a_mirror():
    bpy.ops.mesh.primitive_cube_add()
    bpy.ops.mesh.primitive_cube_add(location=(4, 0, 0))
    bpy.context.object.scale = (-1, 2, 1)
    s = extract().scene
    p = s.positions[s.triangles]
    geometric = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    shading = s.corner_normals.mean(axis=1)
    assert np.all(np.einsum("ij,ij->i", geometric, shading) > 0)


def test_nan_vertex_raises_naming_the_object():
    mesh_object("Broken", [(0, 0, 0), (1, 0, 0), (float("nan"), 1, 0)], [(0, 1, 2)])
    with pytest.raises(ExtractionError, match="Broken"):
        extract()


def test_mesh_without_faces_is_skipped_with_a_warning():
    mesh_object("Floor")
    mesh_object("Points", QUAD, [])
    ex = extract()
    assert "Points has no faces: skipped" in ex.warnings
    assert ex.scene.object_names == ["Floor"]


def test_scene_without_faces_raises():
    mesh_object("Points", QUAD, [])
    with pytest.raises(ExtractionError, match="nothing to bake"):
        extract()


def test_geometry_nodes_instances_share_one_read_mesh_and_keep_their_matrices():
    grid = mesh_object("Grid", [(0, 0, 0), (5, 0, 0), (0, 5, 0)], [])
    tree = bpy.data.node_groups.new("Scatter", "GeometryNodeTree")
    tree.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    tree.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    gin, gout = tree.nodes.new("NodeGroupInput"), tree.nodes.new("NodeGroupOutput")
    on_points = tree.nodes.new("GeometryNodeInstanceOnPoints")
    cube = tree.nodes.new("GeometryNodeMeshCube")
    tree.links.new(gin.outputs[0], on_points.inputs["Points"])
    tree.links.new(cube.outputs[0], on_points.inputs["Instance"])
    tree.links.new(on_points.outputs[0], gout.inputs[0])
    grid.modifiers.new("gn", "NODES").node_group = tree
    ex = extract()
    s = ex.scene
    assert s.num_triangles == 3 * 12
    centres = sorted(tuple(np.round(s.positions[np.unique(s.triangles[s.tri_object == k])].mean(0)
                               + s.origin, 5))
                     for k in range(3))
    assert centres == [(0, 0, 0), (0, 5, 0), (5, 0, 0)]
    assert not any("no faces" in w for w in ex.warnings)
    receiver = extract(receivers=[grid])
    assert receiver.targets == []
    assert "Grid has no faces of its own, only instances: not baked" in receiver.warnings


def test_receivers_limit_targets():
    mesh_object("A")
    b = mesh_object("B")
    b.location.x = 3
    ex = extract(receivers=[b])
    assert [t.object_name for t in ex.targets] == ["B"]
    assert sorted(ex.scene.object_names) == ["A", "B"]
    corner_x = ex.shading.position[ex.targets[0].corner_shading][:, 0] + ex.scene.origin[0]
    assert corner_x.min() == pytest.approx(2.0) and corner_x.max() == pytest.approx(4.0)


def test_realize_copy_holds_the_evaluated_mesh_and_leaves_the_original_alone():
    ob = mesh_object("Base")
    ob.location = (1, 2, 3)
    ob.modifiers.new("s", "SUBSURF").levels = 1
    ob.data.materials.append(material("M"))
    copy = realize_copy(bpy.context, ob)
    assert copy.name == "Base_baked" and len(copy.data.vertices) == 9
    assert len(ob.data.vertices) == 4 and len(ob.modifiers) == 1
    assert copy.matrix_world == ob.matrix_world
    assert copy.data.materials[0] == bpy.data.materials["M"]
    assert set(copy.users_collection) == set(ob.users_collection)
