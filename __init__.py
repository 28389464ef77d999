"""Radiosity Baker: bakes global illumination into Blender meshes.

As a Blender extension this module only forwards ``register``/``unregister`` to ``addon``; it
imports nothing at import time, so ``radiosity_baker.core`` stays usable without bpy.
"""


def register():
    from . import addon
    addon.register()


def unregister():
    from . import addon
    addon.unregister()
