"""Light probes: the SH of the light arriving at points in space, for objects that move through a
baked scene.

The probes lie on a grid over a box (the scene's bounds, or a Light Probe Volume's), a cell's
centre each, ``probe_spacing`` apart at most. Their receivers are the elements (the solved
lighting there, through the one shared path ``receivers.light_at``); ``finish`` then gathers, per
probe, over the whole sphere:

- direct light from every lamp and emissive triangle (``direct.leaf_seen``: its light as a
  receiver facing it sees it, shadowed by ``light_samples`` rays), from its direction;
- indirect light along RAYS stratified directions (a spherical Fibonacci set, turned at random per
  probe): the radiance of the surface each ray hits, ρ × its lighting there — the direct part
  traced at the hit point itself (``direct.estimate``, HIT_SAMPLES shadow rays), the indirect part
  the solved indirect lighting interpolated over the triangle. (Interpolating the direct part
  too would let a vertex lit where the probe cannot look — a ceiling vertex in the gap above a
  light fixture — brighten the visible rest of its triangles: in the sample Cornell box that made
  the probe's light from the ceiling nearly 80 % too bright.)

A probe whose rays hit more than INSIDE of back faces is inside geometry: flagged invalid. The SH
convention is ``core.sh``'s (radiance, L2, nine coefficients per channel; L1 = the first four).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np
import warp as wp

from .. import device as device_mod
from .. import receivers as receivers_mod
from ..errors import SettingsError
from ..lightmap.budget import memory_budget
from ..settings import flag
from ..direct import MODE_FULL, Emitters, estimate, leaf_direction, leaf_seen
from ..directions import cone_sample_of
from ..sh import lighting_from_sh, sh9, sh9_numpy

wp.set_module_options({"enable_backward": False})  # no gradients: halves compile time

# Indirect-light rays per probe, the share of back faces among their hits above which a probe
# counts as inside geometry, the shadow rays of the direct light at each hit (the probe averages
# RAYS of them), and the most rays traced at once (memory: about 100 bytes a ray).
RAYS = 4096
INSIDE = 0.25
HIT_SAMPLES = 1
BATCH_RAYS = 1 << 20
MISS, BACK = -1, -2
# Memory a probe takes at the peak of a probes bake, measured with 200 k probes: Probes.json's
# document and its text 3.1 KB, the grid and its gather 0.8 KB (the viewport's spheres, 2.3 KB,
# are made after the text is freed); the ray batches add a fixed ~300 MB.
BYTES_PER_PROBE = 4096
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
def _direct_kernel(offset: int, mesh: wp.uint64, g: Emitters, points: wp.array(dtype=wp.vec3),
                   samples: int, seed: int, far: float, out: wp.array2d(dtype=wp.vec3)):
    """Per probe: out[i, k] the k-th SH coefficient (RGB) of the direct light arriving at
    points[i] from the lamps and emissive triangles."""
    i = wp.tid() + offset
    p = points[i]
    acc = sh9_rgb()
    for leaf in range(g.tree.leaf_kind.shape[0]):
        light = leaf_seen(g, mesh, leaf, p, seed + i, samples, far)
        if light[0] + light[1] + light[2] > 0.0:
            acc += wp.outer(sh9(leaf_direction(g, leaf, p)), light * 3.141592653589793)
    for k in range(9):
        out[i, k] = wp.vec3(acc[k, 0], acc[k, 1], acc[k, 2])


@wp.kernel
def _ray_kernel(offset: int, mesh: wp.uint64, points: wp.array(dtype=wp.vec3),
                turns: wp.array(dtype=wp.float32), rays: int, positions: wp.array(dtype=wp.vec3),
                tris: wp.array(dtype=wp.vec3i), corner_normals: wp.array(dtype=wp.vec3),
                far: float, direction: wp.array(dtype=wp.vec3), face: wp.array(dtype=wp.int32),
                bary: wp.array(dtype=wp.vec3), hit: wp.array(dtype=wp.vec3),
                normal: wp.array(dtype=wp.vec3)):
    """Ray j of the batch: ray j % ``rays`` of probe j // ``rays`` (points, turns: of the batch's
    probes). face[j]: the scene triangle it hits first, MISS or BACK (a back face); for a front
    face, bary[j] the hit's barycentric weights of the triangle's corners, hit[j] its position
    and normal[j] the interpolated shading normal (corner_normals: vec3[3T])."""
    j = wp.tid() + offset
    i = j // rays
    p = points[i]
    w = cone_sample_of(j - i * rays, rays, wp.vec3(0.0, 0.0, 1.0), -1.0, turns[i])
    direction[j] = w
    face[j] = MISS
    q = wp.mesh_query_ray(mesh, p, w, far)
    if q.result:
        t = tris[q.face]
        a = positions[t[0]]
        b = positions[t[1]]
        c = positions[t[2]]
        nt = wp.cross(b - a, c - a)
        if wp.dot(nt, w) > 0.0:
            face[j] = BACK
        else:
            h = p + w * q.t
            area = wp.length(nt)
            wa = wp.length(wp.cross(b - h, c - h)) / area
            wb = wp.length(wp.cross(c - h, a - h)) / area
            wc = wp.max(1.0 - wa - wb, 0.0)
            f = 3 * q.face
            face[j] = q.face
            bary[j] = wp.vec3(wa, wb, wc)
            hit[j] = h
            normal[j] = wp.normalize(corner_normals[f] * wa + corner_normals[f + 1] * wb
                                     + corner_normals[f + 2] * wc)


def grid_points(lo: np.ndarray, hi: np.ndarray, spacing) -> tuple:
    """(float32[P,3] cell centres of the box lo…hi cut into cells at most ``spacing`` (m; float,
    or float[3] per axis) wide,
    x fastest; (nx, ny, nz); float32[3] the cells' sizes)."""
    extent = np.maximum(np.asarray(hi, np.float64) - lo, 0.0)
    counts = grid_counts(lo, hi, spacing)
    cell = extent / counts
    axes = [lo[k] + (np.arange(counts[k]) + 0.5) * cell[k] for k in range(3)]
    z, y, x = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
    return (np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1).astype(np.float32),
            tuple(int(c) for c in counts), cell.astype(np.float32))


def grid_counts(lo: np.ndarray, hi: np.ndarray, spacing) -> np.ndarray:
    """int64[3]: the cells along each axis of ``grid_points``' grid over lo…hi (m) at ``spacing``."""
    extent = np.maximum(np.asarray(hi, np.float64) - lo, 0.0)
    return np.maximum(np.ceil(extent / spacing - 1e-9), 1).astype(np.int64)


class Target:
    """Light probes on a grid over ``box`` ((lo, hi) float[3] each, m, world; None: the scene's
    bounds), cells at most ``spacing`` m (float or float[3] per axis; None:
    ``settings.probe_spacing``); its result is a ``ProbeGrid``. A box and a spacing given
    together are a Light Probe Volume's (its resolution)."""

    def __init__(self, box: Optional[tuple] = None, spacing=None):
        self.box = box
        self.spacing = spacing

    def _grid(self, scene, settings) -> tuple:
        """((lo, hi) float64[3] each in ``scene``'s frame, spacing: m) of the grid over ``scene``."""
        if self.box is None:
            lo, hi = scene.positions.min(axis=0), scene.positions.max(axis=0)
        else:
            origin = np.asarray(scene.origin, np.float64)
            lo, hi = (np.asarray(b, np.float64) - origin for b in self.box)
        spacing = self.spacing if self.spacing is not None else settings.probe_spacing
        return (np.asarray(lo, np.float64), np.asarray(hi, np.float64)), spacing

    def check(self, scene, settings) -> int:
        """The probes the grid over ``scene`` (a SceneData) will hold; raises SettingsError, before
        anything is allocated, when they would take more than ``memory_budget()`` (BYTES_PER_PROBE
        each), saying what fits: the ``--probe-spacing``, or a Light Probe Volume's resolution."""
        (lo, hi), spacing = self._grid(scene, settings)
        counts = grid_counts(lo, hi, spacing)
        count, budget = int(np.prod(counts, dtype=np.float64)), memory_budget()
        most = budget // BYTES_PER_PROBE
        if count <= most:
            return count
        shape = "×".join(str(int(c)) for c in counts)
        if self.box is not None and self.spacing is not None:
            fit = np.maximum(np.floor(counts * (most / count) ** (1.0 / 3.0)), 1).astype(np.int64)
            while np.prod(fit, dtype=np.float64) > most:
                fit = np.maximum(fit - 1, 1)
            fits = "a resolution of at most " + "×".join(str(int(c)) for c in fit) + " fits"
        else:
            low, high = float(spacing), float(np.max(hi - lo))  # the fitting spacing lies between
            for _ in range(64):
                mid = 0.5 * (low + high)
                low, high = (low, mid) if np.prod(grid_counts(lo, hi, mid), dtype=np.float64) <= most \
                    else (mid, high)
            step = 10.0 ** (np.floor(np.log10(high)) - 2)  # three digits, rounded up: it still fits
            fits = f"a {flag('probe_spacing')} of {np.ceil(high / step) * step:g} m fits"
        raise SettingsError(
            f"light probes: a grid of {shape} = {count:,} probes would take about "
            f"{count * BYTES_PER_PROBE / 2**30:,.1f} GB, more than the {budget / 2**30:,.1f} GB a "
            f"bake may use (half this machine's memory): {fits}")

    def receivers(self, problem) -> receivers_mod.Receivers:
        """The elements: the probes read the solved lighting there."""
        return receivers_mod.at_elements(problem)

    def finish(self, problem, at, light: receivers_mod.Light) -> ProbeGrid:
        scene = problem.scene
        self.check(scene, problem.settings)
        (lo, hi), spacing = self._grid(scene, problem.settings)
        points, shape, cell = grid_points(lo, hi, spacing)
        sh, back = problem.stages.run("probes", self._gather, problem, points, light)
        problem.counts["probes"] = len(points)
        origin = np.asarray(scene.origin, np.float64)
        return ProbeGrid(points=(points + origin).astype(np.float32), sh=sh, valid=back <= INSIDE,
                         shape=shape, spacing=cell)

    @staticmethod
    def _gather(problem, points: np.ndarray, light: receivers_mod.Light) -> tuple:
        """(float32[P,9,3] SH, float32[P] back-face share) at P points (problem frame) from the
        elements' solved ``light``: direct light from the emitters, then RAYS rays a probe in
        batches of BATCH_RAYS at most."""
        scene, settings, dev = problem.scene, problem.settings, problem.device
        d = dev.name
        count = len(points)
        direct = wp.zeros((count, 9), dtype=wp.vec3, device=d)
        points_d = wp.array(np.ascontiguousarray(points, np.float32), dtype=wp.vec3, device=d)
        device_mod.launch(_direct_kernel, count,
                          [problem.mesh.id, problem.lights.emitters, points_d,
                           int(settings.light_samples), int(settings.seed), problem.far, direct],
                          dev, chunks=max(1, min(32, count // 16)))
        sh = direct.numpy().astype(np.float64)
        back = np.zeros(count, np.float32)
        turns = np.random.default_rng(settings.seed).random(count) * 2.0 * np.pi
        step = max(1, BATCH_RAYS // RAYS)
        for first in range(0, count, step):
            part = slice(first, min(first + step, count))
            sh[part] += Target._indirect(problem, points[part], turns[part], light.indirect,
                                         first, count, back[part])
            problem.stages.check()
        return sh.astype(np.float32), back

    @staticmethod
    def _indirect(problem, points: np.ndarray, turns: np.ndarray, indirect: np.ndarray,
                  first: int, count: int, back: np.ndarray) -> np.ndarray:
        """float64[B,9,3]: the SH of the light B probes (points float32[B,3], problem frame; turns
        float[B] of their ray sets) get from the surfaces their rays hit, whose radiance is ρ ×
        (direct light traced at the hit + the elements' ``indirect`` float32[n,3] interpolated);
        fills ``back`` float32[B] with each probe's back-face share. ``first``: the first probe's
        index among all ``count`` (it seeds the hits' shadow rays)."""
        scene, settings, dev = problem.scene, problem.settings, problem.device
        d = dev.name
        n = len(points) * RAYS
        out = {k: wp.zeros(n, dtype=t, device=d) for k, t in
               (("direction", wp.vec3), ("face", wp.int32), ("bary", wp.vec3), ("hit", wp.vec3),
                ("normal", wp.vec3))}
        device_mod.launch(
            _ray_kernel, n,
            [problem.mesh.id, wp.array(np.ascontiguousarray(points, np.float32), dtype=wp.vec3, device=d),
             wp.array(np.asarray(turns, np.float32), dtype=wp.float32, device=d), RAYS,
             problem.mesh.points,
             wp.array(np.ascontiguousarray(scene.triangles, np.int32), dtype=wp.vec3i, device=d),
             wp.array(np.ascontiguousarray(scene.corner_normals.reshape(-1, 3), np.float32),
                      dtype=wp.vec3, device=d),
             problem.far, *out.values()], dev, chunks=max(1, min(32, n // 65536)))
        face = out["face"].numpy()
        back[:] = (face == BACK).reshape(-1, RAYS).mean(axis=1)
        front = np.flatnonzero(face >= 0)
        tri = face[front]
        sizes = np.sqrt(scene.triangle_areas()).astype(np.float32)[tri]
        lit, _, _, _ = estimate(problem, out["hit"].numpy()[front], out["normal"].numpy()[front],
                                sizes, np.full(len(front), MODE_FULL, np.int32), HIT_SAMPLES,
                                int(settings.seed) + 1, first=first * RAYS, whole=count * RAYS)
        bary = out["bary"].numpy()[front]
        between = np.einsum("hk,hkc->hc", bary, indirect[problem.elements.corner[tri]])
        radiance = np.zeros((n, 3), np.float64)
        radiance[front] = scene.albedo[tri] * (lit + between) * (4.0 * np.pi / RAYS)
        basis = sh9_numpy(out["direction"].numpy()).reshape(len(points), RAYS, 9)
        return np.einsum("prk,prc->pkc", basis, radiance.reshape(len(points), RAYS, 3))
