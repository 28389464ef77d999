"""Reference radiosity: all-pairs multi-bounce gather between element disks with explicit,
ray-cast visibility (O(n²) pairs; the ground truth for small scenes).

Transport matrix ``M[i, j] = F_ij · V_ij``: F_ij the form factor from element i's point to the
front face of element j (disk approximation far away, exact triangle form factors of j's fan, a
third each, when d² < NEAR·A_j), V_ij the unblocked fraction of rays from i to jittered points of
j's own triangles. Then iteration of ``I = M (ρ ⊙ (D + I))`` in lighting units (irradiance/π), D the direct
lighting. M is held whole while n² fits the pair budget, else processed in row blocks.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import warp as wp

from .. import device as device_mod
from ..elements import Elements
from ..formfactor import disk_ff, fan_ff

# Below this many disk areas of squared distance the disk approximation is replaced by the
# exact form factor of the sender's triangles. ALGORITHMS.md §1 suggests 4–8 for a fast method;
# the reference pays ~50 % more time for 64, which keeps the perpendicular-squares form factor
# within 0.4 % at 32×32 quads (8 gave 1.2 % low).
NEAR = 64.0


@dataclass
class Solution:
    """indirect: float32[n,3] indirect lighting per element; counts: pairs, rays, iterations."""

    indirect: np.ndarray
    counts: dict = field(default_factory=dict)


@wp.struct
class Surfels:
    """Element disks and the triangles they stand for, as the transport kernels read them.

    mesh: BVH id of all triangles; pos, nrm, area: the elements; fan_offsets/fan_triangles: each
    element's triangles (CSR); tris: flat triangle corners; points: vertex positions; rays: rays
    per pair; eps: ray offset (m); seed: jitter seed.
    """

    mesh: wp.uint64
    pos: wp.array(dtype=wp.vec3)
    nrm: wp.array(dtype=wp.vec3)
    area: wp.array(dtype=wp.float32)
    fan_offsets: wp.array(dtype=wp.int32)
    fan_triangles: wp.array(dtype=wp.int32)
    tris: wp.array(dtype=wp.int32)
    points: wp.array(dtype=wp.vec3)
    rays: int
    eps: float
    seed: int


@wp.func
def _fan_triangle_area2(s: Surfels, t: int) -> float:
    a = s.points[s.tris[3 * t]]
    return wp.length(wp.cross(s.points[s.tris[3 * t + 1]] - a, s.points[s.tris[3 * t + 2]] - a))


@wp.func
def fan_sample(s: Surfels, j: int, u0: float, u1: float, u2: float) -> wp.vec3:
    """A point of element j's own surface: on one of its triangles (chosen by area with u0), in the
    half of it nearest to j. Points on the real surface, unlike the tangent disk, stay inside a
    curved closed mesh."""
    total = float(0.0)
    for k in range(s.fan_offsets[j], s.fan_offsets[j + 1]):
        total += _fan_triangle_area2(s, s.fan_triangles[k])
    pick = u0 * total
    chosen = s.fan_triangles[s.fan_offsets[j]]
    for k in range(s.fan_offsets[j], s.fan_offsets[j + 1]):
        pick -= _fan_triangle_area2(s, s.fan_triangles[k])
        if pick <= 0.0:
            chosen = s.fan_triangles[k]
            break
    a = s.points[s.tris[3 * chosen]]
    b = s.points[s.tris[3 * chosen + 1]]
    c = s.points[s.tris[3 * chosen + 2]]
    r = wp.sqrt(u1)
    q = a * (1.0 - r) + b * (r * (1.0 - u2)) + c * (r * u2)
    pj = s.points[j]
    return pj + (q - pj) * 0.5


@wp.func
def element_ff(s: Surfels, i: int, j: int) -> float:
    """Form factor from element i's point to the front of element j."""
    p = s.pos[i]
    d = s.pos[j] - p
    if wp.dot(d, d) < NEAR * s.area[j]:
        return fan_ff(p, s.nrm[i], j, 1.0, s.fan_offsets, s.fan_triangles, s.tris, s.points)
    return disk_ff(p, s.nrm[i], s.pos[j], s.nrm[j], s.area[j])


@wp.func
def pair_visibility(s: Surfels, i: int, j: int) -> float:
    """Unblocked fraction of rays from min(i,j)'s point to stratified points of the other's own
    surface, both lifted off their surfaces by eps. Seeded by the pair and always traced the same
    way round, so every evaluation of a pair gives the same value."""
    lo = wp.min(i, j)
    hi = wp.max(i, j)
    state = wp.rand_init(s.seed, lo * 65521 + hi)
    origin = s.pos[lo] + s.nrm[lo] * s.eps
    hits = float(0.0)
    for k in range(s.rays):
        u0 = (float(k) + wp.randf(state)) / float(s.rays)
        q = fan_sample(s, hi, u0, wp.randf(state), wp.randf(state)) + s.nrm[hi] * s.eps
        d = q - origin
        dist = wp.length(d)
        if dist <= 0.0:
            hits += 1.0
        elif not wp.mesh_query_ray_anyhit(s.mesh, origin, d / dist, dist * 0.9999):
            hits += 1.0
    return hits / float(s.rays)


@wp.kernel
def _pairs_kernel(offset: int, n_el: int, s: Surfels, out: wp.array2d(dtype=wp.float32),
                  rays: wp.array(dtype=wp.int32)):
    """Whole matrix: thread (i, j) with i < j fills both M[i, j] and M[j, i] (one visibility)."""
    idx = wp.tid() + offset
    i = idx / n_el
    j = idx - i * n_el
    if j <= i or s.area[i] <= 0.0 or s.area[j] <= 0.0:
        return
    f_ij = element_ff(s, i, j)
    f_ji = element_ff(s, j, i)
    if f_ij <= 0.0 and f_ji <= 0.0:
        return
    vis = pair_visibility(s, i, j)
    out[i, j] = f_ij * vis
    out[j, i] = f_ji * vis
    wp.atomic_add(rays, 0, s.rays)


@wp.kernel
def _rows_kernel(offset: int, n_el: int, row0: int, s: Surfels, out: wp.array2d(dtype=wp.float32),
                 rays: wp.array(dtype=wp.int32)):
    """Rows row0.. of M into out (block-local row index): the bounded-memory path."""
    idx = wp.tid() + offset
    r = idx / n_el
    j = idx - r * n_el
    i = row0 + r
    out[r, j] = 0.0
    if i == j or s.area[i] <= 0.0 or s.area[j] <= 0.0:
        return
    f_ij = element_ff(s, i, j)
    if f_ij <= 0.0:
        return
    out[r, j] = f_ij * pair_visibility(s, i, j)
    wp.atomic_add(rays, 0, s.rays)


class Transport:
    """The transport M (lighting at i per unit radiance leaving j) of n elements.

    Held whole (float32[n,n], each pair's visibility traced once) when n² ≤ settings.max_pairs;
    otherwise produced in blocks of ``block_rows`` rows, recomputed on every sweep, so memory stays
    within the budget.
    """

    def __init__(self, geometry, els: Elements, settings, dev: device_mod.Device):
        n = els.count
        self.n = n
        self.dev = dev
        self.geometry = geometry  # keeps the BVH alive: kernels only get its id
        d = dev.name
        self.block_rows = n if n * n <= settings.max_pairs else max(1, settings.max_pairs // n)
        self.rays = wp.zeros(1, dtype=wp.int32, device=d)
        s = Surfels()
        s.mesh = geometry.mesh.id
        s.pos = wp.array(els.position, dtype=wp.vec3, device=d)
        s.nrm = wp.array(els.normal, dtype=wp.vec3, device=d)
        s.area = wp.array(els.area, dtype=wp.float32, device=d)
        s.fan_offsets = wp.array(els.fan_offsets, dtype=wp.int32, device=d)
        s.fan_triangles = wp.array(els.fan_triangles, dtype=wp.int32, device=d)
        s.tris = geometry.indices
        s.points = geometry.points
        s.rays = int(settings.visibility_rays)
        s.eps = float(geometry.eps)
        s.seed = int(settings.seed) + 7919
        self._surfels = s
        self._buffer = wp.zeros((self.block_rows, n), dtype=wp.float32, device=d)
        self.whole = None

    @property
    def held(self) -> bool:
        return self.block_rows == self.n

    def build_whole(self, progress=None) -> np.ndarray:
        """Compute and keep the whole matrix (only when held)."""
        n = self.n
        device_mod.launch(_pairs_kernel, n * n, [n, self._surfels, self._buffer, self.rays], self.dev,
                          chunks=max(1, min(64, n // 64)), on_chunk=progress)
        self.whole = self._buffer.numpy()
        return self.whole

    def rows(self, row0: int) -> np.ndarray:
        """float32[k, n]: rows row0 … row0+k−1 of M (k = block_rows, fewer at the end)."""
        n = self.n
        k = min(self.block_rows, n - row0)
        device_mod.launch(_rows_kernel, k * n, [n, row0, self._surfels, self._buffer, self.rays],
                          self.dev)
        return self._buffer.numpy()[:k]

    @property
    def rays_traced(self) -> int:
        return int(self.rays.numpy()[0])


def solve(geometry, els: Elements, direct: np.ndarray, settings, dev: device_mod.Device,
          progress=None) -> Solution:
    """Indirect lighting per element (float32[n,3]) from direct lighting ``direct`` (float32[n,3]).

    Held transport: Jacobi sweeps ``I ← M (ρ ⊙ (D + I))``. Blocked transport: Gauss–Seidel sweeps
    over row blocks (each block's new values are used by the next block at once). Either stops
    when the largest change is below ``tolerance`` × the largest lighting value, or after
    ``bounces`` sweeps.
    """
    def report(stage, f):
        if progress is not None:
            progress(stage, f)

    transport = Transport(geometry, els, settings, dev)
    rho = els.albedo.astype(np.float64)
    d = direct.astype(np.float64)
    indirect = np.zeros_like(d)
    if transport.held:
        m = transport.build_whole(lambda f: report("form factors", f))
    sweeps = 0
    for sweeps in range(1, settings.bounces + 1):
        before = indirect.copy()
        if transport.held:
            indirect = m @ (rho * (d + indirect))
        else:
            for row0 in range(0, transport.n, transport.block_rows):
                block = transport.rows(row0)
                indirect[row0:row0 + len(block)] = block @ (rho * (d + indirect))
                report("bounces", (sweeps - 1 + (row0 + len(block)) / transport.n) / settings.bounces)
        change = float(np.abs(indirect - before).max(initial=0.0))
        scale = float(max(np.abs(indirect).max(initial=0.0), np.abs(d).max(initial=0.0), 1e-30))
        report("bounces", sweeps / settings.bounces)
        if change <= settings.tolerance * scale:
            break
    return Solution(indirect.astype(np.float32),
                    {"pairs": els.count * els.count, "rays": transport.rays_traced,
                     "iterations": sweeps, "transport_held": int(transport.held),
                     "block_rows": transport.block_rows})
