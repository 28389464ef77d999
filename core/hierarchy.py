"""Cluster tree over the element disks, built data-parallel in Warp.

The leaves are the element disks sorted by the Morton (Z-order) code of their positions
(``wp.utils.radix_sort_pairs``). The tree above them is the octree those codes spell, built
bottom-up one level per launch: the nodes of level l are the distinct runs of ``code >> 3l``
among the sorted leaves (flags where the prefix changes, an inclusive scan numbering the runs),
so every node is an octree cell holding 1–8 children (a cell with many coincident leaves holds
them all), and a level stops at a single root. O(n) work in O(Morton bits) launches, no Python
loop over nodes. Each node is a disk standing for its subtree: area-weighted position,
area-weighted mean normal (unit) with its length kept as ``spread`` (1: all normals agree, 0:
they cancel), summed area and a bounding radius of the subtree's disks; beside them, what link
oracles bound with: the cone of the subtree's normals and how flat its surface lies.

Nodes are stored in one array, level by level, leaves first and the root last; a node's children
are consecutive. Traversal is stackless: ``descend`` goes down (past one-child cells), ``next`` is
where to go when a subtree is done (the next sibling, else the parent's ``next``; −1 after the
last node), so one ``while`` loop per receiver visits a cut of the tree in depth-first order.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from . import device as device_mod
from .surfels import Surfels

wp.set_module_options({"enable_backward": False})  # no gradients: halves compile time

MORTON_BITS = 10  # per axis: 30-bit codes
# Nodes per core below which a level's merge stays on the calling thread (``device.launch``'s
# min_split): the pool's ~80 µs exceed a few hundred nodes' merges.
SPLIT_NODES = 1024
# Levels of the tree at most: the leaves and one per Morton bit (the traversal keeps a weight per level).
MAX_LEVELS = MORTON_BITS + 1


@wp.struct
class Nodes:
    """The m nodes over n element disks, as kernels read them (one array each, node order).

    position: vec3[m] (m); normal: vec3[m] unit area-weighted mean normal; spread: float32[m] length
    of the area-weighted mean of the unit normals (1 for a leaf); area: float32[m] (m²); radius:
    float32[m] (m) bounding radius of the subtree's disks around ``position`` (a leaf: √(area/π));
    reach: float32[m] (m) bounding radius of the subtree's surface around ``position`` (a leaf: of
    its share of its triangles, the third around its vertex, which reaches past its disk where
    its vertex is hidden under an object and the rest lies in view);
    leaves: float32[m] number of disks in the subtree; first_child: int32[m] (−1 for a leaf; the
    children are first_child … child_end − 1); child_end: int32[m] one past the last child (−1 for
    a leaf), so kernels that split a node need no level bounds; descend:
    int32[m] the child a traversal opening the node goes to (its first child, past cells with a
    single child, which repeat their child's disk; −1 for a leaf); parent: int32[m] (−1 for the
    root); next: int32[m] where a traversal goes when the node's subtree is done (−1: the end);
    level: int32[m] (0 for leaves); element: int32[m] the element of a leaf (−1 for inner nodes);
    root: the root's index (m − 1).
    """

    position: wp.array(dtype=wp.vec3)
    normal: wp.array(dtype=wp.vec3)
    spread: wp.array(dtype=wp.float32)
    area: wp.array(dtype=wp.float32)
    radius: wp.array(dtype=wp.float32)
    reach: wp.array(dtype=wp.float32)
    leaves: wp.array(dtype=wp.float32)
    first_child: wp.array(dtype=wp.int32)
    child_end: wp.array(dtype=wp.int32)
    descend: wp.array(dtype=wp.int32)
    parent: wp.array(dtype=wp.int32)
    next: wp.array(dtype=wp.int32)
    level: wp.array(dtype=wp.int32)
    element: wp.array(dtype=wp.int32)
    root: int


@dataclass
class Tree:
    """A cluster tree: ``nodes`` (the ``Nodes`` struct on ``device``), ``order`` int32[n] the
    elements in leaf order (kept for refits) and ``level_offsets`` numpy int64[L+1] (nodes of
    level l are level_offsets[l] … level_offsets[l+1]−1; the root is the last node). What link
    oracles bound with, set with the disks: ``cone`` vec3[m] (cos, sin, 2 sin(·/2)) of the
    half-angle of the cone around each node's normal that holds its subtree's normals (leaves
    (1, 0, 0)); ``plane`` vec2[m] (thickness, extent) of its subtree's surface around its plane:
    the largest distance of a point of it from the plane (position, normal) and from its position
    (m; a leaf's of its element's whole fan triangles, what ``surfels.face_ff`` integrates)."""

    nodes: Nodes
    order: wp.array
    level_offsets: np.ndarray
    device: device_mod.Device
    cone: wp.array
    plane: wp.array

    @property
    def count(self) -> int:
        return int(self.level_offsets[-1])

    @property
    def levels(self) -> int:
        return len(self.level_offsets) - 1

    @property
    def root(self) -> int:
        return self.count - 1


@wp.func
def morton(q: wp.vec3, bits: int) -> int:
    """The Morton code of q (in [0, 1]³, clamped to it) on a grid of 2^bits cells per axis."""
    cells = 1 << bits
    x = wp.clamp(int(q[0] * float(cells)), 0, cells - 1)
    y = wp.clamp(int(q[1] * float(cells)), 0, cells - 1)
    z = wp.clamp(int(q[2] * float(cells)), 0, cells - 1)
    code = int(0)
    for b in range(bits):
        bit = bits - 1 - b
        code = code * 8 + ((x >> bit) & 1) * 4 + ((y >> bit) & 1) * 2 + ((z >> bit) & 1)
    return code


@wp.kernel
def _morton_kernel(offset: int, pos: wp.array(dtype=wp.vec3), lo: wp.vec3, inv_extent: float,
                   all_lo: wp.vec3, all_inv_extent: float, split: int,
                   keys: wp.array(dtype=wp.int32), values: wp.array(dtype=wp.int32)):
    i = wp.tid() + offset
    q = (pos[i] - lo) * inv_extent
    if split == 0:
        keys[i] = morton(q, MORTON_BITS)
    elif wp.min(wp.min(q[0], q[1]), q[2]) >= 0.0 and wp.max(wp.max(q[0], q[1]), q[2]) <= 1.0:
        keys[i] = morton(q, MORTON_BITS - 1)  # the box's: top cell 0
    else:  # outside the box: top cell 1, over the bounds of all
        keys[i] = (1 << (3 * MORTON_BITS - 3)) + morton((pos[i] - all_lo) * all_inv_extent, MORTON_BITS - 1)
    values[i] = i


@wp.func
def share_reach(s: Surfels, e: int, radius: float) -> float:
    """The farthest point of element e's share of its triangles (each triangle's third around e's
    vertex: up to its edges' midpoints and its centroid) from e's point, at least ``radius``."""
    p = s.pos[e]
    v = s.points[s.vertex[e]]
    r = radius
    for k in range(s.fan_offsets[e], s.fan_offsets[e + 1]):
        tri = s.fan_triangles[k]
        a = s.points[s.tris[3 * tri]]
        b = s.points[s.tris[3 * tri + 1]]
        c = s.points[s.tris[3 * tri + 2]]
        r = wp.max(r, wp.length((a + b + c) / 3.0 - p))
        r = wp.max(r, wp.max(wp.length((v + a) * 0.5 - p), wp.max(wp.length((v + b) * 0.5 - p),
                                                                    wp.length((v + c) * 0.5 - p))))
    return r


@wp.kernel
def _leaf_kernel(offset: int, order: wp.array(dtype=wp.int32), s: Surfels, t: Nodes,
                 cone: wp.array(dtype=wp.vec3), plane: wp.array(dtype=wp.vec2)):
    k = wp.tid() + offset
    e = order[k]
    a = wp.max(s.area[e], 0.0)
    p = s.pos[e]
    n = s.nrm[e]
    thick = float(0.0)
    extent = float(0.0)
    for f in range(s.fan_offsets[e], s.fan_offsets[e + 1]):
        tri = s.fan_triangles[f]
        for c in range(3):
            x = s.points[s.tris[3 * tri + c]] - p
            thick = wp.max(thick, wp.abs(wp.dot(x, n)))
            extent = wp.max(extent, wp.length(x))
    cone[k] = wp.vec3(1.0, 0.0, 0.0)
    plane[k] = wp.vec2(thick, extent)
    t.position[k] = p
    t.normal[k] = n
    t.spread[k] = 1.0
    t.area[k] = a
    t.radius[k] = wp.sqrt(a / 3.141592653589793)
    t.reach[k] = share_reach(s, e, t.radius[k])
    t.leaves[k] = 1.0
    t.element[k] = e


@wp.func
def _child_end(node: int, level_end: int, child_level_end: int, first_child: wp.array(dtype=wp.int32)) -> int:
    if node + 1 < level_end:
        return first_child[node + 1]
    return child_level_end


@wp.kernel
def _merge_kernel(offset: int, node0: int, level_end: int, child_level_end: int, t: Nodes,
                  cone: wp.array(dtype=wp.vec3), plane: wp.array(dtype=wp.vec2)):
    """Disk of node node0 + k from its children's disks; its normal cone and plane (``Tree``) from
    theirs."""
    node = node0 + wp.tid() + offset
    n_pos = t.position
    n_nrm = t.normal
    n_spread = t.spread
    n_area = t.area
    n_radius = t.radius
    n_leaves = t.leaves
    c0 = t.first_child[node]
    c1 = _child_end(node, level_end, child_level_end, t.first_child)
    total = float(0.0)
    count = float(0.0)
    centre = wp.vec3(0.0)
    plain = wp.vec3(0.0)
    mean_n = wp.vec3(0.0)
    for c in range(c0, c1):
        a = n_area[c]
        total += a
        count += n_leaves[c]
        centre += n_pos[c] * a
        plain += n_pos[c]
        mean_n += n_nrm[c] * (a * n_spread[c])
    if total > 0.0:
        centre = centre / total
        mean_n = mean_n / total
    else:  # only zero-area disks below: they count for nothing, but keep the node in place
        centre = plain / float(c1 - c0)
    r = float(0.0)
    reach = float(0.0)
    for c in range(c0, c1):
        r = wp.max(r, wp.length(n_pos[c] - centre) + n_radius[c])
        reach = wp.max(reach, wp.length(n_pos[c] - centre) + t.reach[c])
    s = wp.length(mean_n)
    n = wp.vec3(0.0, 0.0, 1.0)
    if s > 0.0:
        n = mean_n / s
    angle = float(0.0)
    thick = float(0.0)
    extent = float(0.0)
    for c in range(c0, c1):
        cc = cone[c]
        nc = n_nrm[c]
        # the child's half-angle back from its cone (|sin|: float32's sin(π) is below 0)
        child = wp.atan2(wp.abs(cc[1]), cc[0])
        angle = wp.max(angle, wp.acos(wp.clamp(wp.dot(n, nc), -1.0, 1.0)) + child)
        # a child's point x = its centre + w, |w| ≤ its extent, |w·n_c| ≤ its thickness
        x = n_pos[c] - centre
        pc = plane[c]
        thick = wp.max(thick, wp.abs(wp.dot(x, n)) + pc[0] + pc[1] * wp.length(n - nc))
        extent = wp.max(extent, wp.length(x) + pc[1])
    angle = wp.min(angle, 3.141592653589793)
    ca = wp.cos(angle)
    cone[node] = wp.vec3(ca, wp.sin(angle), wp.sqrt(2.0 * wp.max(1.0 - ca, 0.0)))
    plane[node] = wp.vec2(thick, extent)
    n_pos[node] = centre
    n_spread[node] = s
    n_nrm[node] = n
    n_area[node] = total
    n_radius[node] = r
    t.reach[node] = reach
    n_leaves[node] = count


@wp.kernel
def _flag_kernel(offset: int, keys: wp.array(dtype=wp.int32), flags: wp.array(dtype=wp.int32)):
    """1 where a child's parent cell (its key without the last 3 bits) differs from the previous."""
    i = wp.tid() + offset
    flags[i] = int(i == 0 or (keys[i] >> 3) != (keys[i - 1] >> 3))


@wp.kernel
def _link_kernel(offset: int, keys: wp.array(dtype=wp.int32), run: wp.array(dtype=wp.int32),
                 parent_keys: wp.array(dtype=wp.int32), parent_local: wp.array(dtype=wp.int32),
                 first_local: wp.array(dtype=wp.int32)):
    """Child i (in a level) → its parent's index in the next level; the first child of each run
    records itself and the parent's key."""
    i = wp.tid() + offset
    p = run[i] - 1
    parent_local[i] = p
    if i == 0 or (keys[i] >> 3) != (keys[i - 1] >> 3):
        first_local[p] = i
        parent_keys[p] = keys[i] >> 3


@wp.kernel
def _place_kernel(offset: int, child0: int, node0: int, parent_local: wp.array(dtype=wp.int32),
                  first_local: wp.array(dtype=wp.int32), size: int, parent: wp.array(dtype=wp.int32),
                  first_child: wp.array(dtype=wp.int32), level: wp.array(dtype=wp.int32), lv: int):
    """Global parent / first-child indices of one level's links (child level at child0, parent
    level at node0)."""
    i = wp.tid() + offset
    parent[child0 + i] = node0 + parent_local[i]
    if i < size:
        first_child[node0 + i] = child0 + first_local[i]
        level[node0 + i] = lv


@wp.kernel
def _descend_kernel(offset: int, node0: int, level_end: int, child_level_end: int,
                    first_child: wp.array(dtype=wp.int32), child_end: wp.array(dtype=wp.int32),
                    descend: wp.array(dtype=wp.int32)):
    """Where opening a node leads, from the level below (already set), and its child range's end."""
    g = node0 + wp.tid() + offset
    c = first_child[g]
    end = _child_end(g, level_end, child_level_end, first_child)
    child_end[g] = end
    if end - c == 1 and descend[c] >= 0:
        descend[g] = descend[c]
    else:
        descend[g] = c


@wp.kernel
def _next_kernel(offset: int, node0: int, level_end: int, parent: wp.array(dtype=wp.int32),
                 next_node: wp.array(dtype=wp.int32)):
    """Escape pointers of one level from those of the level above (already set)."""
    g = node0 + wp.tid() + offset
    p = parent[g]
    if g + 1 < level_end and parent[g + 1] == p:
        next_node[g] = g + 1
    else:
        next_node[g] = next_node[p]


# The share of the elements at either end of an axis that may lie outside the Morton grid's box.
OUTLIERS = 0.01


def morton_box(position: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) float32[3] (m): the box the Morton grid spans over element positions float[n,3]:
    their bounds, cut on each axis to the central 98 % of the elements widened by its own span on
    either side. A scene without outliers keeps its bounds exactly; where the box is cut (a
    2 000 km plane under a 10 m room, which would leave the room in one cell of a 2 km grid: one
    node of thousands of children, linked leaf to leaf), the elements in the box and those
    outside it become the root's two subtrees, each gridded over its own extent at half the
    resolution (``_morton_kernel``)."""
    p = np.asarray(position, np.float64)
    inner_lo, inner_hi = np.percentile(p, [100.0 * OUTLIERS, 100.0 * (1.0 - OUTLIERS)], axis=0)
    span = inner_hi - inner_lo
    lo = np.maximum(p.min(axis=0), inner_lo - span)
    hi = np.minimum(p.max(axis=0), inner_hi + span)
    return lo.astype(np.float32), hi.astype(np.float32)


def _inverse(size: np.ndarray) -> float:
    """1 / the largest side of a box of sides size float[3] (m); 0 for a point."""
    extent = float(np.max(size))
    return 1.0 / extent if extent > 0 else 0.0


def build(problem) -> Tree:
    """The tree over the elements of ``problem`` (a ``core.problem.Problem``): its disks are read
    from the device copy (``problem.surfels``); needs at least one element."""
    els, dev = problem.elements, problem.device
    n = els.count
    if n < 1:
        raise ValueError("a tree needs at least one element")
    d = dev.name
    all_lo, all_hi = (els.position.min(axis=0).astype(np.float32),
                      els.position.max(axis=0).astype(np.float32))
    lo, hi = morton_box(els.position)
    split = int(np.any(lo > all_lo) or np.any(hi < all_hi))
    keys = wp.empty(2 * n, dtype=wp.int32, device=d)
    order = wp.empty(2 * n, dtype=wp.int32, device=d)
    device_mod.launch(_morton_kernel, n, [problem.surfels.pos, wp.vec3(lo), _inverse(hi - lo),
                                          wp.vec3(all_lo), _inverse(all_hi - all_lo), split, keys,
                                          order], dev)
    wp.utils.radix_sort_pairs(keys, order, n)

    # Levels bottom-up: each one the distinct parent cells of the one below.
    sizes, links = [n], []
    level_keys = keys[:n]
    while sizes[-1] > 1:
        size = sizes[-1]
        run = wp.empty(size, dtype=wp.int32, device=d)
        device_mod.launch(_flag_kernel, size, [level_keys, run], dev)
        wp.utils.array_scan(run, run, inclusive=True)
        count = int(run[size - 1:size].numpy()[0])
        parent_keys = wp.empty(count, dtype=wp.int32, device=d)
        parent_local = wp.empty(size, dtype=wp.int32, device=d)
        first_local = wp.empty(count, dtype=wp.int32, device=d)
        device_mod.launch(_link_kernel, size, [level_keys, run, parent_keys, parent_local, first_local],
                          dev)
        links.append((parent_local, first_local))
        sizes.append(count)
        level_keys = parent_keys
    offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    m = int(offsets[-1])

    t = Nodes()
    t.position, t.normal = (wp.empty(m, dtype=wp.vec3, device=d) for _ in range(2))
    t.spread, t.area, t.radius, t.reach, t.leaves = (wp.empty(m, dtype=wp.float32, device=d) for _ in range(5))
    t.first_child, t.child_end, t.descend, t.parent, t.next, t.element = (
        wp.full(m, -1, dtype=wp.int32, device=d) for _ in range(6))
    t.level = wp.zeros(m, dtype=wp.int32, device=d)
    t.root = m - 1
    for lv, (parent_local, first_local) in enumerate(links, start=1):
        device_mod.launch(_place_kernel, sizes[lv - 1],
                          [int(offsets[lv - 1]), int(offsets[lv]), parent_local, first_local, sizes[lv],
                           t.parent, t.first_child, t.level, lv], dev)
    for lv in range(1, len(sizes)):
        device_mod.launch(_descend_kernel, sizes[lv],
                          [int(offsets[lv]), int(offsets[lv + 1]), int(offsets[lv]), t.first_child,
                           t.child_end, t.descend],
                          dev)
    for lv in range(len(sizes) - 2, -1, -1):
        device_mod.launch(_next_kernel, sizes[lv],
                          [int(offsets[lv]), int(offsets[lv + 1]), t.parent, t.next],
                          dev)
    tree = Tree(nodes=t, order=order[:n], level_offsets=offsets, device=dev,
                cone=wp.empty(m, dtype=wp.vec3, device=d), plane=wp.empty(m, dtype=wp.vec2, device=d))
    refit(tree, problem.surfels)
    return tree


def refit(tree: Tree, surfels) -> Tree:
    """Recompute ``tree``'s node disks in place from the elements' disks in ``surfels``
    (``core.surfels.Surfels``, updated by the caller for moved elements: same elements, same
    topology). The Morton order is kept, so a large motion leaves looser (slower, still correct)
    clusters: rebuild then."""
    dev = tree.device
    offs = tree.level_offsets
    bounds = [tree.cone, tree.plane]
    device_mod.launch(_leaf_kernel, int(offs[1]), [tree.order, surfels, tree.nodes, *bounds], dev)
    for lv in range(1, len(offs) - 1):
        device_mod.launch(_merge_kernel, int(offs[lv + 1] - offs[lv]),
                          [int(offs[lv]), int(offs[lv + 1]), int(offs[lv]), tree.nodes, *bounds], dev,
                          min_split=SPLIT_NODES)
    return tree


@wp.kernel
def _mean_kernel(offset: int, node0: int, level_end: int, child_level_end: int, t: Nodes,
                 values: wp.array(dtype=wp.vec3)):
    node = node0 + wp.tid() + offset
    total = float(0.0)
    acc = wp.vec3(0.0)
    for c in range(t.first_child[node], _child_end(node, level_end, child_level_end, t.first_child)):
        total += t.area[c]
        acc += values[c] * t.area[c]
    if total > 0.0:
        acc = acc / total
    values[node] = acc


@wp.kernel
def _scatter_kernel(offset: int, element: wp.array(dtype=wp.int32), per_element: wp.array(dtype=wp.vec3),
                    values: wp.array(dtype=wp.vec3)):
    k = wp.tid() + offset
    values[k] = per_element[element[k]]


def node_means(tree: Tree, per_element, out: wp.array | None = None) -> wp.array:
    """vec3[m]: area-weighted mean of ``per_element`` (float32[n,3], or vec3[n] on the device) over
    each node's subtree.

    ``out`` (vec3[m]) is reused when given, so repeated calls in one bake allocate nothing new.
    """
    dev = tree.device
    d = dev.name
    if out is None:
        out = wp.empty(tree.count, dtype=wp.vec3, device=d)
    if not isinstance(per_element, wp.array):
        per_element = wp.array(np.ascontiguousarray(per_element, np.float32), dtype=wp.vec3, device=d)
    offs = tree.level_offsets
    device_mod.launch(_scatter_kernel, int(offs[1]), [tree.nodes.element, per_element, out], dev)
    for lv in range(1, len(offs) - 1):
        device_mod.launch(_mean_kernel, int(offs[lv + 1] - offs[lv]),
                          [int(offs[lv]), int(offs[lv + 1]), int(offs[lv]), tree.nodes, out], dev)
    return out
