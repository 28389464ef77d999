"""write_color_attributes: results land on the right original vertices and nothing else changes."""
import bpy
import numpy as np
import pytest

from radiosity_baker.addon.extract import extract_scene
from radiosity_baker.addon.outputs import OutputError
from radiosity_baker.addon.write import RESERVED_NAMES, write_color_attributes
from radiosity_baker.core.settings import Settings

from scenes import mesh_data

pytestmark = pytest.mark.usefixtures("empty_scene")


def extract():
    return extract_scene(bpy.context.evaluated_depsgraph_get())


def shading_world(ex):
    """float64[S,3]: world positions of the extraction's shading vertices."""
    return ex.shading.position + ex.scene.origin


def colour_of(position):
    """A per-vertex value that identifies the vertex: float32[N,3] from world positions."""
    return (position * [0.1, 0.2, 0.3] + [1, 2, 3]).astype(np.float32)


def read_attribute(mesh, name):
    out = np.empty(len(mesh.vertices) * 4, np.float32)
    mesh.attributes[name].data.foreach_get("color", out)
    return out.reshape(-1, 4)


def world_positions(ob):
    co = np.empty(len(ob.data.vertices) * 3, np.float32)
    ob.data.vertices.foreach_get("co", co)
    m = np.array(ob.matrix_world)
    return co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]


def add_cube(**kwargs):
    bpy.ops.mesh.primitive_cube_add(**kwargs)
    return bpy.context.object


def test_values_land_on_the_original_vertices():
    cube = add_cube(location=(1, 2, 3), rotation=(0.3, 0.2, 0.1))
    bpy.ops.mesh.primitive_uv_sphere_add(location=(-3, 0, 0))
    bpy.ops.object.shade_smooth()
    sphere = bpy.context.object
    ex = extract()
    warnings = write_color_attributes(ex, colour_of(shading_world(ex)), "Lighting", Settings())
    assert warnings == []
    for ob in (cube, sphere):
        got = read_attribute(ob.data, "Lighting")
        np.testing.assert_allclose(got[:, :3], colour_of(world_positions(ob)), rtol=1e-5)
        np.testing.assert_allclose(got[:, 3], 1.0)
        attr = ob.data.attributes["Lighting"]
        assert (attr.domain, attr.data_type) == ("POINT", "FLOAT_COLOR")
        assert ob.data.color_attributes.active_color_name == "Lighting"


def test_vertex_value_is_the_mean_of_its_corners():
    cube = add_cube()
    ex = extract()
    # each shading vertex's value is its face's axis: |normal| = (1,0,0), (0,1,0) or (0,0,1)
    values = np.abs(ex.shading.normal)
    write_color_attributes(ex, values, "Lighting", Settings())
    # every cube vertex has three corners, one on a face of each axis: the mean is 1/3 each
    np.testing.assert_allclose(read_attribute(cube.data, "Lighting")[:, :3], 1 / 3, rtol=1e-6)


def test_other_attributes_uv_maps_images_and_materials_stay_identical():
    cube = add_cube()
    me = cube.data
    me.uv_layers.new(name="Second")
    paint = me.color_attributes.new("Paint", "BYTE_COLOR", "CORNER")
    paint.data.foreach_set("color", np.random.default_rng(1).random(len(me.loops) * 4, np.float32))
    me.color_attributes.new("Mask", "FLOAT_COLOR", "POINT")
    me.color_attributes.active_color_name = "Paint"
    me.color_attributes.default_color_name = "Mask"
    mat = bpy.data.materials.new("Mat")
    me.materials.append(mat)
    image = bpy.data.images.new("Img", 4, 4, float_buffer=True)
    image.pixels.foreach_set(np.linspace(0, 1, 64, dtype=np.float32))
    before = mesh_data(me, skip=("Lighting",))
    pixels_before = np.empty(64, np.float32)
    image.pixels.foreach_get(pixels_before)
    ex = extract()
    write_color_attributes(ex, colour_of(shading_world(ex)), "Lighting", Settings())
    assert mesh_data(me, skip=("Lighting",)) == before
    pixels_after = np.empty(64, np.float32)
    image.pixels.foreach_get(pixels_after)
    assert pixels_after.tobytes() == pixels_before.tobytes()
    assert len(bpy.data.images) == 1 and [m.name for m in bpy.data.materials] == ["Mat"]
    assert "Lighting" in me.attributes


def test_existing_attribute_of_that_name_is_overwritten_even_with_another_type():
    cube = add_cube()
    me = cube.data
    me.color_attributes.new("Lighting", "BYTE_COLOR", "CORNER")
    me.color_attributes.new("Other", "FLOAT_COLOR", "POINT").data.foreach_set(
        "color", np.full(len(me.vertices) * 4, 0.5, np.float32))
    me.color_attributes.active_color_name = "Other"
    ex = extract()
    write_color_attributes(ex, np.full((ex.shading.count, 3), 2.0, np.float32), "Lighting",
                           Settings())
    attr = me.attributes["Lighting"]
    assert (attr.domain, attr.data_type) == ("POINT", "FLOAT_COLOR")
    np.testing.assert_allclose(read_attribute(me, "Lighting")[:, :3], 2.0)
    np.testing.assert_allclose(read_attribute(me, "Other"), 0.5)
    assert me.color_attributes.active_color_name == "Other"
    # a second bake overwrites in place
    write_color_attributes(ex, np.full((ex.shading.count, 3), 3.0, np.float32), "Lighting",
                           Settings())
    np.testing.assert_allclose(read_attribute(me, "Lighting")[:, :3], 3.0)


def test_topology_changing_modifier_is_skipped_with_a_warning():
    cube = add_cube()
    cube.modifiers.new("s", "SUBSURF").levels = 1
    ex = extract()
    warnings = write_color_attributes(ex, colour_of(shading_world(ex)), "Lighting", Settings())
    assert warnings == ["Cube: its modifiers change the vertex count (26 evaluated vs 8 original); "
                        "apply the modifiers or enable 'Bake Copy' (--bake-copy)"]
    assert "Lighting" not in cube.data.attributes
    assert "Cube_baked" not in bpy.data.objects


def test_topology_changing_modifier_with_bake_copy_writes_into_a_copy():
    cube = add_cube(location=(0, 0, 5))
    cube.modifiers.new("s", "SUBSURF").levels = 1
    ex = extract()
    warnings = write_color_attributes(ex, colour_of(shading_world(ex)), "Lighting",
                                      Settings(bake_copy=True))
    assert warnings == []
    copy = bpy.data.objects["Cube_baked"]
    assert len(copy.data.vertices) == 26 and not copy.modifiers
    np.testing.assert_allclose(read_attribute(copy.data, "Lighting")[:, :3],
                               colour_of(world_positions(copy)), rtol=1e-5)
    assert "Lighting" not in cube.data.attributes and len(cube.data.vertices) == 8


def test_rebake_into_copy_reuses_the_copy_and_leaves_it_out_of_the_scene():
    cube = add_cube()
    cube.modifiers.new("s", "SUBSURF").levels = 1
    for _ in range(2):
        ex = extract()
        assert ex.scene.object_names == ["Cube"]  # the first bake's copy does not double it
        write_color_attributes(ex, colour_of(shading_world(ex)), "Lighting", Settings(bake_copy=True))
    assert [ob.name for ob in bpy.data.objects] == ["Cube", "Cube_baked"]
    assert len(bpy.data.meshes) == 2


def test_shared_mesh_gets_the_average_and_a_warning():
    a = add_cube(location=(-2, 0, 0))
    b = bpy.data.objects.new("Twin", a.data)
    b.location = (2, 0, 0)
    bpy.context.scene.collection.objects.link(b)
    ex = extract()
    warnings = write_color_attributes(ex, colour_of(shading_world(ex)), "Lighting", Settings())
    assert warnings == ["mesh Cube is shared by Cube, Twin: their results were averaged; make them "
                        "single-user for separate results"]
    expected = (colour_of(world_positions(a)) + colour_of(world_positions(b))) / 2
    np.testing.assert_allclose(read_attribute(a.data, "Lighting")[:, :3], expected, rtol=1e-5)


def test_vanished_object_writes_nothing():
    first, second = add_cube(), add_cube(location=(3, 0, 0))
    ex = extract()
    bpy.data.objects.remove(second)
    with pytest.raises(OutputError, match="Cube.001"):
        write_color_attributes(ex, colour_of(shading_world(ex)), "Lighting", Settings())
    assert "Lighting" not in first.data.attributes


def test_reserved_attribute_name_is_refused_before_writing():
    cube = add_cube()
    ex = extract()
    with pytest.raises(OutputError, match="reserved"):
        write_color_attributes(ex, colour_of(shading_world(ex)), "position", Settings())
    assert len(cube.data.vertices) == 8 and "position" in cube.data.attributes


@pytest.mark.parametrize("kind", ["uv map", "float attribute", "face color", "vertex group"])
def test_another_layer_of_that_name_stops_the_write_before_anything_changes(kind):
    first, second = add_cube(), add_cube(location=(3, 0, 0))
    me = second.data
    if kind == "uv map":
        me.uv_layers.new(name="Lighting")
    elif kind == "float attribute":
        me.attributes.new("Lighting", "FLOAT", "POINT").data.foreach_set("value", np.arange(8.0))
    elif kind == "face color":  # FLOAT_COLOR, but not on a domain color attributes live on
        me.attributes.new("Lighting", "FLOAT_COLOR", "FACE")
    else:
        second.vertex_groups.new(name="Lighting")
    before = mesh_data(me)
    ex = extract()
    with pytest.raises(OutputError, match=f"{second.name}: mesh {me.name} already has .*'Lighting'"):
        write_color_attributes(ex, colour_of(shading_world(ex)), "Lighting", Settings())
    assert mesh_data(me) == before and [g.name for g in second.vertex_groups] == (
        ["Lighting"] if kind == "vertex group" else [])
    assert "Lighting" not in first.data.attributes


@pytest.mark.parametrize("name", sorted(RESERVED_NAMES) + [".hidden", "é" * 32])
def test_names_blender_reserves_or_refuses_are_errors_before_writing(name):
    cube = add_cube()
    cube.data.polygons[0].use_smooth = True  # a sharp_face layer with both values
    before = mesh_data(cube.data)
    ex = extract()
    with pytest.raises(OutputError, match="reserved|bytes"):
        write_color_attributes(ex, colour_of(shading_world(ex)), name, Settings())
    assert mesh_data(cube.data) == before


@pytest.mark.parametrize("name", sorted(RESERVED_NAMES))
def test_reserved_names_are_the_ones_blender_refuses_for_a_color_attribute(name):
    cube = add_cube()
    cube.data.polygons[0].use_smooth = True
    attr = cube.data.attributes.new(name, "FLOAT_COLOR", "POINT")
    assert attr is None or attr.name != name
