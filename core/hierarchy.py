"""Cluster tree over the element disks, built data-parallel in Warp.

The leaves are the element disks sorted along a Morton (Z-order) curve of their positions; every
BRANCH consecutive nodes of a level are merged into one parent, level by level, up to one root (a
bottom-up merge: each level is one launch, so building costs O(n) work in O(log n) launches and
no Python loop over nodes). Each node is a disk standing for its subtree: area-weighted position,
area-weighted mean normal (unit) with its length kept as ``spread`` (1: all normals agree, 0: they
cancel), summed area and a bounding radius of the subtree's disks.

Nodes are stored in one array, level by level, leaves first and the root last. Traversal is
stackless: ``first_child`` descends, ``next`` is where to go when a subtree is done (the next
sibling, else the parent's ``next``; −1 after the last node), so one ``while`` loop per receiver
visits a cut of the tree in depth-first order.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from . import device as device_mod
from .elements import Elements

# Children per node. 4 keeps the tree shallow (10 levels for a million disks) while a parent
# still covers a compact run of the Morton curve.
BRANCH = 4
# Levels a traversal can track (see solvers/ao.py): 4^31 leaves.
MAX_LEVELS = 32
MORTON_BITS = 10  # per axis: 30-bit codes


@dataclass
class Hierarchy:
    """m nodes over n element disks (m ≈ 4n/3), all Warp arrays on ``device``.

    position: vec3[m] (m), normal: vec3[m] unit area-weighted mean normal, spread: float32[m] length
    of the area-weighted mean of the unit normals (1 for a leaf), area: float32[m] (m²), radius:
    float32[m] (m) bounding radius of the subtree's disks around ``position`` (a leaf: √(area/π)),
    first_child: int32[m] (−1 for a leaf), next: int32[m] (−1: traversal ends), level: int32[m] (0
    for leaves), element: int32[m] the element of a leaf (−1 for inner nodes), order: int32[n] the
    elements in leaf order (kept for refits). tri_points: vec3[V] and tri_indices: int32[3T], the
    scene's triangles (shared with ``direct.SceneGeometry``), for exact near-field form factors.
    level_offsets: numpy int64[L+1], nodes of level l are level_offsets[l] … level_offsets[l+1]−1;
    root = m − 1.
    """

    position: wp.array
    normal: wp.array
    spread: wp.array
    area: wp.array
    radius: wp.array
    first_child: wp.array
    next: wp.array
    level: wp.array
    element: wp.array
    order: wp.array
    tri_points: wp.array
    tri_indices: wp.array
    level_offsets: np.ndarray
    device: device_mod.Device

    @property
    def count(self) -> int:
        return int(self.level_offsets[-1])

    @property
    def levels(self) -> int:
        return len(self.level_offsets) - 1

    @property
    def root(self) -> int:
        return self.count - 1


@wp.kernel
def _morton_kernel(offset: int, pos: wp.array(dtype=wp.vec3), lo: wp.vec3, inv_extent: float,
                   keys: wp.array(dtype=wp.int32), values: wp.array(dtype=wp.int32)):
    i = wp.tid() + offset
    q = (pos[i] - lo) * inv_extent
    code = int(0)
    for b in range(MORTON_BITS):
        bit = MORTON_BITS - 1 - b
        x = wp.clamp(int(q[0] * 1024.0), 0, 1023)
        y = wp.clamp(int(q[1] * 1024.0), 0, 1023)
        z = wp.clamp(int(q[2] * 1024.0), 0, 1023)
        code = code * 8 + ((x >> bit) & 1) * 4 + ((y >> bit) & 1) * 2 + ((z >> bit) & 1)
    keys[i] = code
    values[i] = i


@wp.kernel
def _leaf_kernel(offset: int, order: wp.array(dtype=wp.int32), pos: wp.array(dtype=wp.vec3),
                 nrm: wp.array(dtype=wp.vec3), area: wp.array(dtype=wp.float32),
                 n_pos: wp.array(dtype=wp.vec3), n_nrm: wp.array(dtype=wp.vec3),
                 n_spread: wp.array(dtype=wp.float32), n_area: wp.array(dtype=wp.float32),
                 n_radius: wp.array(dtype=wp.float32), n_element: wp.array(dtype=wp.int32)):
    k = wp.tid() + offset
    e = order[k]
    a = wp.max(area[e], 0.0)
    n_pos[k] = pos[e]
    n_nrm[k] = nrm[e]
    n_spread[k] = 1.0
    n_area[k] = a
    n_radius[k] = wp.sqrt(a / 3.141592653589793)
    n_element[k] = e


@wp.kernel
def _merge_kernel(offset: int, child0: int, child_end: int, node0: int,
                  n_pos: wp.array(dtype=wp.vec3), n_nrm: wp.array(dtype=wp.vec3),
                  n_spread: wp.array(dtype=wp.float32), n_area: wp.array(dtype=wp.float32),
                  n_radius: wp.array(dtype=wp.float32), first_child: wp.array(dtype=wp.int32)):
    """Node node0 + k of a level from children child0 + BRANCH·k … (fewer at the level's end)."""
    k = wp.tid() + offset
    c0 = child0 + BRANCH * k
    c1 = wp.min(c0 + BRANCH, child_end)
    total = float(0.0)
    centre = wp.vec3(0.0)
    plain = wp.vec3(0.0)
    mean_n = wp.vec3(0.0)
    for c in range(c0, c1):
        a = n_area[c]
        total += a
        centre += n_pos[c] * a
        plain += n_pos[c]
        mean_n += n_nrm[c] * (a * n_spread[c])
    if total > 0.0:
        centre = centre / total
        mean_n = mean_n / total
    else:  # only zero-area disks below: they count for nothing, but keep the node in place
        centre = plain / float(c1 - c0)
    r = float(0.0)
    for c in range(c0, c1):
        r = wp.max(r, wp.length(n_pos[c] - centre) + n_radius[c])
    s = wp.length(mean_n)
    node = node0 + k
    n_pos[node] = centre
    n_spread[node] = s
    if s > 0.0:
        n_nrm[node] = mean_n / s
    else:
        n_nrm[node] = wp.vec3(0.0, 0.0, 1.0)
    n_area[node] = total
    n_radius[node] = r
    first_child[node] = c0


@wp.kernel
def _next_kernel(offset: int, node0: int, size: int, parent0: int, next_node: wp.array(dtype=wp.int32)):
    """Escape pointers of one level from those of the level above (already set)."""
    k = wp.tid() + offset
    if k % BRANCH != BRANCH - 1 and k + 1 < size:
        next_node[node0 + k] = node0 + k + 1
    else:
        next_node[node0 + k] = next_node[parent0 + k / BRANCH]


def _level_offsets(n: int) -> np.ndarray:
    sizes = [n]
    while sizes[-1] > 1:
        sizes.append(-(-sizes[-1] // BRANCH))
    if len(sizes) > MAX_LEVELS:
        raise ValueError(f"{n} elements exceed the hierarchy's {MAX_LEVELS} levels")
    return np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)


def build(els: Elements, dev: device_mod.Device, geometry) -> Hierarchy:
    """The tree over ``els``' disks (positions, normals, areas); needs at least one element.

    geometry: the scene's ``direct.SceneGeometry`` (its ``points`` and ``indices`` are kept by
    reference: after moving vertices update them there and :func:`refit`).
    """
    n = els.count
    if n < 1:
        raise ValueError("a hierarchy needs at least one element")
    d = dev.name
    offsets = _level_offsets(n)
    m = int(offsets[-1])
    lo = els.position.min(axis=0).astype(np.float32)
    extent = float((els.position.max(axis=0) - lo).max())
    keys = wp.empty(2 * n, dtype=wp.int32, device=d)
    order = wp.empty(2 * n, dtype=wp.int32, device=d)
    device_mod.launch(_morton_kernel, n, [wp.array(els.position, dtype=wp.vec3, device=d), wp.vec3(lo),
                                          1.0 / extent if extent > 0 else 0.0, keys, order], dev)
    wp.utils.radix_sort_pairs(keys, order, n)

    h = Hierarchy(position=wp.empty(m, dtype=wp.vec3, device=d), normal=wp.empty(m, dtype=wp.vec3, device=d),
                  spread=wp.empty(m, dtype=wp.float32, device=d), area=wp.empty(m, dtype=wp.float32, device=d),
                  radius=wp.empty(m, dtype=wp.float32, device=d),
                  first_child=wp.full(m, -1, dtype=wp.int32, device=d),
                  next=wp.empty(m, dtype=wp.int32, device=d), level=wp.empty(m, dtype=wp.int32, device=d),
                  element=wp.full(m, -1, dtype=wp.int32, device=d), order=order[:n], tri_points=geometry.points,
                  tri_indices=geometry.indices, level_offsets=offsets,
                  device=dev)
    level = np.repeat(np.arange(len(offsets) - 1, dtype=np.int32), np.diff(offsets))
    h.level.assign(level)
    _aggregate(h, els.position, els.normal, els.area)
    wp.copy(h.next, wp.array([-1], dtype=wp.int32, device=d), dest_offset=m - 1)
    for lv in range(len(offsets) - 3, -1, -1):
        size = int(offsets[lv + 1] - offsets[lv])
        device_mod.launch(_next_kernel, size, [int(offsets[lv]), size, int(offsets[lv + 1]), h.next], dev)
    return h


def refit(h: Hierarchy, positions: np.ndarray, normals: np.ndarray, areas: np.ndarray) -> Hierarchy:
    """Recompute ``h``'s node disks in place for moved elements (same elements, same topology).

    positions, normals: float32[n,3]; areas: float32[n]. The Morton order is kept, so a large motion
    leaves looser (slower, still correct) clusters: rebuild then.
    """
    _aggregate(h, positions, normals, areas)
    return h


def _aggregate(h: Hierarchy, positions, normals, areas) -> None:
    dev = h.device
    d = dev.name
    n = int(h.level_offsets[1])
    device_mod.launch(_leaf_kernel, n, [h.order, wp.array(np.ascontiguousarray(positions, np.float32), dtype=wp.vec3, device=d),
                                        wp.array(np.ascontiguousarray(normals, np.float32), dtype=wp.vec3, device=d),
                                        wp.array(np.ascontiguousarray(areas, np.float32), dtype=wp.float32, device=d),
                                        h.position, h.normal, h.spread, h.area, h.radius, h.element], dev)
    offs = h.level_offsets
    for lv in range(1, len(offs) - 1):
        device_mod.launch(_merge_kernel, int(offs[lv + 1] - offs[lv]),
                          [int(offs[lv - 1]), int(offs[lv]), int(offs[lv]), h.position, h.normal,
                           h.spread, h.area, h.radius, h.first_child], dev)


@wp.kernel
def _mean_kernel(offset: int, child0: int, child_end: int, node0: int, n_area: wp.array(dtype=wp.float32),
                 values: wp.array(dtype=wp.vec3)):
    k = wp.tid() + offset
    c0 = child0 + BRANCH * k
    c1 = wp.min(c0 + BRANCH, child_end)
    total = float(0.0)
    acc = wp.vec3(0.0)
    for c in range(c0, c1):
        total += n_area[c]
        acc += values[c] * n_area[c]
    if total > 0.0:
        acc = acc / total
    values[node0 + k] = acc


@wp.kernel
def _scatter_kernel(offset: int, element: wp.array(dtype=wp.int32), per_element: wp.array(dtype=wp.vec3),
                    values: wp.array(dtype=wp.vec3)):
    k = wp.tid() + offset
    values[k] = per_element[element[k]]


def node_means(h: Hierarchy, per_element: np.ndarray, out: wp.array | None = None) -> wp.array:
    """vec3[m]: area-weighted mean of ``per_element`` (float32[n,3]) over each node's subtree.

    ``out`` (vec3[m]) is reused when given, so repeated calls in one bake allocate nothing new.
    """
    dev = h.device
    d = dev.name
    if out is None:
        out = wp.empty(h.count, dtype=wp.vec3, device=d)
    offs = h.level_offsets
    device_mod.launch(_scatter_kernel, int(offs[1]),
                      [h.element, wp.array(np.ascontiguousarray(per_element, np.float32), dtype=wp.vec3, device=d), out],
                      dev)
    for lv in range(1, len(offs) - 1):
        device_mod.launch(_mean_kernel, int(offs[lv + 1] - offs[lv]),
                          [int(offs[lv - 1]), int(offs[lv]), int(offs[lv]), h.area, out], dev)
    return out

