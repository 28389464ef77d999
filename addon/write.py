"""Bake results -> color attributes on the user's original meshes.

Everything is computed and checked first; Blender data is modified only at the end, so a problem
that can be found beforehand (a vanished object, a reserved attribute name, a name another layer
holds) leaves the file as it was; the same checks run when a bake starts (``check_color_attributes``).
"""
from __future__ import annotations

from dataclasses import dataclass

import bpy
import numpy as np

from .extract import Extraction, ExtractionError, TargetMesh, realize_copy
from .outputs import OutputError


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


# Names Blender keeps for its own mesh attributes, with a fixed domain and type: a color attribute
# cannot take them. Names starting with "." are internal (hidden); Blender cuts names longer than
# MAX_NAME_BYTES (UTF-8) when it makes them unique.
RESERVED_NAMES = frozenset({"position", "material_index", "sharp_face", "sharp_edge"})
MAX_NAME_BYTES = 63


def check_attribute_name(name: str) -> None:
    """Raise OutputError unless Blender can hold a color attribute called ``name`` on any mesh."""
    if name in RESERVED_NAMES or name.startswith("."):
        raise OutputError(f"attribute name {name!r} is reserved by Blender: choose another name")
    if len(name.encode("utf-8")) > MAX_NAME_BYTES:
        raise OutputError(f"attribute name {name[:20]!r}… is {len(name.encode('utf-8'))} bytes long: "
                          f"Blender allows {MAX_NAME_BYTES} (UTF-8)")


def name_clash(ob, mesh, name: str, keep: str):
    """What already holds ``name`` on ``mesh`` (the data of ``ob``), as words, unless it is a layer
    of the kind ``keep`` (``"color"``: a color attribute, ``"uv"``: a UV map); None when nothing
    else does. A mesh's attributes, UV maps and vertex groups share one set of names, so a layer
    of another kind can never be replaced by ours."""
    if name in mesh.uv_layers:
        return None if keep == "uv" else "a UV map"
    attr = mesh.attributes.get(name)
    if attr is not None:
        if name in mesh.color_attributes:
            return None if keep == "color" else "a color attribute"
        return f"a {attr.data_type} attribute on the {attr.domain} domain"
    if name in ob.vertex_groups:
        return "a vertex group"
    return None


@dataclass
class ColorWrites:
    """Color-attribute writes that passed every check; ``apply`` makes them in one step and returns
    the warnings."""

    name: str
    writes: list
    warnings: list

    def apply(self, context=None) -> list[str]:
        """Modify Blender data: make the copies and write the attribute (``context``: see
        :func:`write_color_attributes`)."""
        for w in self.writes:
            mesh = realize_copy(context or bpy.context, w.source).data if w.source is not None else w.mesh
            _write_attribute(mesh, self.name, w.rgba)
        return self.warnings


def _resolve(extraction: Extraction, attribute_name: str, settings, context):
    """(target, its object, whether it is written into a copy) per target written, and warnings.

    Raises OutputError for a reserved name, a vanished or changed object, or a name clash.
    """
    check_attribute_name(attribute_name)
    warnings: list[str] = []
    out = []
    depsgraph = None
    for target in extraction.targets:
        ob = bpy.data.objects.get(target.object_name)
        if ob is None or ob.type != "MESH":
            raise OutputError(f"object {target.object_name} no longer exists as a mesh: nothing written")
        if target.topology_changed:
            if not settings.bake_copy:
                warnings.append(
                    f"{ob.name}: its modifiers change the vertex count ({target.num_vertices} "
                    f"evaluated vs {len(ob.data.vertices)} original); apply the modifiers or "
                    f"enable 'Bake Copy' (--bake-copy)")
                continue
            depsgraph = depsgraph or (context or bpy.context).evaluated_depsgraph_get()
            mesh = ob.evaluated_get(depsgraph).data  # what the copy will hold
        elif ob.data.library is not None:
            warnings.append(f"{ob.name}: mesh {ob.data.name} is linked from a library: not written")
            continue
        else:
            mesh = ob.data
        if len(mesh.vertices) != target.num_vertices:
            raise OutputError(f"{ob.name} changed during the bake ({len(mesh.vertices)} vertices, "
                              f"{target.num_vertices} baked): nothing written")
        clash = name_clash(ob, mesh, attribute_name, "color")
        if clash is not None:
            raise OutputError(f"{ob.name}: mesh {ob.data.name} already has {clash} named "
                              f"{attribute_name!r}, which a color attribute cannot replace: choose "
                              f"another attribute name")
        out.append((target, ob, target.topology_changed))
    return out, warnings


def check_color_attributes(extraction: Extraction, attribute_name: str, settings,
                           context=None) -> None:
    """Raise OutputError now (before baking) when the results could not be written (see
    :func:`write_color_attributes`), ExtractionError when every target would be skipped (linked
    from a library, modifiers changing the vertex count): a bake that writes nothing is no
    success."""
    out, warnings = _resolve(extraction, attribute_name, settings, context)
    if extraction.targets and not out:
        more = f" (and {len(warnings) - 1} more)" if len(warnings) > 1 else ""
        raise ExtractionError(f"nothing to write: {warnings[0]}{more}")


def prepare_color_attributes(extraction: Extraction, values, attribute_name: str, settings,
                             context=None) -> ColorWrites:
    """Check everything :func:`write_color_attributes` does and compute what it writes, without
    modifying Blender data."""
    values = np.asarray(values, np.float32)
    expected = (extraction.shading.count, 3)
    if values.shape != expected:
        raise ValueError(f"values have shape {values.shape}, expected {expected}")
    resolved, warnings = _resolve(extraction, attribute_name, settings, context)
    writes: list[_Write] = []
    shared: dict[str, list] = {}  # mesh name -> [(object name, rgb)]
    meshes = {}
    for target, ob, into_copy in resolved:
        rgb = _per_vertex(target, values)
        if into_copy:
            writes.append(_Write(_rgba(rgb), source=ob))
            continue
        meshes[ob.data.name] = ob.data
        shared.setdefault(ob.data.name, []).append((ob.name, rgb))

    for mesh_name, items in shared.items():
        if len(items) > 1:
            warnings.append(f"mesh {mesh_name} is shared by {', '.join(n for n, _ in items)}: their "
                            f"results were averaged; make them single-user for separate results")
        writes.append(_Write(_rgba(np.mean([rgb for _, rgb in items], axis=0, dtype=np.float32)),
                             mesh=meshes[mesh_name]))
    return ColorWrites(attribute_name, writes, warnings)


def write_color_attributes(extraction: Extraction, values, attribute_name: str, settings,
                           context=None) -> list[str]:
    """Write per-shading-vertex ``values`` (float32[S,3], linear RGB, e.g. BakeResult.output) as a
    POINT-domain FLOAT_COLOR attribute ``attribute_name`` (alpha 1) on each target's original mesh.

    Each vertex gets the mean of its face corners' values. Only a color attribute of exactly that
    name is touched (one of another color type or domain is replaced); other attributes, UV maps,
    images, materials and the active / render colour attribute stay as they are (a mesh with no
    active colour attribute gets the new one as active so it shows).

    Targets whose modifiers change the vertex count are written into a ``<name>_baked`` copy of the
    evaluated mesh when ``settings.bake_copy``, else skipped with a warning. A mesh shared by
    several targets holds one set of attributes: it receives the average of their per-vertex
    results, with a warning suggesting to make them single-user.

    ``context`` (default ``bpy.context``) is only needed for copies. Returns the warnings; raises
    OutputError, before writing anything, for an attribute name Blender reserves, a name that a UV
    map, another attribute or a vertex group of a target holds, or an object that vanished or
    changed its vertex count since extraction (ValueError for mismatched values).
    """
    return prepare_color_attributes(extraction, values, attribute_name, settings, context).apply(context)


def _write_attribute(mesh, name: str, rgba: np.ndarray) -> None:
    """Create or overwrite POINT/FLOAT_COLOR attribute ``name`` with float32[N,4] ``rgba``; an
    existing color attribute of that name but another type or domain is replaced (callers have
    checked that no other kind of layer holds the name)."""
    colors = mesh.color_attributes
    active, default = colors.active_color_name, colors.default_color_name
    attr = colors.get(name)
    if attr is not None and (attr.domain != "POINT" or attr.data_type != "FLOAT_COLOR"):
        colors.remove(attr)
        attr = None
    if attr is None:
        attr = colors.new(name, "FLOAT_COLOR", "POINT")
    attr.data.foreach_set("color", rgba.ravel())
    # Keep the user's choice of active and render colour attributes; with none, show ours.
    colors.active_color_name = active or name
    colors.default_color_name = default or name
    mesh.update()
