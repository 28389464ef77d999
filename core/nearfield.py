"""A sender's light as a receiver close to it sees it, not its element's average (issue 21).

An element sends one radiance, ρ ⊙ (D + I) with D its point's direct lighting, over its share of
its triangles (a third of each, ``surfels.fan_ff``), and is seen or hidden as its point is.
Far away that is what a receiver sees; within about an element's size it is not: the floor under
an object standing on it passes from sun to shadow inside one element, so the object's underside
sees mostly the dark part, and a floor vertex hidden under the object hides none of its triangles
that reach out into view (measured on the open scene, a capsule on a floor under a sun: 82 % of
the squared error against Cycles on the capsule's lowest 5 cm, which no finer link or extra ray
moved).

So every triangle gets direct light traced at fixed points (PER_TRIANGLE each, an R2 set of barycentric coordinates; ``core.direct``,
each with a share of the light samples, POINT_SHARE or POINT_SHARE_EXACT) where its corners' direct light differs. A final
gather at point p (the hierarchical solver's at elements and texels, the reference's last sweep)
then takes an element with such triangles within √FAR of its sizes as its triangles' points: each weighted by the kernel cos θ cos θ' / r² from p, with its own direct light, and where
it weighs more than SEEN of the whole, its own ray from p (elsewhere the link's visible fraction):
ρ ⊙ (D_i + I) summed so over the leaf's exact unoccluded form factor from p (``near_light``), in
full within NEAR sizes and blended back to the link's value by FAR. Indirect light stays the
element's: it varies slowly. (Weighting each point by its corner's hat function as well, so the
corners' radiances interpolate linearly, measured no better on the open scene: 0.91 % against
0.90 %, the contact ring darker in truth than either model.)
"""
from __future__ import annotations

import math

import numpy as np
import warp as wp

from . import direct as direct_mod
from .rays import lift, visible
from .surfels import Surfels, point_ff

wp.set_module_options({"enable_backward": False})  # no gradients: halves compile time

# Points per triangle (measured on the open scene against a brute-force gather of the floor's
# direct light at the capsule's vertices 1–3 cm up: ~11 per triangle +29 %, ~42 +7 %; 32 and 64
# gave the same total error, 0.85 %, in an earlier variant).
PER_TRIANGLE = 32
# Each point traces this share of ``light_samples`` where the light tree chooses the emitters (8
# at the default 64): a hit of the final gather reads its nearest point alone, so a point's noise is
# not averaged with its neighbours', and the tree's choice of emitters adds to it. At 1/32 (2
# samples a point) it was most of the level's error (bench/real_scenes.py, 116 k elements, 8 845
# emitters; against Cycles at 1 024 samples, 128 gather rays): relative RMSE 10.76 % in 14.4 s;
# 1/16 9.65 % (+0.2 s), 1/8 9.06 % (+0.7 s), 1/4 8.99 % (+1.7 s), 1/2 8.96 %. Where every emitter
# is weighed exactly only the shadows are sampled, and 1/32 holds: 1/8 cost the furnished room
# (two lamps) 0.24 s of 1.4 s for no less error (2.54 → 2.57 %).
POINT_SHARE = 8
POINT_SHARE_EXACT = PER_TRIANGLE
# A receiver at squared distance d² from an element's centre sees it integrated over its
# triangles below NEAR × its area, as its element average beyond FAR × its area (blended between).
NEAR = 4.0
FAR = 16.0
# A triangle gets points traced when its corners' direct lighting differs by more
# than this fraction of the brightest direct lighting of any element (elsewhere its corners' own
# values stand).
VARIES = 0.01
# Points of a near sender that weigh, or bring light, more than this fraction of the whole get
# their own ray.
SEEN = 0.01
PI = math.pi


@wp.struct
class Detail:
    """direct: vec3[n] each element's direct lighting (irradiance/π); detailed: int32[n] 1 where
    a triangle of the element has points traced; bary: vec3[PER_TRIANGLE] the points' barycentric
    coordinates; row: int32[T] each triangle's row of ``light``, −1 where its elements' own direct
    light stands; light: vec3[R, PER_TRIANGLE] direct lighting at its points."""

    direct: wp.array(dtype=wp.vec3)
    detailed: wp.array(dtype=wp.int32)
    bary: wp.array(dtype=wp.vec3)
    row: wp.array(dtype=wp.int32)
    light: wp.array2d(dtype=wp.vec3)


@wp.func
def _point(nf: Detail, s: Surfels, tri: int, i: int) -> wp.vec3:
    """Point i of triangle tri."""
    u = nf.bary[i]
    return (s.points[s.tris[3 * tri]] * u[0] + s.points[s.tris[3 * tri + 1]] * u[1]
            + s.points[s.tris[3 * tri + 2]] * u[2])


@wp.func
def _area2(s: Surfels, tri: int) -> float:
    """Twice the area of triangle tri (m²)."""
    c0 = s.points[s.tris[3 * tri]]
    return wp.length(wp.cross(s.points[s.tris[3 * tri + 1]] - c0, s.points[s.tris[3 * tri + 2]] - c0))


@wp.func
def _weight(q: wp.vec3, p: wp.vec3, n: wp.vec3, ne: wp.vec3, area2: float) -> float:
    """The kernel cos θ cos θ' / r² of a point q (a 1/PER_TRIANGLE share of a triangle of twice
    the area ``area2``, front ne) seen from p (normal n), softened by the point's own patch."""
    v = q - p
    r2 = wp.dot(v, v) + area2 / (2.0 * PI * float(PER_TRIANGLE))
    return area2 * wp.max(wp.dot(n, v), 0.0) * wp.max(-wp.dot(ne, v), 0.0) / (r2 * r2)


@wp.func
def varies(nf: Detail, e: int) -> bool:
    """Whether element e's triangles had their direct light traced (it may send light where its
    own vertex has none)."""
    if nf.direct.shape[0] == 0:
        return False
    return nf.detailed[e] != 0


@wp.func
def near_light(nf: Detail, s: Surfels, e: int, glow: wp.vec3, f: float, p: wp.vec3, n: wp.vec3,
               origin: wp.vec3) -> wp.vec3:
    """The light element e (radiance ``glow``) sends to point p (unit normal n; rays leave from
    ``origin``, p lifted) whose transfer from it is f: glow × f far away or where e's triangles'
    direct light does not vary; else its triangles' points as p sees them — each
    weighted by the kernel, with its own direct light and, where it weighs or brings over SEEN of
    the total, its own ray from p (the link's visible fraction elsewhere): the parts actually
    seen, not the element's vertex, whose view may be blocked where its triangles' is not."""
    far = glow * f
    if not varies(nf, e):
        return far
    a = s.area[e]
    d = s.centre[e] - p
    blend = wp.clamp((FAR - wp.dot(d, d) / a) / (FAR - NEAR), 0.0, 1.0)
    if blend <= 0.0:
        return far
    unoccluded = point_ff(s, p, n, e)
    if unoccluded <= 0.0:
        return far
    through = wp.clamp(f / unoccluded, 0.0, 1.0)
    ne = s.nrm[e]
    size = wp.sqrt(a)
    own = nf.direct[e]
    indirect = glow - wp.cw_mul(s.albedo[e], own)  # ρ I, the same at every point
    total = float(0.0)  # Σ w, and Σ w × each point's radiance (luminance): which points get rays
    bright = float(0.0)
    for k in range(s.fan_offsets[e], s.fan_offsets[e + 1]):
        tri = s.fan_triangles[k]
        area2 = _area2(s, tri)
        row = nf.row[tri]
        for i in range(PER_TRIANGLE):
            w = _weight(_point(nf, s, tri, i), p, n, ne, area2)
            total += w
            bright += w * _luminance(_radiance(nf, s, e, row, i, own, indirect))
    if total <= 0.0:
        return far
    lit = wp.vec3(0.0)  # Σ w V (ρ D + ρ I)
    for k in range(s.fan_offsets[e], s.fan_offsets[e + 1]):
        tri = s.fan_triangles[k]
        area2 = _area2(s, tri)
        row = nf.row[tri]
        for i in range(PER_TRIANGLE):
            q = _point(nf, s, tri, i)
            w = _weight(q, p, n, ne, area2)
            if w > 0.0:
                glow_i = _radiance(nf, s, e, row, i, own, indirect)
                # a point that brings much of the light gets its own ray: a hidden bright spot (the
                # ceiling lit 1 mm above a lamp's back) must not shine through the link's fraction
                if w * _luminance(glow_i) > SEEN * bright or w > SEEN * total:
                    w *= visible(s.mesh, origin, lift(q, ne, size))
                else:
                    w *= through
                lit += glow_i * w
    near = lit * (unoccluded / total)  # the kernel's sum over the unoccluded form factor
    return far + (near - far) * blend


@wp.func
def _radiance(nf: Detail, s: Surfels, e: int, row: int, i: int, own: wp.vec3, indirect: wp.vec3) -> wp.vec3:
    """Element e's radiance ρ (D_i + I) at point i of a triangle whose points have ``row``."""
    if row >= 0:
        return wp.cw_mul(s.albedo[e], nf.light[row, i]) + indirect
    return wp.cw_mul(s.albedo[e], own) + indirect


@wp.func
def _luminance(c: wp.vec3) -> float:
    return wp.max(c[0] + c[1] + c[2], 0.0)


def barycentric(count: int) -> np.ndarray:
    """float32[count,3]: an R2 low-discrepancy set of points of a triangle, barycentric, uniform
    by area (the square folded onto the triangle)."""
    g = 1.32471795724474602596
    u = np.mod(0.5 + np.arange(count)[:, None] * np.array([1.0 / g, 1.0 / (g * g)]), 1.0)
    fold = u.sum(axis=1) > 1.0
    u[fold] = 1.0 - u[fold]
    return np.column_stack([1.0 - u.sum(axis=1), u]).astype(np.float32)


def empty(device: str) -> Detail:
    """A ``Detail`` that leaves every sender as its element average."""
    nf = Detail()
    nf.direct = wp.zeros(0, dtype=wp.vec3, device=device)
    nf.detailed = wp.zeros(0, dtype=wp.int32, device=device)
    nf.bary = wp.zeros(PER_TRIANGLE, dtype=wp.vec3, device=device)
    nf.row = wp.zeros(0, dtype=wp.int32, device=device)
    nf.light = wp.zeros((1, PER_TRIANGLE), dtype=wp.vec3, device=device)
    return nf


def build(problem) -> Detail:
    """The ``Detail`` of ``problem``: direct light traced at the points of every triangle whose
    corners' direct light differs (rays counted in ``problem.counts``). Traced for every element,
    not only those near a receiver, so that every solver gets the same (the reference's final
    sweep and the hierarchical final gather over leaf links only agree exactly)."""
    dev, els, scene = problem.device, problem.elements, problem.scene
    d = dev.name
    n = els.count
    # only where its corners' direct light differs can a triangle's vary much (a shadow that
    # crosses a triangle without touching a corner is missed)
    spread = np.ptp(problem.direct[els.corner], axis=1).max(axis=1)
    tris = np.flatnonzero(spread > VARIES * max(float(problem.direct.max(initial=0.0)), 1e-30))
    bary = barycentric(PER_TRIANGLE)
    row = np.full(scene.num_triangles, -1, np.int32)
    row[tris] = np.arange(len(tris), dtype=np.int32)
    detailed = np.zeros(n, np.int32)
    detailed[els.corner[tris].ravel()] = 1
    light = np.zeros((max(len(tris), 1), PER_TRIANGLE, 3), np.float32)
    if len(tris):
        corners = scene.positions[scene.triangles[tris]]  # [M,3,3]
        points = np.einsum("pk,mkc->mpc", bary, corners).reshape(-1, 3)
        normals = np.einsum("pk,mkc->mpc", bary, np.asarray(scene.corner_normals, np.float32)[tris]).reshape(-1, 3)
        sizes = np.repeat(np.sqrt(scene.triangle_areas()[tris] / PER_TRIANGLE), PER_TRIANGLE).astype(np.float32)
        settings = problem.settings
        share = POINT_SHARE_EXACT if direct_mod.exact_selection(problem, len(points)) else POINT_SHARE
        traced, rays, _, _ = direct_mod.estimate(
            problem, points, normals, sizes, np.full(len(points), direct_mod.MODE_FULL, np.int32),
            max(1, math.ceil(settings.light_samples / share)), settings.seed + 7919)
        problem.counts["rays"] += int(rays.sum())
        light = traced.reshape(-1, PER_TRIANGLE, 3)
    problem.counts["near_triangles_traced"] = int(len(tris))
    nf = Detail()
    nf.direct = wp.array(problem.direct, dtype=wp.vec3, device=d)
    nf.detailed = wp.array(detailed, dtype=wp.int32, device=d)
    nf.bary = wp.array(bary, dtype=wp.vec3, device=d)
    nf.row = wp.array(row, dtype=wp.int32, device=d)
    nf.light = wp.array(np.ascontiguousarray(light), dtype=wp.vec3, device=d)
    return nf
