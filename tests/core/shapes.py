"""Small scenes built in code for the core tests (no bpy)."""
from __future__ import annotations

import numpy as np

from radiosity_baker.core import targets
from radiosity_baker.core.lightmap import LightmapObject
from radiosity_baker.core.scene import LAMP_POINT, Lamps, SceneData


def with_lightmap(request) -> list:
    """The targets of a bake into the shading vertices and the lightmaps of ``request``."""
    return [targets.make("vertices"), targets.make("lightmap", request)]


def grid(size: float, n: int, z: float = 0.0, flip: bool = False):
    """An n×n-quad square of side ``size`` centred at the origin at height z, normal +Z (−Z if flip).

    Returns positions float32[(n+1)²,3], normals, triangles int32[2n²,3] (CCW from the normal side).
    """
    s = np.linspace(-size / 2, size / 2, n + 1)
    x, y = np.meshgrid(s, s, indexing="xy")
    pos = np.stack([x.ravel(), y.ravel(), np.full(x.size, z)], axis=1).astype(np.float32)
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, 1:].ravel(), idx[1:, :-1].ravel()
    tris = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)]).astype(np.int32)
    nrm = np.tile(np.array([0, 0, 1], np.float32), (len(pos), 1))
    if flip:
        tris = tris[:, ::-1].copy()
        nrm = -nrm
    return pos, nrm, tris


def icosphere(radius: float = 1.0, subdivisions: int = 3, inward: bool = True):
    """A closed sphere; normals and winding face inward if ``inward``."""
    t = (1 + 5 ** 0.5) / 2
    v = np.array([[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t], [0, -1, -t],
                  [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]], np.float64)
    f = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4],
                  [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8],
                  [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]])
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    for _ in range(subdivisions):
        edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
        uniq, inv = np.unique(edges, axis=0, return_inverse=True)
        mid = v[uniq].mean(axis=1)
        mid /= np.linalg.norm(mid, axis=1, keepdims=True)
        m = inv.reshape(3, -1).T + len(v)
        v = np.concatenate([v, mid])
        f = np.concatenate([np.stack([f[:, 0], m[:, 0], m[:, 2]], 1), np.stack([f[:, 1], m[:, 1], m[:, 0]], 1),
                            np.stack([f[:, 2], m[:, 2], m[:, 1]], 1), m])
    nrm = v.copy()
    if inward:
        f = f[:, ::-1]
        nrm = -nrm
    return (v * radius).astype(np.float32), nrm.astype(np.float32), np.ascontiguousarray(f, np.int32)


def flat(p: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Flat shading of triangles t over positions p: each corner gets its face's normal (the side
    its winding faces), float32[T,3,3]."""
    p = np.asarray(p, np.float64)
    normal = np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    return np.repeat(normal[:, None], 3, 1).astype(np.float32)


def torus(major: float = 1.0, minor: float = 0.4, around: int = 24, tube: int = 12, inward: bool = True):
    """A closed torus about +Z (ring radius ``major``, tube radius ``minor``), ``around`` × ``tube``
    quads; normals and winding face into the tube if ``inward``."""
    u, v = np.meshgrid(np.arange(around) * 2 * np.pi / around, np.arange(tube) * 2 * np.pi / tube, indexing="ij")
    u, v = u.ravel(), v.ravel()
    ring = major + minor * np.cos(v)
    pos = np.stack([ring * np.cos(u), ring * np.sin(u), minor * np.sin(v)], 1)
    nrm = np.stack([np.cos(v) * np.cos(u), np.cos(v) * np.sin(u), np.sin(v)], 1)
    idx = np.arange(around * tube).reshape(around, tube)
    a, b = idx, np.roll(idx, -1, axis=0)
    c, d = np.roll(b, -1, axis=1), np.roll(a, -1, axis=1)
    tris = np.concatenate([np.stack([a.ravel(), b.ravel(), c.ravel()], 1), np.stack([a.ravel(), c.ravel(), d.ravel()], 1)])
    if inward:
        tris, nrm = tris[:, ::-1], -nrm
    return pos.astype(np.float32), nrm.astype(np.float32), np.ascontiguousarray(tris, np.int32)


def lamp(kind: int, position=(0, 0, 0), direction=(0, 0, -1), size=(0.0, 0.0), shape=0,
         power=(1.0, 1.0, 1.0), spot_size=0.0, spot_blend=0.0, axis_u=(1, 0, 0), axis_v=(0, 1, 0)) -> Lamps:
    def row(x):
        return np.array([x], np.float32)
    return Lamps(kind=np.array([kind], np.int32), position=row(position), direction=row(direction),
                 axis_u=row(axis_u), axis_v=row(axis_v), size=row(size), shape=np.array([shape], np.int32),
                 power=row(power), spot_size=np.array([spot_size], np.float32),
                 spot_blend=np.array([spot_blend], np.float32), names=["Lamp"])


def scene(parts, lamps: Lamps | None = None) -> SceneData:
    """SceneData from [(positions, normals, triangles, albedo rgb, emission rgb), ...]: normals per
    vertex [V,3] or per triangle corner [T,3,3] (``flat``)."""
    pos, nrm, tris, alb, emi, obj = [], [], [], [], [], []
    base = 0
    for k, (p, n, t, a, e) in enumerate(parts):
        pos.append(p)
        nrm.append(n[t] if n.ndim == 2 else n)
        tris.append(t + base)
        alb.append(np.tile(np.asarray(a, np.float32), (len(t), 1)))
        emi.append(np.tile(np.asarray(e, np.float32), (len(t), 1)))
        obj.append(np.full(len(t), k, np.int32))
        base += len(p)
    return SceneData(positions=np.concatenate(pos), corner_normals=np.concatenate(nrm),
                     triangles=np.concatenate(tris), tri_object=np.concatenate(obj),
                     albedo=np.concatenate(alb), emission=np.concatenate(emi),
                     lamps=lamps if lamps is not None else Lamps.empty(),
                     object_names=[f"part{k}" for k in range(len(parts))])


def disk(radius: float, rings: int, segments: int, z: float = 0.0, flip: bool = False):
    """A flat disk of concentric rings at height z, normal +Z (−Z if flip); a centre vertex plus
    ``rings`` rings of ``segments`` vertices."""
    r = np.repeat(np.arange(1, rings + 1) / rings * radius, segments)
    a = np.tile(np.arange(segments) * 2 * np.pi / segments, rings)
    pos = np.concatenate([[[0, 0, z]], np.stack([r * np.cos(a), r * np.sin(a), np.full(r.size, z)], 1)])
    ring = lambda k: 1 + k * segments + np.arange(segments)  # noqa: E731
    nxt = lambda idx, k: 1 + k * segments + (idx - 1 - k * segments + 1) % segments  # noqa: E731
    tris = [np.stack([np.zeros(segments, int), ring(0), nxt(ring(0), 0)], 1)]
    for k in range(rings - 1):
        a0, a1 = ring(k), nxt(ring(k), k)
        b0, b1 = ring(k + 1), nxt(ring(k + 1), k + 1)
        tris += [np.stack([a0, b0, b1], 1), np.stack([a0, b1, a1], 1)]
    tris = np.concatenate(tris).astype(np.int32)
    nrm = np.tile(np.array([0, 0, 1], np.float32), (len(pos), 1))
    if flip:
        tris = tris[:, ::-1].copy()
        nrm = -nrm
    return pos.astype(np.float32), nrm, tris


# Rotations taking +Z to each face normal of an axis-aligned box (proper rotations: windings stay
# counter-clockwise about the rotated normal).
_FACES = [np.eye(3), np.diag([1.0, -1.0, -1.0]), np.array([[0, 0, 1], [0, 1, 0], [-1, 0, 0]], float),
          np.array([[0, 0, -1], [0, 1, 0], [1, 0, 0]], float), np.array([[1, 0, 0], [0, 0, 1], [0, -1, 0]], float),
          np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]], float)]


def box(size: float, n: int, centre=(0.0, 0.0, 0.0), inward: bool = False):
    """The six faces of a cube of side ``size`` at ``centre``, n×n quads each, flat normals facing
    out (in if ``inward``): a list of (positions, normals, triangles) for ``scene``."""
    p, nrm, t = grid(size, n)
    out = []
    for rot in _FACES:
        q = p @ rot.T + rot @ np.array([0.0, 0.0, size / 2]) + np.asarray(centre)
        normal = nrm @ rot.T
        tris = t
        if inward:
            normal, tris = -normal, t[:, ::-1]
        out.append((q.astype(np.float32), normal.astype(np.float32), np.ascontiguousarray(tris, np.int32)))
    return out


def quad(corners, nu: int, nv: int, towards):
    """A planar quad (corners a, b, c, d in order) as nu×nv cells, its normal facing the point
    ``towards``: (positions, normals, triangles) for ``scene``."""
    a, b, c, d = (np.asarray(x, np.float64) for x in corners)
    s, t = np.meshgrid(np.linspace(0, 1, nu + 1), np.linspace(0, 1, nv + 1), indexing="xy")
    s, t = s.ravel()[:, None], t.ravel()[:, None]
    pos = (1 - s) * (1 - t) * a + s * (1 - t) * b + s * t * c + (1 - s) * t * d
    idx = np.arange((nu + 1) * (nv + 1)).reshape(nv + 1, nu + 1)
    p0, p1, p2, p3 = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, 1:].ravel(), idx[1:, :-1].ravel()
    tris = np.concatenate([np.stack([p0, p1, p2], 1), np.stack([p0, p2, p3], 1)])
    normal = np.cross(b - a, d - a)
    normal /= np.linalg.norm(normal)
    if normal @ (np.asarray(towards, np.float64) - pos.mean(axis=0)) < 0:
        normal, tris = -normal, tris[:, ::-1]
    nrm = np.tile(normal, (len(pos), 1))
    return pos.astype(np.float32), nrm.astype(np.float32), np.ascontiguousarray(tris, np.int32)


def cornell_box(cells: int = 8):
    """The Cornell box (ALGORITHMS.md §8: Cornell's data in mm, y up, as metres with z up), walls
    of cells×cells quads, the two blocks, and the light as ``sample_blends/make_samples.py`` makes
    it: a black quad 1 mm under the ceiling emitting radiance 16 (from both faces, as Blender's
    emissive meshes do); white 0.73, red (0.65, 0.05, 0.05), green (0.12, 0.45, 0.15)."""
    def m(*points):
        return [np.array([x, z, y]) / 1000.0 for x, y, z in points]

    white, red, green = (0.73,) * 3, (0.65, 0.05, 0.05), (0.12, 0.45, 0.15)
    inside = m((278, 274, 280))[0]
    walls = [(m((552.8, 0, 0), (0, 0, 0), (0, 0, 559.2), (549.6, 0, 559.2)), white),
             (m((556, 548.8, 0), (556, 548.8, 559.2), (0, 548.8, 559.2), (0, 548.8, 0)), white),
             (m((549.6, 0, 559.2), (0, 0, 559.2), (0, 548.8, 559.2), (556, 548.8, 559.2)), white),
             (m((0, 0, 559.2), (0, 0, 0), (0, 548.8, 0), (0, 548.8, 559.2)), red),
             (m((552.8, 0, 0), (549.6, 0, 559.2), (556, 548.8, 559.2), (556, 548.8, 0)), green)]
    parts = [(*quad(c, cells, cells, inside), albedo, (0,) * 3) for c, albedo in walls]
    for top, height in ((((130, 165, 65), (82, 165, 225), (240, 165, 272), (290, 165, 114)), 165),
                        (((423, 330, 247), (265, 330, 296), (314, 330, 456), (472, 330, 406)), 330)):
        corners = m(*top)
        centre = sum(corners) / 4 - np.array([0, 0, height / 2000.0])
        parts.append((*quad(corners, 3, 3, centre + np.array([0, 0, 1.0])), white, (0,) * 3))
        rows = max(2, round(height / 60))
        for k in range(4):
            a, b = corners[k], corners[(k + 1) % 4]
            side = [a, b, b - np.array([0, 0, height / 1000.0]), a - np.array([0, 0, height / 1000.0])]
            outward = (a + b) / 2 + ((a + b) / 2 - centre) * np.array([1, 1, 0])
            parts.append((*quad(side, 3, rows, outward), white, (0,) * 3))
    light = m((343, 547.8, 227), (343, 547.8, 332), (213, 547.8, 332), (213, 547.8, 227))
    parts.append((*quad(light, 2, 2, inside), (0,) * 3, (16.0,) * 3))
    return scene(parts)


def crates(count=6):
    """``count`` 1 m boxes side by side on no floor, lit from above: the scene and one
    ``LightmapObject`` per box (its six faces)."""
    parts = []
    for k in range(count):
        for rot in ([0, 0, 0], [np.pi / 2, 0, 0], [np.pi, 0, 0], [-np.pi / 2, 0, 0], [0, np.pi / 2, 0], [0, -np.pi / 2, 0]):
            p, n, t = grid(1.0, 2, z=0.5)
            cx, sx, cy, sy = np.cos(rot[0]), np.sin(rot[0]), np.cos(rot[1]), np.sin(rot[1])
            r = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]]) @ np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
            parts.append(((p @ r.T + (1.5 * k, 0, 0.5)).astype(np.float32), (n @ r.T).astype(np.float32), t,
                          (0.5,) * 3, (0,) * 3))
    sc = scene(parts, lamp(LAMP_POINT, (4.0, 0.0, 4.0), power=(500.0,) * 3))
    # one target per box (its six faces)
    objects, t0 = [], 0
    per_box = 6 * parts[0][2].shape[0]
    for k in range(count):
        tri = sc.triangles[t0:t0 + per_box]
        corner_vert = tri.ravel() - tri.min()
        objects.append(LightmapObject(f"crate{k}", f"crate{k}", corner_vert=corner_vert.astype(np.int32),
                                      corner_triangles=np.arange(3 * per_box, dtype=np.int32).reshape(-1, 3),
                                      triangle_offset=t0))
        t0 += per_box
    return sc, objects


def floor_under_emissive_sphere(size: float, quads: int, gap: float = 0.001):
    """A grey floor of side ``size`` (quads × quads) ``gap`` (m) under an emissive sphere of radius 0.3 m
    (320 triangles, radiance 1) and under a 4 m panel of radiance 10 at 3 m: where a light tree's
    bounds under-rate the emitters right over a receiver (at the default gap). Returns (scene, floor positions,
    floor triangles); the floor comes first."""
    p, n, t = grid(size, quads)
    q, m, u = icosphere(0.3, 2, inward=False)
    a, b, c = grid(4.0, 2, z=3.0, flip=True)
    sc = scene([(p, n, t, (0.5,) * 3, (0,) * 3),
                (q + np.float32([0, 0, 0.3 + gap]), m, u, (0.0,) * 3, (1.0,) * 3),
                (a, b, c, (0.0,) * 3, (10.0,) * 3)])
    return sc, p, t
