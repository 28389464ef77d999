"""Element geometry every stage shares: the elements as kernels read them (``Surfels``), points
on an element's own triangles, element and face form factors, and the visibility rays between two
elements. Links, directions, the gathers and the solvers all take it from here; nothing here knows
a solver.
"""
from __future__ import annotations

import warp as wp

from .elements import FAN_OPEN_IN, FAN_OPEN_OUT, FAN_TANGLED
from .formfactor import (HORIZON_EPS, INV_TWO_PI, OUTLINE_TRIANGLE, PLANE_EPS, arc_term, disk_ff,
                         far_triangle_ff, outline_ff, side_of, triangle_view)
from .rays import lift

wp.set_module_options({"enable_backward": False})  # no gradients: halves compile time

# Below this many disk areas of squared distance the disk approximation is replaced by the
# exact form factor of the sender's triangles. ALGORITHMS.md §1 suggests 4–8 for a fast method;
# the reference pays ~50 % more time for 64, which keeps the perpendicular-squares form factor
# within 0.4 % at 32×32 quads (8 gave 1.2 % low).
NEAR = 64.0


@wp.struct
class Surfels:
    """The elements and the triangles they stand for, as kernels read them.

    mesh: BVH id of all triangles; points: vec3[V] vertex positions (m) and tris: int32[3T] flat
    triangle corners (the BVH's own arrays); pos, nrm: vec3[n] element points and normals (m,
    unit); centre: vec3[n] the area-weighted centre of each element's share of its triangles
    (``fan_centre``: where its disk stands as a sender); area: float32[n] (m²); albedo, emission:
    vec3[n]; vertex: int32[n] the vertex each element sits on; fan_offsets: int32[n+1] and
    fan_triangles: int32[≤3T], each element's triangles (CSR), fan_outline: vec3i[≤3T] each one's
    edge opposite the element and how it joins the fan (``elements.fan_outline``); tri_centre:
    vec4[T] each triangle's centroid (m) and reach (its farthest corner's distance from it, m); tri_normal:
    vec4[T] its unit normal (along its winding) and size √(2·area) (m) — what ``fan_ff`` would
    otherwise work out again for every point that looks at a triangle.
    """

    mesh: wp.uint64
    points: wp.array(dtype=wp.vec3)
    tris: wp.array(dtype=wp.int32)
    pos: wp.array(dtype=wp.vec3)
    nrm: wp.array(dtype=wp.vec3)
    centre: wp.array(dtype=wp.vec3)
    area: wp.array(dtype=wp.float32)
    albedo: wp.array(dtype=wp.vec3)
    emission: wp.array(dtype=wp.vec3)
    vertex: wp.array(dtype=wp.int32)
    fan_offsets: wp.array(dtype=wp.int32)
    fan_triangles: wp.array(dtype=wp.int32)
    fan_outline: wp.array(dtype=wp.vec3i)
    tri_centre: wp.array(dtype=wp.vec4)
    tri_normal: wp.array(dtype=wp.vec4)


def upload(elements, mesh: wp.Mesh, device: str) -> Surfels:
    """The ``Surfels`` of ``elements`` (``core.elements.Elements``, host arrays) on ``device``, over
    the BVH ``mesh`` of all triangles (its points and indices are the struct's own)."""
    s = Surfels()
    s.mesh = mesh.id
    s.points = mesh.points
    s.tris = mesh.indices
    s.pos = wp.array(elements.position, dtype=wp.vec3, device=device)
    s.nrm = wp.array(elements.normal, dtype=wp.vec3, device=device)
    s.area = wp.array(elements.area, dtype=wp.float32, device=device)
    s.albedo = wp.array(elements.albedo, dtype=wp.vec3, device=device)
    s.emission = wp.array(elements.emission, dtype=wp.vec3, device=device)
    s.vertex = wp.array(elements.vertex, dtype=wp.int32, device=device)
    s.fan_offsets = wp.array(elements.fan_offsets, dtype=wp.int32, device=device)
    s.fan_triangles = wp.array(elements.fan_triangles, dtype=wp.int32, device=device)
    s.fan_outline = wp.array(elements.fan_outline, dtype=wp.vec3i, device=device)
    s.centre = wp.empty(elements.count, dtype=wp.vec3, device=device)
    triangles = mesh.indices.shape[0] // 3
    s.tri_centre = wp.empty(triangles, dtype=wp.vec4, device=device)
    s.tri_normal = wp.empty(triangles, dtype=wp.vec4, device=device)
    _centres(s, device)
    return s


@wp.kernel
def _centre_kernel(s: Surfels):
    e = wp.tid()
    s.centre[e] = fan_centre(e, s.vertex, s.fan_offsets, s.fan_triangles, s.tris, s.points)


@wp.kernel
def _frame_kernel(s: Surfels):
    t = wp.tid()
    a = s.points[s.tris[3 * t]]
    b = s.points[s.tris[3 * t + 1]]
    c = s.points[s.tris[3 * t + 2]]
    centre = (a + b + c) / 3.0
    reach = wp.sqrt(wp.max(wp.length_sq(a - centre),
                           wp.max(wp.length_sq(b - centre), wp.length_sq(c - centre))))
    nt = wp.cross(b - a, c - a)
    lnt = wp.length(nt)
    u = wp.vec3(0.0)
    if lnt > 0.0:
        u = nt / lnt
    s.tri_centre[t] = wp.vec4(centre[0], centre[1], centre[2], reach)
    s.tri_normal[t] = wp.vec4(u[0], u[1], u[2], wp.sqrt(lnt))


def _centres(s: Surfels, device: str) -> None:
    """Fill ``s.centre`` from the triangles (``fan_centre``), and each triangle's centre, reach,
    normal and size."""
    if s.centre.shape[0]:
        wp.launch(_centre_kernel, dim=s.centre.shape[0], inputs=[s], device=device)
    if s.tri_centre.shape[0]:
        wp.launch(_frame_kernel, dim=s.tri_centre.shape[0], inputs=[s], device=device)


def assign(s: Surfels, elements) -> None:
    """Overwrite the moving parts of ``s`` (positions, normals, centres, areas, materials) with
    those of ``elements``: the same elements, deformed or moved (an animation frame; the BVH's
    points already moved)."""
    s.pos.assign(elements.position)
    s.nrm.assign(elements.normal)
    s.area.assign(elements.area)
    s.albedo.assign(elements.albedo)
    s.emission.assign(elements.emission)
    _centres(s, s.pos.device)


@wp.func
def fan_triangle(s: Surfels, j: int, u0: float) -> int:
    """One of element j's triangles, chosen by area with u0 ∈ [0, 1)."""
    total = float(0.0)
    for k in range(s.fan_offsets[j], s.fan_offsets[j + 1]):
        total += _triangle_area2(s.points, s.tris, s.fan_triangles[k])
    pick = u0 * total
    chosen = s.fan_triangles[s.fan_offsets[j]]
    for k in range(s.fan_offsets[j], s.fan_offsets[j + 1]):
        pick -= _triangle_area2(s.points, s.tris, s.fan_triangles[k])
        if pick <= 0.0:
            chosen = s.fan_triangles[k]
            break
    return chosen


@wp.func
def fan_sample(s: Surfels, j: int, u0: float, u1: float, u2: float) -> wp.vec3:
    """A point of element j's own surface: on one of its triangles (chosen by area with u0), in the
    half of it nearest to j's vertex. Points on the real surface, unlike the tangent disk, stay
    inside a curved closed mesh."""
    chosen = fan_triangle(s, j, u0)
    a = s.points[s.tris[3 * chosen]]
    b = s.points[s.tris[3 * chosen + 1]]
    c = s.points[s.tris[3 * chosen + 2]]
    r = wp.sqrt(u1)
    q = a * (1.0 - r) + b * (r * (1.0 - u2)) + c * (r * u2)
    pj = s.points[s.vertex[j]]
    return pj + (q - pj) * 0.5


@wp.func
def _triangle_area2(points: wp.array(dtype=wp.vec3), tris: wp.array(dtype=wp.int32), t: int) -> float:
    """Twice the area of triangle t (the arrays, not the Surfels struct: Warp copies structs)."""
    a = points[tris[3 * t]]
    return wp.length(wp.cross(points[tris[3 * t + 1]] - a, points[tris[3 * t + 2]] - a))


@wp.func
def element_ff(s: Surfels, i: int, j: int) -> float:
    """Form factor from element i's point to the front of element j."""
    return point_ff(s, s.pos[i], s.nrm[i], j)


@wp.func
def fan_ff(s: Surfels, p: wp.vec3, n: wp.vec3, j: int, side: float) -> float:
    """Form factor from p (unit normal n) to one side of element j's share (a third) of its
    triangles: the front faces for side 1, the back faces for side −1; a triangle counts where p
    lies off its plane by more than PLANE_EPS of its size plus their distance (in the plane it is
    seen edge-on). Where every triangle of the fan counts and lies wholly above p's horizon, the
    fan's outline (``outline_fan_ff``); else triangle by triangle, exactly, or from
    ``far_triangle_ff`` where ``triangle_view`` allows (a leaf pair's fans several triangles apart:
    3–4× cheaper)."""
    whole = outline_fan_ff(s, p, n, j, side)
    if whole >= 0.0:
        return whole
    total = float(0.0)
    for k in range(s.fan_offsets[j], s.fan_offsets[j + 1]):
        t = s.fan_triangles[k]
        cr = s.tri_centre[t]
        nr = s.tri_normal[t]
        centre = wp.vec3(cr[0], cr[1], cr[2])
        normal = wp.vec3(nr[0], nr[1], nr[2])
        if _counts(p, side, centre, nr):
            view = triangle_view(p, n, centre, cr[3])
            if view >= 0:
                a = s.points[s.tris[3 * t]]
                b = s.points[s.tris[3 * t + 1]]
                c = s.points[s.tris[3 * t + 2]]
                if view == 1:
                    total += far_triangle_ff(p, n, a, b, c, centre, normal, 0.5 * nr[3] * nr[3])
                else:
                    total += outline_ff(p, n, OUTLINE_TRIANGLE, 3, a, b, c, 0.0, 0.0)
    return total / 3.0


@wp.func
def _counts(p: wp.vec3, side: float, centre: wp.vec3, nr: wp.vec4) -> bool:
    """Whether a triangle (centre, unit normal and size ``nr``: ``Surfels.tri_normal``) shows
    ``side`` to p, off its plane by more than PLANE_EPS of its size plus their distance."""
    d = p - centre
    return side * side_of(wp.dot(d, wp.vec3(nr[0], nr[1], nr[2])), PLANE_EPS * (wp.length(d) + nr[3])) > 0.0


@wp.func
def outline_fan_ff(s: Surfels, p: wp.vec3, n: wp.vec3, j: int, side: float) -> float:
    """``fan_ff`` from the fan's outline where that is exact, else −1: where p sees ``side`` of
    every triangle of element j (as ``_counts``, from the element's vertex and without the square
    root) and no corner lies below p's horizon (by more than HORIZON_EPS of its distance: one on
    it, a wall's foot seen from the floor, clips nothing), the triangles' contour integrals all
    take one sign and none is clipped, so their sum is the integral over the edges opposite the
    element and the open spokes (``elements.fan_outline``: the shared spokes cancel) — a third of
    the arc terms of summing them triangle by triangle. It stops at the first triangle that
    breaks this, so a fan it cannot take costs ``fan_ff`` little more than its own loop."""
    v = s.points[s.vertex[j]] - p
    if not _unclipped(v, n):
        return -1.0
    tol = (PLANE_EPS * PLANE_EPS) * wp.dot(v, v)
    total = float(0.0)
    for k in range(s.fan_offsets[j], s.fan_offsets[j + 1]):
        edge = s.fan_outline[k]
        nr = s.tri_normal[s.fan_triangles[k]]
        # p's height over the triangle's plane, measured from the element's vertex (a corner)
        h = -side * wp.dot(v, wp.vec3(nr[0], nr[1], nr[2])) - PLANE_EPS * nr[3]
        if edge[2] >= FAN_TANGLED or h <= 0.0 or h * h <= tol:
            return -1.0
        a = s.points[edge[0]] - p
        b = s.points[edge[1]] - p
        if not (_unclipped(a, n) and _unclipped(b, n)):
            return -1.0
        total += arc_term(a, b, n)
        if (edge[2] & FAN_OPEN_OUT) != 0:
            total += arc_term(v, a, n)
        if (edge[2] & FAN_OPEN_IN) != 0:
            total += arc_term(b, v, n)
    return wp.abs(total) * (INV_TWO_PI / 3.0)


@wp.func
def _unclipped(x: wp.vec3, n: wp.vec3) -> bool:
    """Whether point x (relative to the receiver) lies above the horizon of unit normal n, or below
    it by at most HORIZON_EPS of its distance (no square root)."""
    h = wp.dot(x, n)
    return h >= 0.0 or h * h <= (HORIZON_EPS * HORIZON_EPS) * wp.dot(x, x)


@wp.func
def point_ff(s: Surfels, p: wp.vec3, n: wp.vec3, j: int) -> float:
    """Form factor from point p (unit normal n) to the front of element j: its disk far away, its
    exact triangles when d² < NEAR·A_j."""
    return face_ff(s, p, n, j, 1.0)


@wp.func
def face_ff(s: Surfels, p: wp.vec3, n: wp.vec3, j: int, side: float) -> float:
    """Form factor from point p (unit normal n) to one face of element j: the front for side 1,
    the back for side −1 (what antiradiance leaves by); as ``point_ff``. The disk stands at the
    centre of j's triangles, not at its point (nudged to its vertex): from a disk at the corner a
    face-corner element of a coarse flat-shaded sphere is seen too far, and its rows summed to
    0.979 instead of 1 (icosphere of 320 faces)."""
    d = s.pos[j] - p
    if wp.dot(d, d) < NEAR * s.area[j]:
        return fan_ff(s, p, n, j, side)
    return disk_ff(p, n, s.centre[j], s.nrm[j] * side, s.area[j])


@wp.func
def ray_ends(i: int, j: int, f_ij: float, f_ji: float) -> wp.vec2i:
    """(from, to): which element's point the visibility rays between elements i and j leave from,
    towards the other's own surface, given the form factors f_ij (i receiving from j) and f_ji.
    Where only one of them receives, from its point: what that point sees of the other is what it
    gets, while the other's point may be hidden (a floor vertex under a box whose triangles reach
    out in front of it). Where both do, one ray serves both ways: from the lower-numbered one's,
    the same either way round."""
    if f_ij > 0.0 and not (f_ji > 0.0):
        return wp.vec2i(i, j)
    if f_ji > 0.0 and not (f_ij > 0.0):
        return wp.vec2i(j, i)
    return wp.vec2i(wp.min(i, j), wp.max(i, j))


@wp.func
def pair_hits(s: Surfels, ends: wp.vec2i, rays: int, seed: int) -> int:
    """Unblocked rays of ``rays`` from element ends[0]'s point to stratified points of element
    ends[1]'s own surface (``ray_ends``), both lifted off their surfaces. Seeded by the pair, so
    every evaluation of a pair gives the same value."""
    i = ends[0]
    j = ends[1]
    state = wp.rand_init(seed, wp.min(i, j) * 65521 + wp.max(i, j))
    origin = lift(s.pos[i], s.nrm[i], wp.sqrt(s.area[i]))
    hits = int(0)
    for k in range(rays):
        u0 = (float(k) + wp.randf(state)) / float(rays)
        q = lift(fan_sample(s, j, u0, wp.randf(state), wp.randf(state)), s.nrm[j], wp.sqrt(s.area[j]))
        d = q - origin
        dist = wp.length(d)
        if dist <= 0.0:
            hits += 1
        elif not wp.mesh_query_ray_anyhit(s.mesh, origin, d / dist, dist * 0.9999):
            hits += 1
    return hits


@wp.func
def fan_centre(e: int, vertex: wp.array(dtype=wp.int32), fan_offsets: wp.array(dtype=wp.int32),
               fan_triangles: wp.array(dtype=wp.int32), tris: wp.array(dtype=wp.int32),
               points: wp.array(dtype=wp.vec3)) -> wp.vec3:
    """The area-weighted centre of element e's share of its triangles (a third each, around its
    vertex)."""
    total = float(0.0)
    acc = wp.vec3(0.0)
    pv = points[vertex[e]]
    for k in range(fan_offsets[e], fan_offsets[e + 1]):
        tri = fan_triangles[k]
        a = points[tris[3 * tri]]
        b = points[tris[3 * tri + 1]]
        c = points[tris[3 * tri + 2]]
        w = wp.length(wp.cross(b - a, c - a))
        total += w
        acc += w * (pv + (a + b + c) / 3.0) * 0.5
    if total > 0.0:
        return acc / total
    return pv
