"""Direct light: lamps and emissive triangles at arbitrary receiver points, with shadow rays.

Lighting is irradiance/π at the receiver's normal (radiance units, W m⁻² sr⁻¹), as Cycles bakes
DIFFUSE Direct without Color. Unoccluded transfer is analytic where it can be (exact polygon form
factors for area lamps and emissive triangles, inverse-square for point/spot, cosine for sun);
shadows are the visible fraction of stratified samples on the lamp, weighted by the transfer
kernel so penumbrae stay unbiased where the kernel varies across the lamp. Samples are a rotated
Hammersley set, stratified for any count.
"""
from __future__ import annotations

import math
from typing import Callable, Optional

import numpy as np
import warp as wp

from . import device as device_mod
from .formfactor import outline_ff, tangent_frame, triangle_ff
from .rays import lift, visible
from .scene import LAMP_AREA, LAMP_POINT, LAMP_SPOT, LAMP_SUN, SceneData

wp.set_module_options({"enable_backward": False})  # no gradients: halves compile time

PI = math.pi
ELLIPSE_SIDES = 32
# An ellipse lamp's outline is a regular polygon whose radii are scaled by this so that its area
# equals the ellipse's.
ELLIPSE_SCALE = 1.0 / math.sqrt(ELLIPSE_SIDES / (2.0 * PI) * math.sin(2.0 * PI / ELLIPSE_SIDES))


class Lights:
    """The scene's lamps and emissive triangles on the device, as the direct-light kernel reads them.

    em_v0, em_v1, em_v2: vec3[E] corners of the emissive triangles with area; em_radiance: vec3[E];
    lamp_*: one entry per lamp (see ``core.scene.Lamps``; spot cones as the cosine of the half
    angle and the smoothstep width of the blend).
    """

    def __init__(self, scene: SceneData, dev: device_mod.Device):
        d = dev.name
        pos = np.asarray(scene.positions, np.float32)
        emissive = (scene.emission.max(axis=1) > 0.0) & (scene.triangle_areas() > 0.0)
        etri = scene.triangles[emissive]
        self.num_emitters = int(emissive.sum())
        self.em_v0, self.em_v1, self.em_v2 = (
            wp.array(np.ascontiguousarray(pos[etri[:, k]]), dtype=wp.vec3, device=d) for k in range(3))
        self.em_radiance = wp.array(np.ascontiguousarray(scene.emission[emissive], np.float32),
                                    dtype=wp.vec3, device=d)
        lamps = scene.lamps
        self.num_lamps = len(lamps)
        cos_half = np.cos(0.5 * lamps.spot_size.astype(np.float64))
        smooth = (1.0 - cos_half) * lamps.spot_blend
        self.lamp_kind = wp.array(lamps.kind.astype(np.int32), dtype=wp.int32, device=d)
        self.lamp_pos = wp.array(lamps.position.astype(np.float32), dtype=wp.vec3, device=d)
        self.lamp_dir = wp.array(unit(lamps.direction), dtype=wp.vec3, device=d)
        self.lamp_u = wp.array(unit(lamps.axis_u), dtype=wp.vec3, device=d)
        self.lamp_v = wp.array(unit(lamps.axis_v), dtype=wp.vec3, device=d)
        self.lamp_size = wp.array(lamps.size.astype(np.float32), dtype=wp.vec2, device=d)
        self.lamp_shape = wp.array(lamps.shape.astype(np.int32), dtype=wp.int32, device=d)
        self.lamp_power = wp.array(lamps.power.astype(np.float32), dtype=wp.vec3, device=d)
        self.lamp_cos_half = wp.array(cos_half.astype(np.float32), dtype=wp.float32, device=d)
        self.lamp_smooth = wp.array(smooth.astype(np.float32), dtype=wp.float32, device=d)


def unit(v: np.ndarray) -> np.ndarray:
    """float32[N,3] rows of ``v`` scaled to unit length (zero rows stay zero)."""
    v = np.asarray(v, np.float64).reshape(-1, 3)
    n = np.linalg.norm(v, axis=1, keepdims=True)
    return (v / np.where(n > 0, n, 1.0)).astype(np.float32)


@wp.func
def _radical_inverse(k: int) -> float:
    """Van der Corput radical inverse of k in base 2: the bits of k mirrored behind the point."""
    r = float(0.0)
    f = float(0.5)
    x = k
    while x > 0:
        if x % 2 == 1:
            r += f
        x = x / 2
        f *= 0.5
    return r


@wp.func
def sample2d(k: int, count: int, rotation: wp.vec2) -> wp.vec2:
    """Point k of a ``count``-point Hammersley set over the unit square, shifted by ``rotation``
    modulo 1 (Cranley–Patterson): stratified for any count, unbiased for a uniform rotation."""
    u = (float(k) + 0.5) / float(count) + rotation[0]
    v = _radical_inverse(k) + rotation[1]
    return wp.vec2(u - wp.floor(u), v - wp.floor(v))


@wp.func
def _disk(s: wp.vec2, u: wp.vec3, v: wp.vec3, rx: float, ry: float) -> wp.vec3:
    """Offset of the uniform point s (unit square) of the ellipse with radii rx, ry along u, v."""
    r = wp.sqrt(s[0])
    phi = 6.283185307179586 * s[1]
    return u * (rx * r * wp.cos(phi)) + v * (ry * r * wp.sin(phi))


@wp.func
def _weighted_visibility(mesh: wp.uint64, origin: wp.vec3, p: wp.vec3, n: wp.vec3, q: wp.vec3,
                         nq: wp.vec3) -> wp.vec2:
    """(w, w·V) for a sample q of a planar sender with normal nq: w = cos_R·|cos_E|/d², the
    transfer kernel, and V the visibility of q (no ray where w = 0)."""
    d = q - p
    d2 = wp.dot(d, d)
    w = wp.max(wp.dot(n, d), 0.0) * wp.abs(wp.dot(nq, d)) / (d2 * d2 + 1.0e-30)
    if w <= 0.0:
        return wp.vec2(0.0, 0.0)
    return wp.vec2(w, w * visible(mesh, origin, q))


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


@wp.kernel
def _direct_kernel(offset: int, mesh: wp.uint64, points: wp.array(dtype=wp.vec3),
                   normals: wp.array(dtype=wp.vec3), sizes: wp.array(dtype=wp.float32),
                   lamp_kind: wp.array(dtype=wp.int32),
                   lamp_pos: wp.array(dtype=wp.vec3), lamp_dir: wp.array(dtype=wp.vec3),
                   lamp_u: wp.array(dtype=wp.vec3), lamp_v: wp.array(dtype=wp.vec3),
                   lamp_size: wp.array(dtype=wp.vec2), lamp_shape: wp.array(dtype=wp.int32),
                   lamp_power: wp.array(dtype=wp.vec3), lamp_cos_half: wp.array(dtype=wp.float32),
                   lamp_smooth: wp.array(dtype=wp.float32), em_v0: wp.array(dtype=wp.vec3),
                   em_v1: wp.array(dtype=wp.vec3), em_v2: wp.array(dtype=wp.vec3),
                   em_radiance: wp.array(dtype=wp.vec3), count: int, far: float,
                   seed: int, ellipse_sides: int, ellipse_scale: float,
                   out: wp.array(dtype=wp.vec3), rays: wp.array(dtype=wp.int32)):
    i = wp.tid() + offset
    p = points[i]
    n = normals[i]
    origin = lift(p, n, sizes[i])
    state = wp.rand_init(seed, i)
    total = wp.vec3(0.0)
    nrays = int(0)

    for l in range(lamp_kind.shape[0]):
        kind = lamp_kind[l]
        power = lamp_power[l]
        rot = wp.vec2(wp.randf(state), wp.randf(state))
        if kind == LAMP_POINT or kind == LAMP_SPOT:
            to = lamp_pos[l] - p
            d2 = wp.dot(to, to)
            if d2 <= 0.0:
                continue
            w = to / wp.sqrt(d2)
            cos_r = wp.dot(n, w)
            if cos_r <= 0.0:
                continue
            radius = lamp_size[l][0]
            # shadowed cone attenuation, averaged over the lamp: Cycles applies the spot cone to
            # each sampled point of a sphere lamp, which widens the blend band by ~asin(r/d)
            lit = float(0.0)
            if radius <= 0.0:
                att = _spot_factor(kind, -w, lamp_dir[l], lamp_cos_half[l], lamp_smooth[l])
                if att > 0.0:
                    lit = att * visible(mesh, origin, lamp_pos[l])
                    nrays += 1
            else:
                t1, t2 = tangent_frame(w)
                for k in range(count):
                    q = lamp_pos[l] + _disk(sample2d(k, count, rot), t1, t2, radius, radius)
                    att = _spot_factor(kind, wp.normalize(p - q), lamp_dir[l], lamp_cos_half[l],
                                       lamp_smooth[l])
                    if att > 0.0:
                        lit += att * visible(mesh, origin, q)
                        nrays += 1
                lit = lit / float(count)
            # intensity P/4π W/sr → irradiance I·cos/d² → lighting = irradiance/π
            total += power * (lit * cos_r / (4.0 * 3.141592653589793 * 3.141592653589793 * d2))
        elif kind == LAMP_SUN:
            w = -lamp_dir[l]
            cos_r = wp.dot(n, w)
            if cos_r <= 0.0:
                continue
            tan_half = wp.tan(0.5 * lamp_size[l][0])
            vis = float(0.0)
            if tan_half <= 0.0:
                vis = visible(mesh, origin, origin + w * far)
                nrays += 1
            else:
                t1, t2 = tangent_frame(w)
                for k in range(count):
                    ws = wp.normalize(w + _disk(sample2d(k, count, rot), t1, t2, tan_half, tan_half))
                    vis += visible(mesh, origin, origin + ws * far)
                vis = vis / float(count)
                nrays += count
            total += power * (vis * cos_r / 3.141592653589793)
        elif kind == LAMP_AREA:
            c = lamp_pos[l]
            axis = lamp_dir[l]
            if wp.dot(p - c, axis) <= 0.0:
                continue  # one-sided: only the side the lamp points to is lit
            hx = 0.5 * lamp_size[l][0]
            hy = 0.5 * lamp_size[l][1]
            ell = lamp_shape[l]
            area = 4.0 * hx * hy
            if ell != 0:
                area = 3.141592653589793 * hx * hy
            # an ellipse's outline polygon is scaled to the ellipse's area
            scale = wp.where(ell != 0, ellipse_scale, 1.0)
            ff = outline_ff(p, n, ell, ellipse_sides, c, lamp_u[l], lamp_v[l], hx * scale, hy * scale)
            if ff <= 0.0 or area <= 0.0:
                continue
            acc = wp.vec2(0.0, 0.0)
            for k in range(count):
                st = sample2d(k, count, rot)
                q = c + _disk(st, lamp_u[l], lamp_v[l], hx, hy)
                if ell == 0:
                    q = c + lamp_u[l] * (hx * (2.0 * st[0] - 1.0)) + lamp_v[l] * (hy * (2.0 * st[1] - 1.0))
                acc += _weighted_visibility(mesh, origin, p, n, q, axis)
            nrays += count
            if acc[0] > 0.0:
                # radiance of a one-sided area lamp: P / (π A)
                total += power * (ff * (acc[1] / acc[0]) / (3.141592653589793 * area))

    for e in range(em_v0.shape[0]):
        a = em_v0[e]
        b = em_v1[e]
        c2 = em_v2[e]
        nt = wp.cross(b - a, c2 - a)
        if wp.abs(wp.dot(p - a, nt)) <= 1.0e-6 * wp.length(nt) * wp.length(p - a):
            continue  # receiver in the emitter's plane sees it edge-on
        ff = triangle_ff(p, n, a, b, c2)
        if ff <= 0.0:
            continue
        rot = wp.vec2(wp.randf(state), wp.randf(state))
        acc = wp.vec2(0.0, 0.0)
        for k in range(count):
            st = sample2d(k, count, rot)
            r = wp.sqrt(st[0])
            q = a * (1.0 - r) + b * (r * (1.0 - st[1])) + c2 * (r * st[1])
            acc += _weighted_visibility(mesh, origin, p, n, q, nt)
        nrays += count
        if acc[0] > 0.0:
            total += em_radiance[e] * (ff * acc[1] / acc[0])

    out[i] = total
    rays[i] = nrays


def direct_lighting(problem, points: np.ndarray, normals: np.ndarray, sizes: np.ndarray,
                    progress: Optional[Callable[[float], None]] = None):
    """Direct lighting at receivers of ``problem`` (a ``core.problem.Problem``: its BVH, lights,
    device and ``settings.light_samples``).

    points, normals: float32[N,3] positions (m, the problem's frame) and unit normals; sizes:
    float32[N] local feature size (m) for the ray offset. Returns (float32[N,3] lighting =
    irradiance/π, number of shadow rays traced).
    """
    n = int(points.shape[0])
    dev = problem.device
    d = dev.name
    pts = wp.array(np.ascontiguousarray(points, np.float32), dtype=wp.vec3, device=d)
    nrm = wp.array(unit(normals), dtype=wp.vec3, device=d)
    size = wp.array(np.ascontiguousarray(sizes, np.float32), dtype=wp.float32, device=d)
    out = wp.zeros(n, dtype=wp.vec3, device=d)
    rays = wp.zeros(n, dtype=wp.int32, device=d)
    g = problem.lights
    device_mod.launch(
        _direct_kernel, n,
        [problem.mesh.id, pts, nrm, size, g.lamp_kind, g.lamp_pos, g.lamp_dir, g.lamp_u, g.lamp_v,
         g.lamp_size, g.lamp_shape, g.lamp_power, g.lamp_cos_half, g.lamp_smooth, g.em_v0, g.em_v1,
         g.em_v2, g.em_radiance, int(problem.settings.light_samples), problem.far,
         int(problem.settings.seed), ELLIPSE_SIDES, float(ELLIPSE_SCALE), out, rays],
        dev, chunks=max(1, min(32, n // 256)), on_chunk=progress)
    return out.numpy().astype(np.float32), int(rays.numpy().astype(np.int64).sum())
