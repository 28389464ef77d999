"""Implicit visibility (Dong, Kautz, Theobalt, Seidel 2007; ALGORITHMS.md §5, §10): multi-bounce
indirect light over links made without rays, where per receiver and direction bin only the
nearest senders count — occluded senders drop out, so link creation is the only geometry work.

The links (``core.links`` with ``visibility=False, sides=2``: every pair whose faces see each
other, either way, refined by the oracle, with unoccluded transfers; the same links antiradiance
uses) are evaluated at each element over its root path — the links of every node above it, as
the hierarchical solver's last step does (``transfer_at``). Once per link build,
``path_weights`` computes per element and path link a weight: the transfer at the element from
the sender's front × the share of the sender's cone (``directions.cone_bin``: the solid angle
the sender's node subtends at the element, ``directions.cone_count`` directions) it keeps. Per
bin (one thread per element over its contiguous path links, a scratch row of its own: no
atomics), any sender with a transfer from either face competes:

- the nearest sender's layer — senders within LAYER × its distance (neighbours on one surface
  are side by side, not behind each other) — keeps its links;
- what lies farther keeps what the layer leaves of the bin's form factor
  (``directions.capacity``), shared in proportion: a small near element hides its own share of
  a bin, not the whole bin. With the nearest sender alone keeping the bin (the paper's rule),
  neighbours on one surface hide each other: an open box lost 57 % / 34 % / 16 % of its
  unoccluded light at 64 / 256 / 1024 bins.

Then Jacobi iterations, as the reference solver in lighting units (irradiance/π) with D the
direct lighting of ``core.direct``: each node's radiance is the area-weighted mean of ρ ⊙ (D + I)
over its leaves (none from a hidden element, ``directions.visible``: its point under a surface in
contact, as the Cornell box's ceiling 1 mm behind its light), and each element's indirect
lighting I the weighted sum over its path links of the senders' radiance, until the largest
change is below ``tolerance``, at most ``bounces``.

Known failure: an occluder less than LAYER times nearer than what it hides, and not in contact
with it, is taken for its neighbour and hides nothing (``tests/core/test_implicit.py`` measures
it).
"""
from __future__ import annotations

import time

import numpy as np
import warp as wp

from .. import device as device_mod
from .. import directions
from .. import links as links_mod
from ..errors import BakeError
from ..hierarchy import Nodes, node_means
from ..links import LinkSet
from ..rootpath import WHOLE, path_link_begin, path_link_next, path_up
from ..surfels import Surfels
from . import base
from .base import Solution, iterate, reconstruct_with_detail
from .hierarchical import transfer_at

wp.set_module_options({"enable_backward": False})  # no gradients: halves compile time

# Senders in a bin within this factor of the nearest one's distance are its layer: they keep
# their links (neighbours on one surface are side by side, not behind each other).
LAYER = 2.0
# Elements whose scratch rows (bins × 12 bytes each) are held at once while the path weights are
# made: 4 096 × 1024 bins is 48 MB.
SCRATCH_ROWS = 4096


def oracle(settings) -> links_mod.Oracle:
    """The links implicit visibility and antiradiance share: the settings' threshold, sample pairs
    and budget, no visibility, both faces (an occluder may show either face; antiradiance leaves
    by the back), geometric — antiradiance's senders send what their directional tables show,
    which already weighs each leaf by its projected area, so a brightness-weighted transfer would
    count bright leaves twice."""
    return links_mod.Oracle(threshold=float(settings.link_threshold), rays=int(settings.visibility_rays),
                            visibility=False, seed=int(settings.seed), budget=int(settings.link_memory) << 20,
                            sides=2)


def links_of(problem):
    """The problem's unoccluded links (built once, cached on the problem)."""
    return problem.links(oracle(problem.settings))


def bins_of(settings) -> int:
    """The directional bin count the settings ask for (64, 256 or 1024)."""
    bins = int(settings.directional_bins)
    directions.side(bins)
    return bins


@wp.struct
class Paths:
    """Each element's root-path links as evaluated at the element: offsets int32[n+1] (leaf k's
    path links are offsets[k] … offsets[k+1]−1, in root-path order: its own links, then its
    parent's …); weight float32[P] what a unit radiance of the link's sender gives the element
    (lighting, irradiance/π)."""

    offsets: wp.array(dtype=wp.int32)
    weight: wp.array(dtype=wp.float32)


@wp.kernel
def _path_count_kernel(offset: int, t: Nodes, ls: LinkSet, counts: wp.array(dtype=wp.int32)):
    """Leaf k: the links of the nodes on its root path."""
    k = wp.tid() + offset
    c = int(0)
    x = k
    while x >= 0:
        c += ls.offsets[x + 1] - ls.offsets[x]
        x = path_up(t, x, WHOLE)
    counts[k] = c


@wp.func
def _cone_of(t: Nodes, b: int, p: wp.vec3):
    """(unit direction, distance, solid angle) of node b's centre seen from p."""
    d = t.position[b] - p
    dist = wp.length(d)
    u = wp.vec3(0.0, 0.0, 1.0)
    if dist > 0.0:
        u = d / dist
    return u, dist, directions.subtended(p, t.position[b], t.normal[b], t.area[b], t.spread[b])


@wp.func
def _front_samples(count: int, n: wp.vec3, u: wp.vec3, omega: float, size: int) -> int:
    """How many of a cone's ``count`` directions fall in front bins (``directions.cone_bin``)."""
    seen = int(0)
    for c in range(count):
        if directions.front(directions.cone_bin(c, count, n, u, omega, size, 0.0), size):
            seen += 1
    return seen


@wp.kernel
def _path_kernel(offset: int, t: Nodes, s: Surfels, ls: LinkSet, sides: int, nearest_on: int, size: int,
                 capacity: wp.array(dtype=wp.float32), bin_omega: float, rows: int, scratch: wp.array(dtype=wp.vec3), out: Paths):
    """Leaf k: the weight of each of its path links (see the module docstring): the transfer at
    the element from the sender's front (``sides`` 1) or both faces (2), each link scaled to the
    element; with ``nearest_on`` 0 that alone (antiradiance). Any link with a transfer from
    either face competes for the bins. ``scratch`` holds ``rows``
    rows of size² bins — (nearest distance, transfer of the nearest layer, of what is behind) —
    leaf k using row k % rows (a launch wave covers at most ``rows`` leaves)."""
    k = wp.tid() + offset
    e = t.element[k]
    p = s.pos[e]
    n = s.nrm[e]
    bins = size * size
    row = (k % rows) * bins
    if nearest_on != 0:
        for b in range(bins):
            scratch[row + b] = wp.vec3(1.0e30, 0.0, 0.0)
        for step in range(2):  # the nearest per bin, then the transfer of its layer and behind it
            walk = path_link_begin(t, ls, k, WHOLE)
            while walk.node >= 0:
                j = walk.link
                f = transfer_at(t, s, ls, j, p, n, 1, 2)
                u, dist, omega = _cone_of(t, ls.sender[j], p)
                count = directions.cone_count(omega, bin_omega)
                seen = _front_samples(count, n, u, omega, size)
                if f > 0.0 and seen > 0:
                    part = f / float(seen)
                    for c in range(count):
                        b = directions.cone_bin(c, count, n, u, omega, size, 0.0)
                        v = scratch[row + b]
                        if step == 0:
                            v = wp.vec3(wp.min(v[0], dist), 0.0, 0.0)
                        elif dist <= v[0] * LAYER:
                            v = wp.vec3(v[0], v[1] + part, v[2])
                        else:
                            v = wp.vec3(v[0], v[1], v[2] + part)
                        scratch[row + b] = v
                walk = path_link_next(t, ls, walk)
    i = out.offsets[k]
    walk = path_link_begin(t, ls, k, WHOLE)
    while walk.node >= 0:
        j = walk.link
        # a leaf's own links hold their transfer at it, from both faces: kept as they are for
        # both faces, scaled to the front otherwise
        f = transfer_at(t, s, ls, j, p, n, int(walk.node != k or sides == 1), sides)
        if nearest_on != 0 and f > 0.0:
            u, dist, omega = _cone_of(t, ls.sender[j], p)
            count = directions.cone_count(omega, bin_omega)
            seen = _front_samples(count, n, u, omega, size)
            won = float(0.0)
            for c in range(count):
                b = directions.cone_bin(c, count, n, u, omega, size, 0.0)
                v = scratch[row + b]
                if directions.front(b, size):
                    if dist <= v[0] * LAYER:
                        won += 1.0
                    elif v[2] > 0.0:  # behind the nearest layer: what the layer leaves of the bin
                        won += wp.min(v[2], wp.max(capacity[b] - v[1], 0.0)) / v[2]
            if seen > 0:
                f *= won / float(seen)
        out.weight[i] = wp.max(f, 0.0)
        i += 1
        walk = path_link_next(t, ls, walk)


def path_weights(problem, links, sides: int, bins: int = 0) -> Paths:
    """The ``Paths`` of ``links`` at every element: with ``bins`` (64, 256, 1024) each link's
    transfer × the share of its sender's cone it wins (implicit visibility), with 0 the transfer
    alone; made once per link build and kept with the links."""
    key = ("paths", sides, bins)
    if key in links.derived:
        return links.derived[key]
    tree, dev = problem.tree, problem.device
    d = dev.name
    n = problem.elements.count
    counts = wp.empty(n, dtype=wp.int32, device=d)
    device_mod.launch(_path_count_kernel, n, [tree.nodes, links.set, counts], dev)
    host = counts.numpy().astype(np.int64)
    offsets = np.concatenate([[0], np.cumsum(host)])
    if offsets[-1] >= 2**31:
        raise BakeError(f"{offsets[-1]} path links of {n} elements exceed 2^31: raise --link-threshold")
    out = Paths()
    out.offsets = wp.array(offsets.astype(np.int32), dtype=wp.int32, device=d)
    out.weight = wp.empty(max(int(offsets[-1]), 1), dtype=wp.float32, device=d)
    size = directions.side(bins) if bins else 1
    rows = min(n, SCRATCH_ROWS) if bins else 1
    scratch = wp.empty(rows * size * size, dtype=wp.vec3, device=d)
    cap = directions.capacity(bins, dev) if bins else wp.zeros(1, dtype=wp.float32, device=d)
    device_mod.launch(_path_kernel, n, [tree.nodes, problem.surfels, links.set, sides, int(bins > 0), size,
                                        cap, directions.solid_angle(bins) if bins else 1.0, rows, scratch, out],
                      dev, chunks=-(-n // rows),
                      on_chunk=lambda f: problem.stages.check())
    links.derived[key] = out
    return out


@wp.kernel
def _sent_kernel(offset: int, ls: LinkSet, radiance: wp.array(dtype=wp.vec3), sent: wp.array(dtype=wp.vec3)):
    """Directed link j: its sender's radiance."""
    j = wp.tid() + offset
    sent[j] = radiance[ls.sender[j]]


@wp.kernel
def _path_gather_kernel(offset: int, t: Nodes, ls: LinkSet, paths: Paths, sent: wp.array(dtype=wp.vec3),
                        out: wp.array(dtype=wp.vec3)):
    """Leaf k's element: Σ over its path links of weight × what the link's sender sends it."""
    k = wp.tid() + offset
    acc = wp.vec3(0.0)
    i = paths.offsets[k]
    walk = path_link_begin(t, ls, k, WHOLE)
    while walk.node >= 0:
        acc += sent[walk.link] * paths.weight[i]
        i += 1
        walk = path_link_next(t, ls, walk)
    out[t.element[k]] = acc


def path_gather(problem, links, paths: Paths, sent: wp.array, out: wp.array) -> None:
    """out (vec3[n]) ← each element's lighting over its path links, ``sent`` (vec3[E]) what each
    directed link's sender sends along it (radiance; one launch)."""
    device_mod.launch(_path_gather_kernel, problem.elements.count,
                      [problem.tree.nodes, links.set, paths, sent, out], problem.device)


def solve(problem) -> Solution:
    """Indirect lighting per element (float32[n,3], irradiance/π): Jacobi iterations over the
    surviving links until the largest change is below ``tolerance``, at most ``bounces``."""
    settings = problem.settings
    bins = bins_of(settings)
    problem.direct  # noqa: B018  (traced before the links, as the stages report it)
    links = links_of(problem)
    paths = problem.stages.run("direction masks", path_weights, problem, links, 1, bins)
    problem.stages.run("direction masks", directions.visible, problem, links)
    tree, dev = problem.tree, problem.device
    d = dev.name
    n = problem.elements.count
    exitance = wp.empty(n, dtype=wp.vec3, device=d)
    radiance = wp.empty(tree.count, dtype=wp.vec3, device=d)
    sent = wp.empty(max(links.count, 1), dtype=wp.vec3, device=d)

    def sweep(direct, current, out, k):
        base.exitance(problem, direct, current, exitance)
        directions.hide(problem, links, exitance)
        node_means(tree, exitance, radiance)
        device_mod.launch(_sent_kernel, links.count, [links.set, radiance, sent], dev)
        path_gather(problem, links, paths, sent, out)

    changes = []
    t0 = time.perf_counter()
    values, iterations, _, _ = iterate(problem, sweep, settings.bounces, changes)
    return Solution(values, {"iterations": iterations, "links": links.count, "link_threshold": links.threshold,
                             "directional_bins": bins, "path_links": int(paths.offsets.numpy()[-1]),
                             "changes": changes,
                             "seconds_per_iteration": (time.perf_counter() - t0) / max(iterations, 1)})


def evaluate(problem, solution: Solution, receivers) -> np.ndarray:
    """Indirect lighting at ``receivers``: the solution at the vertices; at other points (lightmap
    texels) interpolated, plus the detail of the tree's final gather (``texel_indirect``)."""
    return reconstruct_with_detail(problem, solution, receivers)
