"""Properties › Render › "Radiosity Bake", shown whatever the render engine."""
from __future__ import annotations

import importlib.util

import bpy

from ..core.settings import TARGET_OUTPUTS, Settings, reads
from .operator import OBJECT_OT_radiosity_bake


def _prop(layout, s, name: str) -> None:
    """``s.name`` in a row greyed out when the chosen method does not read it."""
    row = layout.row()
    row.active = reads(Settings(method=s.method, content=s.content).solver, name)
    row.prop(s, name)


def _farm(layout, s) -> None:
    """The Scheduler field (a Dask farm), and how to get ``distributed`` where Blender lacks it
    (the extension zip does not bundle it: manual: docs/farm.md)."""
    layout.prop(s, "scheduler")
    if s.scheduler.strip() and importlib.util.find_spec("distributed") is None:
        col = layout.column(align=True)
        col.label(text="Needs the Python package 'distributed':", icon='ERROR')
        col.label(text="pip install distributed into Blender's Python")


class RENDER_PT_radiosity_bake(bpy.types.Panel):
    bl_label = "Radiosity Bake"
    bl_space_type = 'PROPERTIES'
    bl_region_type = 'WINDOW'
    bl_context = "render"

    @classmethod
    def poll(cls, context):
        # The bake does not use the render engine: no COMPAT_ENGINES filter, every engine shows it.
        return context.scene is not None

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        s = context.scene.radiosity_baker
        col = layout.column()
        col.prop(s, "method")
        col.prop(s, "content")
        col.prop(s, "target")
        col.prop(s, "attribute")
        col.prop(s, "device")
        col = layout.column(align=True)
        for name in ("light_samples", "light_selection", "visibility_rays", "link_threshold",
                     "gather_rays", "contact_levels", "directional_bins", "bounces", "ao_distance"):
            _prop(col, s, name)
        layout.prop(s, "bake_copy")
        _farm(layout, s)
        col = layout.column(heading="Lightmap")
        col.active = "lightmap" in TARGET_OUTPUTS[s.target]
        for name in ("texel_density", "max_size", "atlas_pages", "padding", "layout", "output",
                     "hookup", "reunwrap", "supersample", "texel_indirect", "texel_links", "texel_shadows",
                     "shadow_budget", "lightmap_format", "pack_images", "directional"):
            _prop(col, s, name)
        col = layout.column(heading="Probes")
        col.prop(s, "probes")
        row = col.row()
        row.active = s.probes != "none"
        row.prop(s, "probe_spacing")
        if s.probes != "none" and any(o.type == 'LIGHT_PROBE' and o.data.type == 'VOLUME'
                                      for o in context.scene.objects):
            col.label(text="Grid: the Light Probe Volume's box", icon='LIGHTPROBE_VOLUME')
        ob = context.object
        if ob is not None and ob.type == 'MESH':
            col.prop(ob, "radiosity_baker_texel_density", text=f"{ob.name} Density")
        row = layout.row()
        row.scale_y = 1.5
        row.operator(OBJECT_OT_radiosity_bake.bl_idname, text="Bake", icon='RENDER_STILL')
        row = layout.row(align=True)
        row.prop(s, "frames", text="")
        row.operator(OBJECT_OT_radiosity_bake.bl_idname, text="Bake Animation",
                     icon='RENDER_ANIMATION').animation = True
        layout.operator("object.radiosity_bake_clear", text="Clear Lightmaps", icon='TRASH')
        stats = s.last_bake
        if stats.device:
            box = layout.box()
            box.label(text=f"Last bake: {stats.seconds:.2f} s on {stats.device}")
            box.label(text=f"{stats.elements} elements, {stats.triangles} triangles")


class _SubPanel:
    """Where the sub-panels of Radiosity Bake sit."""

    bl_space_type = 'PROPERTIES'
    bl_region_type = 'WINDOW'
    bl_context = "render"
    bl_parent_id = RENDER_PT_radiosity_bake.__name__


class RENDER_PT_radiosity_bake_live(_SubPanel, bpy.types.Panel):
    bl_label = "Live Preview"

    def draw_header(self, context):
        self.layout.prop(context.scene.radiosity_baker_live, "enabled", text="")

    def draw(self, context):
        from . import live

        layout = self.layout
        s = context.scene.radiosity_baker
        layout.prop(context.scene.radiosity_baker_live, "keep")
        layout.label(text=f"Shows '{live.preview_attribute(s)}' (Solid › Attribute colour)")
        running = live.session()
        if running is not None:
            layout.label(text=running.status())
            if running.error:
                layout.label(text=running.error, icon='ERROR')


class RENDER_PT_radiosity_bake_advanced(_SubPanel, bpy.types.Panel):
    bl_label = "Advanced"
    bl_options = {'DEFAULT_CLOSED'}

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        s = context.scene.radiosity_baker
        for name in ("tolerance", "max_pairs", "link_memory", "seed"):
            _prop(layout, s, name)


classes = (RENDER_PT_radiosity_bake, RENDER_PT_radiosity_bake_live, RENDER_PT_radiosity_bake_advanced)
