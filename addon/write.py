"""Bake results -> color attributes on the user's original meshes.

Everything is computed and checked first; Blender data is modified only at the end, so a problem
that can be found beforehand (a vanished object, a reserved attribute name) leaves the file as it was.
"""
from __future__ import annotations

from dataclasses import dataclass

import bpy
import numpy as np

from .extract import Extraction, TargetMesh, realize_copy


@dataclass
class _Write:
    """One mesh to write: float32[N,4] RGBA per vertex into ``mesh`` (or into a copy of ``source``)."""

    rgba: np.ndarray
    mesh: object = None
    source: object = None  # object to realise into a ``<name>_baked`` copy first


def _per_vertex(target: TargetMesh, values: np.ndarray) -> np.ndarray:
    """float32[N,3]: each vertex's mean over its face corners, as Cycles' vertex-colour bake does."""
    n = target.num_vertices
    corner = values[target.corner_shading].astype(np.float64)
    count = np.bincount(target.corner_vert, minlength=n)
    sums = np.stack([np.bincount(target.corner_vert, corner[:, k], minlength=n) for k in range(3)],
                    axis=1)
    return (sums / np.maximum(count, 1)[:, None]).astype(np.float32)


def _rgba(rgb: np.ndarray) -> np.ndarray:
    return np.concatenate([rgb, np.ones((rgb.shape[0], 1), np.float32)], axis=1)


def write_color_attributes(extraction: Extraction, values, attribute_name: str, settings,
                           context=None) -> list[str]:
    """Write per-shading-vertex ``values`` (float32[S,3], linear RGB, e.g. BakeResult.output) as a
    POINT-domain FLOAT_COLOR attribute ``attribute_name`` (alpha 1) on each target's original mesh.

    Each vertex gets the mean of its face corners' values. Only the attribute of exactly that name
    is touched: one of another domain or type is replaced; other attributes, UV maps, images,
    materials and the active / render colour attribute stay as they are (a mesh with no active
    colour attribute gets the new one as active so it shows).

    Targets whose modifiers change the vertex count are written into a ``<name>_baked`` copy of the
    evaluated mesh when ``settings.bake_copy``, else skipped with a warning. A mesh shared by
    several targets holds one set of attributes: it receives the average of their per-vertex
    results, with a warning suggesting to make them single-user.

    ``context`` (default ``bpy.context``) is only needed for copies. Returns the warnings; raises
    ValueError, before writing anything, for mismatched values, vanished objects or an attribute
    name Blender reserves.
    """
    values = np.asarray(values, np.float32)
    expected = (extraction.shading.count, 3)
    if values.shape != expected:
        raise ValueError(f"values have shape {values.shape}, expected {expected}")
    warnings: list[str] = []
    writes: list[_Write] = []
    shared: dict[str, list] = {}  # mesh name -> [(object name, rgb)]
    meshes = {}

    for target in extraction.targets:
        ob = bpy.data.objects.get(target.object_name)
        if ob is None or ob.type != "MESH":
            raise ValueError(f"object {target.object_name} no longer exists as a mesh: nothing written")
        rgb = _per_vertex(target, values)
        if target.topology_changed:
            if settings.bake_copy:
                writes.append(_Write(_rgba(rgb), source=ob))
            else:
                warnings.append(
                    f"{ob.name}: its modifiers change the vertex count ({target.num_vertices} "
                    f"evaluated vs {len(ob.data.vertices)} original); apply the modifiers or "
                    f"enable 'Bake into copy' (--bake-copy)")
            continue
        if ob.data.library is not None:
            warnings.append(f"{ob.name}: mesh {ob.data.name} is linked from a library: not written")
            continue
        meshes[ob.data.name] = ob.data
        shared.setdefault(ob.data.name, []).append((ob.name, rgb))

    for mesh_name, items in shared.items():
        if len(items) > 1:
            warnings.append(f"mesh {mesh_name} is shared by {', '.join(n for n, _ in items)}: their "
                            f"results were averaged; make them single-user for separate results")
        writes.append(_Write(_rgba(np.mean([rgb for _, rgb in items], axis=0, dtype=np.float32)),
                             mesh=meshes[mesh_name]))

    for w in writes:
        if w.mesh is not None:
            existing = w.mesh.attributes.get(attribute_name)
            if existing is not None and (existing.is_required or existing.is_internal):
                raise ValueError(f"attribute name {attribute_name!r} is reserved by Blender "
                                 f"(mesh {w.mesh.name}): nothing written")

    # Everything is known: now modify Blender data.
    for w in writes:
        mesh = realize_copy(context or bpy.context, w.source).data if w.source is not None else w.mesh
        _write_attribute(mesh, attribute_name, w.rgba)
    return warnings


def _write_attribute(mesh, name: str, rgba: np.ndarray) -> None:
    """Create or overwrite POINT/FLOAT_COLOR attribute ``name`` with float32[N,4] ``rgba``."""
    colors = mesh.color_attributes
    active, default = colors.active_color_name, colors.default_color_name
    attr = mesh.attributes.get(name)
    if attr is not None and (attr.domain != "POINT" or attr.data_type != "FLOAT_COLOR"):
        mesh.attributes.remove(attr)
        attr = None
    if attr is None:
        attr = mesh.attributes.new(name, "FLOAT_COLOR", "POINT")
    attr.data.foreach_set("color", rgba.ravel())
    # Keep the user's choice of active and render colour attributes; with none, show ours.
    colors.active_color_name = active or name
    colors.default_color_name = default or name
    mesh.update()
