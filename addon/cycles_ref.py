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

BAKE_TYPES = ("DIFFUSE", "AO")


@contextlib.contextmanager
def _patched(*assignments):
    """Set ``(owner, attribute, value)`` assignments for the duration of the block, then restore."""
    saved = [(owner, name, getattr(owner, name)) for owner, name, _ in assignments]
    try:
        for owner, name, value in assignments:
            setattr(owner, name, value)
        yield
    finally:
        for owner, name, value in reversed(saved):
            setattr(owner, name, value)


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
    cycles = scene.cycles
    settings = (
        (scene.render, "engine", "CYCLES"), (cycles, "device", "CPU"), (cycles, "samples", samples),
        (cycles, "use_denoising", False), (cycles, "sample_clamp_direct", 0.0),
        (cycles, "sample_clamp_indirect", 0.0), (cycles, "max_bounces", bounces),
        (cycles, "diffuse_bounces", bounces), (cycles, "seed", seed),
        (cycles, "use_adaptive_sampling", False), (scene.render.bake, "target", "VERTEX_COLORS"),
    )
    results = {}
    with _patched(*settings):
        for name in object_names:
            ob = scene.objects[name]
            if ob.type != "MESH":
                raise ValueError(f"{name}: only mesh objects can be baked to vertex colors, not {ob.type}")
            with _selection_of(view_layer, ob):
                results[name] = _bake_one(ob, bake_type, passes, attribute)
    return results
