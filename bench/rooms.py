"""Procedural furnished rooms of a chosen element count, for the link and solver benchmarks.

A closed 8 × 6 × 3 m room (inward-facing floor, walls, ceiling) holding a table with four legs,
two shelves, a sofa, a cabinet and a few boxes (outward-facing, flat-shaded boxes), lit by a
ceiling lamp and an area light at a window; every face is a grid of squares whose size is chosen
so the scene has about the asked-for number of elements (one per shading vertex).
"""
from __future__ import annotations

import numpy as np

from radiosity_baker.core.scene import LAMP_AREA, LAMP_POINT, LAMP_SUN, Lamps, SceneData

# (centre x, y, z, size x, y, z, albedo rgb) of the furniture, metres
FURNITURE = [
    ((0.0, 0.0, 0.74), (1.6, 0.9, 0.04), (0.55, 0.35, 0.2)),   # table top
    ((-0.75, -0.4, 0.36), (0.06, 0.06, 0.72), (0.55, 0.35, 0.2)),
    ((0.75, -0.4, 0.36), (0.06, 0.06, 0.72), (0.55, 0.35, 0.2)),
    ((-0.75, 0.4, 0.36), (0.06, 0.06, 0.72), (0.55, 0.35, 0.2)),
    ((0.75, 0.4, 0.36), (0.06, 0.06, 0.72), (0.55, 0.35, 0.2)),
    ((-3.7, 1.0, 1.0), (0.5, 1.6, 2.0), (0.7, 0.7, 0.65)),     # shelf
    ((-3.7, -1.5, 0.9), (0.5, 1.2, 1.8), (0.3, 0.45, 0.6)),    # shelf
    ((2.5, 2.4, 0.4), (2.2, 0.9, 0.8), (0.6, 0.15, 0.12)),     # sofa
    ((2.5, 2.75, 0.9), (2.2, 0.2, 0.4), (0.6, 0.15, 0.12)),    # sofa back
    ((3.4, -2.3, 0.6), (0.9, 0.6, 1.2), (0.8, 0.8, 0.8)),      # cabinet
    ((1.2, -1.8, 0.25), (0.5, 0.5, 0.5), (0.2, 0.6, 0.25)),    # boxes
    ((-1.5, 1.9, 0.2), (0.4, 0.4, 0.4), (0.75, 0.7, 0.2)),
    ((0.3, 0.1, 0.86), (0.2, 0.2, 0.2), (0.9, 0.9, 0.9)),      # a box on the table
]
ROOM = ((0.0, 0.0, 1.5), (8.0, 6.0, 3.0), (0.75, 0.72, 0.68))


def _box(centre, size, albedo, spacing, inward):
    """Six grid faces of an axis-aligned box, flat normals (outward, or inward for the room)."""
    parts = []
    c, h = np.asarray(centre, np.float64), np.asarray(size, np.float64) / 2
    for axis in range(3):
        u, v = [a for a in range(3) if a != axis]
        nu = max(1, int(round(2 * h[u] / spacing)))
        nv = max(1, int(round(2 * h[v] / spacing)))
        su, sv = np.meshgrid(np.linspace(-h[u], h[u], nu + 1), np.linspace(-h[v], h[v], nv + 1), indexing="ij")
        idx = np.arange((nu + 1) * (nv + 1)).reshape(nu + 1, nv + 1)
        a, b, cc, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
        quads = np.concatenate([np.stack([a, b, cc], 1), np.stack([a, cc, d], 1)])
        for side in (1.0, -1.0):
            pos = np.zeros((su.size, 3))
            pos[:, u], pos[:, v] = su.ravel(), sv.ravel()
            pos[:, axis] = side * h[axis]
            pos += c
            normal = np.zeros(3)
            normal[axis] = side * (-1.0 if inward else 1.0)
            tris = quads.copy()
            # counter-clockwise seen from the normal side: (u, v, axis) is right-handed for axis
            # order (0,1,2) cyclic; flip when the normal points along −(u × v)
            if np.dot(np.cross(np.eye(3)[u], np.eye(3)[v]), normal) < 0:
                tris = tris[:, ::-1]
            parts.append((pos.astype(np.float32), np.tile(normal.astype(np.float32), (len(pos), 1)),
                          np.ascontiguousarray(tris, np.int32), albedo))
    return parts


def room(elements: int) -> SceneData:
    """The furnished room with about ``elements`` elements (shading vertices)."""
    boxes = [(ROOM, True)] + [(f, False) for f in FURNITURE]
    area = sum(2 * (s[0] * s[1] + s[1] * s[2] + s[0] * s[2]) for (_, s, _), _ in boxes)
    spacing = float(np.sqrt(area / elements))
    parts = [p for (c, s, a), inward in boxes for p in _box(c, s, a, spacing, inward)]
    pos, nrm, tris, alb, obj = [], [], [], [], []
    base = 0
    for k, (p, n, t, a) in enumerate(parts):
        pos.append(p)
        nrm.append(n[t])
        tris.append(t + base)
        alb.append(np.tile(np.asarray(a, np.float32), (len(t), 1)))
        obj.append(np.full(len(t), k, np.int32))
        base += len(p)
    t_all = np.concatenate(tris)
    lamps = Lamps(kind=np.array([LAMP_POINT, LAMP_AREA], np.int32),
                  position=np.array([[0.5, -0.5, 2.6], [0.0, -2.95, 1.6]], np.float32),
                  direction=np.array([[0, 0, -1], [0, 1, 0]], np.float32),
                  axis_u=np.array([[1, 0, 0], [1, 0, 0]], np.float32),
                  axis_v=np.array([[0, 1, 0], [0, 0, 1]], np.float32),
                  size=np.array([[0.0, 0.0], [1.5, 1.0]], np.float32), shape=np.zeros(2, np.int32),
                  power=np.array([[300.0] * 3, [800.0] * 3], np.float32),
                  spot_size=np.zeros(2, np.float32), spot_blend=np.zeros(2, np.float32),
                  names=["Lamp", "Window"])
    return SceneData(positions=np.concatenate(pos), corner_normals=np.concatenate(nrm), triangles=t_all,
                     tri_object=np.concatenate(obj), albedo=np.concatenate(alb),
                     emission=np.zeros((len(t_all), 3), np.float32), lamps=lamps,
                     object_names=[f"part{k}" for k in range(len(parts))])


def sun(direction, strength: float) -> Lamps:
    """One sun shining along ``direction`` with ``strength`` (W/m²)."""
    d = np.asarray(direction, np.float32)
    return Lamps(kind=np.array([LAMP_SUN], np.int32), position=np.zeros((1, 3), np.float32),
                 direction=(d / np.linalg.norm(d))[None], axis_u=np.array([[1, 0, 0]], np.float32),
                 axis_v=np.array([[0, 1, 0]], np.float32), size=np.zeros((1, 2), np.float32),
                 shape=np.zeros(1, np.int32), power=np.full((1, 3), strength, np.float32),
                 spot_size=np.zeros(1, np.float32), spot_blend=np.zeros(1, np.float32), names=["Sun"])
