"""Ambient occlusion against Cycles' AO bake on the sample scenes, and on a posed armature mesh.

Cycles' AO bake: the cosine-weighted fraction of rays leaving each vertex that hit nothing within
the world's AO distance, averaged over the vertex's face corners; ours: ``--content ao`` through
extraction and the pipeline with the same distance (read from the world). Measured figures are
printed and written to out/test-figures/ao_vs_cycles.json.
"""
import math
from pathlib import Path

import bpy
import numpy as np
import pytest

from harness.compare import bake_vertex_values, stack
from harness.cycles import cycles_bake_vertex_colors
from radiosity_baker.core import Settings
from harness import metrics

import figures as figures_file
from scenes import grid

ROOT = Path(__file__).resolve().parents[2]
CYCLES_SAMPLES = 256   # per face corner: noise σ ≈ 0.03 per corner, averaged over 4–6 corners
TOLERANCE = 0.05       # mean absolute error of accessibility


def _meshes(scene):
    return sorted(ob.name for ob in scene.objects if ob.type == "MESH" and not ob.hide_render)


def _record(case: str, figures: dict) -> None:
    figures_file.record("ao_vs_cycles", case, figures)


def _compare(names):
    reference = stack(cycles_bake_vertex_colors(names, bake_type="AO", samples=CYCLES_SAMPLES), names)
    values, result, seconds = bake_vertex_values(names, Settings(content="ao", device="cpu"))
    ours = stack(values, names)
    assert np.allclose(ours[:, 0], ours[:, 2])
    return ours[:, 0], reference[:, 0], metrics.scalar_summary(ours, reference), result, seconds


@pytest.mark.slow
@pytest.mark.parametrize("blend, distance", [("cornell_box.blend", None), ("lamp_scene.blend", None),
                                             ("cornell_box.blend", 0.2)])
def test_ao_matches_cycles_ao_bake_on_the_sample_scenes(blend, distance):
    """distance: the world's AO distance set for both (m); None keeps the file's (10 m)."""
    bpy.ops.wm.open_mainfile(filepath=str(ROOT / "sample_blends" / blend))
    try:
        scene = bpy.context.scene
        if distance is not None:
            scene.world.light_settings.distance = distance
        distance = scene.world.light_settings.distance
        ours, reference, errors, result, seconds = _compare(_meshes(scene))
        print(f"\n{blend}: AO mean abs error {errors['mean_abs_error']:.4f}, mean bias "
              f"{errors['mean_bias']:+.4f}, p95 {errors['p95_abs_error']:.4f}, Cycles mean "
              f"{reference.mean():.3f}, distance {distance:g} m")
        _record(f"{blend} distance {distance:g} m", {**errors,
                        "cycles_mean": round(float(reference.mean()), 5), "ao_distance": round(distance, 4),
                        "cycles_samples": CYCLES_SAMPLES, "vertices": int(len(reference)),
                        "elements": result.counts["elements"], "nodes": result.counts["nodes"],
                        "seconds": round(seconds, 3)})
        assert 0.05 < reference.mean() < 0.95, "a scene with occlusion to get right"
        assert errors["mean_abs_error"] <= TOLERANCE
    finally:
        bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)


def _folded_column(scene):
    """A tube (0.2 m radius, 2 m tall, 16 × 16 quads, capped) on a ground grid, skinned to two
    bones; the upper bone is bent 150° so the tube folds down beside its own lower half."""
    rings, segments = 17, 16
    a = np.linspace(0.0, 2.0 * np.pi, segments, endpoint=False)
    verts = [(0.2 * np.cos(t), 0.2 * np.sin(t), z) for z in np.linspace(0.0, 2.0, rings) for t in a]
    faces = [(r * segments + k, r * segments + (k + 1) % segments, (r + 1) * segments + (k + 1) % segments,
              (r + 1) * segments + k) for r in range(rings - 1) for k in range(segments)]
    faces += [tuple(range(segments))[::-1], tuple(range((rings - 1) * segments, rings * segments))]
    mesh = bpy.data.meshes.new("Column")
    mesh.from_pydata(verts, [], faces)
    column = bpy.data.objects.new("Column", mesh)
    scene.collection.objects.link(column)
    grid(scene, "Ground", 4.0, 21)
    rig = bpy.data.objects.new("Rig", bpy.data.armatures.new("Rig"))
    scene.collection.objects.link(rig)
    bpy.context.view_layer.objects.active = rig
    bpy.ops.object.mode_set(mode="EDIT")
    lower = rig.data.edit_bones.new("Lower")
    lower.head, lower.tail = (0.0, 0.0, 0.0), (0.0, 0.0, 1.0)
    upper = rig.data.edit_bones.new("Upper")
    upper.head, upper.tail = (0.0, 0.0, 1.0), (0.0, 0.0, 2.0)
    upper.parent = lower
    bpy.ops.object.mode_set(mode="OBJECT")
    z = np.array([v[2] for v in verts])
    column.vertex_groups.new(name="Lower").add(np.flatnonzero(z < 1.0).tolist(), 1.0, "REPLACE")
    column.vertex_groups.new(name="Upper").add(np.flatnonzero(z >= 1.0).tolist(), 1.0, "REPLACE")
    column.modifiers.new("Armature", "ARMATURE").object = rig
    bone = rig.pose.bones["Upper"]
    bone.rotation_mode = "XYZ"
    bone.rotation_euler = (math.radians(150.0), 0.0, 0.0)
    bpy.context.view_layer.update()
    return column, rig


def test_armature_deformed_mesh_gets_the_ao_of_its_posed_shape(empty_scene):
    column, rig = _folded_column(empty_scene)
    names = ["Column", "Ground"]
    settings = Settings(content="ao", device="cpu")
    posed, _, _ = bake_vertex_values(names, settings)
    rig.data.pose_position = "REST"
    bpy.context.view_layer.update()
    rest, _, _ = bake_vertex_values(names, settings)
    rig.data.pose_position = "POSE"
    bpy.context.view_layer.update()
    with bpy.context.temp_override(object=column, active_object=column):
        bpy.ops.object.modifier_apply(modifier="Armature")
    applied, _, _ = bake_vertex_values(names, settings)
    for name in names:
        np.testing.assert_allclose(posed[name], applied[name], atol=1e-5)
    # the fold matters: the halves shade each other and the ground only when posed
    assert np.abs(posed["Column"] - rest["Column"]).mean() > 0.05
    assert posed["Column"].mean() < rest["Column"].mean()
