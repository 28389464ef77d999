"""Reference bakes with Cycles (the yardstick of tests and benchmarks).

Cycles' DIFFUSE bake with the Direct/Indirect passes and without Color gives "lighting":
irradiance/π at the shading normal, excluding the surface's own albedo and emission (DESIGN.md,
Units). Into a POINT color attribute Cycles evaluates each face corner at the vertex, with the
vertex's shading normal, and averages the corners of a vertex.
"""
from __future__ import annotations

import contextlib

import bpy
import numpy as np

from radiosity_baker.addon.temporary import temporarily

BAKE_TYPES = ("DIFFUSE", "AO")


def _path_tracing(scene, samples: int, bounces: int, seed: int, target: str):
    """Render settings of a reference bake: Cycles on the CPU, no denoising, clamping or adaptive
    sampling, ``bounces`` as the maximum and diffuse bounce count; (owner, name, value) triples."""
    cycles = scene.cycles
    return (
        (scene.render, "engine", "CYCLES"), (cycles, "device", "CPU"), (cycles, "samples", samples),
        (cycles, "use_denoising", False), (cycles, "sample_clamp_direct", 0.0),
        (cycles, "sample_clamp_indirect", 0.0), (cycles, "max_bounces", bounces),
        (cycles, "diffuse_bounces", bounces), (cycles, "seed", seed),
        (cycles, "use_adaptive_sampling", False), (scene.render.bake, "target", target),
    )


@contextlib.contextmanager
def _selection_of(view_layer, ob):
    """Make ``ob`` the only selected object and the active one; restore the selection afterwards."""
    selected = [o for o in view_layer.objects if o.select_get()]
    active = view_layer.objects.active
    try:
        for o in selected:
            o.select_set(False)
        ob.select_set(True)
        view_layer.objects.active = ob
        yield
    finally:
        ob.select_set(False)
        for o in selected:
            o.select_set(True)
        view_layer.objects.active = active


def _bake_one(ob, bake_type: str, passes, attribute: str) -> np.ndarray:
    """Bake ``ob`` into a temporary POINT FLOAT_COLOR attribute; return float32[V,3]."""
    me = ob.data
    if attribute in me.attributes:
        raise ValueError(f"{ob.name}: attribute {attribute!r} exists already; pick another name")
    previous = me.color_attributes.active_color_name
    me.color_attributes.new(attribute, "FLOAT_COLOR", "POINT")
    try:
        me.color_attributes.active_color = me.color_attributes[attribute]
        kwargs = {"pass_filter": set(passes)} if bake_type == "DIFFUSE" else {}
        bpy.ops.object.bake(type=bake_type, target="VERTEX_COLORS", **kwargs)
        rgba = np.empty(len(me.vertices) * 4, np.float32)
        me.color_attributes[attribute].data.foreach_get("color", rgba)
        return rgba.reshape(-1, 4)[:, :3].copy()
    finally:
        me.color_attributes.remove(me.color_attributes[attribute])
        if previous and previous in me.color_attributes:
            me.color_attributes.active_color = me.color_attributes[previous]


def cycles_bake_vertex_colors(object_names, *, passes=("DIRECT", "INDIRECT"), bake_type="DIFFUSE",
                              samples=1024, bounces=64, seed=0, attribute="CyclesRef",
                              scene=None) -> dict[str, np.ndarray]:
    """Bake each named mesh object with Cycles on the CPU; return {name: float32[V,3]}.

    V is the vertex count of the object's original mesh; values are linear RGB. bake_type
    ``DIFFUSE`` with ``passes`` (a subset of DIRECT, INDIRECT; Color is never included, so the value
    is lighting = irradiance/π in W m⁻² sr⁻¹) or ``AO`` (cosine-weighted unoccluded fraction within
    the world's AO distance, ``passes`` ignored). Path tracing uses ``samples`` per vertex corner,
    ``bounces`` as the maximum and diffuse bounce count, no clamping, no denoising, the default light
    tree. Nothing is left behind: the temporary attribute is removed and the render settings,
    selection, active object and active color attribute are restored.
    """
    if bake_type not in BAKE_TYPES:
        raise ValueError(f"bake_type must be one of {', '.join(BAKE_TYPES)}, not {bake_type!r}")
    scene = scene or bpy.context.scene
    view_layer = bpy.context.view_layer
    settings = _path_tracing(scene, samples, bounces, seed, "VERTEX_COLORS")
    results = {}
    with temporarily(settings):
        for name in object_names:
            ob = scene.objects[name]
            if ob.type != "MESH":
                raise ValueError(f"{name}: only mesh objects can be baked to vertex colors, not {ob.type}")
            with _selection_of(view_layer, ob):
                results[name] = _bake_one(ob, bake_type, passes, attribute)
    return results


def cycles_bake_image(object_names, uv_map: str, width: int, height: int, *,
                      passes=("DIRECT", "INDIRECT"), samples=256, bounces=64, seed=0,
                      scene=None) -> np.ndarray:
    """Bake the named mesh objects with Cycles (DIFFUSE, ``passes``, no Color) into one shared
    ``width`` × ``height`` float image through their UV map ``uv_map``; return float32[H,W,4]
    (row 0 at the bottom; alpha 1 where Cycles baked a texel, 0 elsewhere; no margin).

    Every object needs a material: a temporary active Image Texture node is added to each of
    them. Path tracing as in :func:`cycles_bake_vertex_colors`. Nothing is left behind: nodes,
    image, active UV maps and active nodes, render settings and selection are restored.
    """
    scene = scene or bpy.context.scene
    view_layer = bpy.context.view_layer
    objects = [scene.objects[n] for n in object_names]
    for ob in objects:
        if ob.type != "MESH" or uv_map not in ob.data.uv_layers:
            raise ValueError(f"{ob.name}: not a mesh with a UV map {uv_map!r}")
        if not any(s.material is not None and s.material.node_tree is not None for s in ob.material_slots):
            raise ValueError(f"{ob.name}: has no node material to bake through")
    image = bpy.data.images.new("CyclesRefBake", width, height, alpha=True, float_buffer=True)
    image.colorspace_settings.name = "Linear Rec.709"
    image.generated_color = (0.0, 0.0, 0.0, 0.0)
    materials = {s.material for ob in objects for s in ob.material_slots if s.material is not None}
    added, active_nodes = [], {}
    active_uv = {ob.data: ob.data.uv_layers.active.name for ob in objects}
    settings = (*_path_tracing(scene, samples, bounces, seed, "IMAGE_TEXTURES"),
                (scene.render.bake, "margin", 0), (scene.render.bake, "use_clear", False))
    selected = [o for o in view_layer.objects if o.select_get()]
    active = view_layer.objects.active
    try:
        for mat in materials:
            nodes = mat.node_tree.nodes
            active_nodes[mat] = nodes.active
            node = nodes.new("ShaderNodeTexImage")
            node.image = image
            nodes.active = node
            added.append((mat, node))
        for ob in objects:
            ob.data.uv_layers.active = ob.data.uv_layers[uv_map]
        with temporarily(settings):
            for o in selected:
                o.select_set(False)
            for ob in objects:
                ob.select_set(True)
            view_layer.objects.active = objects[0]
            bpy.ops.object.bake(type="DIFFUSE", pass_filter=set(passes))
        px = np.empty(width * height * 4, np.float32)
        image.pixels.foreach_get(px)
        return px.reshape(height, width, 4)
    finally:
        for ob in objects:
            ob.select_set(False)
        for o in selected:
            o.select_set(True)
        view_layer.objects.active = active
        for mesh, name in active_uv.items():
            mesh.uv_layers.active = mesh.uv_layers[name]
        for mat, node in added:
            mat.node_tree.nodes.remove(node)
            mat.node_tree.nodes.active = active_nodes[mat]
        bpy.data.images.remove(image)
