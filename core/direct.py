"""Direct light: lamps and emissive triangles at arbitrary receiver points, with shadow rays.

Lighting is irradiance/π at the receiver's normal (radiance units, W m⁻² sr⁻¹), as Cycles bakes
DIFFUSE Direct without Color. Unoccluded transfer is analytic where it can be (exact polygon form
factors for area lamps and emissive triangles — a 3-point quadrature for triangles far from the
receiver, ``formfactor.far_triangle_ff`` —, inverse-square for point/spot, for the sun the projected
solid angle of its cone).

Each receiver traces ``light_samples`` shadow rays in all, however many emitters there are: the
samples are stratified over [0,1) and a light tree (``core.lighttree``) over every lamp and
emissive triangle shares them out by importance (each node's interval of [0,1) split among its
children), down to buckets of a few emitters weighed by their exact unoccluded light; with few
emitters (``light_selection`` auto) every emitter is weighed exactly. A triangle of a closed
emissive surface that shows a receiver the side the surface hides from it (its inner side from
outside, ``closed_sides`` and a winding number per receiver) is weighed INNER_WEIGHT of that.
An emitter's samples are
points of one scrambled (0,2)-sequence on it, its shadow the visible fraction weighted by the
transfer kernel (so penumbrae stay unbiased where the kernel varies across the lamp), and it adds
transfer × shadow × its share of the samples / its probability: unbiased in the choice of emitters,
the cost per receiver growing with the depth of the tree, log(emitters). Lightmap texels add
adaptive shadows on top (``core.lightmap.shadows``): the kernel's PROBE and UNSHADOWED modes.
"""
from __future__ import annotations

import math
from typing import Callable, Optional

import numpy as np
import warp as wp

from . import device as device_mod
from . import lighttree
from .formfactor import far_triangle_ff, outline_ff, tangent_frame, triangle_ff, triangle_view
from .rays import lift, lift_towards, visible
from .scene import LAMP_AREA, LAMP_SPOT, LAMP_SUN, SceneData
from .sh import moment_of

wp.set_module_options({"enable_backward": False})  # no gradients: halves compile time

PI = math.pi
ELLIPSE_SIDES = wp.constant(32)
# An ellipse lamp's outline is a regular polygon whose radii are scaled by this so that its area
# equals the ellipse's.
ELLIPSE_SCALE = wp.constant(1.0 / math.sqrt(32 / (2.0 * PI) * math.sin(2.0 * PI / 32)))
# A shadowed estimate's noise is measured against at least this fraction of its unshadowed light.
NOISE_FLOOR = wp.constant(0.05)
# The stack entry that stands for every leaf at once (``exact``).
ALL_LEAVES = wp.constant(-2)
BUCKET = wp.constant(lighttree.BUCKET)
stack_int = wp.types.vector(length=lighttree.STACK, dtype=wp.int32)
stack_f64 = wp.types.vector(length=lighttree.STACK, dtype=wp.float64)
bucket_vec = wp.types.vector(length=lighttree.BUCKET, dtype=wp.float32)


@wp.struct
class Emitters:
    """The lamps, the emissive triangles and the light tree over them, as kernels read them.

    lamp_*: one entry per lamp (see ``core.scene.Lamps``; unit direction and axes, spot cones as
    the cosine of the half angle and the smoothstep width of the blend); em_v0, em_v1, em_v2:
    vec3[E] corners of the emissive triangles with area, em_centre, em_normal: vec3[E] their centroids
    and unit winding normals, em_area: float32[E] (m²), em_reach: float32[E] the farthest corner
    from the centroid (m), em_radiance: vec3[E]; em_side:
    float32[E] where each lies on a closed surface of emissive triangles (``closed_sides``);
    closed: the ``wp.Mesh`` id of those closed surfaces wound outward (winding numbers tell a
    receiver inside them; 0 without any); tree: the ``lighttree.LightTree`` over all of them.
    """

    lamp_kind: wp.array(dtype=wp.int32)
    lamp_pos: wp.array(dtype=wp.vec3)
    lamp_dir: wp.array(dtype=wp.vec3)
    lamp_u: wp.array(dtype=wp.vec3)
    lamp_v: wp.array(dtype=wp.vec3)
    lamp_size: wp.array(dtype=wp.vec2)
    lamp_shape: wp.array(dtype=wp.int32)
    lamp_power: wp.array(dtype=wp.vec3)
    lamp_cos_half: wp.array(dtype=wp.float32)
    lamp_smooth: wp.array(dtype=wp.float32)
    em_v0: wp.array(dtype=wp.vec3)
    em_v1: wp.array(dtype=wp.vec3)
    em_v2: wp.array(dtype=wp.vec3)
    em_centre: wp.array(dtype=wp.vec3)
    em_normal: wp.array(dtype=wp.vec3)
    em_area: wp.array(dtype=wp.float32)
    em_reach: wp.array(dtype=wp.float32)
    em_radiance: wp.array(dtype=wp.vec3)
    em_side: wp.array(dtype=wp.float32)
    closed: wp.uint64
    tree: lighttree.LightTree


class Lights:
    """The scene's lamps and emissive triangles on the device (``emitters``, the struct kernels
    read) with the light tree over them and the mesh of the closed emissive surfaces
    (``closed_mesh``, None without any); num_lamps, num_emitters (emissive triangles with area)."""

    def __init__(self, scene: SceneData, dev: device_mod.Device):
        d = dev.name
        pos = np.asarray(scene.positions, np.float32)
        emissive = (scene.emission.max(axis=1) > 0.0) & (scene.triangle_areas() > 0.0)
        tri = pos[scene.triangles[emissive]].astype(np.float64)
        radiance = np.ascontiguousarray(scene.emission[emissive], np.float32)
        self.num_emitters = int(emissive.sum())
        lamps = scene.lamps
        self.num_lamps = len(lamps)
        cos_half = np.cos(0.5 * lamps.spot_size.astype(np.float64))
        g = Emitters()
        g.em_v0, g.em_v1, g.em_v2 = (wp.array(np.ascontiguousarray(tri[:, k], np.float32), dtype=wp.vec3,
                                              device=d) for k in range(3))
        centre = tri.mean(axis=1)
        g.em_centre = wp.array(centre.astype(np.float32), dtype=wp.vec3, device=d)
        g.em_normal = wp.array(unit(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])), dtype=wp.vec3, device=d)
        g.em_area = wp.array(scene.triangle_areas()[emissive].astype(np.float32), dtype=wp.float32, device=d)
        g.em_reach = wp.array(np.linalg.norm(tri - centre[:, None], axis=2).max(axis=1).astype(np.float32),
                              dtype=wp.float32, device=d)
        g.em_radiance = wp.array(radiance, dtype=wp.vec3, device=d)
        side = closed_sides(tri)
        g.em_side = wp.array(side, dtype=wp.float32, device=d)
        # kept here: the struct holds only the mesh's id
        self.closed_mesh = None
        g.closed = 0
        if (side != 0).any():
            out = np.where((side < 0)[:, None, None], tri[:, [0, 2, 1]], tri)[side != 0]
            self.closed_mesh = wp.Mesh(points=wp.array(out.reshape(-1, 3).astype(np.float32), dtype=wp.vec3, device=d),
                                       indices=wp.array(np.arange(out.shape[0] * 3, dtype=np.int32), device=d),
                                       support_winding_number=True)
            g.closed = self.closed_mesh.id
        g.lamp_kind = wp.array(lamps.kind.astype(np.int32), dtype=wp.int32, device=d)
        g.lamp_pos = wp.array(lamps.position.astype(np.float32), dtype=wp.vec3, device=d)
        g.lamp_dir = wp.array(unit(lamps.direction), dtype=wp.vec3, device=d)
        g.lamp_u = wp.array(unit(lamps.axis_u), dtype=wp.vec3, device=d)
        g.lamp_v = wp.array(unit(lamps.axis_v), dtype=wp.vec3, device=d)
        g.lamp_size = wp.array(lamps.size.astype(np.float32), dtype=wp.vec2, device=d)
        g.lamp_shape = wp.array(lamps.shape.astype(np.int32), dtype=wp.int32, device=d)
        g.lamp_power = wp.array(lamps.power.astype(np.float32), dtype=wp.vec3, device=d)
        g.lamp_cos_half = wp.array(cos_half.astype(np.float32), dtype=wp.float32, device=d)
        g.lamp_smooth = wp.array(((1.0 - cos_half) * lamps.spot_blend).astype(np.float32),
                                 dtype=wp.float32, device=d)
        leaves = _leaves(lamps, tri, radiance)
        g.tree = (lighttree.upload(lighttree.build(leaves), leaves, d) if len(leaves)
                  else lighttree.upload_empty(d))
        self.emitters = g


def _leaves(lamps, tri: np.ndarray, radiance: np.ndarray) -> lighttree.Leaves:
    """Light-tree leaves of the lamps and emissive triangles (float64[E,3,3] corners): boxes,
    orientation cones and powers in lighting units at unit distance (irradiance/π: a point lamp of
    power P gives P/4π² there, an area lamp P/π², a Lambertian triangle of radiance L and area A
    seen straight on L·A/π)."""
    kind = lamps.kind
    nl = len(lamps)
    size = lamps.size.astype(np.float64)
    half = np.where(kind == LAMP_AREA, 0.5 * np.hypot(size[:, 0], size[:, 1]),
                    np.where(kind == LAMP_SUN, 0.0, size[:, 0]))
    lamp_power = lamps.power.astype(np.float64).sum(axis=1)
    lamp_power = lamp_power * np.where(kind == LAMP_AREA, 1.0 / PI ** 2, 1.0 / (4.0 * PI ** 2))
    nt = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area = 0.5 * np.linalg.norm(nt, axis=1)
    pos = lamps.position.astype(np.float64)
    # point lamps emit every way; spots are bounded by their cone widened by a right angle (a
    # sphere lamp's points see past the cone's edge); area lamps and triangles are Lambertian
    lamp_theta_o = np.where(kind == LAMP_AREA, 0.0, np.where(kind == LAMP_SPOT, np.minimum(
        0.5 * lamps.spot_size.astype(np.float64), PI), PI))
    return lighttree.Leaves(
        kind=np.concatenate([np.full(nl, lighttree.LEAF_LAMP),
                             np.full(len(tri), lighttree.LEAF_TRIANGLE)]).astype(np.int32),
        index=np.concatenate([np.arange(nl), np.arange(len(tri))]).astype(np.int32),
        lo=np.concatenate([pos - half[:, None], tri.min(axis=1)]).astype(np.float32),
        hi=np.concatenate([pos + half[:, None], tri.max(axis=1)]).astype(np.float32),
        axis=np.concatenate([unit(lamps.direction), unit(nt)]).astype(np.float32),
        theta_o=np.concatenate([lamp_theta_o, np.zeros(len(tri))]).astype(np.float32),
        theta_e=np.full(nl + len(tri), 0.5 * PI, np.float32),
        two_sided=np.concatenate([np.zeros(nl, bool), np.ones(len(tri), bool)]),
        power=np.concatenate([lamp_power,
                              radiance.astype(np.float64).sum(axis=1) * area / PI]).astype(np.float32),
        distant=np.concatenate([kind == LAMP_SUN, np.zeros(len(tri), bool)]))


def closed_sides(tri: np.ndarray) -> np.ndarray:
    """float32[E] for triangles with corners float64[E,3,3] (m): +1 where a triangle's winding
    normal (b−a)×(c−a) points out of the closed, consistently wound surface it is part of (every
    edge of that connected surface shared by exactly two of its triangles, wound opposite ways;
    corners within 10⁻⁶ of the extent welded), −1 where it points in, 0 on an open surface."""
    e = len(tri)
    if e == 0:
        return np.zeros(0, np.float32)
    pts = tri.reshape(-1, 3)
    grid = 1e-6 * max(float(np.ptp(pts, axis=0).max()), 1e-30)
    _, vid = np.unique(np.round(pts / grid).astype(np.int64), axis=0, return_inverse=True)
    v = vid.reshape(e, 3)
    a, b = v.ravel(), v[:, [1, 2, 0]].ravel()
    face = np.repeat(np.arange(e), 3)
    code = np.minimum(a, b) * (int(vid.max()) + 1) + np.maximum(a, b)
    codes, edge, count = np.unique(code, return_inverse=True, return_counts=True)
    forward = np.bincount(edge, weights=(a < b), minlength=len(codes))
    good_edge = (count == 2) & (forward == 1)
    good = np.bincount(face, weights=good_edge[edge], minlength=e) == 3
    # connected surfaces: faces joined by their shared edges, labels by min-propagation and jumps
    order = np.argsort(edge, kind="stable")
    shared = good_edge[edge[order]]
    f1, f2 = face[order][shared][0::2], face[order][shared][1::2]
    label = np.arange(e)
    while True:
        low = np.minimum(label[f1], label[f2])
        new = label.copy()
        np.minimum.at(new, f1, low)
        np.minimum.at(new, f2, low)
        new = new[new]
        if np.array_equal(new, label):
            break
        label = new
    closed = ~np.isin(label, label[~good])
    volume = np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2]))
    sign = np.sign(np.bincount(label, weights=volume, minlength=e))[label]
    return np.where(closed, sign, 0.0).astype(np.float32)


def unit(v: np.ndarray) -> np.ndarray:
    """float32[N,3] rows of ``v`` scaled to unit length (zero rows stay zero)."""
    v = np.asarray(v, np.float64).reshape(-1, 3)
    n = np.linalg.norm(v, axis=1, keepdims=True)
    return (v / np.where(n > 0, n, 1.0)).astype(np.float32)


@wp.func
def _sobol_bits(k: int, second: int) -> wp.uint32:
    """The 32 bits of coordinate 0 (the radical inverse in base 2) or 1 (``second``) of point k
    of the Sobol (0,2)-sequence."""
    v = wp.uint32(1) << wp.uint32(31)  # bit 31
    r = wp.uint32(0)
    x = k
    while x > 0:
        if x % 2 == 1:
            r = r ^ v
        x = x / 2
        if second != 0:
            v = v ^ (v >> wp.uint32(1))
        else:
            v = v >> wp.uint32(1)
    return r


@wp.func
def sample2d(k: int, scramble: wp.vec2) -> wp.vec2:
    """Point k of the (0,2)-sequence over the unit square with its digits scrambled by
    ``scramble`` (two numbers in [0,1), their bits XORed in): every prefix is stratified and
    scrambling keeps it so (a probe's tile shares one sequence); unbiased for a uniform scramble."""
    su = wp.uint32(scramble[0] * 4294967040.0)
    sv = wp.uint32(scramble[1] * 4294967040.0)
    u = float(_sobol_bits(k, 0) ^ su) * 2.3283064365386963e-10
    v = float(_sobol_bits(k, 1) ^ sv) * 2.3283064365386963e-10
    return wp.vec2(wp.min(u, 0.99999994), wp.min(v, 0.99999994))


@wp.func
def _disk(s: wp.vec2, u: wp.vec3, v: wp.vec3, rx: float, ry: float) -> wp.vec3:
    """Offset of the uniform point s (unit square) of the ellipse with radii rx, ry along u, v."""
    r = wp.sqrt(s[0])
    phi = 6.283185307179586 * s[1]
    return u * (rx * r * wp.cos(phi)) + v * (ry * r * wp.sin(phi))


@wp.func
def _weighted_visibility(mesh: wp.uint64, origin: wp.vec3, p: wp.vec3, n: wp.vec3, q: wp.vec3,
                         nq: wp.vec3, size: float) -> wp.vec2:
    """(w, w·V) for a sample q of a planar sender with normal nq (any length) and feature size
    ``size`` (m): w = cos_R·|cos_E|/d², the transfer kernel, and V the visibility of q, its ray
    ending off the sender on the receiver's side (``lift_towards``; no ray where w = 0)."""
    d = q - p
    d2 = wp.dot(d, d)
    w = wp.max(wp.dot(n, d), 0.0) * wp.abs(wp.dot(nq, d)) / (d2 * d2 + 1.0e-30)
    if w <= 0.0:
        return wp.vec2(0.0, 0.0)
    return wp.vec2(w, w * visible(mesh, origin, lift_towards(q, nq, origin, size)))


@wp.func
def _spot_factor(kind: int, w_from_lamp: wp.vec3, axis: wp.vec3, cos_half: float, smooth: float) -> float:
    """Blender/Cycles spot cone: smoothstep of (cos angle − cos half-angle) over the blend width."""
    if kind != LAMP_SPOT:
        return 1.0
    t = wp.dot(w_from_lamp, axis) - cos_half
    if t <= 0.0:
        return 0.0
    if smooth <= 0.0 or t >= smooth:
        return 1.0
    return wp.smoothstep(0.0, 1.0, t / smooth)


@wp.func
def _sun_half_angle(g: Emitters, l: int) -> float:
    """Half the angular diameter of sun lamp l (rad), at most a right angle (Blender's 180°)."""
    return wp.min(0.5 * g.lamp_size[l][0], 1.5707963267948966)


@wp.func
def _sun_cosine(cos_t: float, half: float) -> float:
    """A sun's lighting over its strength S, times π, at a surface whose normal makes the angle
    with cosine ``cos_t`` with the direction to the sun's centre; ``half`` the sun's half angle
    (rad, ≤ π/2). Cycles gives the sun the radiance S/(π sin²half) over its cone, so that a
    surface facing it receives the irradiance S: this is ∫cone max(0, n·ω) dω / (π sin²half),
    cos_t while the cone stays above the horizon and less once it dips below (the closed form
    of a spherical cap's projected solid angle, Snyder 1996)."""
    s2 = wp.sin(half) * wp.sin(half)
    if half <= 0.0 or cos_t * cos_t >= s2:
        return wp.max(cos_t, 0.0)
    sin_t = wp.max(wp.sqrt(wp.max(1.0 - cos_t * cos_t, 0.0)), 1.0e-6)
    x = wp.sqrt(wp.max(1.0 / s2 - 1.0, 0.0))
    y = wp.clamp(-x * cos_t / sin_t, -1.0, 1.0)
    a = sin_t * wp.sqrt(1.0 - y * y)
    return wp.max(((cos_t * wp.acos(y) - x * a) * s2 + wp.atan2(a, x)) / (3.141592653589793 * s2), 0.0)


@wp.func
def _lamp_transfer(g: Emitters, l: int, p: wp.vec3, n: wp.vec3) -> wp.vec3:
    """Unoccluded lighting of lamp l at p (normal n): inverse square for point and spot lamps,
    over d² + radius² (no cone: it is applied per shadow sample), the sun's cone's projected solid angle, the exact form factor of an area
    lamp's outline (one-sided)."""
    kind = g.lamp_kind[l]
    power = g.lamp_power[l]
    if kind == LAMP_SUN:
        return power * (_sun_cosine(-wp.dot(n, g.lamp_dir[l]), _sun_half_angle(g, l)) / 3.141592653589793)
    if kind == LAMP_AREA:
        c = g.lamp_pos[l]
        if wp.dot(p - c, g.lamp_dir[l]) <= 0.0:
            return wp.vec3(0.0)  # one-sided: only the side the lamp points to is lit
        hx = 0.5 * g.lamp_size[l][0]
        hy = 0.5 * g.lamp_size[l][1]
        ell = g.lamp_shape[l]
        area = 4.0 * hx * hy
        scale = float(1.0)
        if ell != 0:
            area = 3.141592653589793 * hx * hy
            scale = ELLIPSE_SCALE  # an ellipse's outline polygon is scaled to the ellipse's area
        ff = outline_ff(p, n, ell, ELLIPSE_SIDES, c, g.lamp_u[l], g.lamp_v[l], hx * scale, hy * scale)
        if ff <= 0.0 or area <= 0.0:
            return wp.vec3(0.0)
        # radiance of a one-sided area lamp: P / (π A)
        return power * (ff / (3.141592653589793 * area))
    to = g.lamp_pos[l] - p
    d2 = wp.dot(to, to)
    if d2 <= 0.0:
        return wp.vec3(0.0)
    cos_r = wp.dot(n, to) / wp.sqrt(d2)
    if cos_r <= 0.0:
        return wp.vec3(0.0)
    # intensity P/4π W/sr → irradiance I·cos/d² → lighting = irradiance/π; a lamp of radius r
    # gives cos/(d² + r²) in Cycles, as a disk of radius r facing the receiver (measured through
    # bpy: r/d = 1/6, 1/3, 1/2 give 1/(1 + r²/d²) of the point's light to four digits)
    r = g.lamp_size[l][0]
    return power * (cos_r / (4.0 * 3.141592653589793 * 3.141592653589793 * (d2 + r * r)))


@wp.func
def _lamp_shadow(g: Emitters, mesh: wp.uint64, l: int, p: wp.vec3, n: wp.vec3, origin: wp.vec3,
                 k0: int, k1: int, rot: wp.vec2, far: float, trace: int):
    """(shadow, rays): the visible fraction of lamp l from p over points k0 … k1−1 of its point
    sequence (spot cones applied per sample, area lamps weighted by the transfer kernel); with
    ``trace`` 0 every sample counts as visible (no rays)."""
    kind = g.lamp_kind[l]
    if trace == 0 and kind != LAMP_SPOT:
        return 1.0, 0
    if kind == LAMP_SUN:
        # directions uniform over the sun's cone (as Cycles samples it), weighted by their cosine
        w = -g.lamp_dir[l]
        half = _sun_half_angle(g, l)
        if half <= 0.0:
            return visible(mesh, origin, origin + w * far), 1
        t1, t2 = tangent_frame(w)
        one_minus_cos = 2.0 * wp.sin(0.5 * half) * wp.sin(0.5 * half)
        acc = wp.vec2(0.0, 0.0)
        rays = int(0)
        for k in range(k0, k1):
            st = sample2d(k, rot)
            below = st[0] * one_minus_cos  # 1 − cos of the sample's angle from the sun's centre
            sin_a = wp.sqrt(wp.max(below * (2.0 - below), 0.0))
            phi = 6.283185307179586 * st[1]
            ws = w * (1.0 - below) + t1 * (sin_a * wp.cos(phi)) + t2 * (sin_a * wp.sin(phi))
            cos_r = wp.dot(n, ws)
            if cos_r > 0.0:
                acc += wp.vec2(cos_r, cos_r * visible(mesh, origin, origin + ws * far))
                rays += 1
        if acc[0] <= 0.0:
            return 0.0, rays
        return acc[1] / acc[0], rays
    if kind == LAMP_AREA:
        c = g.lamp_pos[l]
        hx = 0.5 * g.lamp_size[l][0]
        hy = 0.5 * g.lamp_size[l][1]
        acc = wp.vec2(0.0, 0.0)
        for k in range(k0, k1):
            st = sample2d(k, rot)
            q = c + _disk(st, g.lamp_u[l], g.lamp_v[l], hx, hy)
            if g.lamp_shape[l] == 0:
                q = c + g.lamp_u[l] * (hx * (2.0 * st[0] - 1.0)) + g.lamp_v[l] * (hy * (2.0 * st[1] - 1.0))
            acc += _weighted_visibility(mesh, origin, p, n, q, g.lamp_dir[l], hx + hy)
        if acc[0] <= 0.0:
            return 0.0, k1 - k0
        return acc[1] / acc[0], k1 - k0
    # point and spot: cone attenuation averaged over the lamp (Cycles applies the spot cone to
    # each sampled point of a sphere lamp, which widens the blend band by ~asin(r/d))
    lp = g.lamp_pos[l]
    radius = g.lamp_size[l][0]
    if radius <= 0.0:
        att = _spot_factor(kind, wp.normalize(p - lp), g.lamp_dir[l], g.lamp_cos_half[l], g.lamp_smooth[l])
        if att <= 0.0:
            return 0.0, 0
        if trace == 0:
            return att, 0
        return att * visible(mesh, origin, lp), 1
    t1, t2 = tangent_frame(wp.normalize(lp - p))
    lit = float(0.0)
    rays = int(0)
    for k in range(k0, k1):
        q = lp + _disk(sample2d(k, rot), t1, t2, radius, radius)
        att = _spot_factor(kind, wp.normalize(p - q), g.lamp_dir[l], g.lamp_cos_half[l], g.lamp_smooth[l])
        if att > 0.0:
            if trace == 0:
                lit += att
            else:
                lit += att * visible(mesh, origin, q)
                rays += 1
    return lit / float(k1 - k0), rays


@wp.func
def _triangle_transfer(g: Emitters, e: int, p: wp.vec3, n: wp.vec3) -> wp.vec3:
    """Unoccluded lighting of emissive triangle e at p (normal n): its radiance × the exact form
    factor (both faces emit; none where p lies in its plane, ``triangle_ff``), from a quadrature
    where the triangle is far and above p's horizon (``far_triangle_ff``: 3–4× cheaper); none where
    it lies wholly below that horizon."""
    view = triangle_view(p, n, g.em_centre[e], g.em_reach[e])
    if view == -1:
        return wp.vec3(0.0)
    ff = float(0.0)
    if view == 1:
        ff = far_triangle_ff(p, n, g.em_v0[e], g.em_v1[e], g.em_v2[e], g.em_centre[e], g.em_normal[e],
                             g.em_area[e])
    else:
        ff = triangle_ff(p, n, g.em_v0[e], g.em_v1[e], g.em_v2[e])
    if ff <= 0.0:
        return wp.vec3(0.0)
    return g.em_radiance[e] * ff


@wp.func
def _triangle_shadow(g: Emitters, mesh: wp.uint64, e: int, p: wp.vec3, n: wp.vec3, origin: wp.vec3,
                     k0: int, k1: int, rot: wp.vec2, trace: int):
    """(shadow, rays): the kernel-weighted visible fraction of emissive triangle e over points
    k0 … k1−1 of its point sequence (uniform by area); 1 with ``trace`` 0."""
    if trace == 0:
        return 1.0, 0
    a = g.em_v0[e]
    b = g.em_v1[e]
    c = g.em_v2[e]
    nt = wp.cross(b - a, c - a)
    size = wp.sqrt(0.5 * wp.length(nt))
    acc = wp.vec2(0.0, 0.0)
    for k in range(k0, k1):
        st = sample2d(k, rot)
        r = wp.sqrt(st[0])
        q = a * (1.0 - r) + b * (r * (1.0 - st[1])) + c * (r * st[1])
        acc += _weighted_visibility(mesh, origin, p, n, q, nt, size)
    if acc[0] <= 0.0:
        return 0.0, k1 - k0
    return acc[1] / acc[0], k1 - k0


@wp.func
def _leaf_transfer(g: Emitters, leaf: int, p: wp.vec3, n: wp.vec3) -> wp.vec3:
    """Unoccluded lighting at p of light-tree leaf ``leaf`` (a lamp or an emissive triangle)."""
    i = g.tree.leaf_index[leaf]
    if g.tree.leaf_kind[leaf] == lighttree.LEAF_LAMP:
        return _lamp_transfer(g, i, p, n)
    return _triangle_transfer(g, i, p, n)


# The weight of an emissive triangle of a closed surface that shows a receiver outside the closed
# surfaces its inner side, or a receiver inside them its outer side: the surface itself hides that
# side from it (the inside decided once per receiver by the winding number of all closed emissive
# surfaces together, so nested ones count as inside the outer). The weight only makes such samples
# rarer, so the estimate stays unbiased where the guess is wrong.
# Measured on the emissive room (exact weighing, 64 samples): 1, 1/16, 1/64, 1/256 give 5.3 %,
# 2.2 %, 1.5 %, 1.2 % relative RMSE against Cycles; a receiver inside one closed emitter and
# outside another pays for a smaller weight in noise.
INNER_WEIGHT = wp.constant(1.0 / 64.0)
# With weights shared by a group of receivers (``exact`` 2, see ``emitter_weights``), this share of
# the samples is spread evenly over all emitters: a receiver that an emitter lights where the
# group's point sees none of it still samples it (unbiased), at the cost of a few samples.
SHARED_FLOOR = wp.constant(1.0 / 32.0)


@wp.func
def _leaf_light(g: Emitters, leaf: int, p: wp.vec3, n: wp.vec3, outside: float, shadows: int):
    """(unoccluded lighting vec3, weight, spot) of ``leaf`` at p: the weight, how likely it is
    chosen among its bucket, is the lighting's RGB sum (for a point-like spot times its cone, which
    then decides alone whether it lights p; for a triangle of a closed emissive surface that shows
    p the side it hides times INNER_WEIGHT: its inner side where ``outside`` is 1 (p outside the
    closed surfaces), its outer side where it is −1 (p inside), neither where it is 0); spot 1 for
    a spot lamp, whose cone the shadow applies. Without ``shadows`` (an unshadowed estimate) such a
    hidden side is no light at all: its own surface hides it, the one shadow known without rays
    (counted, it nearly doubled the unshadowed light of a neon tube)."""
    t = _leaf_transfer(g, leaf, p, n)
    w = t[0] + t[1] + t[2]
    i = g.tree.leaf_index[leaf]
    spot = int(0)
    if g.tree.leaf_kind[leaf] == lighttree.LEAF_TRIANGLE:
        # a lit triangle shows p its front where p lies above its plane (no rounding matters: p
        # in its plane gets no light from it)
        if w > 0.0 and g.em_side[i] != 0.0:
            if outside * g.em_side[i] * wp.dot(p - g.em_centre[i], g.em_normal[i]) < 0.0:
                if shadows == 0:
                    return wp.vec3(0.0), 0.0, spot
                w *= INNER_WEIGHT
    if g.tree.leaf_kind[leaf] == lighttree.LEAF_LAMP:
        if g.lamp_kind[i] == LAMP_SPOT:
            spot = 1
            if w > 0.0 and g.lamp_size[i][0] <= 0.0:
                w *= _spot_factor(LAMP_SPOT, wp.normalize(p - g.lamp_pos[i]), g.lamp_dir[i],
                                  g.lamp_cos_half[i], g.lamp_smooth[i])
    return t, w, spot


@wp.func
def leaf_direction(g: Emitters, leaf: int, p: wp.vec3) -> wp.vec3:
    """Unit direction from p towards light-tree leaf ``leaf``: a lamp's position (against a sun's
    direction), an emissive triangle's centroid."""
    i = g.tree.leaf_index[leaf]
    if g.tree.leaf_kind[leaf] == lighttree.LEAF_LAMP:
        if g.lamp_kind[i] == LAMP_SUN:
            return -g.lamp_dir[i]
        return wp.normalize(g.lamp_pos[i] - p)
    return wp.normalize(g.em_centre[i] - p)


@wp.func
def _importance(g: Emitters, node: int, p: wp.vec3, n: wp.vec3) -> float:
    """Importance of a tree node at p: the bound for local nodes, the exact unoccluded lighting of
    distant lamps (they have no position to bound)."""
    t = g.tree
    if t.distant[node] == 0:
        return lighttree.bound_importance(t, node, p, n)
    s = float(0.0)
    for j in range(t.first[node], t.first[node] + t.count[node]):
        tj, w, sj = _leaf_light(g, j, p, n, 0.0, 1)
        s += w
    return s


@wp.func
def _outside(g: Emitters, origin: wp.vec3, far: float) -> float:
    """1 where ``origin`` lies outside every closed emissive surface (or there are none), −1 inside
    one (its winding number), for ``_leaf_light``."""
    if g.closed == wp.uint64(0):
        return 1.0
    q = wp.mesh_query_point_sign_winding_number(g.closed, origin, far)
    if q.result and q.sign < 0.0:
        return -1.0
    return 1.0


@wp.func
def _first_sample(x: wp.float64, count: int, r: wp.float64) -> int:
    """Index of the first of ``count`` stratified samples (k + r)/count at or above x ∈ [0, 1]."""
    return wp.clamp(int(wp.ceil(x * wp.float64(count) - r)), 0, count)


@wp.func
def _rotation(seed: int, leaf: int) -> wp.vec2:
    """The Cranley–Patterson rotation of the point set on ``leaf`` for a receiver (or tile) seed."""
    state = wp.rand_init(seed, leaf)
    return wp.vec2(wp.randf(state), wp.randf(state))


@wp.func
def _place(c: float, lo: wp.float64, hi: wp.float64, total: float) -> wp.float64:
    """Where cumulative weight ``c`` of a bucket's ``total`` falls in its interval [lo, hi] of u."""
    if c < total:
        return lo + (hi - lo) * wp.float64(c / total)
    return hi


@wp.func
def _cumulative(k: int, count: int, r: wp.float64, lo: wp.float64, hi: wp.float64, total: float) -> float:
    """A cumulative weight of a bucket (``total`` over [lo, hi] of u) that a leaf must reach to
    hold stratified sample k (at u = (k + r)/count): just below where that sample falls."""
    u = (wp.float64(k) + r) / wp.float64(count)
    return float((u - lo) / (hi - lo)) * total * (1.0 - 1.0e-5)


@wp.func
def _estimate(g: Emitters, mesh: wp.uint64, p: wp.vec3, n: wp.vec3, origin: wp.vec3, count: int,
              kb: int, ke: int, seed: int, shadows: int, exact: int, far: float,
              kept: wp.array2d(dtype=wp.float32), row: int):
    """Direct lighting at p (normal n, rays from ``origin``) from samples kb … ke−1 of ``count``
    stratified light samples: (vec3 lighting, rays, lit, dark, noise, moment).

    Sample k is u = (k + r)/count for one random r; the light tree maps u to an emitter, each node
    splitting its interval of u among its children by importance (a bucket among its leaves by their
    exact unoccluded lighting), so the samples an emitter gets are a run of consecutive k and its
    probability is its interval's length. The tree is walked depth first, each node once, over the
    intervals that hold samples. Each emitter's samples are points of one (0,2)-sequence on it; it
    adds transfer × shadow × samples / (samples asked × probability): unbiased in the choice of
    emitters, the shadow the kernel-weighted visible fraction as for a single lamp. ``shadows`` 0
    leaves shadows out (every sample visible, no rays). ``exact`` 1 weighs every emitter by its
    exact unoccluded lighting, as one bucket: each emitter's share of the samples is then its share
    of the light (hidden sides of closed emissive surfaces weighed less, ``_leaf_light``); with
    ``row`` ≥ 0 the weights are kept in that row of ``kept`` (float32[receivers, leaves]) between
    the pass that sums them and the one that shares the samples out, which then weighs again
    only the emitters that get samples (else every emitter is weighed twice). ``exact`` 2: the
    weights are row ``row`` of ``kept`` already (float32[groups, leaves + 1], the last column
    their sum, or −1 where an emitter is too near the group for them: the light tree chooses
    there), weighed at a point standing for a group of receivers (``emitter_weights``), with
    SHARED_FLOOR of the samples spread evenly; each emitter that gets samples is weighed at p
    for its light. lit / dark: 1 if some emitter's shadow was above 0 / below 1. noise: the
    estimate's standard error from the spread of its samples, relative to it (or to NOISE_FLOOR of
    its unshadowed light where it is darker than that); 0 unshadowed. moment: mat33, rows R, G, B
    of Σ (each emitter's lighting / cosθ) × its direction (``moment_of``): where the light comes
    from, (1/π) ∫ L ω dω; its rows dotted with n give the lighting.
    """
    t = g.tree
    value = wp.vec3(0.0)
    moment = wp.mat33(0.0)
    rays = int(0)
    lit = int(0)
    dark = int(0)
    # Σ x, Σ x² and Σ x unshadowed (luminance) of the samples' contributions x, for the noise
    sx = float(0.0)
    sxx = float(0.0)
    su = float(0.0)
    if t.root < 0:
        return value, rays, lit, dark, 0.0, moment
    r = wp.float64(wp.randf(wp.rand_init(seed, -1)))
    outside = _outside(g, origin, far)
    nodes = stack_int()
    los = stack_f64()
    his = stack_f64()
    nodes[0] = t.root
    if exact == 2:
        if kept[row, kept.shape[1] - 1] < 0.0:
            exact = 0  # an emitter too near for the group's weights to stand for p's: the tree's
            row = -1
    if exact != 0:
        nodes[0] = ALL_LEAVES
    los[0] = wp.float64(0.0)
    his[0] = wp.float64(1.0)
    sp = int(1)
    asked = float(ke - kb)
    weights = bucket_vec()
    red = bucket_vec()
    green = bucket_vec()
    blue = bucket_vec()
    while sp > 0:
        sp -= 1
        node = nodes[sp]
        lo = los[sp]
        hi = his[sp]
        if wp.max(_first_sample(lo, count, r), kb) >= wp.min(_first_sample(hi, count, r), ke):
            continue  # no sample falls into this node
        left = int(-1)
        first = int(0)
        leaves = t.leaf_kind.shape[0]
        if node != ALL_LEAVES:
            left = t.left[node]
            first = t.first[node]
            leaves = t.count[node]
        if left >= 0:
            il = _importance(g, left, p, n)
            ir = _importance(g, t.right[node], p, n)
            if il + ir <= 0.0:
                continue
            s = lo + (hi - lo) * wp.float64(il / (il + ir))
            if ir > 0.0:
                nodes[sp] = t.right[node]
                los[sp] = s
                his[sp] = hi
                sp += 1
            if il > 0.0:
                nodes[sp] = left
                los[sp] = lo
                his[sp] = s
                sp += 1
            continue
        total = float(0.0)
        light = wp.vec3(0.0)
        light_moment = wp.mat33(0.0)
        spots = int(0)
        even = float(0.0)
        if exact == 2:
            even = 1.0 / float(leaves)  # the group's point sees none: every emitter alike
            if kept[row, leaves] > 0.0:
                even = SHARED_FLOOR * kept[row, leaves] / float(leaves)
            total = kept[row, leaves] + even * float(leaves)
            spots = 1  # sampled, never summed whole
        else:  # the weights at p
            for j in range(leaves):
                tj, wj, sj = _leaf_light(g, first + j, p, n, outside, shadows)
                if j < BUCKET:
                    weights[j] = wj
                    red[j] = tj[0]
                    green[j] = tj[1]
                    blue[j] = tj[2]
                elif row >= 0:
                    kept[row, first + j] = wj
                if wj > 0.0:
                    total += wj
                    light += tj
                    if shadows == 0:
                        light_moment += moment_of(tj, leaf_direction(g, first + j, p), n)
                    spots += sj
        if total <= 0.0:
            continue
        if shadows == 0 and spots == 0:
            # unshadowed, the bucket's samples may as well count all its leaves at once
            a = wp.max(_first_sample(lo, count, r), kb)
            b = wp.min(_first_sample(hi, count, r), ke)
            share = float(b - a) / (asked * float(hi - lo))
            value += light * share
            moment += light_moment * share
            continue
        cum = float(0.0)
        # the next sample of ours, as a cumulative weight below which a leaf ends before it: the
        # leaves in between get no sample and are passed over without placing them on u (with a
        # margin, so a leaf that may hold a sample is always placed as before)
        end = wp.min(_first_sample(hi, count, r), ke)
        nxt = wp.max(_first_sample(lo, count, r), kb)
        skip = _cumulative(nxt, count, r, lo, hi, total)
        for j in range(leaves):
            w = float(0.0)
            tj = wp.vec3(0.0)
            if exact == 2:
                w = kept[row, j] + even
            elif j < BUCKET:
                w = weights[j]
                tj = wp.vec3(red[j], green[j], blue[j])
            elif row >= 0:
                w = kept[row, first + j]
            else:
                tj, w, sj = _leaf_light(g, first + j, p, n, outside, shadows)
            if w <= 0.0:
                continue
            before = cum
            cum += w
            if cum < skip:
                continue
            l0 = _place(before, lo, hi, total)
            l1 = _place(cum, lo, hi, total)
            a = _first_sample(l0, count, r)
            b = _first_sample(l1, count, r)
            e0 = wp.max(a, kb)
            e1 = wp.min(b, ke)
            nxt = wp.max(b, kb)
            if nxt >= end:
                skip = 2.0 * total  # no sample left: only this leaf's own, if any
            else:
                skip = _cumulative(nxt, count, r, lo, hi, total)
            if e0 < e1:
                leaf = first + j
                if exact == 2:
                    tj, wj, sj = _leaf_light(g, leaf, p, n, outside, shadows)
                elif j >= BUCKET and row >= 0:
                    tj = _leaf_transfer(g, leaf, p, n)
                i = t.leaf_index[leaf]
                rot = _rotation(seed, leaf)
                shadow = float(0.0)
                nr = int(0)
                if t.leaf_kind[leaf] == lighttree.LEAF_LAMP:
                    shadow, nr = _lamp_shadow(g, mesh, i, p, n, origin, e0 - a, e1 - a, rot, far, shadows)
                else:
                    shadow, nr = _triangle_shadow(g, mesh, i, p, n, origin, e0 - a, e1 - a, rot, shadows)
                rays += nr
                if shadow > 0.0:
                    lit = 1
                if shadow < 1.0:
                    dark = 1
                if shadow > 0.0:
                    part = tj * (shadow * float(e1 - e0) / (asked * float(l1 - l0)))
                    value += part
                    moment += moment_of(part, leaf_direction(g, leaf, p), n)
                # each sample adds x = T/p where seen: Σx² ≈ (T/p)² × shadow × samples
                x = (tj[0] + tj[1] + tj[2]) / float(l1 - l0)
                sx += x * shadow * float(e1 - e0)
                sxx += x * x * shadow * float(e1 - e0)
                su += x * float(e1 - e0)
    noise = float(0.0)
    if asked > 1.0 and su > 0.0:
        error = wp.sqrt(wp.max(sxx - sx * sx / asked, 0.0) / (asked * (asked - 1.0)))
        noise = error / wp.max(sx / asked, NOISE_FLOOR * su / asked)
    return value, rays, lit, dark, noise, moment


@wp.func
def leaf_seen(g: Emitters, mesh: wp.uint64, leaf: int, p: wp.vec3, seed: int, samples: int,
              far: float) -> wp.vec3:
    """The light of light-tree leaf ``leaf`` at a point p in space, as a receiver facing it sees it
    (its unoccluded lighting towards ``leaf_direction`` × its visible fraction over ``samples``
    shadow rays): (1/π) ∫ L dω over the emitter, for light probes."""
    w = leaf_direction(g, leaf, p)
    t = _leaf_transfer(g, leaf, p, w)
    if t[0] + t[1] + t[2] <= 0.0:
        return wp.vec3(0.0)
    i = g.tree.leaf_index[leaf]
    rot = _rotation(seed, leaf)
    shadow = float(0.0)
    rays = int(0)
    if g.tree.leaf_kind[leaf] == lighttree.LEAF_LAMP:
        shadow, rays = _lamp_shadow(g, mesh, i, p, w, p, 0, samples, rot, far, 1)
    else:
        shadow, rays = _triangle_shadow(g, mesh, i, p, w, p, 0, samples, rot, 1)
    return t * shadow


# Modes of the direct-light kernel per receiver.
MODE_SKIP, MODE_FULL, MODE_UNSHADOWED, MODE_PROBE = -1, 0, 1, 2


@wp.kernel
def _direct_kernel(offset: int, mesh: wp.uint64, g: Emitters, points: wp.array(dtype=wp.vec3),
                   normals: wp.array(dtype=wp.vec3), sizes: wp.array(dtype=wp.float32),
                   mode: wp.array(dtype=wp.int32), count: int, tile: wp.array(dtype=wp.int32),
                   tile_index: wp.array(dtype=wp.int32), tile_count: wp.array(dtype=wp.int32),
                   seed: int, first: int, exact: int, far: float, out: wp.array(dtype=wp.vec3),
                   rays: wp.array(dtype=wp.int32), flags: wp.array(dtype=wp.int32),
                   noise: wp.array(dtype=wp.float32), with_moments: int,
                   moments: wp.array(dtype=wp.mat33), keep: int, kept: wp.array2d(dtype=wp.float32),
                   group: wp.array(dtype=wp.int32)):
    """Per receiver by ``mode``: FULL ``count`` shadowed samples; UNSHADOWED the same without
    shadows; PROBE one sample, the receiver's own of its tile's stratified set (tile_index of
    tile_count, seeded per tile); SKIP nothing (0). Receiver i's jitter is seeded by first + i (its
    index in the whole set). flags: 1 lit, 2 dark, 3 both; noise: relative standard error;
    moments (``with_moments`` 1): where the light comes from (see _estimate); keep 1: kept is
    float32[W, leaves] scratch for ``exact`` weights (see _estimate), receiver i in row i mod W,
    each launch wave W receivers or fewer; keep 0: weigh twice; ``exact`` 2: kept holds the
    weights of groups of receivers, receiver i's in row group[i]."""
    i = wp.tid() + offset
    md = mode[i]
    if md == MODE_SKIP:
        out[i] = wp.vec3(0.0)
        rays[i] = 0
        flags[i] = 0
        noise[i] = 0.0
        if with_moments != 0:
            moments[i] = wp.mat33(0.0)
        return
    p = points[i]
    n = normals[i]
    origin = lift(p, n, sizes[i])
    total = count
    kb = int(0)
    ke = count
    s = wp.randi(wp.rand_init(seed, first + i))
    if md == MODE_PROBE:
        total = tile_count[i]
        kb = tile_index[i]
        ke = kb + 1
        s = wp.randi(wp.rand_init(seed + 1, tile[i]))
    shadows = int(1)
    if md == MODE_UNSHADOWED:
        shadows = 0
    row = int(-1)
    if keep != 0:
        row = i % kept.shape[0]
    if exact == 2:
        row = group[i]
    value, nr, lit, dark, err, moment = _estimate(g, mesh, p, n, origin, total, kb, ke, s, shadows,
                                                  exact, far, kept, row)
    out[i] = value
    if with_moments != 0:
        moments[i] = moment
    rays[i] = nr
    flags[i] = lit + 2 * dark
    noise[i] = err


def estimate(problem, points: np.ndarray, normals: np.ndarray, sizes: np.ndarray, mode: np.ndarray,
             count: int, seed: int, tiles=None, progress: Optional[Callable[[float], None]] = None,
             first: int = 0, whole: Optional[int] = None, with_moments: bool = False,
             exact: Optional[bool] = None, shared=None):
    """One pass of the direct-light kernel over N receivers of ``problem``.

    points, normals: float32[N,3] (m, the problem's frame; unit); sizes: float32[N] local feature
    size (m) for the ray offset; mode: int32[N] MODE_* per receiver; count: samples of the FULL and
    UNSHADOWED modes; seed: of the sample jitter; tiles: for MODE_PROBE, (tile int[N], the
    receiver's index in its tile int[N], receivers in its tile int[N]); first: the index of these
    receivers' first in the whole set they are part of (a lightmap page baked alone), which seeds
    their jitter, and whole: that set's size (it decides exact emitter weighing), None: N — so a
    part gets the light the whole would; exact: whether every emitter is weighed exactly (None:
    ``exact_selection``); shared: an ``emitter_weights.Shared`` of these receivers, whose groups'
    weights choose the emitters instead (``exact`` is then not looked at). Returns (float32[N,3]
    lighting, int64[N] rays, int32[N] flags: 1 some emitter was seen, 2 some was shadowed, 3 both;
    float32[N] noise: each estimate's standard error relative to it, see ``_estimate``), and with
    ``with_moments`` a fifth, float32[N,3,3]: per receiver rows R, G, B of the light's first moment
    (1/π) ∫ L ω dω (world-space vectors; each row · normal = the lighting).
    """
    dev = problem.device
    d = dev.name
    n = int(mode.shape[0])
    out = wp.zeros(n, dtype=wp.vec3, device=d)
    rays = wp.zeros(n, dtype=wp.int32, device=d)
    flags = wp.zeros(n, dtype=wp.int32, device=d)
    noise = wp.zeros(n, dtype=wp.float32, device=d)
    moments = wp.zeros(n if with_moments else 1, dtype=wp.mat33, device=d)
    if tiles is None:
        tiles = (np.zeros(1, np.int32),) * 3
    tile_arrays = [wp.array(np.ascontiguousarray(a, np.int32), dtype=wp.int32, device=d) for a in tiles]
    if exact is None and shared is None:
        exact = exact_selection(problem, n if whole is None else whole)
    leaves = problem.lights.num_lamps + problem.lights.num_emitters
    # exact weights kept per receiver, for as many receivers per launch wave as KEPT_FLOATS allow
    chunks = max(1, min(32, n // 256))
    keep = shared is None and exact and leaves <= KEPT_FLOATS
    if keep:
        chunks = max(chunks, -(-n * leaves // KEPT_FLOATS))
    wave = -(-n // max(1, min(chunks, n)))
    kept = wp.empty((wave, leaves) if keep else (1, 1), dtype=wp.float32, device=d)
    group = wp.zeros(1, dtype=wp.int32, device=d)
    if shared is not None:
        kept, group, exact = shared.kept, shared.row, 2
    device_mod.launch(
        _direct_kernel, n,
        [problem.mesh.id, problem.lights.emitters,
         wp.array(np.ascontiguousarray(points, np.float32), dtype=wp.vec3, device=d),
         wp.array(unit(normals), dtype=wp.vec3, device=d),
         wp.array(np.ascontiguousarray(sizes, np.float32), dtype=wp.float32, device=d),
         wp.array(np.ascontiguousarray(mode, np.int32), dtype=wp.int32, device=d), int(count),
         *tile_arrays, int(seed), int(first), int(exact), problem.far, out, rays, flags, noise,
         int(with_moments), moments, int(keep), kept, group],
        dev, chunks=chunks, on_chunk=progress)
    result = (out.numpy().astype(np.float32), rays.numpy().astype(np.int64), flags.numpy(),
              noise.numpy())
    return result + (moments.numpy(),) if with_moments else result


# Where ``light_selection`` auto let the light tree choose the emitters, receivers whose estimate's
# relative standard error exceeds this are estimated again with every emitter weighed exactly: the
# tree's bounds under-rate emitters very near a receiver, which then get too few samples (a lamp
# post's top 1 cm under its emissive globe got 0.05 … 14.7 where Cycles gives 2.1; 2.0 … 2.3 with
# every receiver weighed exactly). Measured on the level of ``bench/real_scenes.py``: relative RMSE
# 18.1 → 13.4 % against a 256-sample Cycles truth, direct light 2.2 → 4.7 s on two cores.
EXACT_NOISE = 0.3


def direct_lighting(problem, points: np.ndarray, normals: np.ndarray, sizes: np.ndarray,
                    progress: Optional[Callable[[float], None]] = None, part=None):
    """Direct lighting at receivers of ``problem`` (a ``core.problem.Problem``: its BVH, lights,
    device and ``settings.light_samples``, the stratified light samples per receiver).

    points, normals: float32[N,3] positions (m, the problem's frame) and unit normals; sizes:
    float32[N] local feature size (m) for the ray offset; part: where they lie in a larger set
    (``receivers.Part``), None for a whole set. Where the light tree chose the emitters, the
    noisiest receivers are estimated again weighing every emitter exactly (``exact_again``).
    Returns (float32[N,3] lighting = irradiance/π, number of shadow rays traced).
    """
    n = int(points.shape[0])
    seeding = part.seeding() if part is not None else {}
    count, seed = problem.settings.light_samples, problem.settings.seed
    mode = np.full(n, MODE_FULL, np.int32)
    out, rays, _, noise = estimate(problem, points, normals, sizes, mode, count, seed, progress=progress, **seeding)
    noisy, again, more = exact_again(problem, points, normals, sizes, mode, noise, count, seed + 1, seeding)
    out[noisy] = again[noisy]
    return out, int(rays.sum() + more.sum())


def exact_again(problem, points: np.ndarray, normals: np.ndarray, sizes: np.ndarray, mode: np.ndarray,
                noise: np.ndarray, count: int, seed: int, seeding: dict):
    """Where ``light_selection`` auto let the light tree choose the emitters: the receivers whose
    estimate (``mode`` int32[N], its ``noise`` float32[N] from ``estimate``) has a relative standard
    error above EXACT_NOISE, estimated again in the same mode with ``count`` samples weighing every
    emitter exactly. Returns (bool[N] those receivers, float32[N,3] their lighting, int64[N] rays);
    none under exact or tree selection, or where auto weighs exactly already."""
    n = int(mode.shape[0])
    noisy = (noise > EXACT_NOISE) & (mode != MODE_SKIP)
    if (problem.settings.light_selection != "auto" or not noisy.any()
            or exact_selection(problem, seeding.get("whole", n))):
        return np.zeros(n, bool), np.zeros((n, 3), np.float32), np.zeros(n, np.int64)
    again, rays, _, _ = estimate(problem, points, normals, sizes, np.where(noisy, mode, MODE_SKIP).astype(np.int32),
                                 count, seed, exact=True, **seeding)
    return noisy, again, rays


# The back of a surface without thickness counts as lit where its direct light reaches this
# fraction of the brightest direct lighting of any element.
BACK_LIGHT = 0.01
# Light samples per element of that check (at most ``light_samples``): it only tells lit backs from
# dark ones, against a threshold far below the light of a lit one.
BACK_SAMPLES = 16


def lit_backs(problem) -> tuple[list, int]:
    """(sorted names of the objects without thickness (``elements.open_objects``) whose back faces
    direct light reaches — at some element at least BACK_LIGHT of the brightest direct lighting
    of the elements —, shadow rays traced). Elements are one-sided: that light is not passed on,
    where Cycles reflects it off the back face. An unshadowed pass picks the candidates, a
    shadowed one (BACK_SAMPLES samples) confirms them."""
    from . import elements as elements_mod

    scene, els, settings = problem.scene, problem.elements, problem.settings
    objects = els.objects(scene)
    at = np.flatnonzero(elements_mod.open_objects(scene)[objects] & (els.area > 0))
    threshold = BACK_LIGHT * float(problem.direct.max(initial=0.0))
    if not len(at) or threshold <= 0.0:
        return [], 0
    points, backs, sizes = els.position[at], -els.normal[at], problem.element_sizes[at]
    for mode in (MODE_UNSHADOWED, MODE_FULL):
        light, rays, _, _ = estimate(problem, points, backs, sizes, np.full(len(at), mode, np.int32),
                                     min(settings.light_samples, BACK_SAMPLES), settings.seed)
        lit = light.max(axis=1) >= threshold
        at, points, backs, sizes = at[lit], points[lit], backs[lit], sizes[lit]
        if not len(at):
            break
    return sorted({scene.object_names[i] for i in np.unique(objects[at])}), int(rays.sum())


# ``light_selection`` auto weighs every emitter exactly at every receiver where there are at most
# EXACT_EMITTERS (about as much work per receiver as a few shadow rays) or where that is at most
# EXACT_WORK weighings in all (about 4 s on two cores at ~60 ns a weighing).
EXACT_EMITTERS = 16
EXACT_WORK = 1 << 27
# Most exact weights (float32) kept at once, per launch wave: 256 MB.
KEPT_FLOATS = 1 << 26


def exact_selection(problem, receivers: int) -> bool:
    """Whether direct light at ``receivers`` receivers weighs every emitter exactly
    (``light_selection``: exact; tree; auto: see EXACT_EMITTERS)."""
    mode = problem.settings.light_selection
    if mode != "auto":
        return mode == "exact"
    emitters = problem.lights.num_lamps + problem.lights.num_emitters
    return emitters <= EXACT_EMITTERS or receivers * emitters <= EXACT_WORK
