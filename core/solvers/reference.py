"""All-pairs multi-bounce gather between element disks with ray-cast visibility (O(n²)).

Transport matrix ``M[i, j] = F_ij · V_ij``: F_ij the form factor from element i's point to the
front face of element j (disk approximation far away, exact triangle form factors of j's fan, a
third each, when d² < NEAR·A_j), V_ij the unblocked fraction of rays from i to jittered points of
j's own triangles. Then Jacobi iteration of ``I = M (ρ ⊙ (D + I))`` in lighting units (irradiance/π), D the
direct lighting. Small scenes only: M is held whole (n² float32).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import warp as wp

from .. import device as device_mod
from ..elements import Elements
from ..errors import BakeError
from ..formfactor import disk_ff, triangle_ff

# Below this many disk areas of squared distance the disk approximation is replaced by the
# exact form factor of the sender's triangles (ALGORITHMS.md §1 suggests 4–8).
NEAR = 8.0


@dataclass
class Solution:
    """indirect: float32[n,3] indirect lighting per element; counts: pairs, rays, iterations."""

    indirect: np.ndarray
    counts: dict = field(default_factory=dict)


@wp.func
def fan_ff(p: wp.vec3, n: wp.vec3, j: int, fan_offsets: wp.array(dtype=wp.int32),
           fan_triangles: wp.array(dtype=wp.int32), tris: wp.array(dtype=wp.int32),
           points: wp.array(dtype=wp.vec3)) -> float:
    """Exact form factor from p to the front faces of element j's share (a third) of its triangles."""
    s = float(0.0)
    for k in range(fan_offsets[j], fan_offsets[j + 1]):
        t = fan_triangles[k]
        a = points[tris[3 * t]]
        b = points[tris[3 * t + 1]]
        c = points[tris[3 * t + 2]]
        nt = wp.cross(b - a, c - a)
        h = wp.dot(p - a, nt)
        if h > 1.0e-6 * wp.length(nt) * wp.length(p - a):
            s += triangle_ff(p, n, a, b, c)
    return s / 3.0


@wp.func
def fan_sample(j: int, u0: float, u1: float, u2: float, fan_offsets: wp.array(dtype=wp.int32),
               fan_triangles: wp.array(dtype=wp.int32), tris: wp.array(dtype=wp.int32),
               points: wp.array(dtype=wp.vec3)) -> wp.vec3:
    """A point of element j's own surface: on one of its triangles (chosen by area with u0), in the
    half of it nearest to j. Points on the real surface, unlike the tangent disk, stay inside a
    curved closed mesh."""
    total = float(0.0)
    for k in range(fan_offsets[j], fan_offsets[j + 1]):
        t = fan_triangles[k]
        a = points[tris[3 * t]]
        total += wp.length(wp.cross(points[tris[3 * t + 1]] - a, points[tris[3 * t + 2]] - a))
    pick = u0 * total
    chosen = fan_triangles[fan_offsets[j]]
    for k in range(fan_offsets[j], fan_offsets[j + 1]):
        t = fan_triangles[k]
        a = points[tris[3 * t]]
        pick -= wp.length(wp.cross(points[tris[3 * t + 1]] - a, points[tris[3 * t + 2]] - a))
        if pick <= 0.0:
            chosen = t
            break
    a = points[tris[3 * chosen]]
    b = points[tris[3 * chosen + 1]]
    c = points[tris[3 * chosen + 2]]
    r = wp.sqrt(u1)
    q = a * (1.0 - r) + b * (r * (1.0 - u2)) + c * (r * u2)
    pj = points[j]
    return pj + (q - pj) * 0.5


@wp.func
def element_ff(p: wp.vec3, n: wp.vec3, j: int, pos: wp.array(dtype=wp.vec3),
               nrm: wp.array(dtype=wp.vec3), area: wp.array(dtype=wp.float32),
               fan_offsets: wp.array(dtype=wp.int32), fan_triangles: wp.array(dtype=wp.int32),
               tris: wp.array(dtype=wp.int32), points: wp.array(dtype=wp.vec3)) -> float:
    d = pos[j] - p
    if wp.dot(d, d) < NEAR * area[j]:
        return fan_ff(p, n, j, fan_offsets, fan_triangles, tris, points)
    return disk_ff(p, n, pos[j], nrm[j], area[j])


@wp.kernel
def _transport_kernel(offset: int, n_el: int, mesh: wp.uint64, pos: wp.array(dtype=wp.vec3),
                      nrm: wp.array(dtype=wp.vec3), area: wp.array(dtype=wp.float32),
                      fan_offsets: wp.array(dtype=wp.int32), fan_triangles: wp.array(dtype=wp.int32),
                      tris: wp.array(dtype=wp.int32), points: wp.array(dtype=wp.vec3),
                      rays_per_pair: int, eps: float, seed: int,
                      out: wp.array2d(dtype=wp.float32), rays: wp.array(dtype=wp.int32)):
    idx = wp.tid() + offset
    i = idx / n_el
    j = idx - i * n_el
    if j <= i or area[i] <= 0.0 or area[j] <= 0.0:
        return
    pi = pos[i]
    pj = pos[j]
    ni = nrm[i]
    nj = nrm[j]
    f_ij = element_ff(pi, ni, j, pos, nrm, area, fan_offsets, fan_triangles, tris, points)
    f_ji = element_ff(pj, nj, i, pos, nrm, area, fan_offsets, fan_triangles, tris, points)
    if f_ij <= 0.0 and f_ji <= 0.0:
        return
    # Visibility is shared by both directions: rays from i's surface point to jittered points of
    # j's surface, both lifted off their surfaces.
    state = wp.rand_init(seed, idx)
    origin = pi + ni * eps
    hits = float(0.0)
    for k in range(rays_per_pair):
        u0 = (float(k) + wp.randf(state)) / float(rays_per_pair)
        q = fan_sample(j, u0, wp.randf(state), wp.randf(state), fan_offsets, fan_triangles, tris,
                       points) + nj * eps
        d = q - origin
        dist = wp.length(d)
        if dist > 0.0:
            if not wp.mesh_query_ray_anyhit(mesh, origin, d / dist, dist * 0.9999):
                hits += 1.0
        else:
            hits += 1.0
    vis = hits / float(rays_per_pair)
    out[i, j] = f_ij * vis
    out[j, i] = f_ji * vis
    wp.atomic_add(rays, 0, rays_per_pair)


def transport_matrix(geometry, els: Elements, settings, dev: device_mod.Device,
                     progress=None):
    """float32[n,n] matrix M (lighting at i per unit radiance leaving j) and the rays traced."""
    n = els.count
    if n * n > settings.max_pairs:
        raise BakeError(f"bruteforce needs {n}² = {n * n:,} element pairs, more than the budget of "
                        f"{settings.max_pairs:,}: use fewer vertices or raise max_pairs")
    d = dev.name
    out = wp.zeros((n, n), dtype=wp.float32, device=d)
    rays = wp.zeros(1, dtype=wp.int32, device=d)
    device_mod.launch(
        _transport_kernel, n * n,
        [n, geometry.mesh.id, wp.array(els.position, dtype=wp.vec3, device=d),
         wp.array(els.normal, dtype=wp.vec3, device=d), wp.array(els.area, dtype=wp.float32, device=d),
         wp.array(els.fan_offsets, dtype=wp.int32, device=d),
         wp.array(els.fan_triangles, dtype=wp.int32, device=d),
         geometry.indices, geometry.points, int(settings.visibility_rays), float(geometry.eps), int(settings.seed) + 7919,
         out, rays],
        dev, chunks=max(1, min(64, n // 64)), on_chunk=progress)
    return out.numpy(), int(rays.numpy()[0])


def solve(geometry, els: Elements, direct: np.ndarray, settings, dev: device_mod.Device,
          progress=None) -> Solution:
    """Indirect lighting per element (float32[n,3]) from direct lighting ``direct`` (float32[n,3])."""
    def report(stage, f):
        if progress is not None:
            progress(stage, f)

    m, rays = transport_matrix(geometry, els, settings, dev,
                               lambda f: report("form factors", f))
    rho = els.albedo.astype(np.float64)
    d = direct.astype(np.float64)
    indirect = np.zeros_like(d)
    iterations = 0
    for iterations in range(1, settings.bounces + 1):
        new = m @ (rho * (d + indirect))
        change = float(np.abs(new - indirect).max(initial=0.0))
        scale = float(max(np.abs(new).max(initial=0.0), np.abs(d).max(initial=0.0), 1e-30))
        indirect = new
        report("bounces", iterations / settings.bounces)
        if change <= settings.tolerance * scale:
            break
    return Solution(indirect.astype(np.float32),
                    {"pairs": els.count * els.count, "rays": rays, "iterations": iterations})
