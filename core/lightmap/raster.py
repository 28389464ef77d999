"""Texels of a lightmap page: which triangle each covered texel samples, where, and facing where.

Coverage is conservative: a texel is covered when a triangle comes within half a texel diagonal of
its centre, so thin triangles still get texels. A texel several triangles reach samples the one
covering its centre (distance 0), else the nearest (ties: the lowest triangle index, so results do
not depend on thread timing). Rasterisation runs per triangle over its bounding box in Warp.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from .. import device as device_mod
from ..formfactor import tangent_frame
from ..rays import lift

wp.set_module_options({"enable_backward": False})  # no gradients: halves compile time

# Half a texel's diagonal (texel units): a triangle within this distance of a texel's centre
# overlaps the texel.
REACH = 0.7072
# Sample points are pulled this fraction of the way towards their triangle's centroid, so points on
# an edge where a wall meets the floor are not in the wall's plane.
INSET = 1.0e-3
_NONE = np.iinfo(np.int32).max


@dataclass
class Texels:
    """N covered texels of one page.

    index: int64[N] texel index ``y * width + x`` (row 0 at v = 0, Blender's bottom row).
    triangle: int32[N] index of the sampled triangle in the page's triangle list.
    bary: float32[N,3] barycentric coordinates of the sample point in that triangle (corner order
        of the triangle's UVs).
    width, height: page size in texels.
    """

    index: np.ndarray
    triangle: np.ndarray
    bary: np.ndarray
    width: int
    height: int

    @property
    def count(self) -> int:
        return int(self.index.shape[0])


@wp.func
def closest_bary(p: wp.vec2, a: wp.vec2, b: wp.vec2, c: wp.vec2) -> wp.vec3:
    """Barycentric coordinates (of a, b, c) of the point of triangle abc closest to p (Ericson)."""
    ab = b - a
    ac = c - a
    ap = p - a
    d1 = wp.dot(ab, ap)
    d2 = wp.dot(ac, ap)
    if d1 <= 0.0 and d2 <= 0.0:
        return wp.vec3(1.0, 0.0, 0.0)
    bp = p - b
    d3 = wp.dot(ab, bp)
    d4 = wp.dot(ac, bp)
    if d3 >= 0.0 and d4 <= d3:
        return wp.vec3(0.0, 1.0, 0.0)
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        return wp.vec3(1.0 - v, v, 0.0)
    cp = p - c
    d5 = wp.dot(ab, cp)
    d6 = wp.dot(ac, cp)
    if d6 >= 0.0 and d5 <= d6:
        return wp.vec3(0.0, 0.0, 1.0)
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        return wp.vec3(1.0 - w, 0.0, w)
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and (d4 - d3) >= 0.0 and (d5 - d6) >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return wp.vec3(0.0, 1.0 - w, w)
    denom = 1.0 / (va + vb + vc)
    v = vb * denom
    w = vc * denom
    return wp.vec3(1.0 - v - w, v, w)


@wp.func
def _texel_distance(x: int, y: int, a: wp.vec2, b: wp.vec2, c: wp.vec2) -> float:
    p = wp.vec2(float(x) + 0.5, float(y) + 0.5)
    bc = closest_bary(p, a, b, c)
    return wp.length(p - (a * bc[0] + b * bc[1] + c * bc[2]))


@wp.kernel
def _raster_kernel(offset: int, uv0: wp.array(dtype=wp.vec2), uv1: wp.array(dtype=wp.vec2),
                   uv2: wp.array(dtype=wp.vec2), width: int, height: int, reach: float, claim: int,
                   best: wp.array(dtype=wp.float32), owner: wp.array(dtype=wp.int32)):
    """Pass claim=0: smallest distance of any triangle per texel; claim=1: lowest triangle index
    among those at that distance."""
    t = wp.tid() + offset
    a = uv0[t]
    b = uv1[t]
    c = uv2[t]
    x0 = wp.max(int(wp.floor(wp.min(wp.min(a[0], b[0]), c[0]) - reach)), 0)
    x1 = wp.min(int(wp.floor(wp.max(wp.max(a[0], b[0]), c[0]) + reach)), width - 1)
    y0 = wp.max(int(wp.floor(wp.min(wp.min(a[1], b[1]), c[1]) - reach)), 0)
    y1 = wp.min(int(wp.floor(wp.max(wp.max(a[1], b[1]), c[1]) + reach)), height - 1)
    for y in range(y0, y1 + 1):
        for x in range(x0, x1 + 1):
            d = _texel_distance(x, y, a, b, c)
            if d <= reach:
                i = y * width + x
                if claim == 0:
                    wp.atomic_min(best, i, d)
                elif d == best[i]:
                    wp.atomic_min(owner, i, t)


@wp.kernel
def _bary_kernel(offset: int, texel: wp.array(dtype=wp.int64), tri: wp.array(dtype=wp.int32),
                 uv0: wp.array(dtype=wp.vec2), uv1: wp.array(dtype=wp.vec2),
                 uv2: wp.array(dtype=wp.vec2), width: int, out: wp.array(dtype=wp.vec3)):
    i = wp.tid() + offset
    k = texel[i]
    y = int(k / wp.int64(width))
    x = int(k - wp.int64(y) * wp.int64(width))
    t = tri[i]
    out[i] = closest_bary(wp.vec2(float(x) + 0.5, float(y) + 0.5), uv0[t], uv1[t], uv2[t])


def rasterize(tri_uv: np.ndarray, width: int, height: int, dev: device_mod.Device) -> Texels:
    """Covered texels of a ``width`` × ``height`` page.

    tri_uv: float32[T,3,2] UVs of each triangle's corners in [0,1] of the page (NaN: triangle
    left out; triangles with no UV area cover nothing).
    """
    d = dev.name
    uv = np.asarray(tri_uv, np.float64) * np.array([width, height], np.float64)
    e1, e2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    usable = np.isfinite(uv).all(axis=(1, 2)) & (np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]) > 1e-12)
    # Left-out triangles get an empty box far off the page instead of a branch in the kernel.
    uv = np.where(usable[:, None, None], uv, -16.0).astype(np.float32)
    corners = [wp.array(np.ascontiguousarray(uv[:, k]), dtype=wp.vec2, device=d) for k in range(3)]
    n = width * height
    best = wp.full(n, 1.0e30, dtype=wp.float32, device=d)
    owner = wp.full(n, _NONE, dtype=wp.int32, device=d)
    t = uv.shape[0]
    for claim in (0, 1):  # neighbouring triangles meet on texels through atomic_min: one thread
        device_mod.launch(_raster_kernel, t, [*corners, width, height, REACH, claim, best, owner], dev,
                          serial=True)
    owner_np = owner.numpy()
    index = np.flatnonzero(owner_np != _NONE).astype(np.int64)
    tri = owner_np[index].astype(np.int32)
    bary = wp.zeros(index.shape[0], dtype=wp.vec3, device=d)
    device_mod.launch(_bary_kernel, index.shape[0],
                      [wp.array(index, dtype=wp.int64, device=d), wp.array(tri, dtype=wp.int32, device=d),
                       *corners, width, bary], dev)
    return Texels(index=index, triangle=tri, bary=bary.numpy(), width=width, height=height)


@wp.kernel
def _surface_kernel(offset: int, mesh: wp.uint64, bary: wp.array(dtype=wp.vec3),
                    tri: wp.array(dtype=wp.int32), p0: wp.array(dtype=wp.vec3),
                    p1: wp.array(dtype=wp.vec3), p2: wp.array(dtype=wp.vec3),
                    n0: wp.array(dtype=wp.vec3), n1: wp.array(dtype=wp.vec3),
                    n2: wp.array(dtype=wp.vec3), reach: wp.array(dtype=wp.float32),
                    inset: float, out_p: wp.array(dtype=wp.vec3), out_n: wp.array(dtype=wp.vec3)):
    i = wp.tid() + offset
    t = tri[i]
    bc = bary[i] * (1.0 - inset) + wp.vec3(inset / 3.0)
    p = p0[t] * bc[0] + p1[t] * bc[1] + p2[t] * bc[2]
    n = wp.normalize(n0[t] * bc[0] + n1[t] * bc[1] + n2[t] * bc[2])
    # Leak guard: a surface the texel straddles (a wall standing on this floor) is seen from
    # behind by a ray along the surface; the sample then moves just in front of that wall, to the
    # side of it the texel's own triangle is on.
    length = reach[t]
    origin = lift(p, n, length)
    t1, t2 = tangent_frame(n)
    best = length
    moved = p
    for k in range(4):
        d = t1
        if k == 1:
            d = -t1
        elif k == 2:
            d = t2
        elif k == 3:
            d = -t2
        q = wp.mesh_query_ray(mesh, origin, d, best)
        if q.result:
            fn = wp.normalize(q.normal)
            if wp.dot(fn, d) > 0.0:
                best = q.t
                moved = lift(origin + d * q.t, fn, length)
    out_p[i] = moved
    out_n[i] = n


def surface_points(texels: Texels, tri_pos: np.ndarray, tri_nrm: np.ndarray, metres_per_texel: np.ndarray,
                   problem):
    """Sample points and normals of ``texels``: float32[N,3] each.

    tri_pos, tri_nrm: float32[T,3,3] corner positions (m, the problem's frame) and shading normals
    of the page's triangles; metres_per_texel: float32[T] world size of a texel on each triangle;
    problem: the bake's ``core.problem.Problem`` (its BVH and device).
    """
    dev = problem.device
    d = dev.name
    n = texels.count
    arrays = [wp.array(np.ascontiguousarray(a[:, k], np.float32), dtype=wp.vec3, device=d)
              for a in (tri_pos, tri_nrm) for k in range(3)]
    out_p = wp.zeros(n, dtype=wp.vec3, device=d)
    out_n = wp.zeros(n, dtype=wp.vec3, device=d)
    device_mod.launch(
        _surface_kernel, n,
        [problem.mesh.id, wp.array(texels.bary, dtype=wp.vec3, device=d),
         wp.array(texels.triangle, dtype=wp.int32, device=d), *arrays,
         wp.array((metres_per_texel * REACH).astype(np.float32), dtype=wp.float32, device=d),
         INSET, out_p, out_n], dev)
    return out_p.numpy(), out_n.numpy()
