"""Lightmaps: xatlas layout (``unwrap``), texel rasterisation (``raster``), pages laid out and
assembled, dilation and seams (``pages``), OpenEXR / PNG files (``files``). No bpy here."""
from .pages import (ATLAS_NAME, Layout, LightmapObject, LightmapRequest, LightmapResult, Page,
                    assemble, lay_out, rasterize)

__all__ = ["ATLAS_NAME", "Layout", "LightmapObject", "LightmapRequest", "LightmapResult", "Page",
           "assemble", "lay_out", "rasterize"]
