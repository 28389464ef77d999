"""Shading vertices and surface elements.

A *shading vertex* is a mesh vertex with one shading normal: a vertex whose triangle corners carry
different normals (a hard edge) is split into one shading vertex per distinct normal. Results for
color attributes are wanted there.

*Elements* are the unknowns of the solvers: here one oriented disk per shading vertex (Bunnell).
The front face (along the normal) emits and reflects; the back face casts shadow only, so light
reaching the back of a surface without thickness (``open_objects``) is not passed on
(``core.direct.lit_backs`` finds where that happens). Solvers that need other elements map them to
receivers through ``core.receivers``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .scene import SceneData

# Fraction of the way from a border vertex towards the centre of its triangle fan its receiver
# point moves.
NUDGE = 0.01
# Corner normals are grouped per vertex after rounding to 1/1024 (≈0.06°): corners of a smooth
# vertex carry the same normal, corners on either side of a hard edge differ by far more.
NORMAL_STEPS = 1024


@dataclass
class ShadingVertices:
    """S points where a mesh vertex meets one shading normal.

    position, normal: float32[S,3] (m, unit); vertex: int32[S] the mesh vertex of each;
    corner: int32[T,3] the shading vertex of each triangle corner (the scene's triangles over
    shading vertices).
    """

    position: np.ndarray
    normal: np.ndarray
    vertex: np.ndarray
    corner: np.ndarray

    @property
    def count(self) -> int:
        return int(self.position.shape[0])


def shading_vertices(scene: SceneData) -> ShadingVertices:
    """Split ``scene``'s vertices where their triangle corners' normals differ."""
    t = scene.num_triangles
    corner_vertex = scene.triangles.reshape(-1).astype(np.int64)
    normals = np.nan_to_num(np.asarray(scene.corner_normals, np.float32).reshape(-1, 3))
    q = np.rint(normals * NORMAL_STEPS).astype(np.int64) + NORMAL_STEPS
    if scene.num_vertices < 1 << 27:  # vertex index and three 12-bit normal components fit one int64
        key = (corner_vertex << 36) | (q[:, 0] << 24) | (q[:, 1] << 12) | q[:, 2]
        _, first, grouped = np.unique(key, return_index=True, return_inverse=True)
    else:
        _, first, grouped = np.unique(np.column_stack([corner_vertex, q]), axis=0, return_index=True,
                                      return_inverse=True)
    # Numbered by vertex, then by their first corner, not by the normal's value: a deforming mesh
    # (an animation's frames) keeps its shading vertices in the same order.
    order = np.lexsort((first, corner_vertex[first]))
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    first, corner = first[order], rank[grouped.reshape(-1)]
    vertex = corner_vertex[first].astype(np.int32)
    n = normals[first].astype(np.float64)
    length = np.linalg.norm(n, axis=1, keepdims=True)
    n = np.where(length > 0, n / np.where(length > 0, length, 1.0), (0.0, 0.0, 1.0))
    return ShadingVertices(position=np.ascontiguousarray(scene.positions[vertex], np.float32),
                           normal=n.astype(np.float32), vertex=vertex,
                           corner=corner.reshape(t, 3).astype(np.int32))


def _edge_keys(tris: np.ndarray) -> tuple[np.ndarray, int]:
    """(int64[3T]: each triangle edge (its edges 01, 12, 20 in turn) as one number, lower vertex ×
    stride + higher, the same for both triangles that share it; stride: the largest vertex + 1).
    A 1-D key: ``np.unique`` over rows of two is ~10× slower."""
    a = np.concatenate([tris[:, 0], tris[:, 1], tris[:, 2]]).astype(np.int64)
    b = np.concatenate([tris[:, 1], tris[:, 2], tris[:, 0]]).astype(np.int64)
    stride = int(tris.max()) + 1 if tris.size else 1
    return np.minimum(a, b) * stride + np.maximum(a, b), stride


def open_objects(scene: SceneData) -> np.ndarray:
    """bool[O]: for each of ``scene``'s objects, whether its surface is open — some mesh edge
    borders one triangle with area only: a surface without thickness (a leaf card, a banner, a
    floor plane), whose back can be seen and lit."""
    tris = scene.triangles[scene.triangle_areas() > 0]
    _, inverse, uses = np.unique(_edge_keys(tris)[0], return_inverse=True, return_counts=True)
    open_triangle = (uses[inverse.reshape(-1)] == 1).reshape(3, -1).any(axis=0)
    out = np.zeros(len(scene.object_names), bool)
    out[scene.tri_object[scene.triangle_areas() > 0][open_triangle]] = True
    return out


@dataclass
class Elements:
    """n disks, one per shading vertex.

    position, normal: float32[n,3] (m, unit); a vertex on the border of its surface is moved 1 %
    towards the centre of its triangle fan (see NUDGE). area: float32[n] (m²), a third of the
    adjacent triangles' area. albedo, emission: float32[n,3], area-weighted means over adjacent
    triangles (emission in radiance units). vertex: int32[n] the mesh vertex each sits on.
    fan_offsets: int32[n+1] and fan_triangles: int32[3T] list, per element, the triangles it is a
    corner of (CSR), for exact near-field form factors; fan_outline: int32[3T,3] per entry of that
    list, its triangle's edge opposite the element and how it joins the fan (``fan_outline``).
    corner: int32[T,3] the element of each triangle corner.
    """

    position: np.ndarray
    normal: np.ndarray
    area: np.ndarray
    albedo: np.ndarray
    emission: np.ndarray
    vertex: np.ndarray
    fan_offsets: np.ndarray
    fan_triangles: np.ndarray
    fan_outline: np.ndarray
    corner: np.ndarray

    @property
    def count(self) -> int:
        return int(self.position.shape[0])

    def objects(self, scene: SceneData) -> np.ndarray:
        """int32[n]: the object (index into ``scene.object_names``) of each element."""
        return scene.tri_object[self.fan_triangles[self.fan_offsets[:-1]]]


# Flags of a fan entry (``fan_outline``): its triangle's first spoke (from the element's vertex to
# the next corner) is open, its second (from the corner after that back to the vertex) is open,
# the fan repeats a spoke (its outline is no simple sum).
FAN_OPEN_OUT, FAN_OPEN_IN, FAN_TANGLED = 1, 2, 4


def fan_outline(triangles: np.ndarray, corners: np.ndarray, order: np.ndarray) -> np.ndarray:
    """int32[3T,3]: per fan entry (``order``: the triangle corners, 3·t + c, in fan order;
    ``corners``: int[3T] the element of each corner; ``triangles``: int[T,3] mesh vertices), the
    mesh vertices of its triangle's edge opposite the element (the corners after the element's,
    in winding order) and its flags: FAN_OPEN_OUT / FAN_OPEN_IN where the triangle's spoke from
    (to) the element's vertex is shared with no other triangle of the fan (in the opposite
    direction), FAN_TANGLED on every entry of a fan that repeats a spoke in one direction (not a
    manifold fan).

    Summed over a fan, the contour integrals of its triangles' edges cancel along shared spokes,
    so a point that sees every triangle of a fan from one side, unclipped, sees the fan as those
    edges plus its open spokes (``surfels.outline_fan_ff``)."""
    t, c = order // 3, order % 3
    e = corners[order].astype(np.int64)
    after, then = triangles[t, (c + 1) % 3], triangles[t, (c + 2) % 3]
    stride = int(triangles.max()) + 1 if triangles.size else 1
    out_key, in_key = e * stride + after, e * stride + then
    flags = FAN_OPEN_OUT * ~np.isin(out_key, in_key) + FAN_OPEN_IN * ~np.isin(in_key, out_key)
    tangled = np.zeros(int(e.max()) + 1 if e.size else 0, bool)
    for key in (out_key, in_key):
        uniq, uses = np.unique(key, return_counts=True)
        tangled[uniq[uses > 1] // stride] = True
    flags[tangled[e]] |= FAN_TANGLED
    return np.stack([after, then, flags], axis=1).astype(np.int32)


@dataclass
class Fans:
    """What ``build`` takes from the topology alone, the same for every frame of a deforming mesh
    (``Problem.move`` keeps it): border: bool[n] the elements on an edge of one triangle;
    fan_offsets, fan_triangles, fan_outline: as in ``Elements``."""

    border: np.ndarray
    fan_offsets: np.ndarray
    fan_triangles: np.ndarray
    fan_outline: np.ndarray


def fans(scene: SceneData, shading: ShadingVertices) -> Fans:
    """The ``Fans`` of ``shading``'s elements over ``scene``'s triangles."""
    n, tris = shading.count, shading.corner
    corners = tris.reshape(-1)
    keys, stride = _edge_keys(tris)
    keys, uses = np.unique(keys, return_counts=True)
    once = keys[uses == 1]
    border = np.zeros(n, bool)
    border[once // stride] = True
    border[once % stride] = True
    order = np.argsort(corners, kind="stable")
    fan_offsets = np.zeros(n + 1, np.int32)
    np.cumsum(np.bincount(corners, minlength=n), out=fan_offsets[1:])
    return Fans(border=border, fan_offsets=fan_offsets, fan_triangles=(order // 3).astype(np.int32),
                fan_outline=fan_outline(scene.triangles, corners, order))


def build(scene: SceneData, shading: ShadingVertices | None = None, topology: Fans | None = None) -> Elements:
    """One disk per shading vertex of ``scene`` (split here unless given); vertices in no triangle
    with area get zero area. ``topology``: ``fans(scene, shading)`` when known (an animation's
    earlier frame)."""
    shading = shading if shading is not None else shading_vertices(scene)
    topology = topology if topology is not None else fans(scene, shading)
    n = shading.count
    tris = shading.corner
    tri_area = scene.triangle_areas()
    corners = tris.reshape(-1)
    share = np.repeat(tri_area / 3.0, 3)
    area = np.bincount(corners, weights=share, minlength=n)

    def weighted(values: np.ndarray) -> np.ndarray:
        per_corner = np.repeat(values.astype(np.float64), 3, axis=0) * share[:, None]
        acc = np.stack([np.bincount(corners, weights=per_corner[:, c], minlength=n) for c in range(3)], axis=1)
        return acc / np.where(area > 0, area, 1.0)[:, None]

    # Receivers on the border of their surface move a hair into their fan: a floor vertex on the
    # edge where a wall stands lies in the wall's plane and would see it edge-on (F = 0), while
    # the lighting there is the limit from the surface's interior (what Cycles' offset rays see).
    # They move towards the centre of their largest triangle, so they stay in its plane (on a
    # curved fan a point between the planes would see its own triangles from behind). Interior
    # vertices stay put, so closed and curved surfaces are untouched.
    p = shading.position.astype(np.float64)
    border = topology.border & (area > 0)
    position = p.copy()
    # the largest triangle of each vertex; of triangles equal to 10⁻⁴ the first, so that rounding
    # (a moved copy of the mesh) cannot pick another
    most = np.zeros(n)
    np.maximum.at(most, corners, share)
    candidate = share >= most[corners] * (1.0 - 1e-4)
    largest = np.full(n, np.iinfo(np.int64).max)
    np.minimum.at(largest, corners[candidate], np.flatnonzero(candidate) // 3)
    largest[largest == np.iinfo(np.int64).max] = 0
    centre = p[tris[largest]].mean(axis=1)
    position[border] += NUDGE * (centre[border] - p[border])

    return Elements(
        position=position.astype(np.float32),
        normal=shading.normal,
        area=area.astype(np.float32),
        albedo=weighted(scene.albedo).astype(np.float32),
        emission=weighted(scene.emission).astype(np.float32),
        vertex=shading.vertex,
        fan_offsets=topology.fan_offsets,
        fan_triangles=topology.fan_triangles,
        fan_outline=topology.fan_outline,
        corner=tris,
    )
