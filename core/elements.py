"""Surface elements: one oriented disk per shading vertex (Bunnell).

The front face (along the normal) emits and reflects; the back face casts shadow only.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .scene import SceneData

# Fraction of the way from a border vertex towards the centre of its triangle fan its receiver
# point moves.
NUDGE = 0.01


@dataclass
class Elements:
    """n disks.

    position, normal: float32[n,3] (m, unit); a vertex on the border of its surface is moved 1 %
    towards the centre of its triangle fan (see NUDGE). area: float32[n] (m²), a third of the adjacent
    triangles' area. albedo, emission: float32[n,3], area-weighted means over adjacent triangles
    (emission in radiance units). fan_offsets: int32[n+1] and fan_triangles: int32[3T] list, per
    element, the triangles it is a corner of (CSR), for exact near-field form factors.
    """

    position: np.ndarray
    normal: np.ndarray
    area: np.ndarray
    albedo: np.ndarray
    emission: np.ndarray
    fan_offsets: np.ndarray
    fan_triangles: np.ndarray

    @property
    def count(self) -> int:
        return int(self.position.shape[0])


def build(scene: SceneData) -> Elements:
    """Elements of ``scene``'s shading vertices; vertices in no triangle get zero area."""
    n = scene.num_vertices
    tris = scene.triangles
    tri_area = scene.triangle_areas().astype(np.float64)
    tri_area = np.where(np.isfinite(tri_area), tri_area, 0.0)
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
    # Interior vertices stay put, so closed and curved surfaces are untouched.
    p = scene.positions.astype(np.float64)
    edges = np.sort(np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]]), axis=1)
    uniq, uses = np.unique(edges, axis=0, return_counts=True)
    border = np.zeros(n, bool)
    border[uniq[uses == 1].ravel()] = True
    border &= area > 0
    position = p.copy()
    position[border] += NUDGE * (weighted(p[tris].mean(axis=1))[border] - p[border])

    order = np.argsort(corners, kind="stable")
    fan_triangles = (order // 3).astype(np.int32)
    fan_offsets = np.zeros(n + 1, np.int32)
    np.cumsum(np.bincount(corners, minlength=n), out=fan_offsets[1:])
    return Elements(
        position=position.astype(np.float32),
        normal=np.ascontiguousarray(scene.normals, np.float32),
        area=area.astype(np.float32),
        albedo=weighted(scene.albedo).astype(np.float32),
        emission=weighted(scene.emission).astype(np.float32),
        fan_offsets=fan_offsets,
        fan_triangles=fan_triangles,
    )
