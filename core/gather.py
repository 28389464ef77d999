"""A gather over the cluster tree at any receivers: accessibility (AO), bent normals and, given the
senders' radiance, the light they send (Bunnell's bounce, final gathers).

Per receiver, the tree is traversed (``core.traversal``) and each sender counts with the transfer
of its disk: nodes farther than OPEN bounding radii as one cluster disk (``cluster_ff``), nearer
ones opened (blended ±10 %), leaves closer than √NEAR disk radii with the exact form factors of the
element's own triangles (``formfactor.fan_ff``), farther leaves with their disk. Senders beyond
the AO distance count for nothing (as in Cycles' AO).

Overlapping occluders must not add up. Bunnell's multi-pass fix (ALGORITHMS.md §2: weight each
sender by its own accessibility from the previous pass) cannot get both cases of §8 right: inside
a closed sphere every sender has accessibility 0, so pass 2 says "fully open" (the passes
alternate 0, 1, 0 …), while the farther of two stacked disks is half open itself yet wholly
hidden from the receiver. So overlaps are resolved per direction instead (``core.hemisphere``):
each contribution is splatted into the cells around its direction, and a cell is covered at most
once. Near-field (exact) parts count whole and take their cell first (a close, wide sender can
exceed one cell); farther ones fill what is left.

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

from . import device as device_mod
from .formfactor import PLANE_EPS, disk_ff, fan_ff, triangle_ff
from .hemisphere import BINS, CELL, bins_vec, frame_of, splat_of
from .hierarchy import Nodes
from .problem import Surfels
from .traversal import cut_advance, cut_begin, cut_skip, cut_weight, opening

wp.set_module_options({"enable_backward": False})  # no gradients: halves compile time

# Open a node when d² < OPEN·radius² (blended over ±10 %): the cluster disk then subtends less than
# ~14°, where its form factor is within the 2 % the tests ask of the all-pairs sum.
OPEN = 16.0
# A leaf nearer than d² < NEAR·area uses the exact form factor of its triangles (ALGORITHMS.md §1:
# 4–8; the disk approximation is off by more than 5 % inside that).
NEAR = 8.0
# Offset towards an opposite-facing near sender, relative to its disk's √area (see leaf_transfer).
CONTACT = 1.0e-3
# open_k of the all-pairs sum: every node is opened, every leaf visited.
ALL_PAIRS = 1.0e30


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
               leaves: float) -> wp.vec2:
    """Form factors (front, back) of a cluster of ``leaves`` disks: as many disks of its mean area
    at its centre (their sum, not one disk of the whole area, whose π d² + A denominator would be
    too large) for aligned normals (spread 1), facing with nq (front) or against it (back); an
    isotropic blob of projected area A/4 (a closed convex surface's mean) where they cancel
    (spread 0), the same from either side; linearly between."""
    d = q - p
    d2 = wp.dot(d, d)
    if d2 <= 0.0:
        return wp.vec2(0.0, 0.0)
    inv = 1.0 / wp.sqrt(d2)
    cos_r = wp.max(wp.dot(n, d) * inv, 0.0)
    each = area / leaves
    iso = (1.0 - spread) * 0.25 * area * cos_r / (3.141592653589793 * d2 + 0.25 * each)
    # disk_ff of both faces at once: cos_E is −nq·d̂ for the front and +nq·d̂ for the back
    cos_e = -wp.dot(nq, d) * inv
    disks = spread * leaves * each * cos_r / (3.141592653589793 * d2 + each)
    return wp.vec2(disks * wp.max(cos_e, 0.0) + iso, disks * wp.max(-cos_e, 0.0) + iso)


def fan_centres(problem) -> np.ndarray:
    """float32[n,3]: the area-weighted centre of each element's share of its triangles (a third
    each, around its vertex; the vertex itself where they have no area)."""
    els, scene = problem.elements, problem.scene
    pos = np.asarray(scene.positions, np.float64)
    counts = np.diff(els.fan_offsets)
    owner = np.repeat(np.arange(els.count), counts)
    corners = pos[scene.triangles[els.fan_triangles[:els.fan_offsets[-1]]]]
    w = np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    pv = pos[els.vertex]
    acc = np.zeros((els.count, 3))
    np.add.at(acc, owner, w[:, None] * 0.5 * (pv[owner] + corners.mean(axis=1)))
    total = np.bincount(owner, weights=w, minlength=els.count)
    out = np.where(total[:, None] > 0, acc / np.where(total > 0, total, 1.0)[:, None], pv)
    return out.astype(np.float32)


@wp.func
def leaf_blend(d2: float, area: float) -> float:
    """How much of a leaf at squared distance d2 counts as its disk (the rest: its triangles)."""
    return wp.clamp((d2 / (NEAR * area) - 0.9) * 5.0, 0.0, 1.0)


@wp.func
def leaf_direction(t: Nodes, centres: wp.array(dtype=wp.vec3), node: int, p: wp.vec3,
                   d2: float) -> wp.vec3:
    """Where a leaf lies as seen from p: its disk's centre far away; within about the element's
    own size, where that direction is no longer where its triangles are (and undefined for a
    receiver on the element), towards the centre of its triangles (``fan_centres``), blended in."""
    toward = wp.clamp((d2 / t.area[node] - 0.25) / 0.75, 0.0, 1.0)
    v = t.position[node] - p
    if toward < 1.0:
        v = toward * v + (1.0 - toward) * (centres[t.element[node]] - p)
    return wp.normalize(v)


@wp.func
def fan_sides(p: wp.vec3, n: wp.vec3, j: int, s: Surfels) -> wp.vec2:
    """``formfactor.fan_ff`` of both sides of element j at once: (front, back), each of its
    triangles counting for the side p lies on."""
    front = float(0.0)
    back = float(0.0)
    for k in range(s.fan_offsets[j], s.fan_offsets[j + 1]):
        tri = s.fan_triangles[k]
        a = s.points[s.tris[3 * tri]]
        b = s.points[s.tris[3 * tri + 1]]
        c = s.points[s.tris[3 * tri + 2]]
        nt = wp.cross(b - a, c - a)
        h = wp.dot(p - a, nt)
        lnt = wp.length(nt)
        eps = PLANE_EPS * lnt * (wp.length(p - a) + wp.sqrt(lnt))
        if h > eps:
            front += triangle_ff(p, n, a, b, c)
        elif -h > eps:
            back += triangle_ff(p, n, a, b, c)
    return wp.vec2(front, back) / 3.0


@wp.func
def leaf_transfer(t: Nodes, s: Surfels, node: int, p: wp.vec3, n: wp.vec3, d2: float) -> wp.vec4:
    """(front far, back far, front exact, back exact) form factors of leaf ``node`` from p (normal
    n): the disk beyond NEAR, the element's own triangles inside, blended over ±10 %."""
    a = t.area[node]
    q = t.position[node]
    nq = t.normal[node]
    blend = leaf_blend(d2, a)
    out = wp.vec4(0.0)
    if blend > 0.0:
        out[0] = blend * disk_ff(p, n, q, nq, a)
        out[1] = blend * disk_ff(p, n, q, -nq, a)
    if blend < 1.0:
        e = t.element[node]
        # A surface facing the receiver in its own plane is in contact with it (a box resting on
        # the floor): seen from a hair off the receiver, as Cycles' offset rays see it, it covers
        # the hemisphere instead of vanishing edge-on.
        if wp.dot(nq, n) < 0.0:
            pe = p - n * (CONTACT * wp.sqrt(a))
            out[2] = (1.0 - blend) * fan_ff(pe, n, e, 1.0, s.fan_offsets, s.fan_triangles, s.tris, s.points)
            out[3] = (1.0 - blend) * fan_ff(p, n, e, -1.0, s.fan_offsets, s.fan_triangles, s.tris, s.points)
        else:
            sides = (1.0 - blend) * fan_sides(p, n, e, s)
            out[2] = sides[0]
            out[3] = sides[1]
    return out


@wp.struct
class Cover:
    """What a receiver's hemisphere cells hold during a gather: per cell the far front cover, its
    largest single far part, the far back cover, the near-field front and back cover, and the far
    front light per channel; near_light is the near field's light (never capped)."""

    front: bins_vec
    peak: bins_vec
    back: bins_vec
    near: bins_vec
    near_back: bins_vec
    red: bins_vec
    green: bins_vec
    blue: bins_vec
    near_light: wp.vec3


@wp.func
def _cover(front: bins_vec, peak: bins_vec, back: bins_vec, near: bins_vec, near_back: bins_vec,
           red: bins_vec, green: bins_vec, blue: bins_vec, near_light: wp.vec3) -> Cover:
    c = Cover()
    c.front = front
    c.peak = peak
    c.back = back
    c.near = near
    c.near_back = near_back
    c.red = red
    c.green = green
    c.blue = blue
    c.near_light = near_light
    return c


@wp.func
def cover_resolve(c: Cover) -> wp.vec4:
    """(occlusion, light r, g, b): each cell covered at most once. Near-field parts count whole,
    and so does the largest single far part (a wide sender can exceed a cell); stacked parts fill
    what they leave. Front and back faces of one closed object show the same directions: the
    larger of the two, not their sum. Senders stacked in one cell share what is left of it: their
    mean radiance."""
    occ = float(0.0)
    light = c.near_light
    for b in range(BINS):
        blocked = wp.max(c.near[b], c.near_back[b])
        fill = wp.max(c.front[b] + c.near[b], c.back[b] + c.near_back[b])
        occ += wp.max(wp.max(blocked, c.peak[b]), wp.min(fill, CELL))
        f = c.front[b]
        if f > 0.0:
            light += wp.vec3(c.red[b], c.green[b], c.blue[b]) * wp.min(1.0, wp.max(CELL - blocked, c.peak[b]) / f)
    return wp.vec4(occ, light[0], light[1], light[2])


@wp.kernel
def _gather_kernel(offset: int, rp: wp.array(dtype=wp.vec3), rn: wp.array(dtype=wp.vec3), t: Nodes,
                   s: Surfels, centres: wp.array(dtype=wp.vec3), distance: float, open_k: float,
                   with_light: int,
                   radiance: wp.array(dtype=wp.vec3), out_access: wp.array(dtype=wp.float32),
                   out_bent: wp.array(dtype=wp.vec3), out_light: wp.array(dtype=wp.vec3),
                   out_visits: wp.array(dtype=wp.int32)):
    i = wp.tid() + offset
    p = rp[i]
    n = rn[i]
    f = frame_of(n)
    front = bins_vec()
    peak = bins_vec()
    back = bins_vec()
    near = bins_vec()
    near_back = bins_vec()
    red = bins_vec()
    green = bins_vec()
    blue = bins_vec()
    near_light = wp.vec3(0.0)
    raw = float(0.0)
    dirsum = wp.vec3(0.0)
    visits = int(0)
    cut = cut_begin(t.root, t.level[t.root])
    while cut.node >= 0:
        node = cut.node
        visits += 1
        v = t.position[node] - p
        r = t.radius[node]
        d2 = wp.dot(v, v)
        dist = wp.sqrt(d2)
        if dist - r >= distance or wp.dot(v, n) <= -r or t.area[node] <= 0.0:
            cut = cut_skip(cut, t.next[node])
            continue
        level = t.level[node]
        w = cut_weight(cut, level)
        child = t.descend[node]
        part = wp.vec4(0.0)
        take = float(1.0)
        leaf = child < 0
        if leaf:
            if dist < distance:
                part = w * leaf_transfer(t, s, node, p, n, d2)
        else:
            # Never nearer than a leaf would take its exact form factor: a chain of one-child
            # cells over a single disk must reach that leaf's near field.
            take = opening(d2, r, NEAR * t.area[node], open_k)
            if take > 0.0:
                # A far node straddling the AO distance counts with the part of its depth inside
                # (opening it down to the leaves would visit a whole shell of them per receiver).
                share = w * take * wp.clamp((distance - dist + r) / (2.0 * r), 0.0, 1.0)
                sides = share * cluster_ff(p, n, t.position[node], t.normal[node], t.area[node],
                                           t.spread[node], t.leaves[node])
                part[0] = sides[0]
                part[1] = sides[1]
        cut = cut_advance(cut, level, child, t.level[wp.max(child, 0)], t.next[node], take)
        total = part[0] + part[1] + part[2] + part[3]
        if total > 0.0:
            dhat = v / dist
            if leaf:
                dhat = leaf_direction(t, centres, node, p, d2)
            raw += total
            dirsum += dhat * total
            light = wp.vec3(0.0)
            if with_light != 0:
                light = radiance[node]
            # the sender's parts (far front, far back, exact front, exact back) and its radiance
            # into the cells around its direction, in local tables (updated in place: a struct
            # field's table would be copied on every access)
            sp = splat_of(f, dhat)
            for c in range(4):
                cell = sp.cells[c]
                wc = sp.weights[c]
                if part[0] > 0.0:
                    fc = part[0] * wc
                    front[cell] += fc
                    peak[cell] = wp.max(peak[cell], fc)
                    red[cell] += light[0] * fc
                    green[cell] += light[1] * fc
                    blue[cell] += light[2] * fc
                if part[1] > 0.0:
                    back[cell] += part[1] * wc
                if part[2] > 0.0 or part[3] > 0.0:
                    near[cell] += part[2] * wc
                    near_back[cell] += part[3] * wc
            near_light += light * part[2]
    res = cover_resolve(_cover(front, peak, back, near, near_back, red, green, blue, near_light))
    occ = res[0]
    out_access[i] = wp.clamp(1.0 - occ, 0.0, 1.0)
    out_visits[i] = visits
    if with_light != 0:
        out_light[i] = wp.vec3(res[1], res[2], res[3])
    bent = n
    if raw > 0.0:
        bent = n - dirsum * (wp.min(occ, 1.0) / raw)
    if wp.length(bent) > 1.0e-6:
        out_bent[i] = wp.normalize(bent)
    else:
        out_bent[i] = n


def gather(problem, points: np.ndarray, normals: np.ndarray, distance: float,
           radiance: Optional[wp.array] = None, open_k: float = OPEN, progress=None) -> Gather:
    """Accessibility, bent normals and (with ``radiance``) gathered light at N receivers from the
    elements of ``problem`` (over ``problem.tree``).

    points: float32[N,3] receiver positions (m); normals: float32[N,3] unit; distance: AO distance
    (m), senders farther away count for nothing; radiance: vec3[tree.count] radiance leaving each
    node's front (e.g. ``hierarchy.node_means`` of per-element radiance), or None for AO only;
    open_k: OPEN, or ALL_PAIRS for the brute-force sum over every element; progress(fraction).
    """
    tree = problem.tree
    dev = problem.device
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
         tree.nodes, problem.surfels,
         wp.array(fan_centres(problem), dtype=wp.vec3, device=d), float(distance), float(open_k),
         int(with_light), radiance,
         access, bent, light, visits],
        dev, chunks=max(1, min(32, count // 4096)), on_chunk=progress)
    return Gather(access.numpy(), bent.numpy(), light.numpy() if with_light else None, visits.numpy())


# Distance of the senders' accessibility, in median element sizes (√area): measured on the sample
# scenes against the reference, 2 removes the Cornell box's hidden hot spot (lighting relative
# RMSE 0.44 → 0.06) and changes the lamp scene little (0.048 → 0.047).
LOCAL = 2.0


def sender_radiance(problem, lighting: np.ndarray) -> wp.array:
    """vec3[tree.count]: the radiance leaving each node's front as gathers see it: ρ ⊙ lighting per
    element (lighting float32[n,3], irradiance/π), weighted by the element's accessibility within
    LOCAL element sizes and averaged over each node's subtree.

    Occlusion finer than a hemisphere cell is not resolved by the gather, so a surface closed in at
    close range (the ceiling 1 mm above the Cornell box's light panel, lit hard by the panel's back)
    would shine through; its local accessibility hides it from everything farther away, while the
    open surfaces that carry most light keep it (their accessibility over the whole scene would
    darken every corner twice)."""
    from .hierarchy import node_means

    els = problem.elements
    size = float(np.sqrt(np.median(els.area)))
    local = gather(problem, els.position, els.normal, LOCAL * size).accessibility
    return node_means(problem.tree, (els.albedo * lighting * local[:, None]).astype(np.float32))


def light_at(problem, radiance: wp.array, points: np.ndarray, normals: np.ndarray,
             progress=None) -> np.ndarray:
    """float32[N,3]: the lighting (irradiance/π) the senders' ``radiance`` (``sender_radiance``)
    sends to N points (float32[N,3], m) with unit normals over the whole scene."""
    return gather(problem, points, normals, problem.far, radiance=radiance,
                  progress=progress).light.astype(np.float32)
