"""Radiosity Baker computation core: numpy + NVIDIA Warp, never imports bpy.

Public surface: :class:`Settings`, :class:`SceneData`, :class:`Lamps`, :func:`bake`.
"""
from .settings import Settings
from .scene import Lamps, SceneData
from .pipeline import BakeCancelled, BakeError, BakeResult, bake

__all__ = ["Settings", "SceneData", "Lamps", "bake", "BakeResult", "BakeError", "BakeCancelled"]
