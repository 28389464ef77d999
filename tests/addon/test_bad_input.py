"""Scenes and settings that cannot be baked: a clear message naming the culprit, nothing changed."""
import threading

import bpy
import numpy as np
import pytest

from radiosity_baker.addon import cli
from radiosity_baker.addon.job import BakeJob
from radiosity_baker.addon.outputs import OutputError

from scenes import GROUND, OCCLUDER, fast_settings, grid, lit_ground, snapshot


def add_mesh(scene, name, verts, edges=(), faces=()):
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(list(verts), list(edges), list(faces))
    ob = bpy.data.objects.new(name, mesh)
    scene.collection.objects.link(ob)
    return ob


def test_nan_geometry_is_an_error_naming_the_object(empty_scene):
    lit_ground(empty_scene)
    fast_settings(empty_scene)
    add_mesh(empty_scene, "Broken", [(0, 0, 1), (1, 0, 1), (float("nan"), 1, 1)], faces=[(0, 1, 2)])
    before = snapshot()
    with pytest.raises(RuntimeError, match="Broken"):
        bpy.ops.object.radiosity_bake()
    assert snapshot() == before


def test_scene_without_faces_is_a_clear_error(empty_scene):
    fast_settings(empty_scene)
    add_mesh(empty_scene, "Wire", [(0, 0, 0), (1, 0, 0), (1, 1, 0)], edges=[(0, 1), (1, 2)])
    before = snapshot()
    with pytest.raises(RuntimeError, match="nothing to bake"):
        bpy.ops.object.radiosity_bake()
    assert snapshot() == before


def test_empty_scene_is_a_clear_error(empty_scene):
    with pytest.raises(RuntimeError, match="nothing to bake"):
        bpy.ops.object.radiosity_bake()


def test_object_without_faces_is_skipped_with_a_warning(empty_scene):
    lit_ground(empty_scene)
    fast_settings(empty_scene)
    add_mesh(empty_scene, "Wire", [(0, 0, 0), (1, 0, 0)], edges=[(0, 1)])
    job = BakeJob(empty_scene.radiosity_baker.to_settings())
    warnings = job.run_sync(bpy.context)
    assert any("Wire" in w for w in warnings)
    assert "Lighting" in bpy.data.objects[GROUND].data.attributes
    assert "Lighting" not in bpy.data.objects["Wire"].data.attributes


def test_reserved_attribute_name_is_refused_before_writing(empty_scene):
    lit_ground(empty_scene)
    fast_settings(empty_scene, attribute="position")
    before = snapshot()
    with pytest.raises(RuntimeError, match="reserved"):
        bpy.ops.object.radiosity_bake()
    assert snapshot() == before


def test_object_deleted_during_a_threaded_bake_writes_nothing(empty_scene):
    lit_ground(empty_scene)
    fast_settings(empty_scene)
    job = BakeJob(empty_scene.radiosity_baker.to_settings())
    job.start(bpy.context)
    bpy.data.objects.remove(bpy.data.objects[OCCLUDER])
    before = snapshot()
    while not job.poll()[2]:
        threading.Event().wait(0.01)
    with pytest.raises(OutputError, match=OCCLUDER):
        job.finish(bpy.context)
    assert snapshot() == before


def test_cli_nan_geometry_is_one_line_naming_the_object(empty_scene, tmp_path, capsys):
    grid(empty_scene, GROUND, 2.0, 3)
    add_mesh(empty_scene, "Broken", [(0, 0, 1), (1, 0, 1), (float("inf"), 1, 1)], faces=[(0, 1, 2)])
    path = tmp_path / "nan.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    assert cli.main(["bake", str(path), "--method", "direct"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("radiosity_baker: error:") and "Broken" in err[-1]


def _second_lamp(scene, energy: float):
    light = bpy.data.lights.new("Odd", 'POINT')
    light.energy = energy
    lamp = bpy.data.objects.new("Odd", light)
    lamp.location = (1.0, 1.0, 2.0)
    scene.collection.objects.link(lamp)


@pytest.mark.parametrize("energy, shown", [(-1000.0, "power -1000"), (float("nan"), "power NaN"),
                                           (float("inf"), "power inf")])
def test_a_lamp_of_negative_or_nan_power_is_left_out_with_a_warning_naming_it(empty_scene, energy, shown):
    """Before: a negative lamp was dropped without a word, and a NaN one was blamed on albedo.
    (Blender stores an infinite power as FLT_MAX.)"""
    lit_ground(empty_scene)
    fast_settings(empty_scene)
    plain = BakeJob(empty_scene.radiosity_baker.to_settings())
    plain.run_sync(bpy.context)
    expected = plain.result.output
    _second_lamp(empty_scene, energy)
    job = BakeJob(empty_scene.radiosity_baker.to_settings())
    warnings = job.run_sync(bpy.context)
    odd = [w for w in warnings if "'Odd'" in w]
    assert len(odd) == 1 and shown in odd[0] and "left out" in odd[0], warnings
    assert not any("albedo" in w for w in warnings)
    assert (job.result.output == expected).all()  # the bake of the good lamp alone


@pytest.mark.parametrize("strength", [float("inf"), float("nan"), -5.0])
def test_emission_of_inf_nan_or_negative_strength_is_left_out_with_a_warning_naming_the_object(
        empty_scene, strength):
    lit_ground(empty_scene)
    fast_settings(empty_scene)
    mat = bpy.data.materials.new("Glow")
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Emission Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    bsdf.inputs["Emission Strength"].default_value = strength
    bpy.data.objects[OCCLUDER].data.materials.append(mat)
    job = BakeJob(empty_scene.radiosity_baker.to_settings())
    warnings = job.run_sync(bpy.context)
    assert any("emission" in w and OCCLUDER in w and "left out" in w for w in warnings), warnings
    assert np.isfinite(job.result.output).all()
