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

from typing import Callable, Optional

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


# Frames × vertices × 16 bytes (an RGBA float per vertex and frame) of attribute cache beyond which
# a frame-range bake warns before it starts: the cache lives in memory and in the saved .blend.
CACHE_WARN_BYTES = 1 << 30


def cache_warning(extraction, frames: int) -> Optional[str]:
    """A warning when ``frames`` per-frame attributes on the meshes of ``extraction`` would hold
    more than CACHE_WARN_BYTES, else None."""
    vertices = sum(t.num_vertices for t in extraction.targets)
    size = frames * vertices * 16
    if size <= CACHE_WARN_BYTES:
        return None
    return (f"{frames} frames × {vertices} vertices make {size / 2**30:.1f} GB of per-frame color "
            f"attributes (more than {CACHE_WARN_BYTES / 2**30:g} GB), held in memory and saved in "
            f"the .blend: bake fewer frames (--frames A:B:STEP) or into lightmaps")


class CacheWrites:
    """Checked writes of an animation's color attributes (one ``write.ColorWrites`` per frame and
    one for ``<name>``); ``apply`` makes them, adds the playback modifiers and returns warnings.
    progress(fraction): called as frames are written, from ``start`` to 1."""

    def __init__(self, name: str, frames: list[int], per_frame: list, shown, objects: list[str],
                 progress: Optional[Callable[[float], None]] = None, start: float = 0.0):
        self.name, self.frames, self.per_frame, self.shown, self.objects = (name, frames, per_frame,
                                                                            shown, objects)
        self._progress, self._start = progress, start

    def apply(self, context=None) -> list[str]:
        warnings = self.shown.apply(context)
        for k, writes in enumerate(self.per_frame):
            writes.apply(context)
            _report(self._progress, self._start + (1.0 - self._start) * (k + 1) / len(self.per_frame))
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


def _report(progress, fraction: float) -> None:
    if progress is not None:
        progress(fraction)


def prepare(baked: list, name: str, settings, frame_now: int, context=None,
            progress: Optional[Callable[[float], None]] = None) -> CacheWrites:
    """Check and compute the writes of an animation: ``baked`` lists (frame, extraction, values
    float32[S,3]) in frame order. Raises OutputError (nothing written) where a frame's attribute
    name is taken by other data or an object changed; objects whose topology changes between
    frames cannot hold a cache (their vertex count is the attribute's length).

    progress(fraction): called as frames are prepared (up to 0.5) and then, by ``apply``, written
    (up to 1). Time grows linearly with the frames."""
    frames = [f for f, _, _ in baked]
    per_frame = []
    for k, (f, extraction, values) in enumerate(baked):
        per_frame.append(write.prepare_color_attributes(extraction, values, frame_attribute(name, f),
                                                        settings, context))
        _report(progress, 0.5 * (k + 1) / len(baked))
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
    return CacheWrites(name, frames, per_frame, shown, objects, progress, 0.5)


def _playback_group(name: str, frames: list[int]):
    """The node group storing the current frame's ``<name>.<frame>`` as ``<name>`` (frames outside
    the range show the nearest end): the scene frame, rounded to the nearest baked one, makes the
    attribute's name (a Format String node), so the group has the same few nodes for any number
    of frames (one node per frame made building it quadratic in the frames)."""
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
    frame = nodes.new("ShaderNodeMath")  # index → baked frame
    frame.operation = "MULTIPLY_ADD"
    frame.inputs[1].default_value, frame.inputs[2].default_value = step, frames[0]
    whole = nodes.new("FunctionNodeFloatToInt")
    whole.rounding_mode = "ROUND"
    text = nodes.new("FunctionNodeFormatString")  # frame_attribute's name: <name>.<frame, 4 digits>
    text.format_items.new("INT", "frame")
    text.inputs["Format"].default_value = name.replace("{", "{{").replace("}", "}}") + ".{frame:04}"
    read = nodes.new("GeometryNodeInputNamedAttribute")
    read.data_type = "FLOAT_COLOR"
    store = nodes.new("GeometryNodeStoreNamedAttribute")
    store.data_type, store.domain = "FLOAT_COLOR", "POINT"
    store.inputs["Name"].default_value = name
    chain = [(time.outputs["Frame"], index.inputs["Value"]), (index.outputs["Result"], rounded.inputs[0]),
             (rounded.outputs[0], frame.inputs[0]), (frame.outputs[0], whole.inputs[0]),
             (whole.outputs[0], text.inputs["frame"]), (text.outputs["String"], read.inputs["Name"]),
             (gin.outputs[0], store.inputs["Geometry"]), (read.outputs["Attribute"], store.inputs["Value"]),
             (store.outputs[0], gout.inputs[0])]
    for out, into in chain:
        links.new(out, into)
    for x, node in enumerate((gin, time, index, rounded, frame, whole, text, read, store, gout)):
        node.location = (200.0 * x - 800.0, 200.0)
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
