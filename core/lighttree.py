"""A light tree over the scene's emitters (lamps and emissive triangles), for sampling them by
importance with a cost per receiver that grows with log(emitters).

Each emitter is a leaf with bounds: a box, a power (its unoccluded lighting at unit distance,
straight on: so bounds of different kinds compare in the same units) and an orientation cone
(axis, half-angle θ_o of the normals, emission spread θ_e beyond them; two-sided for emissive
triangles, which emit from both faces). Nodes are built top-down over the leaves: each range of
leaves is split at the midpoint of its centroids' longest axis (the median where that leaves a
side empty) until a node holds at most BUCKET leaves; a node's leaves are one contiguous range of
the leaf order. Distant lamps (suns) have no position: they form nodes of their own beside the
local tree, under the root.

Importance of a node at a receiver (Conty Estevez & Kulla 2018, as Cycles' light tree): power ×
the cosine at the receiver and the cosine at the emitters, each widened by the angle the node's
bounding sphere subtends, over the squared distance (clamped to the sphere's radius inside it).
It is zero only where no emitter of the node can light the receiver (wholly below its horizon, or
outside every emission cone), so sampling by it is unbiased. Inside a bucket the caller weighs the
leaves by their exact unoccluded transfer (``core.direct``), so with at most BUCKET emitters the
choice is exactly proportional to each emitter's light.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

# Most leaves a bucket node holds (weighed exactly by the caller).
BUCKET = 8
# Deepest node (the traversal keeps one stack entry per level); midpoint splits below this depth
# fall back to median splits, which halve the count.
MAX_DEPTH = 48
STACK = 64
# Radians a node's cone is widened by.
CONE_MARGIN = 1e-3
PI = np.pi


@wp.struct
class LightTree:
    """M nodes over L leaves, as kernels read them.

    lo, hi: vec3[M] box of the node's emitters (m); axis: vec3[M] unit cone axis; cos_o, sin_o:
    float32[M] of the half-angle θ_o of the normals around it; cos_e: float32[M] of the emission
    spread θ_e beyond them (π/2 for Lambertian emitters: 0); two_sided: int32[M] whether −axis
    emits too; power: float32[M] summed power (lighting at unit distance, straight on); distant:
    int32[M] 1 for nodes of distant lamps (no position: the caller weighs them exactly); left, right:
    int32[M] children (−1 for a bucket); first, count: int32[M] the node's leaves in the leaf order;
    leaf_kind: int32[L] LEAF_LAMP or LEAF_TRIANGLE; leaf_index: int32[L] the lamp or emissive
    triangle; root (−1: no emitters).
    """

    lo: wp.array(dtype=wp.vec3)
    hi: wp.array(dtype=wp.vec3)
    axis: wp.array(dtype=wp.vec3)
    cos_o: wp.array(dtype=wp.float32)
    sin_o: wp.array(dtype=wp.float32)
    cos_e: wp.array(dtype=wp.float32)
    two_sided: wp.array(dtype=wp.int32)
    power: wp.array(dtype=wp.float32)
    distant: wp.array(dtype=wp.int32)
    left: wp.array(dtype=wp.int32)
    right: wp.array(dtype=wp.int32)
    first: wp.array(dtype=wp.int32)
    count: wp.array(dtype=wp.int32)
    leaf_kind: wp.array(dtype=wp.int32)
    leaf_index: wp.array(dtype=wp.int32)
    root: int


LEAF_LAMP, LEAF_TRIANGLE = 0, 1


@dataclass
class Leaves:
    """L emitters to build a tree over (host arrays).

    kind: int32[L] LEAF_LAMP / LEAF_TRIANGLE; index: int32[L] lamp or emissive triangle; lo, hi:
    float32[L,3] boxes (m); axis: float32[L,3] unit; theta_o, theta_e: float32[L] (rad);
    two_sided: bool[L]; power: float32[L] (≥ 0); distant: bool[L] (suns: box and power unused).
    """

    kind: np.ndarray
    index: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    axis: np.ndarray
    theta_o: np.ndarray
    theta_e: np.ndarray
    two_sided: np.ndarray
    power: np.ndarray
    distant: np.ndarray

    def __len__(self) -> int:
        return int(self.kind.shape[0])


@dataclass
class Nodes:
    """The built tree on the host: per node (M) lo, hi, axis float32[M,3]; theta_o, theta_e,
    power float32[M]; two_sided, distant bool[M]; left, right, first, count int32[M]; ``order``
    int64[L] the leaves in leaf order; root; depth (levels below the root)."""

    lo: np.ndarray
    hi: np.ndarray
    axis: np.ndarray
    theta_o: np.ndarray
    theta_e: np.ndarray
    power: np.ndarray
    two_sided: np.ndarray
    distant: np.ndarray
    left: np.ndarray
    right: np.ndarray
    first: np.ndarray
    count: np.ndarray
    order: np.ndarray
    root: int
    depth: int


def _ranges(starts: np.ndarray, counts: np.ndarray):
    """(positions int64[Σcounts] of the ranges' elements, the range of each, each range's first
    position among them) for disjoint ranges [start, start + count)."""
    first = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
    seg = np.repeat(np.arange(starts.size), counts)
    return np.repeat(starts - first, counts) + np.arange(int(counts.sum())), seg, first


def _split(centre: np.ndarray, order: np.ndarray, starts: np.ndarray, counts: np.ndarray,
           median: bool) -> np.ndarray:
    """Sort each range [start, start + count) of ``order`` along its centroids' longest axis (in
    place) and return where each splits (int64[S], counted from its start): at the midpoint of that
    axis, or at the median where the midpoint leaves a side empty (always with ``median``)."""
    idx, seg, first = _ranges(starts, counts)
    pts = centre[order[idx]]
    lo = np.minimum.reduceat(pts, first, axis=0)
    hi = np.maximum.reduceat(pts, first, axis=0)
    axis = np.argmax(hi - lo, axis=1)
    key = pts[np.arange(pts.shape[0]), axis[seg]]
    perm = np.lexsort((key, seg))
    order[idx] = order[idx[perm]]
    key = key[perm]
    rows = np.arange(starts.size)
    mid = 0.5 * (lo[rows, axis] + hi[rows, axis])
    below = np.add.reduceat((key < mid[seg]).astype(np.int64), first)
    return np.where(median | (below <= 0) | (below >= counts), counts // 2, below)


def _bounds(leaves: Leaves, order: np.ndarray, starts: np.ndarray, counts: np.ndarray):
    """Bounds of disjoint leaf ranges: (lo, hi, axis, theta_o, theta_e, power, two_sided).

    The cone's axis is the mean of the leaves' axes (a two-sided leaf's turned towards the
    range's first), its half-angle the widest leaf cone around it (π where the axes cancel)."""
    idx, seg, first = _ranges(starts, counts)
    leaf = order[idx]
    lo = np.minimum.reduceat(leaves.lo[leaf], first, axis=0)
    hi = np.maximum.reduceat(leaves.hi[leaf], first, axis=0)
    power = np.add.reduceat(leaves.power[leaf].astype(np.float64), first)
    two = np.maximum.reduceat(leaves.two_sided[leaf].astype(np.int64), first) > 0
    a = leaves.axis[leaf].astype(np.float64)
    ref = a[first][seg]
    flip = leaves.two_sided[leaf] & ((a * ref).sum(axis=1) < 0)
    a = np.where(flip[:, None], -a, a)
    mean = np.add.reduceat(a, first, axis=0)
    norm = np.linalg.norm(mean, axis=1)
    axis = mean / np.where(norm > 0, norm, 1.0)[:, None]
    cos = np.clip((a * axis[seg]).sum(axis=1), -1.0, 1.0)
    spread = np.maximum.reduceat(np.arccos(cos) + leaves.theta_o[leaf], first)
    # (widened a little: float32 rounding must not put a leaf's normal outside its node's cone)
    theta_o = np.where(norm > 1e-3 * counts, np.minimum(spread + CONE_MARGIN, PI), PI)
    theta_e = np.maximum.reduceat(leaves.theta_e[leaf], first)
    return lo, hi, axis, theta_o, theta_e, power, two


def build(leaves: Leaves) -> Nodes:
    """The tree over ``leaves`` (at least one): local ones split top-down (see the module),
    distant ones in buckets of their own beside them under the root."""
    local = np.flatnonzero(~leaves.distant)
    far = np.flatnonzero(leaves.distant)
    order = np.concatenate([local, far]).astype(np.int64)
    centre = 0.5 * (leaves.lo.astype(np.float64) + leaves.hi)
    # nodes as (first, count, parent, distant), created top-down level by level
    first, count, parent, distant = [], [], [], []

    def add(starts, counts, parents, is_far):
        base = len(first)
        first.extend(starts.tolist())
        count.extend(counts.tolist())
        parent.extend(parents.tolist())
        distant.extend([is_far] * starts.size)
        return np.arange(base, base + starts.size)

    depth = 0
    tops = []
    for is_far, (start, n) in ((False, (0, local.size)), (True, (local.size, far.size))):
        if n == 0:
            continue
        level = add(np.array([start]), np.array([n]), np.array([-1]), is_far)
        tops.append(int(level[0]))
        level_depth = 0
        while True:
            starts = np.asarray(first, np.int64)[level]
            counts = np.asarray(count, np.int64)[level]
            split = counts > BUCKET
            if not split.any():
                break
            s, c, nodes = starts[split], counts[split], level[split]
            if is_far:
                cut = c // 2  # suns have no position: any halving will do
            else:
                cut = _split(centre, order, s, c, level_depth >= MAX_DEPTH // 2)
            level = add(np.concatenate([s, s + cut]), np.concatenate([cut, c - cut]),
                        np.concatenate([nodes, nodes]), is_far)
            level_depth += 1
        depth = max(depth, level_depth)
    root = tops[0]
    if len(tops) == 2:  # the root joins the local tree and the distant lamps
        root = int(add(np.array([0]), np.array([len(order)]), np.array([-1]), False)[0])
        parent[tops[0]] = parent[tops[1]] = root
        depth += 1
    m = len(first)
    first_a, count_a, parent_a = (np.asarray(x, np.int64) for x in (first, count, parent))
    child = np.flatnonzero(parent_a >= 0)
    left = np.full(m, m, np.int64)
    right = np.full(m, -1, np.int64)
    np.minimum.at(left, parent_a[child], child)  # the left half was added first
    np.maximum.at(right, parent_a[child], child)
    left[left == m] = -1
    lo, hi, axis, theta_o, theta_e, power, two = _bounds(leaves, order, first_a, count_a)
    return Nodes(lo=lo.astype(np.float32), hi=hi.astype(np.float32), axis=axis.astype(np.float32),
                 theta_o=theta_o.astype(np.float32), theta_e=theta_e.astype(np.float32),
                 power=power.astype(np.float32), two_sided=np.asarray(two, bool),
                 distant=np.asarray(distant, bool), left=left.astype(np.int32),
                 right=right.astype(np.int32), first=first_a.astype(np.int32),
                 count=count_a.astype(np.int32), order=order, root=root, depth=depth)


def upload(nodes: Nodes, leaves: Leaves, device: str) -> LightTree:
    """The ``LightTree`` struct of a built tree on ``device``."""
    t = LightTree()
    for name in ("lo", "hi", "axis"):
        setattr(t, name, wp.array(np.ascontiguousarray(getattr(nodes, name)), dtype=wp.vec3, device=device))
    for name, values in (("cos_o", np.cos(nodes.theta_o)), ("sin_o", np.sin(nodes.theta_o)),
                         ("cos_e", np.cos(nodes.theta_e)), ("power", nodes.power)):
        setattr(t, name, wp.array(values.astype(np.float32), dtype=wp.float32, device=device))
    for name in ("two_sided", "distant", "left", "right", "first", "count"):
        setattr(t, name, wp.array(getattr(nodes, name).astype(np.int32), dtype=wp.int32, device=device))
    t.leaf_kind = wp.array(leaves.kind[nodes.order].astype(np.int32), dtype=wp.int32, device=device)
    t.leaf_index = wp.array(leaves.index[nodes.order].astype(np.int32), dtype=wp.int32, device=device)
    t.root = int(nodes.root)
    return t


def upload_empty(device: str) -> LightTree:
    """The ``LightTree`` struct of a scene without emitters (root −1) on ``device``."""
    t = LightTree()
    for name in ("lo", "hi", "axis"):
        setattr(t, name, wp.zeros(0, dtype=wp.vec3, device=device))
    for name in ("cos_o", "sin_o", "cos_e", "power"):
        setattr(t, name, wp.zeros(0, dtype=wp.float32, device=device))
    for name in ("two_sided", "distant", "left", "right", "first", "count", "leaf_kind", "leaf_index"):
        setattr(t, name, wp.zeros(0, dtype=wp.int32, device=device))
    t.root = -1
    return t


@wp.func
def _cos_past(cos_a: float, cos_b: float, sin_b: float) -> float:
    """cos(max(0, a − b)) for angles a ∈ [0, π] (given its cosine) and b (cosine, sine; b ≥ π
    where sin_b < 0): 1 inside b, else cos a·cos b + sin a·sin b."""
    if sin_b < 0.0 or cos_a >= cos_b:
        return 1.0
    return cos_a * cos_b + wp.sqrt(wp.max(1.0 - cos_a * cos_a, 0.0)) * sin_b


@wp.func
def bound_importance(t: LightTree, node: int, p: wp.vec3, n: wp.vec3) -> float:
    """Importance of local ``node`` at a receiver at p with unit normal n (see the module); 0 only
    where none of its emitters can light the receiver. In cosines: no inverse trigonometry."""
    lo = t.lo[node]
    hi = t.hi[node]
    c = 0.5 * (lo + hi)
    r2 = 0.25 * wp.dot(hi - lo, hi - lo)
    v = c - p
    d2 = wp.dot(v, v)
    if d2 <= r2:
        return t.power[node] / wp.max(r2, 1.0e-30)  # inside the bounding sphere: no cosine bound
    d = wp.sqrt(d2)
    sin_u = wp.min(wp.sqrt(r2) / d, 1.0)  # the angle θ_u the bounding sphere subtends
    cos_u = wp.sqrt(wp.max(1.0 - sin_u * sin_u, 0.0))
    w = v / d
    cos_i = _cos_past(wp.clamp(wp.dot(n, w), -1.0, 1.0), cos_u, sin_u)
    if cos_i <= 0.0:
        return 0.0  # wholly below the receiver's horizon
    cos_a = -wp.dot(t.axis[node], w)
    if t.two_sided[node] != 0:
        cos_a = wp.abs(cos_a)
    # the normals' cone widened by θ_u: θ_o + θ_u
    co = t.cos_o[node]
    so = t.sin_o[node]
    cos_e = _cos_past(wp.clamp(cos_a, -1.0, 1.0), co * cos_u - so * sin_u, so * cos_u + co * sin_u)
    if cos_e <= t.cos_e[node]:
        return 0.0  # outside every emission cone
    return t.power[node] * cos_i * cos_e / d2
