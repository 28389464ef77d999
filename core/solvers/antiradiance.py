"""Antiradiance (Dachsbacher, Stamminger, Drettakis, Durand 2007; ALGORITHMS.md §6, §10):
multi-bounce indirect light with no visibility at all — light goes through every surface, and
each surface sends what arrives at it on through its other face as antiradiance A, in the same
direction, which cancels the light that should not have got through.

Fixed point, from A = 0: L⁽ⁱ⁺¹⁾ = E + K U(L⁽ⁱ⁾ − A⁽ⁱ⁾), A⁽ⁱ⁺¹⁾ = J U(L⁽ⁱ⁾ − A⁽ⁱ⁾), with E = ρ ⊙ D
(D the direct lighting of ``core.direct``, already shadowed by rays, as the reference and the
hierarchical solvers inject it), U unoccluded transport over the links (``core.links`` with
``visibility=False, sides=2``: pairs linked whichever faces they show, transfers from both faces
of the sender), K diffuse reflection and J pass-through. What is propagated is L − A, signed.

Each leaf and each inner node with links (``rows``: one-child cells repeat their child and have
none, and no one reads the others') holds a directional table ``[rows × bins]`` (vec3,
``core.directions``' bins in the node's frame) of what it shows: a leaf's holds −A (A per bin,
in its propagation direction; what arrived at the front leaves by the back half, what arrived at
the back — a one-sided emitter's back lit by the ceiling 1 mm above it — by the front half) and
it shows its radiance L = ρ ⊙ (D + I), isotropic (diffuse), in its front bins besides, unless it
is hidden (``directions.visible``: its element point under a surface in contact, as that
ceiling's cells over the emitter — antiradiance from 1 mm away, cancelling their light, leaked
round the emitter's rim); an inner node's bin is the mean over its leaves, weighted by their
projected area |cos| in the bin's centre direction, of what each shows that way. One iteration
(a launch each):

- pull: the inner nodes' tables from their leaves;
- U (global pass, one thread per receiver node over its CSR links, no atomics): each link's
  signed radiance is the mean of what the sender shows over the bins of the cone the receiver
  subtends at it (``directions.Masks``, box-filtered, made once per link build); it lands in the
  receiver's table of incoming radiance, spread over the bins of the cone the sender subtends
  there (widened by ``directions.COVER``; near and in contact, see ``directions``), with the
  bins' net coverage (the radiance × the link's ``gain``: leaves in contact carry all the light
  the one stops of the other's);
- K: each element's indirect lighting I is its root-path links' unoccluded transfer at the
  element (``implicit.path_weights`` without the nearest filter) × their signed radiance;
- J (local pass): each leaf bin ← −(the radiance arriving from the opposite direction), summed
  over the nodes with links on its root path (their tables read at the bin's centre direction)
  and divided by the net coverage where that exceeds 1 (round cones overlap).

Iterations start from A = 0 and the indirect light 0, or in an animation from the previous
frame's (its leaves' tables and its solution: the refitted tree keeps its leaves), and stop when
the largest change of I is below ``tolerance`` × the largest lighting value, at most
``bounces``; each iteration's change is kept (``counts["changes"]``). Values stay signed
(``cache["signed"]``); the solution, which is output, is clamped at 0. The tables take rows ×
bins × 28 bytes (``table_bytes``, ``counts["table_bytes"]``; a warning before the solve above
TABLE_WARN), float32: tables rounded to half precision after every pass measured the same errors
(docs/antiradiance.md), but the incoming table accumulates every link's deposit and would accumulate in half;
kept float32.
"""
from __future__ import annotations

import time

import numpy as np
import warp as wp

from .. import device as device_mod
from .. import directions
from .. import links as links_mod
from ..directions import Masks
from ..hierarchy import Nodes
from ..links import LinkSet
from ..rootpath import WHOLE, path_up
from . import base
from .base import Solution, iterate, reconstruct_with_detail
from .implicit import bins_of, links_of, path_gather, path_weights

wp.set_module_options({"enable_backward": False})  # no gradients: halves compile time

# Table memory (bytes) above which the bake warns (and says what fewer bins would take).
TABLE_WARN = 2 << 30
# Iterations whose changes may grow without damping (``relaxation``), and the smallest step.
GROWTH_FROM = 3
MIN_RELAX = 0.125


@wp.func
def shown(t: Nodes, row: wp.array(dtype=wp.int32), table: wp.array(dtype=wp.vec3), exitance: wp.array(dtype=wp.vec3),
          node: int, b: int, size: int) -> wp.vec3:
    """The signed radiance node ``node`` shows in its bin b: its table's value (−A for a leaf; its
    row ``row[node]``), plus a leaf's radiance ρ ⊙ (D + I) (``exitance``, per element) in its
    front bins."""
    v = table[row[node] * size * size + b]
    if t.descend[node] < 0 and directions.front(b, size):
        v += exitance[t.element[node]]
    return v


@wp.kernel
def _pull_kernel(offset: int, linked: wp.array(dtype=wp.int32), n: int, t: Nodes, row: wp.array(dtype=wp.int32),
                 first_leaf: wp.array(dtype=wp.int32), size: int, exitance: wp.array(dtype=wp.vec3),
                 table: wp.array(dtype=wp.vec3)):
    """Bin i of the inner nodes with links (``linked`` after its n leaves; their rows follow the
    leaves'): the |cos|-weighted mean of what the node's leaves show in the bin's centre
    direction."""
    i = wp.tid() + offset
    bins = size * size
    x = linked[n + i // bins]
    w = directions.to_world(t.normal[x], directions.bin_dir(i % bins, size))
    acc = wp.vec3(0.0)
    total = float(0.0)
    lo = first_leaf[x]
    for leaf in range(lo, lo + int(t.leaves[x] + 0.5)):
        normal = t.normal[leaf]
        weight = t.area[leaf] * wp.abs(wp.dot(normal, w))
        acc += shown(t, row, table, exitance, leaf, directions.bin_of(directions.frame_dir(normal, w), size),
                     size) * weight
        total += weight
    out = wp.vec3(0.0)
    if total > 0.0:
        out = acc / total
    table[n * bins + i] = out


@wp.kernel
def _transport_kernel(offset: int, linked: wp.array(dtype=wp.int32), t: Nodes, row: wp.array(dtype=wp.int32),
                      ls: LinkSet, masks: Masks, size: int, bin_omega: float, exitance: wp.array(dtype=wp.vec3),
                      table: wp.array(dtype=wp.vec3), sent: wp.array(dtype=wp.vec3),
                      incoming: wp.array(dtype=wp.vec3), coverage: wp.array(dtype=wp.float32)):
    """U at receiver node x (row r of ``linked``): each link's signed radiance (``sent``) and the
    radiance arriving per bin at either face of x (its row of ``incoming``), and the bin's net
    coverage (its row of ``coverage``: senders showing their fronts count +1, their backs −1 —
    the way out of a closed object — by the share of the bin their cones cover)."""
    r = wp.tid() + offset
    x = linked[r]
    bins = size * size
    row_x = r * bins
    for b in range(bins):
        incoming[row_x + b] = wp.vec3(0.0)
        coverage[row_x + b] = 0.0
    for j in range(ls.offsets[x], ls.offsets[x + 1]):
        sender = ls.sender[j]
        v = wp.vec3(0.0)
        lo = masks.send_offsets[j]
        hi = masks.send_offsets[j + 1]
        for k in range(lo, hi):
            v += shown(t, row, table, exitance, sender, int(masks.send[k]), size)
        v /= float(hi - lo)
        sent[j] = v
        lo = masks.receive_offsets[j]
        hi = masks.receive_offsets[j + 1]
        share = masks.omega[j] / (float(hi - lo) * bin_omega)
        facing = t.spread[sender] * wp.sign(wp.dot(t.normal[sender], t.position[x] - t.position[sender]))
        for k in range(lo, hi):
            b = row_x + int(masks.receive[k])
            incoming[b] = incoming[b] + v * (share * masks.gain[j])
            coverage[b] = coverage[b] + facing * share


@wp.kernel
def _through_kernel(offset: int, t: Nodes, row: wp.array(dtype=wp.int32), size: int,
                    incoming: wp.array(dtype=wp.vec3), coverage: wp.array(dtype=wp.float32),
                    relax: float, table: wp.array(dtype=wp.vec3)):
    """J at leaf bin i: −(the radiance arriving from the opposite direction, at either face),
    from the incoming tables of the nodes with links on the leaf's root path. The senders'
    cones, round where the nodes are not, overlap each other in places: where the net coverage
    exceeds 1 it divides."""
    i = wp.tid() + offset
    bins = size * size
    k = i // bins
    arrival = -directions.to_world(t.normal[k], directions.bin_dir(i % bins, size))
    acc = wp.vec3(0.0)
    covered = float(0.0)
    x = k
    while x >= 0:
        if row[x] >= 0:
            b = row[x] * bins + directions.bin_of(directions.frame_dir(t.normal[x], arrival), size)
            acc += incoming[b]
            covered += coverage[b]
        x = path_up(t, x, WHOLE)
    table[i] = table[i] + (-acc / wp.max(covered, 1.0) - table[i]) * relax


@wp.kernel
def _relax_kernel(offset: int, current: wp.array(dtype=wp.vec3), relax: float, out: wp.array(dtype=wp.vec3)):
    """out ← current + relax × (out − current): a damped step of the indirect light."""
    e = wp.tid() + offset
    out[e] = current[e] + (out[e] - current[e]) * relax


def relaxation(changes: list, relax: float, since: int) -> tuple[float, int]:
    """(the step for the next iteration, the iteration from which growth counts): ``relax``
    halved (to at least MIN_RELAX) when the relative changes so far (``changes``) grew twice in a
    row after ``since``, else kept. The first iterations' changes are large by design (unoccluded
    light, then its cancellation); sustained growth is the iteration's oscillating mode — the
    antiradiance of nearly parallel surfaces close together over-cancelling, each iteration the
    opposite sign and larger (× 1.2 in the furnished room of ``bench/rooms.py``, 15 cm between a
    wall and the sofa's back) — which a damped step (same fixed point) turns into a converging
    one."""
    k = len(changes)
    if k >= max(since, GROWTH_FROM) + 3 and changes[-1] > changes[-2] > changes[-3] and relax > MIN_RELAX:
        return relax * 0.5, k
    return relax, since


def table_bytes(nodes: int, bins: int) -> int:
    """Bytes of the directional tables of ``nodes`` nodes at ``bins`` bins: what each shows and
    what arrives at it (float32 RGB each) and the arrivals' coverage (float32)."""
    return nodes * bins * (2 * 3 * 4 + 4)


def check(problem) -> list[str]:
    """A warning before the solve when the tables could be large: every tree node's, before the
    links say which nodes have any."""
    bins = bins_of(problem.settings)
    nodes = problem.tree.count
    need = table_bytes(nodes, bins)
    if need < TABLE_WARN:
        return []
    return [f"antiradiance tables of {problem.elements.count} elements ({nodes} tree nodes) at {bins} bins "
            f"take up to {need / 2**30:.1f} GiB; --directional-bins 64 takes up to "
            f"{table_bytes(nodes, 64) / 2**30:.2f} GiB"]


def rows(problem, links) -> tuple[wp.array, wp.array]:
    """(int32[m] each tree node's row in the tables, −1 for a node without links; int32[k] the
    k nodes with rows, in row order): the leaves (rows 0 … n−1, all of them: J writes theirs) and
    the inner nodes with links — one in eight or fewer (one-child cells repeat their child and
    get none). Nothing reads the tables of the others."""
    n, m = problem.elements.count, problem.tree.count
    offsets = links.set.offsets.numpy()
    has = np.diff(offsets) > 0
    has[links.set.sender.numpy()[:offsets[-1]]] = True  # (links go both ways: senders receive too)
    has[:n] = True
    linked = np.flatnonzero(has).astype(np.int32)
    row = np.full(m, -1, np.int32)
    row[linked] = np.arange(linked.size, dtype=np.int32)
    d = problem.device.name
    return wp.array(row, dtype=wp.int32, device=d), wp.array(linked, dtype=wp.int32, device=d)


def solve(problem) -> Solution:
    """Indirect lighting per element (float32[n,3], irradiance/π, clamped at 0; signed in
    ``cache["signed"]``): iterations of U, K and J until the largest change is below
    ``tolerance`` × the largest lighting value, at most ``bounces``."""
    settings = problem.settings
    bins = bins_of(settings)
    size = directions.side(bins)
    problem.direct  # noqa: B018  (traced before the links, as the stages report it)
    links = links_of(problem)
    stages = problem.stages
    masks = stages.run("direction masks", directions.masks, problem, links, bins)
    paths = stages.run("direction masks", path_weights, problem, links, 2)
    stages.run("direction masks", directions.visible, problem, links)
    tree, dev = problem.tree, problem.device
    d = dev.name
    n = problem.elements.count
    row, linked = rows(problem, links)
    rowed = linked.size
    table = wp.zeros(rowed * bins, dtype=wp.vec3, device=d)
    before = problem.previous.cache.get("table") if problem.previous is not None else None
    if before is not None and before.shape[0] >= n * bins:
        # an animation's previous frame: its leaves' antiradiance (leaf rows are the refitted
        # tree's leaves, the same elements) is where this frame's starts
        wp.copy(table, before, count=n * bins)
    incoming = wp.zeros(rowed * bins, dtype=wp.vec3, device=d)
    sent = wp.zeros(max(links.count, 1), dtype=wp.vec3, device=d)
    exitance = wp.empty(n, dtype=wp.vec3, device=d)
    coverage = wp.empty(rowed * bins, dtype=wp.float32, device=d)
    first_leaf = links_mod.sampling(tree).first_leaf
    bin_omega = directions.solid_angle(bins)
    changes = []
    step = {"relax": 1.0, "since": 0}

    def sweep(direct, current, out, k):
        step["relax"], step["since"] = relaxation(changes, step["relax"], step["since"])
        relax = step["relax"]
        base.exitance(problem, direct, current, exitance)
        directions.hide(problem, links, exitance)
        device_mod.launch(_pull_kernel, (rowed - n) * bins, [linked, n, tree.nodes, row, first_leaf, size, exitance,
                                                        table], dev)
        device_mod.launch(_transport_kernel, rowed, [linked, tree.nodes, row, links.set, masks, size, bin_omega,
                                                 exitance, table, sent, incoming, coverage], dev)
        path_gather(problem, links, paths, sent, out)
        if relax < 1.0:
            device_mod.launch(_relax_kernel, n, [current, relax, out], dev)
        device_mod.launch(_through_kernel, n * bins, [tree.nodes, row, size, incoming, coverage, relax, table],
                          dev)

    t0 = time.perf_counter()
    signed, iterations, _, _ = iterate(problem, sweep, settings.bounces, changes)
    seconds = (time.perf_counter() - t0) / max(iterations, 1)
    memory = table_bytes(rowed, bins)
    return Solution(np.maximum(signed, 0.0), {
        "iterations": iterations, "links": links.count, "link_threshold": links.threshold,
        "directional_bins": bins, "table_bytes": memory, "table_nodes": rowed, "changes": changes, "seconds_per_iteration": seconds,
        "negative_elements": int((signed < 0).any(axis=1).sum()), "relaxation": step["relax"]}, cache={"signed": signed, "table": table})


def evaluate(problem, solution: Solution, receivers) -> np.ndarray:
    """Indirect lighting at ``receivers``: the solution at the vertices; at other points (lightmap
    texels) interpolated, plus the detail of the tree's final gather (``texel_indirect``)."""
    return reconstruct_with_detail(problem, solution, receivers)
