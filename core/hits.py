"""What each element's hemisphere rays hit: the hierarchical solver's final gather (issue 21).

Links carry light between clusters with a visibility sampled between some of their leaves, and an
element sends one radiance over its whole fan. Where light changes within an element's size — a
gap under a sofa, the floor under a sphere, the wall behind shelves, Suzanne's chin on a table —
both are wrong, and more, finer links buy accuracy only at Cycles' own rate (measured in the
furnished room of ``bench/real_scenes.py``). A final gather by rays sees what each element actually
sees: ``trace`` sends RAYS cosine-distributed rays from every element (an R2 set shifted per
element) and keeps where each first meets a front face (triangle and barycentric coordinates;
misses, back faces and mesh lights' own light send nothing here: the direct light holds them).
The same rays tell each element's open fraction (``enclosure``: the share of them whose first hit is
a front face or nothing), which the links weigh their samples by: the solver traces them first.
The light an element then receives is the mean radiance at those points,

    I_e = 1/K Σ_k ρ(h_k) ⊙ (D(h_k) + Σ_c b_c(h_k) I_c)

(cosine-distributed directions make the lighting irradiance/π the plain mean of the radiances
seen), with D(h) the direct light at the hit: where the triangle's direct light varies, that of
its nearest point among the near field's traced points (``nearfield.Detail``, looked up in
``nearest_table``), so a shadow edge inside a triangle stays sharp; elsewhere its corners'
interpolated; and I interpolated between its corners.
The direct part does not change between sweeps, so ``trace`` sums it once (``Hits.direct``); a
sweep (``sweep``) only interpolates the corners' indirect light. The solver starts the sweeps
from its links' solution and runs them until they converge: each sweep is one more bounce with
the rays' visibility and the hit points' own light, where the links' cluster averages stood.
"""
from __future__ import annotations

import math

import numpy as np
import warp as wp

from . import device as device_mod
from .directions import cosine_r2
from .formfactor import tangent_frame
from .nearfield import Detail
from .rays import lift
from .surfels import Surfels

wp.set_module_options({"enable_backward": False})  # no gradients: halves compile time

# The near field's traced point nearest to a hit is looked up in a GRID × GRID table over the
# barycentric square (measured as on an equilateral triangle), not searched among all of them.
GRID = 32
# Bytes a ray's hit takes: its triangle (int32) and two float16 barycentric coordinates.
BYTES_PER_RAY = 8
# A kept hit's ray is checked against the moved triangles 1 % beyond the hit (its point is rebuilt
# from float16 barycentric weights). Where more than MOST_MOVED of the triangles moved, that check
# costs about what tracing does, and every ray is traced again.
SEGMENT_MARGIN = 0.01
MOST_MOVED = 0.5


@wp.struct
class Hits:
    """K rays per element, element e's at rows e·K … e·K + K − 1. face: int32[n·K] the face
    first hit (f ≥ 0 a front face, −1 none, −2 − f back face f: the sweeps take front faces, the
    next frame of an animation all); bary: vec2h[n·K] its barycentric weights of the triangle's
    corners 0 and 1 (corner 2 gets the rest); direct: vec3[n] the mean over the rays of
    ρ ⊙ D at the hits (irradiance/π), which the sweeps do not change; free: float32[n] the share
    of the rays whose first hit is a front face or nothing (``enclosure.open_fraction``); rays: K."""

    face: wp.array(dtype=wp.int32)
    bary: wp.array(dtype=wp.vec2h)
    direct: wp.array(dtype=wp.vec3)
    free: wp.array(dtype=wp.float32)
    rays: int


@wp.func
def _nearest(table: wp.array(dtype=wp.int32), u: float, v: float) -> int:
    """The traced point (``nearest_table``) nearest to barycentric weights (u, v, 1 − u − v)."""
    i = wp.clamp(int(u * float(GRID)), 0, GRID - 1)
    j = wp.clamp(int(v * float(GRID)), 0, GRID - 1)
    return table[i * GRID + j]


@wp.func
def _corners(corner: wp.array(dtype=wp.int32), f: int) -> wp.vec3i:
    """The elements at triangle f's corners."""
    return wp.vec3i(corner[3 * f], corner[3 * f + 1], corner[3 * f + 2])


@wp.func
def _mix(values: wp.array(dtype=wp.vec3), c: wp.vec3i, u: float, v: float) -> wp.vec3:
    """values at a triangle's corners c interpolated at barycentric weights (u, v, 1 − u − v)."""
    return values[c[0]] * u + values[c[1]] * v + values[c[2]] * (1.0 - u - v)


@wp.struct
class Moved:
    """``problem.Motion`` on the device: face: int32[T] 1 where a triangle moved; element: int32[n]
    1 where an element's rays changed; mesh: the BVH of the moved triangles where they are now
    (``any`` 0 where none moved)."""

    face: wp.array(dtype=wp.int32)
    element: wp.array(dtype=wp.int32)
    mesh: wp.uint64
    any: int


@wp.func
def _still(m: Moved, s: Surfels, origin: wp.vec3, d: wp.vec3, far: float, code: int, u: float, v: float) -> int:
    """1 where the previous frame's hit of the ray (origin, unit d) holds in this one: its face
    (code: ``Hits.face``) did not move and no moved triangle, where it is now, meets the ray up
    to it (SEGMENT_MARGIN beyond it: the barycentric weights are float16). That is exact: a moved
    triangle in front of the old hit before would have been the hit, whose face then moved."""
    t = far
    kept = int(1)
    if code != -1:
        f = code
        if code < -1:
            f = -2 - code
        if m.face[f] != 0:
            kept = 0
        else:
            p = (s.points[s.tris[3 * f]] * u + s.points[s.tris[3 * f + 1]] * v
                 + s.points[s.tris[3 * f + 2]] * (1.0 - u - v))
            t = wp.length(p - origin) * (1.0 + SEGMENT_MARGIN)
    if kept == 1 and m.any != 0:
        if wp.mesh_query_ray(m.mesh, origin, d, t).result:
            kept = 0
    return kept


@wp.func
def _reflected(s: Surfels, corner: wp.array(dtype=wp.int32), nf: Detail, table: wp.array(dtype=wp.int32),
               direct: wp.array(dtype=wp.vec3), f: int, u: float, v: float) -> wp.vec3:
    """ρ ⊙ D at a front hit on triangle f at barycentric weights (u, v): D the near field's
    traced point nearest to it where the triangle's direct light varies, else its corners'."""
    c = _corners(corner, f)
    light = _mix(direct, c, u, v)
    if nf.row.shape[0] > 0:
        traced = nf.row[f]
        if traced >= 0:
            light = nf.light[traced, _nearest(table, u, v)]
    return wp.cw_mul(_mix(s.albedo, c, u, v), light)


@wp.kernel
def _trace_kernel(offset: int, mesh: wp.uint64, s: Surfels, corner: wp.array(dtype=wp.int32), nf: Detail,
                  table: wp.array(dtype=wp.int32),
                  direct: wp.array(dtype=wp.vec3), size: wp.array(dtype=wp.float32), rays: int, far: float,
                  seed: int, m: Moved, reuse: int, face: wp.array(dtype=wp.int32),
                  bary: wp.array(dtype=wp.vec2h), out: wp.array(dtype=wp.vec3), free: wp.array(dtype=wp.float32),
                  traced: wp.array(dtype=wp.int32)):
    """Element e: its rays' hits (with ``reuse``, those of the previous frame that still hold are
    kept: ``_still``), their mean ρ ⊙ D into out[e], the share of them that met a front face or
    nothing into free[e] and the rays traced into traced[e]."""
    e = wp.tid() + offset
    n = s.nrm[e]
    tu, tv = tangent_frame(n)
    origin = lift(s.pos[e], n, size[e])
    state = wp.rand_init(seed, e)
    shift0 = wp.randf(state)
    shift = wp.vec2(shift0, wp.randf(state))
    again = int(1)
    if reuse != 0:
        again = m.element[e]
    acc = wp.vec3(0.0)
    back = int(0)
    count = int(0)
    for k in range(rays):
        d = cosine_r2(n, tu, tv, shift, k)
        row = e * rays + k
        fresh = again
        code = int(-1)
        u = float(0.0)
        v = float(0.0)
        if again == 0:
            code = face[row]
            u = float(bary[row][0])
            v = float(bary[row][1])
            fresh = 1 - _still(m, s, origin, d, far, code, u, v)
        if fresh != 0:
            count += 1
            q = wp.mesh_query_ray(mesh, origin, d, far)
            code = -1
            if q.result:
                u = q.u
                v = q.v
                code = q.face
                if wp.dot(q.normal, d) >= 0.0:
                    code = -2 - q.face
            face[row] = code
            bary[row] = wp.vec2h(wp.float16(u), wp.float16(v))
        if code >= 0:
            acc += _reflected(s, corner, nf, table, direct, code, u, v)
        elif code < -1:
            back += 1
    out[e] = acc / float(rays)
    free[e] = float(rays - back) / float(rays)
    traced[e] = count


@wp.kernel
def _sweep_kernel(offset: int, h: Hits, s: Surfels, corner: wp.array(dtype=wp.int32),
                  indirect: wp.array(dtype=wp.vec3), out: wp.array(dtype=wp.vec3)):
    """Element e: I_e = direct part + 1/K Σ_k ρ(h_k) ⊙ I(h_k) over its stored hits."""
    e = wp.tid() + offset
    acc = wp.vec3(0.0)
    for row in range(e * h.rays, (e + 1) * h.rays):
        f = h.face[row]
        if f >= 0:
            u = float(h.bary[row][0])
            v = float(h.bary[row][1])
            c = _corners(corner, f)
            acc += wp.cw_mul(_mix(s.albedo, c, u, v), _mix(indirect, c, u, v))
    out[e] = h.direct[e] + acc / float(h.rays)


def nearest_table(bary: np.ndarray) -> np.ndarray:
    """int32[GRID²]: for each cell (i, j) of the barycentric square (weights of corners 0 and 1),
    the index of the point of ``bary`` (float32[P,3], ``nearfield.barycentric``) nearest to its
    centre on an equilateral triangle."""
    corners = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, math.sqrt(0.75)]])
    c = (np.arange(GRID) + 0.5) / GRID
    u, v = np.meshgrid(c, c, indexing="ij")
    cells = np.stack([u.ravel(), v.ravel(), 1.0 - u.ravel() - v.ravel()], axis=1) @ corners
    points = np.asarray(bary, np.float64) @ corners
    d = ((cells[:, None, :] - points[None, :, :]) ** 2).sum(axis=2)
    return d.argmin(axis=1).astype(np.int32)


def _moved_mesh(s: Surfels, triangles: np.ndarray, faces: np.ndarray, device: str) -> wp.Mesh:
    """The BVH of the ``triangles`` (int32[T,3], the scene's, on the host: no copy back from the
    device) that ``faces`` (bool[T]) flags, on the points of ``s``'s BVH (shared, not copied)."""
    tris = np.asarray(triangles, np.int32)[faces]
    return wp.Mesh(points=s.points, indices=wp.array(np.ascontiguousarray(tris.reshape(-1)), dtype=wp.int32,
                                                      device=device))


# Rows of hits a kernel indexes with int32.
MOST_ROWS = 2 ** 31 - 1


def bytes_needed(elements: int, rays: int) -> int:
    """Bytes the hits of ``rays`` rays from each of ``elements`` elements take."""
    return int(elements) * int(rays) * BYTES_PER_RAY


def trace(problem, rays: int, previous: Hits | None = None) -> Hits:
    """The ``Hits`` of ``rays`` cosine-distributed rays from each element of ``problem`` (rays
    traced counted in ``problem.counts``), the near field's traced direct light (``problem.near``)
    at the hits where it varies, and the open fraction they tell (``Hits.free``). ``previous``: the
    hits of the previous frame of an animation (``problem.motion`` what moved since), updated in
    place: only the rays of moved elements, to or from moved triangles or crossing a moved object's
    triangle where it is now are traced again (``counts["gather_rays_kept"]`` the others); all of
    them where more than MOST_MOVED of the triangles moved."""
    dev, s, els = problem.device, problem.surfels, problem.elements
    d = dev.name
    n = els.count
    motion = problem.motion
    fits = previous is not None and previous.rays == rays and previous.face.shape[0] == n * rays
    reuse = fits and motion is not None and motion.faces.mean() <= MOST_MOVED
    if fits:
        h = previous  # its memory, even where every ray is traced again
    else:
        h = Hits()
        h.rays = int(rays)
        h.face = wp.empty(n * rays, dtype=wp.int32, device=d)
        h.bary = wp.empty(n * rays, dtype=wp.vec2h, device=d)
        h.direct = wp.empty(n, dtype=wp.vec3, device=d)
        h.free = wp.empty(n, dtype=wp.float32, device=d)
    m = Moved()
    m.face = wp.array(motion.faces.astype(np.int32) if reuse else np.zeros(0, np.int32), dtype=wp.int32, device=d)
    m.element = wp.array(motion.elements.astype(np.int32) if reuse else np.zeros(0, np.int32), dtype=wp.int32,
                         device=d)
    moved = _moved_mesh(s, problem.scene.triangles, motion.faces, d) if reuse and motion.faces.any() else None
    m.mesh = moved.id if moved is not None else 0
    m.any = int(moved is not None)
    corner = wp.array(np.ascontiguousarray(els.corner.reshape(-1), np.int32), dtype=wp.int32, device=d)
    sizes = wp.array(problem.element_sizes.astype(np.float32), dtype=wp.float32, device=d)
    direct = wp.array(problem.direct, dtype=wp.vec3, device=d)
    nf = problem.near
    table = wp.array(nearest_table(nf.bary.numpy()), dtype=wp.int32, device=d)
    traced = wp.empty(n, dtype=wp.int32, device=d)
    device_mod.launch(_trace_kernel, n, [problem.mesh.id, s, corner, nf, table, direct, sizes, h.rays,
                                         float(problem.far), int(problem.settings.seed) + 104729, m, int(reuse),
                                         h.face, h.bary, h.direct, h.free, traced], dev, uneven=reuse)
    count = int(traced.numpy().sum(dtype=np.int64))
    problem.counts["rays"] += count
    problem.counts["gather_rays_kept"] = n * rays - count
    return h


class Sweep:
    """One bounce over the hits of ``problem``'s elements: ``sweep(indirect, out)`` (vec3[n]
    device arrays, lighting irradiance/π) sets out to what the elements receive when they send
    ρ ⊙ (D + indirect)."""

    def __init__(self, problem, hits: Hits):
        self.problem, self.hits = problem, hits
        self.corner = wp.array(np.ascontiguousarray(problem.elements.corner.reshape(-1), np.int32),
                               dtype=wp.int32, device=problem.device.name)

    def __call__(self, indirect: wp.array, out: wp.array) -> None:
        p = self.problem
        device_mod.launch(_sweep_kernel, p.elements.count,
                          [self.hits, p.surfels, self.corner, indirect, out], p.device)
