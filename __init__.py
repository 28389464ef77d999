"""Radiosity Baker: bakes global illumination into Blender meshes.

As a Blender extension this module only forwards ``register``/``unregister`` to ``addon``; it
imports nothing at import time, so ``radiosity_baker.core`` stays usable without bpy.
Blender's glTF exporter and importer look for ``glTF2ExportUserExtension`` /
``glTF2ImportUserExtension`` on this module of each enabled add-on: they are handed out on first
access (``addon.gltf``).
"""


def register():
    from . import addon
    addon.register()


def unregister():
    from . import addon
    addon.unregister()


def __getattr__(name):
    if name in ("glTF2ExportUserExtension", "glTF2ImportUserExtension"):
        from .addon import gltf
        return getattr(gltf, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
