"""Hierarchical radiosity over links between cluster-tree nodes (Hanrahan et al. 1991, with
clusters; ALGORITHMS.md §4, §9): multi-bounce indirect light in O(links) per iteration.

The links (``core.links``, cached on the problem) join pairs of tree nodes that exchange light as
wholes, each with its transfer — form factor and visibility estimated together from a few sample
pairs between the two nodes' leaves, traced once when the link is made. One iteration, in lighting
units (irradiance/π) as the reference solver's sweep, with D the direct lighting from
``core.direct``:

- pull: each node's radiance is the area-weighted mean of ρ ⊙ (D + I) over its leaves;
- gather: each node receives Σ over its links of transfer × the sender's radiance (one thread per
  receiver node over its CSR range, no atomics);
- push: an element's indirect lighting I is the sum of what the nodes on its root path received
  (irradiance pushed down unchanged).

Iterations repeat until the largest change is below ``tolerance`` × the largest lighting value
(Jacobi, as the reference), at most ``bounces``; the last one is made at the elements themselves
(``_leaf_gather_kernel``): every link of an element's root path is evaluated at the element, its
transfer scaled by the sender's centroid form factor from the element over the link's normaliser
(what a cluster receiving as a whole cannot tell its leaves: nearer, farther, turned away).

By default (``gather_rays``) that last bounce is replaced by a final gather by rays
(``core.hits``): from the links' solution, sweeps over each element's own rays' hits, until they
converge. The answer is then what the rays see, and the links only start it, so they are made
coarse (GATHER_THRESHOLD, one ray each).

At receivers that are not the elements (lightmap texels) ``evaluate`` runs the same final gather
over the same links at each texel (``texel_gather``), for each element the texel is
reconstructed from: the elements' own links to leaves exactly, with a ray from the texel to each
such leaf, and links whose rays found them partly visible with the texel's own rays to their
senders — so small occluders near a surface cast sharp indirect shadows between its vertices.
"""
from __future__ import annotations

import numpy as np
import warp as wp

from .. import device as device_mod
from .. import hits as hits_mod
from .. import links as links_mod
from .. import nearfield
from ..errors import BakeError
from ..hierarchy import Nodes, node_means
from ..links import LinkSet, Sampling, leaf_point, sample_leaf, sided_ff
from ..nearfield import Detail, near_light, varies
from ..rays import lift, visible
from ..rootpath import WHOLE, path_link_begin, path_link_next, path_top, path_up
from ..surfels import Surfels, fan_sample, point_ff
from .base import Solution, exitance, iterate, reconstruct_with_detail



# The last iteration and the texels evaluate the links of receivers with at most this many leaves
# at each element or texel, those of larger receivers once at the highest node below them with at
# most this many leaves: evaluating every link at every leaf below its receiver would cost
# 2.7 k link evaluations per element at 20 k elements, 16.7 k at 200 k. A cap for large scenes:
# receivers that large are far from their senders (measured: the 20 k-element room within 0.05 %
# of evaluating everything at every leaf).
LEAF_LIMIT = 1024
# With the final gather by rays (``core.hits``) the links only give its sweeps their start, and the
# sweeps converge to the same light from any (measured on bench/real_scenes.py's scenes: the same
# error against the truth to 0.01 percentage points, the furnished room and the open scene at
# thresholds 0.1, 0.5 and 1.0, all three at 1, 2 or 4 rays a link), so they are made coarse:
# threshold 0.5 took the room 3.98 → 2.67 s and the level's links 37.5 → 13.4 s (at 1.0 the
# links' own iterations stopped converging: 64 in the room); one ray a link instead of 4 the room
# 2.72 → 2.31 s, the level 34.3 → 25.5 s.
GATHER_THRESHOLD = 0.5
# A small scene's elements get more rays than ``gather_rays``, up to this many in all and this many
# each: the gather's noise (per element, ∝ 1/√rays) is most of its error there and its rays are
# cheap next to the rest of the bake (measured on the Cornell box, 2 825 elements, against Cycles
# at 2 048 samples: 256 rays 3.45 % relative RMSE in 0.52 s, 1 024 rays 2.59 % in 1.09 s, the
# links' own last bounce 3.02 %; the default's 742 rays 2.67 %).
GATHER_BUDGET = 1 << 21
GATHER_MOST = 4096
# The final gather at the elements runs in this many waves on the CPU (each split over the
# threads), so that uneven work evens out.
GATHER_WAVES = 16


def oracle(settings) -> links_mod.Oracle:
    """The links this solver asks for: the settings' threshold and rays (with ``gather_rays``, at
    least GATHER_THRESHOLD and one ray, unless texels are gathered over them: ``texel_links``)
    and budget, weighted by the first estimate of the radiance (``first_radiance``)."""
    threshold, rays = float(settings.link_threshold), int(settings.visibility_rays)
    if settings.gather_rays and not settings.texel_links:
        threshold, rays = max(threshold, GATHER_THRESHOLD), 1
    return links_mod.Oracle(threshold=threshold, rays=rays,
                            seed=int(settings.seed), budget=int(settings.link_memory) << 20,
                            brightness="first estimate")


def first_radiance(problem) -> np.ndarray:
    """float32[n,3]: a first estimate of each element's radiance before solving, ρ ⊙ (D + ī):
    the direct lighting D plus a uniform indirect lighting ī = ρ̄ D̄ / (1 − ρ̄) (area means; what a
    closed room of uniform albedo reflects, an overestimate for open scenes, so refinement errs
    on the fine side)."""
    els = problem.elements
    area = els.area.astype(np.float64)[:, None]
    total = max(float(area.sum()), 1e-30)
    albedo = (els.albedo * area).sum(axis=0) / total
    reflected = (els.albedo * problem.direct * area).sum(axis=0) / total
    indirect = reflected / np.maximum(1.0 - albedo, 0.05)
    return (els.albedo * (problem.direct + indirect)).astype(np.float32)


def links_of(problem):
    """The problem's links for this solver (built once, cached)."""
    return problem.links(oracle(problem.settings), lambda: first_radiance(problem))


@wp.kernel
def _gather_kernel(offset: int, ls: LinkSet, radiance: wp.array(dtype=wp.vec3),
                   out: wp.array(dtype=wp.vec3)):
    """What receiver node r gets over its links: Σ F · visibility · radiance of the sender."""
    r = wp.tid() + offset
    acc = wp.vec3(0.0)
    for j in range(ls.offsets[r], ls.offsets[r + 1]):
        acc += radiance[ls.sender[j]] * ls.transfer[j]
    out[r] = acc


@wp.kernel
def _push_kernel(offset: int, t: Nodes, gathered: wp.array(dtype=wp.vec3), open_fraction: wp.array(dtype=wp.float32),
                 out: wp.array(dtype=wp.vec3)):
    """Leaf k's element: the sum of what its root path received, its ancestors' share scaled by
    the element's ``open_fraction`` (their links' rays left from other leaves)."""
    k = wp.tid() + offset
    e = t.element[k]
    acc = wp.vec3(0.0)
    x = path_up(t, k, WHOLE)
    while x >= 0:
        acc += gathered[x]
        x = path_up(t, x, WHOLE)
    out[e] = gathered[k] + acc * open_fraction[e]


@wp.func
def transfer_at(t: Nodes, s: Surfels, ls: LinkSet, j: int, p: wp.vec3, n: wp.vec3, scaled: int,
                sides: int) -> float:
    """Link j's transfer at point p (unit normal n) of its receiver: as stored (the receiver's
    average), or ``scaled`` by the sender's form factor from p (``sided_ff``: its front, or both
    faces for ``sides`` 2 as the links were made) over the link's normaliser."""
    f = ls.transfer[j]
    norm = ls.form_factor[j]
    if scaled != 0 and norm > 0.0:
        f = sided_ff(t, s, p, n, ls.sender[j], sides) * f / norm
    return f


@wp.kernel
def _above_kernel(offset: int, t: Nodes, s: Surfels, ls: LinkSet, radiance: wp.array(dtype=wp.vec3),
                  limit: float, above: wp.array(dtype=wp.vec3)):
    """Node y with at most ``limit`` leaves under a parent with more (a node of the cut): what the
    links of its ancestors bring to its centre and normal (``transfer_at``); 0 elsewhere."""
    y = wp.tid() + offset
    acc = wp.vec3(0.0)
    x = t.parent[y]
    if t.leaves[y] <= limit and x >= 0 and t.leaves[x] > limit:
        p = t.position[y]
        n = t.normal[y]
        walk = path_link_begin(t, ls, x, WHOLE)
        while walk.node >= 0:
            acc += radiance[ls.sender[walk.link]] * transfer_at(t, s, ls, walk.link, p, n, 1, 1)
            walk = path_link_next(t, ls, walk)
    above[y] = acc


@wp.func
def sent(nf: Detail, t: Nodes, s: Surfels, radiance: wp.array(dtype=wp.vec3), b: int, f: float, p: wp.vec3,
         n: wp.vec3, origin: wp.vec3) -> wp.vec3:
    """What node b sends to point p over a link of transfer f at p: a leaf as p sees it
    (``nearfield.near_light``), a cluster its radiance × f."""
    if t.descend[b] < 0:
        return near_light(nf, s, t.element[b], radiance[b], f, p, n, origin)
    return radiance[b] * f


@wp.func
def path_gather(t: Nodes, s: Surfels, ls: LinkSet, nf: Detail, radiance: wp.array(dtype=wp.vec3),
                above: wp.array(dtype=wp.vec3), limit: float, k: int, p: wp.vec3, n: wp.vec3, size: float,
                open_fraction: float):
    """(lighting, links evaluated) that leaf k's root path brings to point p (unit normal n, local
    feature size ``size``, ``open_fraction`` of its view not inside a closed surface): the links of
    nodes with at most ``limit`` leaves each at p (``transfer_at``, leaf k's own as they are; near
    senders as p sees them, ``nearfield.near_light``), those of larger nodes as they bring it to
    the highest such node (``above``); what leaf k's ancestors bring scaled by ``open_fraction``."""
    own = wp.vec3(0.0)
    acc = wp.vec3(0.0)
    count = int(0)
    origin = lift(p, n, size)
    walk = path_link_begin(t, ls, k, limit)
    while walk.node >= 0:
        light = sent(nf, t, s, radiance, ls.sender[walk.link],
                     transfer_at(t, s, ls, walk.link, p, n, int(walk.node != k), 1), p, n, origin)
        if walk.node == k:
            own += light
        else:
            acc += light
        count += 1
        walk = path_link_next(t, ls, walk)
    acc += above[path_top(t, k, limit)]  # 0 at the root
    return own + acc * open_fraction, count


@wp.kernel
def _leaf_gather_kernel(offset: int, t: Nodes, s: Surfels, ls: LinkSet, nf: Detail,
                        radiance: wp.array(dtype=wp.vec3), above: wp.array(dtype=wp.vec3), limit: float,
                        open_fraction: wp.array(dtype=wp.float32), out: wp.array(dtype=wp.vec3),
                        evaluations: wp.array(dtype=wp.int32)):
    """Leaf k's element: ``path_gather`` at its own point and normal."""
    k = wp.tid() + offset
    e = t.element[k]
    light, count = path_gather(t, s, ls, nf, radiance, above, limit, k, s.pos[e], s.nrm[e], wp.sqrt(s.area[e]),
                               open_fraction[e])
    out[e] = light
    evaluations[k] = count


class Iteration:
    """One gather + push over the links of ``problem`` on its device."""

    def __init__(self, problem, links):
        self.problem, self.links = problem, links
        tree = problem.tree
        d = problem.device.name
        self.radiance = wp.empty(tree.count, dtype=wp.vec3, device=d)
        self.gathered = wp.empty(tree.count, dtype=wp.vec3, device=d)
        self.exitance = wp.empty(problem.elements.count, dtype=wp.vec3, device=d)

    def __call__(self, direct: wp.array, indirect: wp.array, out: wp.array) -> None:
        """out ← push(gather(pull(ρ ⊙ (direct + indirect)))) (vec3[n] device arrays)."""
        p = self.problem
        tree, dev = p.tree, p.device
        exitance(p, direct, indirect, self.exitance)
        node_means(tree, self.exitance, self.radiance)
        device_mod.launch(_gather_kernel, tree.count,
                          [self.links.set, self.radiance, self.gathered], dev)
        device_mod.launch(_push_kernel, int(tree.level_offsets[1]),
                          [tree.nodes, self.gathered, p.open_fraction, out], dev)

    def at_leaves(self, direct: wp.array, indirect: wp.array, out: wp.array) -> int:
        """out ← the same step with each link evaluated at every leaf below its receiver
        (``_leaf_gather_kernel``); returns the link evaluations made."""
        p = self.problem
        exitance(p, direct, indirect, self.exitance)
        return _leaf_gather(p, self.links, p.near, self.exitance, self.radiance, out)


def _above(problem, links, radiance: wp.array) -> wp.array:
    """vec3[m]: ``_above_kernel`` for the nodes' ``radiance`` (vec3[m]) over ``links``."""
    tree, dev = problem.tree, problem.device
    above = wp.empty(tree.count, dtype=wp.vec3, device=dev.name)
    device_mod.launch(_above_kernel, tree.count,
                      [tree.nodes, problem.surfels, links.set, radiance, float(LEAF_LIMIT), above], dev)
    return above


def _leaf_gather(problem, links, detail: Detail, exitance: wp.array, radiance: wp.array, out: wp.array) -> int:
    """out (vec3[n]) ← the leaf gather of ``exitance`` (vec3[n], ρ ⊙ lighting per element) over
    ``links`` with the near senders' ``detail``, ``radiance`` (vec3[m]) the node means it fills;
    returns the link evaluations."""
    tree, dev = problem.tree, problem.device
    n = problem.elements.count
    node_means(tree, exitance, radiance)
    evaluations = wp.empty(n, dtype=wp.int32, device=dev.name)
    # in waves: the near field's work gathers where shadows fall, in a few runs of the leaf order,
    # and one range per thread left one thread with most of it (measured: 1.7 CPU s in 1.4 s wall)
    device_mod.launch(_leaf_gather_kernel, n,
                      [tree.nodes, problem.surfels, links.set, detail, radiance, _above(problem, links, radiance),
                       float(LEAF_LIMIT), problem.open_fraction, out, evaluations], dev,
                      chunks=1 if dev.is_cuda else max(1, min(GATHER_WAVES, n // 1024)))
    return int(evaluations.numpy().astype(np.int64).sum())


def leaf_gather(problem, links, exitance: np.ndarray) -> np.ndarray:
    """float32[n,3]: the lighting (irradiance/π) each element receives over ``links`` from the
    elements' ``exitance`` (float32[n,3], the radiance ρ ⊙ lighting leaving their fronts), each
    link evaluated at the receiving element (what the solver's last step does, without the near
    senders' detail of the direct light: ``exitance`` is any)."""
    d = problem.device.name
    out = wp.empty(problem.elements.count, dtype=wp.vec3, device=d)
    _leaf_gather(problem, links, nearfield.empty(d),
                 wp.array(np.ascontiguousarray(exitance, np.float32), dtype=wp.vec3, device=d),
                 wp.empty(problem.tree.count, dtype=wp.vec3, device=d), out)
    return out.numpy()


def gather_rays(problem) -> int:
    """Rays per element of the final gather: the settings' ``gather_rays``, or more up to
    GATHER_BUDGET rays in all (at most GATHER_MOST each); halved until the hits fit half the
    ``link_memory`` budget (the links take the rest) and int32 rows, with a warning when that
    happens."""
    settings = problem.settings
    n = problem.elements.count
    rays = max(settings.gather_rays, min(GATHER_MOST, GATHER_BUDGET // max(n, 1)))
    budget = settings.link_memory * 2 ** 20 // 2
    fitting = rays
    while fitting > 1 and (hits_mod.bytes_needed(n, fitting) > budget or n * fitting > hits_mod.MOST_ROWS):
        fitting //= 2
    if fitting < rays:
        problem.stages.warn(f"the final gather's {rays} rays per element would take "
                            f"{hits_mod.bytes_needed(n, rays) / 2 ** 20:.0f} MB for {n} elements, "
                            f"over half the link memory budget: {fitting} rays instead")
    return fitting


def solve(problem) -> Solution:
    """Indirect lighting per element (float32[n,3], irradiance/π): iterations over the links until
    the largest change is below ``tolerance`` × the largest lighting value, or ``bounces``; then,
    with ``gather_rays``, sweeps over each element's rays' hits (``core.hits``) from there, until
    they converge as well."""
    rays = gather_rays(problem) if problem.settings.gather_rays else 0
    if rays:
        # traced before the links: its rays tell the open fraction the links weigh their samples
        # by, which ``enclosure`` would otherwise trace rays of its own for
        previous = problem.previous.cache.get("hits") if problem.previous is not None else None
        hits = problem.stages.run("gather rays", hits_mod.trace, problem, rays, previous)
        problem.open_fraction = hits.free
    links = links_of(problem)
    step = Iteration(problem, links)
    if rays:
        # the bounces are shared: the gather's sweeps make at least the last one, as the leaf
        # gather does without them; links that did not converge in theirs, or diverged (coarse
        # links carry more or less than the power they get: with albedo 1 in a closed box 9 %
        # more a bounce, measured), are no start, so the sweeps then make all the bounces
        bounces = problem.settings.bounces
        try:
            start, iterations, _, _ = iterate(problem, lambda d, i, o, k: step(d, i, o), bounces - 1)
        except BakeError:
            start, iterations = None, 0
        if iterations >= bounces - 1:
            start, iterations = None, 0
        sweep = hits_mod.Sweep(problem, hits)
        values, sweeps, _, _ = iterate(problem, lambda d, i, o, k: sweep(i, o), max(1, bounces - iterations),
                                       start=start)
        return Solution(values, {"iterations": iterations, "gather_sweeps": sweeps, "links": links.count,
                                 "link_threshold": links.threshold, "gather_rays": rays},
                        cache={"hits": hits})  # the next frame of an animation keeps what still holds
    # the last bounce is made at the elements themselves
    _, iterations, dev_direct, current = iterate(problem, lambda d, i, o, k: step(d, i, o),
                                               problem.settings.bounces - 1)
    nxt = wp.empty(problem.elements.count, dtype=wp.vec3, device=problem.device.name)
    evaluations = step.at_leaves(dev_direct, current, nxt)
    return Solution(nxt.numpy(), {"iterations": iterations + 1, "links": links.count,
                                  "link_threshold": links.threshold, "leaf_evaluations": evaluations})


@wp.func
def on_path(t: Nodes, leaf: int, x: int) -> int:
    """1 when node x lies on the path from ``leaf`` to the root, else 0."""
    y = leaf
    size = t.leaves[x]
    while y >= 0:
        if y == x:
            return 1
        y = path_up(t, y, size)
    return 0


@wp.kernel
def _texel_gather_kernel(offset: int, rp: wp.array(dtype=wp.vec3), rn: wp.array(dtype=wp.vec3),
                         rsize: wp.array(dtype=wp.float32), corners: wp.array2d(dtype=wp.int32),
                         weights: wp.array2d(dtype=wp.float32), leaf_of: wp.array(dtype=wp.int32), t: Nodes,
                         s: Surfels, ls: LinkSet, nf: Detail, sm: Sampling, radiance: wp.array(dtype=wp.vec3),
                         above: wp.array(dtype=wp.vec3), limit: float, rays: int, seed: int,
                         out: wp.array(dtype=wp.vec3), traced: wp.array(dtype=wp.int32)):
    """Receiver i (a texel): for each element it is reconstructed from (weights), what the links of
    that element's root path bring to the texel's point and normal — the links' transfer scaled
    by the sender's ``centroid_ff`` from the texel over the link's normaliser; the element's own
    links to leaves exactly, with a ray to each; links its rays found partly visible with the
    visible fraction of ``rays`` rays from the texel to points drawn on the sender by radiance;
    the share of receivers with more than ``limit`` leaves as they received it (``above``). The
    corners' paths meet a few levels up: a node on several is evaluated once, with their weights
    summed, by the first corner that reaches it."""
    i = wp.tid() + offset
    p = rp[i]
    n = rn[i]
    origin = lift(p, n, rsize[i])
    state = wp.rand_init(seed, i)
    acc = wp.vec3(0.0)
    count = int(0)
    for c in range(corners.shape[1]):
        w = weights[i, c]
        if w <= 0.0:
            continue
        k = leaf_of[corners[i, c]]
        x = k
        while x >= 0:
            shared = w
            for c2 in range(corners.shape[1]):
                w2 = weights[i, c2]
                if c2 != c and w2 > 0.0 and shared > 0.0:
                    if on_path(t, leaf_of[corners[i, c2]], x) != 0:
                        if c2 < c:
                            shared = 0.0  # done with the earlier corner
                        else:
                            shared += w2
            if shared <= 0.0:  # an earlier corner's path from here up
                break
            for j in range(ls.offsets[x], ls.offsets[x + 1]):
                b = ls.sender[j]
                glow = radiance[b]
                if glow[0] + glow[1] + glow[2] <= 0.0:
                    if t.descend[b] >= 0:
                        continue
                    if not varies(nf, t.element[b]):  # a dark leaf may still show lit points
                        continue
                f = float(0.0)
                if x == k and t.descend[b] < 0:
                    f = point_ff(s, p, n, t.element[b]) * visible(s.mesh, origin, leaf_point(t, s, b))
                    count += 1
                else:
                    f = transfer_at(t, s, ls, j, p, n, 1, 1)
                    seen = int(ls.visible[j])
                    if seen > 0 and seen < 255 and f > 0.0:
                        h = float(0.0)
                        for r in range(rays):
                            e = t.element[sample_leaf(t, sm, b, (float(r) + wp.randf(state)) / float(rays))]
                            q = fan_sample(s, e, wp.randf(state), wp.randf(state), wp.randf(state))
                            h += visible(s.mesh, origin, lift(q, s.nrm[e], wp.sqrt(s.area[e])))
                        f *= h / float(rays) * 255.0 / float(seen)  # the texel's visible fraction for the link's
                        count += rays
                acc += sent(nf, t, s, radiance, b, f, p, n, origin) * shared
            x = path_up(t, x, limit)
        acc += above[path_top(t, k, limit)] * w  # 0 at the root
    out[i] = acc
    traced[i] = count  # per texel: Warp's CPU atomics are not atomic across our threads


def texel_gather(problem, links, lighting: np.ndarray, receivers, progress=None):
    """(float32[R,3] indirect lighting, rays traced) at ``receivers`` (``core.receivers``) from the
    elements' reflected light ρ ⊙ ``lighting`` (float32[n,3], irradiance/π) over ``links``."""
    tree, dev, settings = problem.tree, problem.device, problem.settings
    d = dev.name
    count = len(receivers)
    exitance = (problem.elements.albedo * lighting).astype(np.float32)
    sm = links_mod.sampling(tree, links_mod.leaf_luminance(tree, exitance))
    leaf_of = np.empty(problem.elements.count, np.int32)
    leaf_of[tree.order.numpy()] = np.arange(problem.elements.count, dtype=np.int32)
    radiance = node_means(tree, exitance)
    out = wp.empty(count, dtype=wp.vec3, device=d)
    traced = wp.zeros(count, dtype=wp.int32, device=d)

    def arr(x, dtype):
        return wp.array(np.ascontiguousarray(x), dtype=dtype, device=d)

    device_mod.launch(
        _texel_gather_kernel, count,
        [arr(receivers.points.astype(np.float32), wp.vec3), arr(receivers.normals.astype(np.float32), wp.vec3),
         arr(receivers.sizes.astype(np.float32), wp.float32), arr(receivers.elements.astype(np.int32), wp.int32),
         arr(receivers.weights.astype(np.float32), wp.float32), arr(leaf_of, wp.int32), tree.nodes,
         problem.surfels, links.set, problem.near, sm, radiance, _above(problem, links, radiance),
         float(LEAF_LIMIT),
         int(settings.visibility_rays), int(settings.seed) + 104729, out, traced],
        dev, chunks=max(1, min(32, count // 4096)), on_chunk=progress)
    return out.numpy(), int(traced.numpy().sum(dtype=np.int64))


def evaluate(problem, solution: Solution, receivers) -> np.ndarray:
    """Indirect lighting at ``receivers``: the solution at the vertices; at other points (lightmap
    texels) as the reference evaluates them (``base.reconstruct_with_detail``: interpolated, plus
    the detail of the tree's final gather), or with ``texel_links`` the final gather over the links
    with rays from each texel."""
    settings = problem.settings
    if (receivers.aligned or settings.texel_indirect != "gather" or not settings.texel_links
            or not len(receivers)):
        return reconstruct_with_detail(problem, solution, receivers)
    stages = problem.stages
    light, rays = stages.run("texel gather", texel_gather, problem, links_of(problem),
                             problem.direct + solution.values, receivers, stages.reporter("texel gather"))
    problem.counts["rays"] += rays
    return light
