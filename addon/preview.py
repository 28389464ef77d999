"""A PNG of the camera view showing a baked colour attribute as it is (emission, no shading)."""
from __future__ import annotations

import math
from pathlib import Path

import bpy
import numpy as np
from mathutils import Vector

from .temporary import temporarily

_NAME = "radiosity_baker_preview"


def render_preview(scene, attribute_name: str, path, size: int = 512, samples: int = 8) -> None:
    """Render ``scene``'s camera view at ``size``×``size`` pixels to the PNG ``path``.

    Every surface shows its colour attribute ``attribute_name`` as emission of strength 1 (black
    where it is missing), through Cycles on the CPU with ``samples`` samples and no bounces, view
    transform Standard, so pixel values are the baked values (sRGB-encoded), scaled down by whole
    exposure stops when needed so that at most 5 % of the vertices clip. Everything
    the render needs (material override, camera when the scene has none, render settings) is
    temporary: the scene is as before afterwards, whatever happens.
    """
    material = _emission_material(attribute_name)
    camera = None if scene.camera else _framing_camera(scene)
    overrides = [(layer, "material_override", material) for layer in scene.view_layers]
    overrides += [
        (scene, "camera", scene.camera or camera),
        (scene.render, "engine", 'CYCLES'),
        (scene.render, "resolution_x", size),
        (scene.render, "resolution_y", size),
        (scene.render, "resolution_percentage", 100),
        (scene.render, "film_transparent", False),
        (scene.render.image_settings, "file_format", 'PNG'),
        (scene.render.image_settings, "color_mode", 'RGB'),
        (scene.render.image_settings, "color_depth", '8'),
        (scene.cycles, "device", 'CPU'),
        (scene.cycles, "samples", samples),
        (scene.cycles, "use_denoising", False),
        (scene.cycles, "max_bounces", 0),
        (scene.view_settings, "view_transform", 'Standard'),
        (scene.view_settings, "look", 'None'),
        (scene.view_settings, "exposure", _exposure(scene, attribute_name)),
        (scene.view_settings, "gamma", 1.0),
        (scene.view_settings, "use_curve_mapping", False),
    ]
    try:
        with temporarily(overrides), bpy.context.temp_override(scene=scene):
            bpy.ops.render.render()
            result = next(im for im in bpy.data.images if im.type == 'RENDER_RESULT')
            result.save_render(filepath=str(Path(path)), scene=scene)
    finally:
        bpy.data.materials.remove(material)
        if camera is not None:
            data = camera.data
            bpy.data.objects.remove(camera)
            bpy.data.cameras.remove(data)


def _exposure(scene, attribute_name: str) -> float:
    """Exposure (stops, ≤ 0) that brings the 95th percentile of the attribute's values to ≤ 1."""
    values = []
    for ob in scene.objects:
        attr = ob.data.attributes.get(attribute_name) if ob.type == 'MESH' else None
        if attr is not None and attr.data_type == 'FLOAT_COLOR' and len(attr.data):
            rgba = np.empty(len(attr.data) * 4, np.float32)
            attr.data.foreach_get("color", rgba)
            values.append(rgba.reshape(-1, 4)[:, :3].max(axis=1))
    if not values:
        return 0.0
    high = float(np.percentile(np.concatenate(values), 95))
    return -float(math.ceil(math.log2(high))) if high > 1.0 else 0.0


def _emission_material(attribute_name: str):
    """A material emitting the colour attribute with strength 1: Attribute → Emission → Output."""
    material = bpy.data.materials.new(_NAME)
    tree = material.node_tree
    tree.nodes.clear()
    attribute = tree.nodes.new("ShaderNodeAttribute")
    attribute.attribute_type = 'GEOMETRY'
    attribute.attribute_name = attribute_name
    emission = tree.nodes.new("ShaderNodeEmission")
    emission.inputs["Strength"].default_value = 1.0
    output = tree.nodes.new("ShaderNodeOutputMaterial")
    tree.links.new(attribute.outputs["Color"], emission.inputs["Color"])
    tree.links.new(emission.outputs["Emission"], output.inputs["Surface"])
    return material


def _framing_camera(scene):
    """A camera linked to ``scene`` looking down at all rendered meshes from the front right."""
    corners = [ob.matrix_world @ Vector(c) for ob in scene.objects
               if ob.type == 'MESH' and not ob.hide_render for c in ob.bound_box]
    if corners:
        lo = Vector(tuple(min(c[i] for c in corners) for i in range(3)))
        hi = Vector(tuple(max(c[i] for c in corners) for i in range(3)))
    else:
        lo, hi = Vector((-1, -1, -1)), Vector((1, 1, 1))
    center, radius = (lo + hi) / 2, max((hi - lo).length / 2, 1e-3)
    data = bpy.data.cameras.new(_NAME)
    camera = bpy.data.objects.new(_NAME, data)
    scene.collection.objects.link(camera)
    direction = Vector((1.0, -1.0, 0.8)).normalized()
    distance = radius / math.sin(data.angle / 2)  # the bounding sphere fills the view
    camera.location = center + direction * distance
    camera.rotation_euler = (-direction).to_track_quat('-Z', 'Y').to_euler()
    data.clip_start = max(distance - radius, 1e-3) * 0.5
    data.clip_end = (distance + radius) * 2
    return camera
