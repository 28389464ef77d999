"""Lightmaps: xatlas layout (``unwrap``), texel rasterisation (``raster``), per-texel lighting,
dilation and seams (``pages``), OpenEXR / PNG files (``files``). No bpy here."""
from .pages import (ATLAS_NAME, LightmapRequest, LightmapResult, LightmapTarget, Page,
                    bake_lightmaps)

__all__ = ["ATLAS_NAME", "LightmapRequest", "LightmapResult", "LightmapTarget", "Page", "bake_lightmaps"]
