"""Light probes: the SH of the light arriving at points in space, for objects that move through a
baked scene.

The probes lie on a grid over a box (the scene's bounds, or a Light Probe Volume's), a cell's
centre each, ``probe_spacing`` apart at most. Their receivers are the elements (the solved
lighting there, through the one shared path ``receivers.light_at``); ``finish`` then gathers, per
probe, over the whole sphere:

- direct light from every lamp and emissive triangle (``direct.leaf_seen``: its light as a
  receiver facing it sees it, shadowed by ``light_samples`` rays), from its direction;
- indirect light along RAYS stratified directions (a spherical Fibonacci set, turned at random per
  probe): the radiance of the surface hit, ρ × the solved lighting interpolated over its triangle.

A probe whose rays hit more than INSIDE of back faces is inside geometry: flagged invalid. The SH
convention is ``core.sh``'s (radiance, L2, nine coefficients per channel; L1 = the first four).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

import numpy as np
import warp as wp

from .. import device as device_mod
from .. import receivers as receivers_mod
from ..direct import Emitters, leaf_seen, leaf_direction
from ..sh import lighting_from_sh, sh9

wp.set_module_options({"enable_backward": False})  # no gradients: halves compile time

# Indirect-light rays per probe, and the share of back faces among their hits above which a probe
# counts as inside geometry.
RAYS = 4096
INSIDE = 0.25
GOLDEN = math.pi * (3.0 - math.sqrt(5.0))
sh9_rgb = wp.types.matrix(shape=(9, 3), dtype=wp.float32)


@dataclass
class ProbeGrid:
    """P probes: points float32[P,3] (m, world), sh float32[P,9,3] SH of the arriving radiance
    (``core.sh``: W m⁻² sr⁻¹ · sr), valid bool[P] (False: inside geometry), shape (nx, ny, nz)
    with the points in x-fastest order, spacing float32[3] (m)."""

    points: np.ndarray
    sh: np.ndarray
    valid: np.ndarray
    shape: tuple
    spacing: np.ndarray

    def lighting(self, normals: np.ndarray, order: int = 2) -> np.ndarray:
        """float32[P,D,3]: the lighting (irradiance/π) each probe's SH gives a surface of unit
        normal float[D,3] there, from its L1 (``order`` 1) or L2 coefficients."""
        return lighting_from_sh(self.sh[:, :(order + 1) ** 2], normals)


@wp.kernel
def _probe_kernel(offset: int, mesh: wp.uint64, g: Emitters, points: wp.array(dtype=wp.vec3),
                  positions: wp.array(dtype=wp.vec3), tris: wp.array(dtype=wp.vec3i),
                  radiance: wp.array(dtype=wp.vec3), rays: int, samples: int, seed: int,
                  far: float, out: wp.array2d(dtype=wp.vec3), back: wp.array(dtype=wp.float32)):
    """Per probe: out[i, k] the k-th SH coefficient (RGB) of the radiance arriving at points[i],
    back[i] the share of its rays that hit a back face. radiance: per scene triangle corner
    (vec3[3T]), what the surface sends there."""
    i = wp.tid() + offset
    p = points[i]
    acc = sh9_rgb()
    for leaf in range(g.tree.leaf_kind.shape[0]):
        light = leaf_seen(g, mesh, leaf, p, seed + i, samples, far)
        if light[0] + light[1] + light[2] > 0.0:
            acc += wp.outer(sh9(leaf_direction(g, leaf, p)), light * 3.141592653589793)
    state = wp.rand_init(seed, i)
    turn = wp.randf(state) * 6.283185307179586
    backs = float(0.0)
    weight = 4.0 * 3.141592653589793 / float(rays)
    for k in range(rays):
        z = 1.0 - (2.0 * float(k) + 1.0) / float(rays)
        r = wp.sqrt(wp.max(1.0 - z * z, 0.0))
        phi = float(k) * GOLDEN + turn
        w = wp.vec3(r * wp.cos(phi), r * wp.sin(phi), z)
        q = wp.mesh_query_ray(mesh, p, w, far)
        if q.result:
            t = tris[q.face]
            a = positions[t[0]]
            b = positions[t[1]]
            c = positions[t[2]]
            nt = wp.cross(b - a, c - a)
            if wp.dot(nt, w) > 0.0:
                backs += 1.0
            else:
                h = p + w * q.t
                area = wp.length(nt)
                wa = wp.length(wp.cross(b - h, c - h)) / area
                wb = wp.length(wp.cross(c - h, a - h)) / area
                wc = wp.max(1.0 - wa - wb, 0.0)
                f = 3 * q.face
                seen = radiance[f] * wa + radiance[f + 1] * wb + radiance[f + 2] * wc
                acc += wp.outer(sh9(w), seen * weight)
    for k in range(9):
        out[i, k] = wp.vec3(acc[k, 0], acc[k, 1], acc[k, 2])
    back[i] = backs / float(rays)


def grid_points(lo: np.ndarray, hi: np.ndarray, spacing: float) -> tuple:
    """(float32[P,3] cell centres of the box lo…hi cut into cells at most ``spacing`` (m) wide,
    x fastest; (nx, ny, nz); float32[3] the cells' sizes)."""
    extent = np.maximum(np.asarray(hi, np.float64) - lo, 0.0)
    counts = np.maximum(np.ceil(extent / spacing - 1e-9), 1).astype(int)
    cell = extent / counts
    axes = [lo[k] + (np.arange(counts[k]) + 0.5) * cell[k] for k in range(3)]
    z, y, x = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
    return (np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1).astype(np.float32),
            tuple(int(c) for c in counts), cell.astype(np.float32))


class Target:
    """Light probes on a grid over ``box`` ((lo, hi) float[3] each, m, world; None: the scene's
    bounds), cells at most ``spacing`` m (None: ``settings.probe_spacing``); its result is a
    ``ProbeGrid``."""

    def __init__(self, box: Optional[tuple] = None, spacing: Optional[float] = None):
        self.box = box
        self.spacing = spacing

    def receivers(self, problem) -> receivers_mod.Receivers:
        """The elements: the probes read the solved lighting there."""
        return receivers_mod.at_elements(problem)

    def finish(self, problem, at, light: receivers_mod.Light) -> ProbeGrid:
        scene = problem.scene
        origin = np.asarray(scene.origin, np.float64)
        if self.box is None:
            lo, hi = scene.positions.min(axis=0), scene.positions.max(axis=0)
        else:
            lo, hi = (np.asarray(b, np.float64) - origin for b in self.box)
        spacing = self.spacing or problem.settings.probe_spacing
        points, shape, cell = grid_points(np.asarray(lo, np.float64), np.asarray(hi, np.float64),
                                          spacing)
        sh, back = problem.stages.run("probes", self._gather, problem, points,
                                      light.direct + light.indirect)
        problem.counts["probes"] = len(points)
        return ProbeGrid(points=(points + origin).astype(np.float32), sh=sh, valid=back <= INSIDE,
                         shape=shape, spacing=cell)

    @staticmethod
    def _gather(problem, points: np.ndarray, lighting: np.ndarray) -> tuple:
        """(float32[P,9,3] SH, float32[P] back-face share) at P points (problem frame) from the
        elements' lighting float32[n,3]."""
        scene = problem.scene
        corner = problem.elements.corner  # the element of each triangle corner
        sent = scene.albedo[:, None, :] * lighting[corner]  # [T,3 corners,3]
        dev = problem.device
        d = dev.name
        count = len(points)
        out = wp.zeros((count, 9), dtype=wp.vec3, device=d)
        back = wp.zeros(count, dtype=wp.float32, device=d)
        device_mod.launch(
            _probe_kernel, count,
            [problem.mesh.id, problem.lights.emitters,
             wp.array(np.ascontiguousarray(points, np.float32), dtype=wp.vec3, device=d),
             problem.mesh.points, wp.array(np.ascontiguousarray(scene.triangles, np.int32),
                                           dtype=wp.vec3i, device=d),
             wp.array(np.ascontiguousarray(sent.reshape(-1, 3), np.float32), dtype=wp.vec3, device=d),
             RAYS, int(problem.settings.light_samples), int(problem.settings.seed), problem.far,
             out, back],
            dev, chunks=max(1, min(32, count // 16)))
        return out.numpy().astype(np.float32), back.numpy()
