"""Our per-vertex results in the shape Cycles' vertex bake returns them, for tests and benchmarks.

Nothing is written to Blender: values are mapped to original vertices exactly as the color
attribute writer would (each vertex the mean of its face corners).
"""
from __future__ import annotations

import time

import bpy
import numpy as np

from radiosity_baker.addon.extract import extract_scene
from radiosity_baker.addon.write import _per_vertex
from radiosity_baker.core import Settings, bake


def bake_vertex_values(object_names, settings: Settings):
    """Bake the current scene; return ({name: float32[V,3]} of ``settings.content``, BakeResult,
    wall seconds of extraction + bake). V is the vertex count of each object's evaluated mesh."""
    t0 = time.perf_counter()
    receivers = [bpy.data.objects[name] for name in object_names]
    extraction = extract_scene(bpy.context.evaluated_depsgraph_get(), receivers=receivers)
    result = bake(extraction.scene, settings)
    seconds = time.perf_counter() - t0
    values = {t.object_name: _per_vertex(t, result.output) for t in extraction.targets}
    return values, result, seconds


def stack(values: dict, names) -> np.ndarray:
    """float[ΣV,3]: the named objects' per-vertex values one after another."""
    return np.concatenate([values[n] for n in names])
