"""Animation bakes in Blender: the color-attribute cache that plays a baked frame range back.

Each baked frame's values go into a POINT FLOAT_COLOR attribute ``<name>.<frame>`` (four digits,
``Lighting.0012``) of each mesh; ``<name>`` itself holds the frame that was current when the bake
ran (what the saved file shows without playback, and what an exporter that takes one attribute
reads). A Geometry Nodes modifier ``RB Playback`` (node group ``RB Playback <name>``, last in the
stack) stores the current frame's attribute as ``<name>`` when the mesh is evaluated, so the
viewport (Solid › Attribute colour, Material Preview through a Color Attribute node) and renders
show the lighting move. The per-frame attributes are the cache an engine exporter reads. A mesh
records the attributes a bake made in its custom property ``radiosity_baker_frames``, so clearing
and rebaking remove exactly those.
"""
from __future__ import annotations

import bpy

from . import write
from .outputs import OutputError

PLAYBACK = "RB Playback"
FRAMES_TAG = "radiosity_baker_frames"


def frame_attribute(name: str, frame: int) -> str:
    """The attribute holding ``frame`` of the animation baked as ``name``."""
    return f"{name}.{frame:04d}"


def current(frames: list[int], frame: int) -> int:
    """The baked frame shown by ``<name>``: ``frame`` if baked, else the nearest baked one."""
    return min(frames, key=lambda f: (abs(f - frame), f))


class CacheWrites:
    """Checked writes of an animation's color attributes (one ``write.ColorWrites`` per frame and
    one for ``<name>``); ``apply`` makes them, adds the playback modifiers and returns warnings."""

    def __init__(self, name: str, frames: list[int], per_frame: list, shown, objects: list[str]):
        self.name, self.frames, self.per_frame, self.shown, self.objects = (name, frames, per_frame,
                                                                            shown, objects)

    def apply(self, context=None) -> list[str]:
        warnings = self.shown.apply(context)
        for writes in self.per_frame:
            writes.apply(context)
        group = _playback_group(self.name, self.frames)
        for name in self.objects:
            ob = bpy.data.objects[name]
            mod = ob.modifiers.get(PLAYBACK)
            if mod is None or mod.type != "NODES":
                mod = ob.modifiers.new(PLAYBACK, "NODES")
            mod.node_group = group
            made = set(ob.data.get(FRAMES_TAG, []))
            ob.data[FRAMES_TAG] = sorted(made | {frame_attribute(self.name, f) for f in self.frames})
        return warnings


def prepare(baked: list, name: str, settings, frame_now: int, context=None) -> CacheWrites:
    """Check and compute the writes of an animation: ``baked`` lists (frame, extraction, values
    float32[S,3]) in frame order. Raises OutputError (nothing written) where a frame's attribute
    name is taken by other data or an object changed; objects whose topology changes between
    frames cannot hold a cache (their vertex count is the attribute's length)."""
    frames = [f for f, _, _ in baked]
    per_frame = [write.prepare_color_attributes(extraction, values, frame_attribute(name, f),
                                                settings, context)
                 for f, extraction, values in baked]
    shown_frame = current(frames, frame_now)
    _, extraction, values = baked[frames.index(shown_frame)]
    shown = write.prepare_color_attributes(extraction, values, name, settings, context)
    sizes = {}
    for _, extraction, _ in baked:
        for t in extraction.targets:
            sizes.setdefault(t.object_name, set()).add(t.num_vertices)
    changing = sorted(n for n, s in sizes.items() if len(s) > 1)
    if changing:
        raise OutputError(f"{', '.join(changing)}: the vertex count changes between frames, so "
                                f"no per-frame attribute can hold them; bake them into lightmaps or "
                                f"apply the modifiers")
    objects = sorted({t.object_name for t in baked[0][1].targets if not t.topology_changed})
    return CacheWrites(name, frames, per_frame, shown, objects)


def _playback_group(name: str, frames: list[int]):
    """The node group storing the current frame's ``<name>.<frame>`` as ``<name>`` (frames outside
    the range show the nearest end)."""
    group_name = f"{PLAYBACK} {name}"
    group = bpy.data.node_groups.get(group_name)
    if group is not None:
        group.nodes.clear()
    else:
        group = bpy.data.node_groups.new(group_name, "GeometryNodeTree")
        group.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
        group.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    nodes, links = group.nodes, group.links
    step = frames[1] - frames[0] if len(frames) > 1 else 1
    gin, gout = nodes.new("NodeGroupInput"), nodes.new("NodeGroupOutput")
    time = nodes.new("GeometryNodeInputSceneTime")
    index = nodes.new("ShaderNodeMapRange")  # frame → index, clamped to the baked range
    index.inputs["From Min"].default_value = frames[0]
    index.inputs["From Max"].default_value = frames[-1]
    index.inputs["To Min"].default_value = 0.0
    index.inputs["To Max"].default_value = (frames[-1] - frames[0]) / step
    index.clamp = True
    rounded = nodes.new("ShaderNodeMath")
    rounded.operation = "ROUND"
    switch = nodes.new("GeometryNodeIndexSwitch")
    switch.data_type = "RGBA"
    while len(switch.index_switch_items) < len(frames):
        switch.index_switch_items.new()
    store = nodes.new("GeometryNodeStoreNamedAttribute")
    store.data_type, store.domain = "FLOAT_COLOR", "POINT"
    store.inputs["Name"].default_value = name
    links.new(time.outputs["Frame"], index.inputs["Value"])
    links.new(index.outputs["Result"], rounded.inputs[0])
    links.new(rounded.outputs[0], switch.inputs["Index"])
    for k, frame in enumerate(frames):
        read = nodes.new("GeometryNodeInputNamedAttribute")
        read.data_type = "FLOAT_COLOR"
        read.inputs["Name"].default_value = frame_attribute(name, frame)
        read.location = (-200.0, -180.0 * k)
        links.new(read.outputs["Attribute"], switch.inputs[k + 1])
    links.new(gin.outputs[0], store.inputs["Geometry"])
    links.new(switch.outputs[0], store.inputs["Value"])
    links.new(store.outputs[0], gout.inputs[0])
    for x, node in enumerate((gin, time, index, rounded, switch, store, gout)):
        node.location = (220.0 * x - 600.0, 200.0)
    return group


def clear(objects) -> int:
    """Remove what animation bakes added to ``objects``: their playback modifier and the per-frame
    attributes their meshes record; unused playback node groups go too. Returns how many items
    were removed."""
    removed = 0
    for ob in objects:
        mod = ob.modifiers.get(PLAYBACK)
        if mod is not None and mod.type == "NODES":
            ob.modifiers.remove(mod)
            removed += 1
        me = ob.data if ob.type == "MESH" else None
        if me is not None and FRAMES_TAG in me:
            for attr_name in me[FRAMES_TAG]:
                attr = me.color_attributes.get(attr_name)
                if attr is not None:
                    me.color_attributes.remove(attr)
                    removed += 1
            del me[FRAMES_TAG]
    for group in [g for g in bpy.data.node_groups if g.name.startswith(PLAYBACK + " ") and g.users == 0]:
        bpy.data.node_groups.remove(group)
        removed += 1
    return removed
