"""Emitter weights shared by groups of nearby receivers: exact light selection at a fraction of its cost.

Weighing every emitter exactly at a receiver (``direct.exact_selection``) makes each emitter's
share of the light samples its share of the light, but costs one unoccluded transfer per emitter
per receiver: on the emissive room's 512 page (177 k texels, 2 930 emitters and lamps) most of the
32 s its direct light took that way, so the light tree chooses there instead, and its samples are noisy enough that nearly every texel then
traced the whole shadow budget. Texels a few apart on one triangle see the emitters nearly alike,
so a group of them shares one set of weights, weighed at its centroid (``direct._estimate`` with
``exact`` 2: each chosen emitter is still weighed at the texel for its light, and a share of the
samples is spread over all emitters, so the estimate stays unbiased where the group's point is a
poor stand-in). A group near an emitter (REACH) keeps the light tree. On the 256 page at
supersample 2: texel direct 9.0 s shared against 29.1 s with the tree, the same 1.5 % from exact.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from . import device as device_mod
from .direct import Emitters, _leaf_light, _outside, unit
from .rays import lift
from .scene import LAMP_SUN


@dataclass
class Shared:
    """Weights of G groups of N receivers: ``kept`` float32[G, leaves + 1] on the device (each
    emitter's weight at the group's point, the last column their sum, −1 for a group too near an
    emitter to share them), ``row`` int32[N] the group of each receiver."""

    kept: wp.array
    row: wp.array


# A group shares weights only where every emitter lies farther from its centroid than this many
# times the group's radius: nearer, an emitter's light differs too much across the group (the
# emissive room's floor beside the glowing tube lying on it: some texels got all their samples
# on parts of the tube hidden from them, 0 where the light was 9, others rare huge ones; texel
# RMSE 14 % against exact weighing where the tree gave 1.5 %). Such groups keep the light tree.
REACH = 4.0


@wp.func
def _nearest(g: Emitters, p: wp.vec3) -> float:
    """A lower bound on the distance (m) from p to the nearest emitter: lamps with a position
    by it, emissive triangles by their centroid's distance less their corners' farthest from it."""
    d = float(1.0e30)
    for l in range(g.lamp_pos.shape[0]):
        if g.lamp_kind[l] != LAMP_SUN:
            d = wp.min(d, wp.length(g.lamp_pos[l] - p) - wp.max(g.lamp_size[l][0], g.lamp_size[l][1]))
    for e in range(g.em_centre.shape[0]):
        c = g.em_centre[e]
        reach = wp.max(wp.length(g.em_v0[e] - c), wp.max(wp.length(g.em_v1[e] - c), wp.length(g.em_v2[e] - c)))
        d = wp.min(d, wp.length(c - p) - reach)
    return d


@wp.kernel
def _weights_kernel(offset: int, g: Emitters, points: wp.array(dtype=wp.vec3), normals: wp.array(dtype=wp.vec3),
                    sizes: wp.array(dtype=wp.float32), radii: wp.array(dtype=wp.float32), far: float,
                    kept: wp.array2d(dtype=wp.float32)):
    """Row k of kept: every emitter's weight (``direct._leaf_light``, shadowed estimates) at
    group k's point, then their sum; the sum −1 where an emitter lies within REACH × the group's
    radius (``radii``, m) of it."""
    k = wp.tid() + offset
    p = points[k]
    n = normals[k]
    leaves = kept.shape[1] - 1
    if _nearest(g, p) < REACH * radii[k]:
        kept[k, leaves] = -1.0
        return
    outside = _outside(g, lift(p, n, sizes[k]), far)
    total = float(0.0)
    for j in range(leaves):
        tj, w, sj = _leaf_light(g, j, p, n, outside, 1)
        kept[k, j] = w
        total += w
    kept[k, leaves] = total


def shared_weights(problem, points: np.ndarray, normals: np.ndarray, sizes: np.ndarray,
                   group: np.ndarray) -> Shared:
    """Weights for N receivers of ``problem`` (points float32[N,3] m, unit normals float32[N,3],
    sizes float32[N] m, as ``direct.estimate`` takes them) in groups ``group`` int[N] (0 … G−1,
    each used): each group weighed once at the mean of its points and normals (none where an
    emitter is within REACH of its radius: see there)."""
    dev = problem.device
    d = dev.name
    group = np.asarray(group, np.int64)
    count = int(group.max()) + 1 if len(group) else 0
    members = np.bincount(group, minlength=count).astype(np.float64)[:, None]
    centre = np.stack([np.bincount(group, points[:, a], count) for a in range(3)], 1) / members
    normal = np.stack([np.bincount(group, normals[:, a], count) for a in range(3)], 1)
    size = np.bincount(group, sizes, count) / members[:, 0]
    radius = np.zeros(count)
    np.maximum.at(radius, group, np.linalg.norm(points - centre[group], axis=1))
    leaves = problem.lights.num_lamps + problem.lights.num_emitters
    kept = wp.empty((max(count, 1), leaves + 1), dtype=wp.float32, device=d)
    device_mod.launch(_weights_kernel, count,
                      [problem.lights.emitters, wp.array(centre.astype(np.float32), dtype=wp.vec3, device=d),
                       wp.array(unit(normal), dtype=wp.vec3, device=d),
                       wp.array(size.astype(np.float32), dtype=wp.float32, device=d),
                       wp.array(radius.astype(np.float32), dtype=wp.float32, device=d), problem.far, kept],
                      dev, chunks=max(1, min(32, count // 256)))
    return Shared(kept=kept, row=wp.array(group.astype(np.int32), dtype=wp.int32, device=d))
