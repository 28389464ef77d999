"""Scene properties: ``scene.radiosity_baker`` mirrors every field of core ``Settings``.

The properties are made from the settings' metadata (``core.settings.Option``: label, help,
default, range, choices), so the panel, the command line and core cannot disagree.
"""
from __future__ import annotations

from dataclasses import MISSING, fields

import bpy
from bpy.props import (BoolProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty,
                       StringProperty)

from ..core import settings as core_settings
from ..core.settings import Settings, option


def _items(choices):
    return [(c, c.replace("_", " ").title(), core_settings.CHOICE_HELP.get(c, "")) for c in choices]


def _property(f):
    """The bpy property of Settings field ``f``."""
    opt = option(f.name)
    common = dict(name=opt.label, description=opt.help[0].upper() + opt.help[1:], default=f.default)
    if opt.choices is not None:
        shown = [c for c in opt.choices if c not in core_settings.METHOD_ALIASES]
        return EnumProperty(items=_items(shown), **common)
    bounds = {k: v for k, v in (("min", opt.low), ("max", opt.high), ("soft_max", opt.soft_high))
              if v is not None}
    if isinstance(f.default, bool):
        return BoolProperty(**common)
    if isinstance(f.default, int):
        return IntProperty(**common, **{k: int(v) for k, v in bounds.items()})
    if isinstance(f.default, float):
        extra = {"unit": "LENGTH"} if opt.length else {}
        if opt.digits is not None:
            extra["precision"] = opt.digits
        return FloatProperty(**common, **bounds, **extra)
    if opt.folder:
        return StringProperty(**common, subtype='DIR_PATH', options={'PATH_SUPPORTS_BLEND_RELATIVE'})
    return StringProperty(**common)


class RadiosityBakeStats(bpy.types.PropertyGroup):
    """What the last bake of this scene did, for the panel."""

    seconds: FloatProperty(name="Time", description="Wall time of the last bake (s)")
    elements: IntProperty(name="Elements", description="Surface elements (shading vertices) baked")
    triangles: IntProperty(name="Triangles", description="Triangles in the baked scene")
    device: StringProperty(name="Device", description="Where the last bake ran")


def _to_settings(self) -> Settings:
    """The core Settings these properties describe (not validated)."""
    return Settings(**{f.name: getattr(self, f.name) for f in fields(Settings)})


RadiosityBakeSettings = type("RadiosityBakeSettings", (bpy.types.PropertyGroup,), {
    "__doc__": "Bake settings shown in the panel; ``to_settings()`` turns them into core Settings.",
    "__annotations__": {**{f.name: _property(f) for f in fields(Settings) if f.default is not MISSING},
                        "last_bake": PointerProperty(type=RadiosityBakeStats)},
    "to_settings": _to_settings,
})


def store_stats(scene, result, seconds: float) -> None:
    """Record a finished bake (core BakeResult, wall time in s) on ``scene`` for the panel."""
    stats = scene.radiosity_baker.last_bake
    stats.seconds = seconds
    stats.elements = int(result.counts.get("elements", 0))
    stats.triangles = int(result.counts.get("triangles", 0))
    stats.device = result.device


classes = (RadiosityBakeStats, RadiosityBakeSettings)

# An object's own lightmap texel density (``addon.lightmap.DENSITY_PROP``).
OBJECT_DENSITY = FloatProperty(
    name="Object Texel Density", default=0.0, min=0.0, soft_max=1000.0,
    description="This object's lightmap texels per metre of surface; 0 uses the bake's Texel Density")


def register() -> None:
    for cls in classes:
        bpy.utils.register_class(cls)
    bpy.types.Scene.radiosity_baker = PointerProperty(type=RadiosityBakeSettings)
    bpy.types.Object.radiosity_baker_texel_density = OBJECT_DENSITY


def unregister() -> None:
    del bpy.types.Object.radiosity_baker_texel_density
    del bpy.types.Scene.radiosity_baker
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
