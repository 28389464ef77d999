"""Ambient occlusion (accessibility) and gathered light over the disk tree, O(n log n).

Per receiver one stackless traversal of the hierarchy (``hierarchy.py``) sums form factors
(ALGORITHMS.md §1): a node far enough away (d² ≥ OPEN·r², r its bounding radius) counts as one
disk and its subtree is skipped, a nearer one is opened; within ±10 % of the threshold both are
blended so nothing steps where the level switches. Leaves nearer than NEAR·area use the exact
form factor of the element's own triangles (``formfactor.fan_ff``), farther ones their disk.
Senders beyond the AO distance count for nothing (as in Cycles' AO).

Overlapping occluders must not add up. Bunnell's multi-pass fix (ALGORITHMS.md §2: weight each
sender by its own accessibility from the previous pass) cannot get both cases of §8 right: inside
a closed sphere every sender has accessibility 0, so pass 2 says "fully open" (the passes
alternate 0, 1, 0 …), while the farther of two stacked disks is half open itself yet wholly
hidden from the receiver. So overlaps are resolved per direction instead: the receiver's
hemisphere is cut into BINS cells of equal cosine-weighted measure (rings of equal sin²θ ×
sectors of equal azimuth); each contribution is splatted bilinearly into the cells around its
direction, and a cell is covered at most once. Near-field (exact) parts count whole and take
their cell first (a close, wide sender can exceed one cell); farther ones fill what is left.

Front faces always count. Back faces block too (Cycles' AO rays stop at either side, so a
receiver under a box resting on it, or behind a single-sided sheet, is dark), but a cell takes
the larger of its front and back cover, not their sum: a closed object shows the same directions
twice, its near side's front faces and its far side's back faces. A surface facing the receiver
in the receiver's own plane (contact) is seen from a hair off the receiver, as Cycles' offset
rays see it.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np
import warp as wp

from .. import device as device_mod
from ..elements import Elements
from ..formfactor import disk_ff, fan_ff, tangent_frame
from ..hierarchy import MAX_LEVELS, Hierarchy

# Open a node when d² < OPEN·radius² (blended over ±10 %): the cluster disk then subtends less than
# ~14°, where its form factor is within the 2 % the tests ask of the all-pairs sum.
OPEN = 16.0
# A leaf nearer than d² < NEAR·area uses the exact form factor of its triangles (ALGORITHMS.md §1:
# 4–8; the disk approximation is off by more than 5 % inside that).
NEAR = 8.0
# Offset towards an opposite-facing near sender, relative to its disk's √area (see the kernel).
CONTACT = 1.0e-3
RINGS = 4
SECTORS = 8
BINS = RINGS * SECTORS
CELL = 1.0 / BINS
# open_k of the all-pairs sum: every node is opened, every leaf visited.
ALL_PAIRS = 1.0e30
# Cycles' default AO distance (world.light_settings.distance), m.
DEFAULT_DISTANCE = 10.0

_bins = wp.types.vector(length=BINS, dtype=wp.float32)
_levels = wp.types.vector(length=MAX_LEVELS, dtype=wp.float32)


@dataclass
class Gather:
    """Per receiver: accessibility float32[N] in [0,1]; bent_normal float32[N,3] unit (the mean
    unoccluded direction); light float32[N,3] gathered lighting (irradiance/π from the senders'
    radiance, overlaps resolved per cell), None when no radiance was given; visits: int32[N] tree
    nodes each traversal visited (the work per receiver)."""

    accessibility: np.ndarray
    bent_normal: np.ndarray
    light: Optional[np.ndarray]
    visits: np.ndarray


@wp.func
def cluster_ff(p: wp.vec3, n: wp.vec3, q: wp.vec3, nq: wp.vec3, area: float, spread: float,
               leaves: float) -> float:
    """Form factor of a cluster of ``leaves`` disks: as many disks of its mean area at its centre
    (their sum, not one disk of the whole area, whose π d² + A denominator would be too large) for
    aligned normals (spread 1); an isotropic blob of projected area A/4 (a closed convex surface's
    mean) where they cancel (spread 0); linearly between."""
    d = q - p
    d2 = wp.dot(d, d)
    if d2 <= 0.0:
        return 0.0
    cos_r = wp.max(wp.dot(n, d) / wp.sqrt(d2), 0.0)
    each = area / leaves
    iso = 0.25 * area * cos_r / (3.141592653589793 * d2 + 0.25 * each)
    return spread * leaves * disk_ff(p, n, q, nq, each) + (1.0 - spread) * iso


@wp.func
def cell_of(d: wp.vec3, tu: wp.vec3, tv: wp.vec3, n: wp.vec3):
    """Bilinear splat of unit direction d over the hemisphere cells: four cells and weights."""
    z = wp.dot(d, n)
    fr = wp.clamp(1.0 - z * z, 0.0, 1.0) * float(RINGS) - 0.5
    phi = wp.atan2(wp.dot(d, tv), wp.dot(d, tu))
    fs = (phi * 0.15915494309189535 + 0.5) * float(SECTORS) - 0.5
    r0 = int(wp.floor(fr))
    wr = fr - float(r0)
    s0 = int(wp.floor(fs))
    ws = fs - float(s0)
    r1 = wp.min(r0 + 1, RINGS - 1)
    r0 = wp.max(r0, 0)
    s1 = (s0 + 1 + SECTORS) % SECTORS
    s0 = (s0 + SECTORS) % SECTORS
    return (r0 * SECTORS + s0, r0 * SECTORS + s1, r1 * SECTORS + s0, r1 * SECTORS + s1,
            (1.0 - wr) * (1.0 - ws), (1.0 - wr) * ws, wr * (1.0 - ws), wr * ws)


@wp.kernel
def _gather_kernel(offset: int, rp: wp.array(dtype=wp.vec3), rn: wp.array(dtype=wp.vec3),
                   n_pos: wp.array(dtype=wp.vec3), n_nrm: wp.array(dtype=wp.vec3),
                   n_spread: wp.array(dtype=wp.float32), n_area: wp.array(dtype=wp.float32),
                   n_radius: wp.array(dtype=wp.float32), n_leaves: wp.array(dtype=wp.float32),
                   descend: wp.array(dtype=wp.int32),
                   next_node: wp.array(dtype=wp.int32), level: wp.array(dtype=wp.int32),
                   element: wp.array(dtype=wp.int32), root: int,
                   fan_offsets: wp.array(dtype=wp.int32), fan_triangles: wp.array(dtype=wp.int32),
                   tris: wp.array(dtype=wp.int32), points: wp.array(dtype=wp.vec3),
                   distance: float, open_k: float, with_light: int, radiance: wp.array(dtype=wp.vec3),
                   out_access: wp.array(dtype=wp.float32), out_bent: wp.array(dtype=wp.vec3),
                   out_light: wp.array(dtype=wp.vec3), out_visits: wp.array(dtype=wp.int32)):
    i = wp.tid() + offset
    p = rp[i]
    n = rn[i]
    tu, tv = tangent_frame(n)
    cover = _bins()
    back = _bins()
    peak = _bins()  # the largest single far front contribution per cell
    red = _bins()
    green = _bins()
    blue = _bins()
    weights = _levels()
    weights[level[root]] = 1.0
    near = _bins()  # near-field front faces, per cell
    near_back = _bins()
    near_light = wp.vec3(0.0)
    raw = float(0.0)
    dirsum = wp.vec3(0.0)
    node = root
    visits = int(0)
    while node >= 0:
        visits += 1
        sender = node
        q = n_pos[node]
        r = n_radius[node]
        v = q - p
        d2 = wp.dot(v, v)
        dist = wp.sqrt(d2)
        if dist - r >= distance or wp.dot(v, n) <= -r or n_area[node] <= 0.0:
            node = next_node[node]
            continue
        w = weights[level[node]]
        far = float(0.0)    # front faces, splatted into the cells
        far_b = float(0.0)  # back faces, splatted
        exact = float(0.0)  # front faces, near field: never capped
        exact_b = float(0.0)
        child = descend[node]
        if child < 0:
            if dist < distance:
                a = n_area[node]
                t = wp.clamp((d2 / (NEAR * a) - 0.9) * 5.0, 0.0, 1.0)
                if t > 0.0:
                    far = w * t * disk_ff(p, n, q, n_nrm[node], a)
                    far_b = w * t * disk_ff(p, n, q, -n_nrm[node], a)
                if t < 1.0:
                    e = element[node]
                    # A surface facing the receiver in its own plane is in contact with it (a box
                    # resting on the floor): seen from a hair off the receiver, as Cycles' offset
                    # rays see it, it covers the hemisphere instead of vanishing edge-on.
                    pe = p
                    if wp.dot(n_nrm[node], n) < 0.0:
                        pe = p - n * (CONTACT * wp.sqrt(a))
                    exact = w * (1.0 - t) * fan_ff(pe, n, e, 1.0, fan_offsets, fan_triangles, tris, points)
                    exact_b = w * (1.0 - t) * fan_ff(p, n, e, -1.0, fan_offsets, fan_triangles, tris,
                                                     points)
            node = next_node[node]
        else:
            # Never nearer than a leaf would take its exact form factor: a chain of one-child
            # cells over a single disk must reach that leaf's near field.
            alpha = wp.clamp((d2 / wp.max(open_k * r * r, NEAR * n_area[node]) - 0.9) * 5.0, 0.0, 1.0)
            if alpha > 0.0:
                # A far node straddling the AO distance counts with the part of its depth inside
                # (opening it down to the leaves would visit a whole shell of them per receiver).
                part = w * alpha * wp.clamp((distance - dist + r) / (2.0 * r), 0.0, 1.0)
                far = part * cluster_ff(p, n, q, n_nrm[node], n_area[node], n_spread[node],
                                        n_leaves[node])
                far_b = part * cluster_ff(p, n, q, -n_nrm[node], n_area[node], n_spread[node],
                                          n_leaves[node])
            if alpha < 1.0:
                weights[level[child]] = w * (1.0 - alpha)
                node = child
            else:
                node = next_node[node]
        if far + far_b + exact + exact_b > 0.0:
            dhat = v / dist
            raw += far + far_b + exact + exact_b
            dirsum += dhat * (far + far_b + exact + exact_b)
            c0, c1, c2, c3, w0, w1, w2, w3 = cell_of(dhat, tu, tv, n)
            cover[c0] = cover[c0] + far * w0
            cover[c1] = cover[c1] + far * w1
            cover[c2] = cover[c2] + far * w2
            cover[c3] = cover[c3] + far * w3
            peak[c0] = wp.max(peak[c0], far * w0)
            peak[c1] = wp.max(peak[c1], far * w1)
            peak[c2] = wp.max(peak[c2], far * w2)
            peak[c3] = wp.max(peak[c3], far * w3)
            back[c0] = back[c0] + far_b * w0
            back[c1] = back[c1] + far_b * w1
            back[c2] = back[c2] + far_b * w2
            back[c3] = back[c3] + far_b * w3
            near[c0] = near[c0] + exact * w0
            near[c1] = near[c1] + exact * w1
            near[c2] = near[c2] + exact * w2
            near[c3] = near[c3] + exact * w3
            near_back[c0] = near_back[c0] + exact_b * w0
            near_back[c1] = near_back[c1] + exact_b * w1
            near_back[c2] = near_back[c2] + exact_b * w2
            near_back[c3] = near_back[c3] + exact_b * w3
            if with_light != 0:
                L = radiance[sender]
                near_light += L * exact
                red[c0] = red[c0] + L[0] * far * w0
                red[c1] = red[c1] + L[0] * far * w1
                red[c2] = red[c2] + L[0] * far * w2
                red[c3] = red[c3] + L[0] * far * w3
                green[c0] = green[c0] + L[1] * far * w0
                green[c1] = green[c1] + L[1] * far * w1
                green[c2] = green[c2] + L[1] * far * w2
                green[c3] = green[c3] + L[1] * far * w3
                blue[c0] = blue[c0] + L[2] * far * w0
                blue[c1] = blue[c1] + L[2] * far * w1
                blue[c2] = blue[c2] + L[2] * far * w2
                blue[c3] = blue[c3] + L[2] * far * w3
    occ = float(0.0)
    light = near_light
    for b in range(BINS):
        # Near-field parts count whole, and so does the largest single far part (a wide sender
        # can exceed a cell); stacked parts fill what they leave. Front and back faces of one
        # closed object show the same directions: the larger of the two, not their sum.
        blocked = wp.max(near[b], near_back[b])
        fill = wp.max(cover[b] + near[b], back[b] + near_back[b])
        occ += wp.max(wp.max(blocked, peak[b]), wp.min(fill, CELL))
        c = cover[b]
        if with_light != 0 and c > 0.0:
            # senders stacked in one cell share what is left of it: their mean radiance
            light += wp.vec3(red[b], green[b], blue[b]) * wp.min(1.0, wp.max(CELL - blocked, peak[b]) / c)
    out_access[i] = wp.clamp(1.0 - occ, 0.0, 1.0)
    out_visits[i] = visits
    if with_light != 0:
        out_light[i] = light
    bent = n
    if raw > 0.0:
        bent = n - dirsum * (wp.min(occ, 1.0) / raw)
    if wp.length(bent) > 1.0e-6:
        out_bent[i] = wp.normalize(bent)
    else:
        out_bent[i] = n


def gather(hier: Hierarchy, els: Elements, points: np.ndarray, normals: np.ndarray, distance: float,
           dev: device_mod.Device, radiance: Optional[wp.array] = None, open_k: float = OPEN,
           progress=None) -> Gather:
    """Accessibility, bent normals and (with ``radiance``) gathered light at N receivers from the
    elements ``els`` that ``hier`` was built over.

    points: float32[N,3] receiver positions (m); normals: float32[N,3] unit; distance: AO distance
    (m), senders farther away count for nothing; radiance: vec3[hier.count] radiance leaving each
    node's front (e.g. ``hierarchy.node_means`` of per-element radiance), or None for AO only;
    open_k: OPEN, or ALL_PAIRS for the brute-force sum over every element; progress(fraction).
    """
    d = dev.name
    count = int(points.shape[0])
    access = wp.empty(count, dtype=wp.float32, device=d)
    bent = wp.empty(count, dtype=wp.vec3, device=d)
    with_light = radiance is not None
    light = wp.empty(count if with_light else 1, dtype=wp.vec3, device=d)
    visits = wp.empty(count, dtype=wp.int32, device=d)
    if not with_light:
        radiance = light  # not read
    device_mod.launch(
        _gather_kernel, count,
        [wp.array(np.ascontiguousarray(points, np.float32), dtype=wp.vec3, device=d),
         wp.array(np.ascontiguousarray(normals, np.float32), dtype=wp.vec3, device=d),
         hier.position, hier.normal, hier.spread, hier.area, hier.radius, hier.leaves, hier.descend,
         hier.next, hier.level, hier.element, hier.root,
         wp.array(els.fan_offsets, dtype=wp.int32, device=d),
         wp.array(els.fan_triangles, dtype=wp.int32, device=d), hier.tri_indices, hier.tri_points,
         float(distance), float(open_k), int(with_light), radiance, access, bent, light, visits],
        dev, chunks=max(1, min(32, count // 4096)), on_chunk=progress)
    return Gather(access.numpy(), bent.numpy(), light.numpy() if with_light else None, visits.numpy())


def ao_distance(settings) -> float:
    """The AO distance (m) ``settings`` ask for: their ``ao_distance``, or Cycles' default when 0."""
    return float(settings.ao_distance) if settings.ao_distance > 0 else DEFAULT_DISTANCE


def accessibility(hier: Hierarchy, els: Elements, points: np.ndarray, normals: np.ndarray, settings,
                  dev: device_mod.Device, progress=None) -> np.ndarray:
    """float32[N] accessibility in [0,1] (1: open sky) at receivers ``points`` float32[N,3] (m) with
    unit ``normals`` float32[N,3]: the cosine-weighted fraction of the hemisphere not covered by
    the surfaces of ``els`` within the AO distance (what Cycles' AO bake gives). ``hier`` is
    the tree over ``els``; progress(fraction) is called between launches."""
    return gather(hier, els, points, normals, ao_distance(settings), dev, progress=progress).accessibility
