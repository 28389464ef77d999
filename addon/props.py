"""Scene properties: ``scene.radiosity_baker`` mirrors every field of core ``Settings``."""
from __future__ import annotations

from dataclasses import fields

import bpy
from bpy.props import (BoolProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty,
                       StringProperty)

from ..core import settings as core_settings
from ..core.settings import Settings

_DEFAULTS = Settings()

# One line per choice for the UI tooltips; the choices themselves come from core.settings.
_ITEM_DESCRIPTIONS = {
    "direct": "Lamps and emissive surfaces only, with shadows (fast)",
    "reference": "Direct light plus multi-bounce indirect light, all element pairs with ray-cast "
                 "visibility (ground truth, small scenes)",
    "bunnell": "Direct light plus one bounce of indirect light gathered over a disk hierarchy "
               "(fast, large scenes, approximate)",
    "lighting": "Light arriving at the surface (irradiance/π), without the surface colour",
    "combined": "Emission + surface colour × lighting: what the surface looks like",
    "indirect": "Only the light that bounced off other surfaces",
    "ao": "Ambient occlusion: the unoccluded fraction of the sky within the AO distance, in all "
          "three channels (what Cycles' AO bake gives)",
    "vertex_colors": "A FLOAT_COLOR point attribute on each mesh",
    "lightmap": "OpenEXR lightmaps on a 'Lightmap' UV map, loaded as images",
    "both": "A color attribute and lightmaps",
    "atlas": "One lightmap shared by all baked objects",
    "per_object": "One lightmap per object",
    "none": "Leave materials alone",
    "node": "Add a UV Map + Image Texture node pair showing the lightmap to each material",
    "multiply": "Add the node pair and multiply the lightmap into the Base Color",
    "half": "16-bit float channels (smaller files)",
    "float": "32-bit float channels",
    "auto": "The GPU when Warp finds a usable one, else the CPU",
    "cpu": "The CPU, all cores",
    "cuda": "An NVIDIA GPU through CUDA",
}


def _items(choices):
    return [(c, c.replace("_", " ").title(), _ITEM_DESCRIPTIONS.get(c, "")) for c in choices]


class RadiosityBakeStats(bpy.types.PropertyGroup):
    """What the last bake of this scene did, for the panel."""

    seconds: FloatProperty(name="Time", description="Wall time of the last bake (s)")
    elements: IntProperty(name="Elements", description="Surface elements (shading vertices) baked")
    triangles: IntProperty(name="Triangles", description="Triangles in the baked scene")
    device: StringProperty(name="Device", description="Where the last bake ran")


class RadiosityBakeSettings(bpy.types.PropertyGroup):
    """Bake settings shown in the panel; ``to_settings()`` turns them into core ``Settings``."""

    method: EnumProperty(name="Method", items=_items(core_settings.METHODS),
                         default=_DEFAULTS.method, description="How light transport is computed")
    content: EnumProperty(name="Content", items=_items(core_settings.CONTENTS),
                          default=_DEFAULTS.content, description="Which quantity is baked")
    target: EnumProperty(name="Target", items=_items(core_settings.TARGETS),
                         default=_DEFAULTS.target, description="Where the result is written")
    attribute: StringProperty(name="Attribute", default=_DEFAULTS.attribute,
                              description="Name of the color attribute written (only this name "
                                          "is ever overwritten)")
    device: EnumProperty(name="Device", items=_items(core_settings.DEVICES),
                         default=_DEFAULTS.device, description="Where the computation runs")
    light_samples: IntProperty(name="Light Samples", default=_DEFAULTS.light_samples, min=1,
                               soft_max=256, description="Shadow samples per light and receiver "
                                                         "(softer, less noisy shadows)")
    visibility_rays: IntProperty(name="Visibility Rays", default=_DEFAULTS.visibility_rays, min=1,
                                 soft_max=64, description="Rays per element pair for the "
                                                          "visibility of indirect light")
    bounces: IntProperty(name="Bounces", default=_DEFAULTS.bounces, min=1, soft_max=128,
                         description="Maximum number of indirect bounces")
    tolerance: FloatProperty(name="Tolerance", default=_DEFAULTS.tolerance, min=1e-8, max=0.5,
                             precision=6, description="Stop bouncing when the largest change, "
                                                      "relative to the largest value, is below this")
    max_pairs: IntProperty(name="Max Pairs", default=_DEFAULTS.max_pairs, min=1,
                           description="Memory budget of the all-pairs transport, in element "
                                       "pairs (4 bytes each)")
    seed: IntProperty(name="Seed", default=_DEFAULTS.seed, min=0,
                      description="Random seed of the sample jitter")
    bake_copy: BoolProperty(name="Bake Copy", default=_DEFAULTS.bake_copy,
                            description="When modifiers change an object's vertex count, bake into "
                                        "a new object '<name>_baked' instead of skipping it")
    ao_distance: FloatProperty(name="AO Distance", default=_DEFAULTS.ao_distance, min=0.0,
                               soft_max=100.0, unit='LENGTH', description="Occluders farther than "
                               "this do not count for AO; 0 uses the world's AO distance")
    texel_density: FloatProperty(name="Texel Density", default=_DEFAULTS.texel_density, min=1e-3,
                                 soft_max=1000.0, description="Lightmap texels per metre of surface")
    max_size: IntProperty(name="Max Size", default=_DEFAULTS.max_size, min=16, soft_max=8192,
                          description="Largest lightmap side in texels; the density is lowered "
                                      "until the atlas fits")
    padding: IntProperty(name="Padding", default=_DEFAULTS.padding, min=1, soft_max=16,
                         description="Texels between lightmap charts, filled by dilation")
    layout: EnumProperty(name="Layout", items=_items(core_settings.LAYOUTS),
                         default=_DEFAULTS.layout, description="How lightmaps are shared")
    output: StringProperty(name="Output", default=_DEFAULTS.output, subtype='DIR_PATH',
                           options={'PATH_SUPPORTS_BLEND_RELATIVE'},
                           description="Folder the EXR lightmaps and PNG previews are written to "
                                       "('//' is the .blend's folder)")
    hookup: EnumProperty(name="Hook Up", items=_items(core_settings.HOOKUPS),
                         default=_DEFAULTS.hookup, description="Whether to show the lightmap "
                                                               "in the objects' materials")
    reunwrap: BoolProperty(name="Re-unwrap", default=_DEFAULTS.reunwrap,
                           description="Make new 'Lightmap' UVs even where a mesh already has them")
    supersample: IntProperty(name="Supersample", default=_DEFAULTS.supersample, min=1, max=8,
                             description="Lighting samples per texel along each axis")
    texel_indirect: EnumProperty(name="Texel Indirect", items=_items(core_settings.TEXEL_INDIRECT),
                                 default=_DEFAULTS.texel_indirect,
                                 description="Indirect light per texel: the per-vertex solution "
                                             "interpolated, or that plus the detail of a final "
                                             "gather over the element hierarchy at each texel")
    lightmap_format: EnumProperty(name="EXR Format", items=_items(core_settings.LIGHTMAP_FORMATS),
                                  default=_DEFAULTS.lightmap_format,
                                  description="Precision of the EXR channels")
    pack_images: BoolProperty(name="Pack Images", default=_DEFAULTS.pack_images,
                              description="Pack the lightmap images into the .blend file")
    last_bake: PointerProperty(type=RadiosityBakeStats)

    def to_settings(self) -> Settings:
        """The core Settings these properties describe (not validated)."""
        return Settings(**{f.name: getattr(self, f.name) for f in fields(Settings)})


def store_stats(scene, result, seconds: float) -> None:
    """Record a finished bake (core BakeResult, wall time in s) on ``scene`` for the panel."""
    stats = scene.radiosity_baker.last_bake
    stats.seconds = seconds
    stats.elements = int(result.counts.get("elements", 0))
    stats.triangles = int(result.counts.get("triangles", 0))
    stats.device = result.device


classes = (RadiosityBakeStats, RadiosityBakeSettings)


def register() -> None:
    for cls in classes:
        bpy.utils.register_class(cls)
    bpy.types.Scene.radiosity_baker = PointerProperty(type=RadiosityBakeSettings)


def unregister() -> None:
    del bpy.types.Scene.radiosity_baker
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
