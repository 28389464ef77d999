"""A gather over the cluster tree at any receivers: accessibility (AO), bent normals and, given the
senders' radiance, the light they send (Bunnell's bounce, final gathers).

Per receiver, the tree is traversed (``core.traversal``) and each sender counts with the transfer
of its disk: nodes farther than OPEN bounding radii as one cluster disk (``cluster_ff``), nearer
ones opened (blended ±10 %), leaves closer than √NEAR disk radii with the exact form factors of the
element's own triangles (``surfels.fan_ff``), farther leaves with their disk. Senders beyond
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
from .formfactor import cluster_ff, disk_ff
from .hemisphere import BINS, CELL, bins_vec, frame_of, splat_of
from .hierarchy import Nodes
from .sh import GRAZING, moment_of
from .surfels import Surfels, fan_centre, fan_ff
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
    nodes each traversal visited (the work per receiver); moment: float32[N,3,3] where the gathered
    light comes from (``core.sh``: rows R, G, B of (1/π) ∫ L ω dω, world space; each row · the
    normal ≈ light), None unless asked for."""

    accessibility: np.ndarray
    bent_normal: np.ndarray
    light: Optional[np.ndarray]
    visits: np.ndarray
    moment: Optional[np.ndarray] = None


@wp.func
def leaf_blend(d2: float, area: float) -> float:
    """How much of a leaf at squared distance d2 counts as its disk (the rest: its triangles)."""
    return wp.clamp((d2 / (NEAR * area) - 0.9) * 5.0, 0.0, 1.0)


@wp.func
def leaf_transfer(s: Surfels, p: wp.vec3, n: wp.vec3, q: wp.vec3, nq: wp.vec3, a: float, e: int,
                  d2: float) -> wp.vec4:
    """(front far, back far, front exact, back exact) form factors of a leaf (disk at q, normal nq,
    area a, element e) from p (normal n) at squared distance d2: the disk beyond NEAR, the
    element's own triangles inside, blended over ±10 %."""
    blend = leaf_blend(d2, a)
    out = wp.vec4(0.0)
    if blend > 0.0:
        out[0] = blend * disk_ff(p, n, q, nq, a)
        out[1] = blend * disk_ff(p, n, q, -nq, a)
    if blend < 1.0:
        # A surface facing the receiver in its own plane is in contact with it (a box resting on
        # the floor): seen from a hair off the receiver, as Cycles' offset rays see it, it covers
        # the hemisphere instead of vanishing edge-on.
        pe = p
        if wp.dot(nq, n) < 0.0:
            pe = p - n * (CONTACT * wp.sqrt(a))
        out[2] = (1.0 - blend) * fan_ff(s, pe, n, e, 1.0)
        out[3] = (1.0 - blend) * fan_ff(s, p, n, e, -1.0)
    return out


@wp.func
def resolve(near: bins_vec, near_back: bins_vec, front: bins_vec, back: bins_vec, peak: bins_vec,
            red: bins_vec, green: bins_vec, blue: bins_vec, near_light: wp.vec3) -> wp.vec4:
    """(occlusion, light r, g, b) of a receiver from its cells: per cell the near-field front and
    back cover, the far front and back cover, the largest single far front part and the far
    front light per channel; near_light the near field's light. Each cell is covered at most
    once: near-field parts count whole, and so does the largest single far part (a wide sender can
    exceed a cell); stacked parts fill what they leave. Front and back faces of one closed object
    show the same directions: the larger of the two, not their sum. Senders stacked in one cell
    share what is left of it: their mean radiance."""
    occ = float(0.0)
    light = near_light
    for b in range(BINS):
        blocked = wp.max(near[b], near_back[b])
        fill = wp.max(front[b] + near[b], back[b] + near_back[b])
        occ += wp.max(wp.max(blocked, peak[b]), wp.min(fill, CELL))
        light += wp.vec3(red[b], green[b], blue[b]) * cell_share(near[b], near_back[b], front[b], peak[b])
    return wp.vec4(occ, light[0], light[1], light[2])


@wp.func
def cell_share(near: float, near_back: float, front: float, peak: float) -> float:
    """The share of a cell's far front light that reaches the receiver (see ``resolve``)."""
    if front <= 0.0:
        return 0.0
    return wp.min(1.0, wp.max(CELL - wp.max(near, near_back), peak) / front)


@wp.func
def resolve_moment(near: bins_vec, near_back: bins_vec, front: bins_vec, peak: bins_vec,
                   red: bins_vec, green: bins_vec, blue: bins_vec, mx: bins_vec, my: bins_vec,
                   mz: bins_vec, near_moment: wp.mat33) -> wp.mat33:
    """Where the light ``resolve`` finds comes from (``core.sh.moment_of``): each cell's light as
    ``resolve`` takes it, from its contributions' mean direction over cosθ (mx, my, mz: that
    direction summed weighted by each contribution's light, all channels), plus the near
    field's own moment."""
    moment = near_moment
    for b in range(BINS):
        weight = red[b] + green[b] + blue[b]
        if weight > 0.0:
            share = cell_share(near[b], near_back[b], front[b], peak[b])
            moment += wp.outer(wp.vec3(red[b], green[b], blue[b]) * share,
                               wp.vec3(mx[b], my[b], mz[b]) / weight)
    return moment


@wp.kernel
def _gather_kernel(offset: int, rp: wp.array(dtype=wp.vec3), rn: wp.array(dtype=wp.vec3), t: Nodes,
                   s: Surfels, distance: float, open_k: float, with_light: int,
                   radiance: wp.array(dtype=wp.vec3), out_access: wp.array(dtype=wp.float32),
                   out_bent: wp.array(dtype=wp.vec3), out_light: wp.array(dtype=wp.vec3),
                   out_visits: wp.array(dtype=wp.int32), with_moment: int,
                   out_moment: wp.array(dtype=wp.mat33)):
    i = wp.tid() + offset
    p = rp[i]
    n = rn[i]
    f = frame_of(n)
    # the receiver's cells (see resolve)
    front = bins_vec()
    peak = bins_vec()
    back = bins_vec()
    near = bins_vec()
    near_back = bins_vec()
    red = bins_vec()
    green = bins_vec()
    blue = bins_vec()
    near_light = wp.vec3(0.0)
    # where the far light of each cell comes from, and the near field's moment (with_moment)
    mx = bins_vec()
    my = bins_vec()
    mz = bins_vec()
    near_moment = wp.mat33(0.0)
    raw = float(0.0)
    dirsum = wp.vec3(0.0)
    visits = int(0)
    cut = cut_begin(t.root, t.level[t.root])
    while cut.node >= 0:
        node = cut.node
        visits += 1
        q = t.position[node]
        v = q - p
        r = t.radius[node]
        d2 = wp.dot(v, v)
        dist = wp.sqrt(d2)
        area = t.area[node]
        if dist - r >= distance or wp.dot(v, n) <= -r or area <= 0.0:
            cut = cut_skip(cut, t.next[node])
            continue
        level = t.level[node]
        w = cut_weight(cut, level)
        child = t.descend[node]
        part = wp.vec4(0.0)
        take = float(1.0)
        dhat = v / dist
        near_dir = dhat  # where a leaf's exact (near-field) part comes from, for the moment
        if child < 0:
            if dist < distance:
                e = t.element[node]
                part = w * leaf_transfer(s, p, n, q, t.normal[node], area, e, d2)
                # Within about the element's own size the direction to its disk's centre is no
                # longer where its triangles are (and undefined for a receiver on the element):
                # towards the centre of its triangles instead, blended in.
                toward = wp.clamp((d2 / area - 0.25) / 0.75, 0.0, 1.0)
                if toward < 1.0 and part[0] + part[1] + part[2] + part[3] > 0.0:
                    centre = fan_centre(e, s.vertex, s.fan_offsets, s.fan_triangles, s.tris, s.points)
                    dhat = wp.normalize(toward * v + (1.0 - toward) * (centre - p))
                # The near field's moment: from the centre of the element's triangles, not of its
                # disk (a wall's bottom vertex lies at the floor's horizon, its triangles above it).
                if with_moment != 0 and part[2] > 0.0:
                    near_dir = wp.normalize(
                        fan_centre(e, s.vertex, s.fan_offsets, s.fan_triangles, s.tris, s.points) - p)
        else:
            # Never nearer than a leaf would take its exact form factor: a chain of one-child
            # cells over a single disk must reach that leaf's near field.
            take = opening(d2, r, NEAR * area, open_k)
            if take > 0.0:
                # A far node straddling the AO distance counts with the part of its depth inside
                # (opening it down to the leaves would visit a whole shell of them per receiver).
                share = w * take * wp.clamp((distance - dist + r) / (2.0 * r), 0.0, 1.0)
                nq = t.normal[node]
                part[0] = share * cluster_ff(p, n, q, nq, area, t.spread[node], t.leaves[node])
                part[1] = share * cluster_ff(p, n, q, -nq, area, t.spread[node], t.leaves[node])
        cut = cut_advance(cut, level, child, t.level[wp.max(child, 0)], t.next[node], take)
        total = part[0] + part[1] + part[2] + part[3]
        if total > 0.0:
            raw += total
            dirsum += dhat * total
            light = wp.vec3(0.0)
            if with_light != 0:
                light = radiance[node]
            sp = splat_of(f, dhat)
            slant = dhat / wp.max(wp.dot(dhat, n), GRAZING)
            lum = (light[0] + light[1] + light[2]) * part[0]
            for k in range(4):  # the splat's cells, updated in place
                c = sp.cells[k]
                wk = sp.weights[k]
                front[c] += part[0] * wk
                peak[c] = wp.max(peak[c], part[0] * wk)
                back[c] += part[1] * wk
                near[c] += part[2] * wk
                near_back[c] += part[3] * wk
                red[c] += light[0] * part[0] * wk
                green[c] += light[1] * part[0] * wk
                blue[c] += light[2] * part[0] * wk
                if with_moment != 0:
                    mx[c] += slant[0] * lum * wk
                    my[c] += slant[1] * lum * wk
                    mz[c] += slant[2] * lum * wk
            near_light += light * part[2]
            if with_moment != 0:
                near_moment += moment_of(light * part[2], near_dir, n)
    res = resolve(near, near_back, front, back, peak, red, green, blue, near_light)
    occ = res[0]
    out_access[i] = wp.clamp(1.0 - occ, 0.0, 1.0)
    out_visits[i] = visits
    if with_light != 0:
        out_light[i] = wp.vec3(res[1], res[2], res[3])
    if with_moment != 0:
        out_moment[i] = resolve_moment(near, near_back, front, peak, red, green, blue, mx, my, mz,
                                       near_moment)
    bent = n
    if raw > 0.0:
        bent = n - dirsum * (wp.min(occ, 1.0) / raw)
    if wp.length(bent) > 1.0e-6:
        out_bent[i] = wp.normalize(bent)
    else:
        out_bent[i] = n


def gather(problem, points: np.ndarray, normals: np.ndarray, distance: float,
           radiance: Optional[wp.array] = None, open_k: float = OPEN, progress=None,
           with_moment: bool = False) -> Gather:
    """Accessibility, bent normals and (with ``radiance``) gathered light at N receivers from the
    elements of ``problem`` (over ``problem.tree``).

    points: float32[N,3] receiver positions (m); normals: float32[N,3] unit; distance: AO distance
    (m), senders farther away count for nothing; radiance: vec3[tree.count] radiance leaving each
    node's front (e.g. ``hierarchy.node_means`` of per-element radiance), or None for AO only;
    open_k: OPEN, or ALL_PAIRS for the brute-force sum over every element; progress(fraction);
    with_moment (needs ``radiance``): also where the light comes from (``Gather.moment``).
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
    moment = wp.empty(count if with_moment else 1, dtype=wp.mat33, device=d)
    if not with_light:
        radiance = light  # not read
    device_mod.launch(
        _gather_kernel, count,
        [wp.array(np.ascontiguousarray(points, np.float32), dtype=wp.vec3, device=d),
         wp.array(np.ascontiguousarray(normals, np.float32), dtype=wp.vec3, device=d),
         tree.nodes, problem.surfels, float(distance), float(open_k), int(with_light), radiance,
         access, bent, light, visits, int(with_moment), moment],
        dev, chunks=max(1, min(32, count // 4096)), on_chunk=progress)
    return Gather(access.numpy(), bent.numpy(), light.numpy() if with_light else None, visits.numpy(),
                  moment.numpy() if with_moment else None)


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
