"""The light probes in Blender: the box a Light Probe Volume gives the grid, and the probes shown in
the viewport after a bake — one mesh object, ``RB Probes``, a small sphere per probe coloured by
its L0 (magenta: inside geometry), tagged (``tags.PROBES_TAG``) so that a rebake replaces it and
Clear removes it, and nothing of the user's is touched."""
from __future__ import annotations

from typing import Optional

import bpy
import numpy as np

from ..core.sh import sh9_numpy
from .extract import ExtractionError
from .tags import PROBES_TAG

NAME = "RB Probes"
ATTRIBUTE = "Probe L0"
INVALID = (1.0, 0.0, 1.0)  # the colour of a probe inside geometry
# A probe's sphere: an icosahedron of this radius relative to the smallest cell side.
RADIUS = 0.15
_T = (1.0 + 5.0 ** 0.5) / 2.0
_ICO_VERTS = np.array([(-1, _T, 0), (1, _T, 0), (-1, -_T, 0), (1, -_T, 0), (0, -1, _T), (0, 1, _T),
                       (0, -1, -_T), (0, 1, -_T), (_T, 0, -1), (_T, 0, 1), (-_T, 0, -1), (-_T, 0, 1)],
                      np.float64) / np.hypot(1.0, _T)
_ICO_FACES = np.array([(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9),
                       (5, 11, 4), (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2),
                       (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5), (2, 4, 11), (6, 2, 10),
                       (8, 6, 7), (9, 8, 1)], np.int32)


def volume_box(scene) -> tuple[Optional[tuple], Optional[np.ndarray]]:
    """((lo, hi) float64[3] each, m, world; float64[3] cell sides) of the first Light Probe Volume
    among ``scene``'s objects: the world-space bounds of its box (the unit cube under its matrix)
    and that box cut into its grid resolution; (None, None) without one. A volume whose box
    holds no volume (a scale of 0 along any of its axes, however turned) is refused naming it."""
    for ob in scene.objects:
        if ob.type == 'LIGHT_PROBE' and ob.data.type == 'VOLUME':
            m = np.array(ob.matrix_world, np.float64)
            axes = np.linalg.norm(m[:3, :3], axis=0)
            flat = abs(np.linalg.det(m[:3, :3])) <= 1e-12 * max(axes.max(), 1e-300) ** 3
            if flat or not np.all(np.isfinite(m)):
                raise ExtractionError(f"Light Probe Volume '{ob.name}' has no volume (its box is flat "
                                      "or of zero size): scale it along all three axes, or remove it "
                                      "for a grid over the whole scene")
            cube = np.array([(x, y, z, 1.0) for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)])
            corners = (cube @ m.T)[:, :3]
            lo, hi = corners.min(axis=0), corners.max(axis=0)
            resolution = np.array([ob.data.resolution_x, ob.data.resolution_y,
                                   ob.data.resolution_z], np.float64)
            return (lo, hi), (hi - lo) / resolution
    return None, None


def l0_colours(grid) -> np.ndarray:
    """float32[P,3]: each probe's L0 — the lighting (irradiance/π) its SH gives on average over
    all normals — or INVALID for a probe inside geometry."""
    mean = grid.sh[:, 0, :] * sh9_numpy(np.zeros((1, 3)))[0, 0]
    return np.where(grid.valid[:, None], mean, INVALID).astype(np.float32)


def show(context, grid) -> list[str]:
    """Replace our ``RB Probes`` object (if any) by one showing ``grid`` (``core.targets.probes.
    ProbeGrid``) in ``context.scene``; returns warnings (none)."""
    clear(list(bpy.data.objects))
    count = len(grid.points)
    radius = RADIUS * float(np.min(grid.spacing))
    verts = (grid.points[:, None, :] + radius * _ICO_VERTS[None]).reshape(-1, 3)
    faces = (_ICO_FACES[None] + len(_ICO_VERTS) * np.arange(count)[:, None, None]).reshape(-1, 3)
    mesh = bpy.data.meshes.new(NAME)
    mesh.vertices.add(len(verts))
    mesh.vertices.foreach_set("co", verts.astype(np.float32).ravel())
    mesh.loops.add(faces.size)
    mesh.loops.foreach_set("vertex_index", faces.ravel())
    mesh.polygons.add(len(faces))
    mesh.polygons.foreach_set("loop_start", np.arange(0, faces.size, 3, dtype=np.int32))
    mesh.update()
    colour = mesh.color_attributes.new(ATTRIBUTE, 'FLOAT_COLOR', 'POINT')
    rgba = np.concatenate([np.repeat(l0_colours(grid), len(_ICO_VERTS), axis=0),
                           np.ones((len(verts), 1), np.float32)], axis=1)
    colour.data.foreach_set("color", rgba.ravel())
    mesh.color_attributes.active_color = colour
    mesh.materials.append(_material())
    ob = bpy.data.objects.new(NAME, mesh)
    for block in (ob, mesh):
        block[PROBES_TAG] = True
    ob.hide_render = True  # shown, never baked or rendered
    context.scene.collection.objects.link(ob)
    return []


def _material():
    """Our emission material showing the probes' colour attribute (made once, tagged)."""
    mat = next((m for m in bpy.data.materials if m.get(PROBES_TAG)), None)
    if mat is not None:
        return mat
    mat = bpy.data.materials.new(NAME)
    mat[PROBES_TAG] = True
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    nodes.clear()
    attribute = nodes.new("ShaderNodeAttribute")
    attribute.attribute_name = ATTRIBUTE
    emission = nodes.new("ShaderNodeEmission")
    output = nodes.new("ShaderNodeOutputMaterial")
    links.new(attribute.outputs["Color"], emission.inputs["Color"])
    links.new(emission.outputs["Emission"], output.inputs["Surface"])
    return mat


def clear(objects) -> int:
    """Remove our probe objects among ``objects`` (their meshes, and the material once unused);
    returns how many data-blocks went."""
    removed = 0
    for ob in [o for o in objects if o.get(PROBES_TAG)]:
        mesh = ob.data
        bpy.data.objects.remove(ob)
        removed += 1
        if mesh is not None and mesh.get(PROBES_TAG) and mesh.users == 0:
            bpy.data.meshes.remove(mesh)
            removed += 1
    for mat in [m for m in bpy.data.materials if m.get(PROBES_TAG) and m.users == 0]:
        bpy.data.materials.remove(mat)
        removed += 1
    return removed
