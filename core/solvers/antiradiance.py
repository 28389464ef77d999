"""Antiradiance (Dachsbacher, Stamminger, Drettakis, Durand 2007; ALGORITHMS.md §6, §10):
multi-bounce indirect light with no visibility at all — light goes through every surface, and
each surface sends what arrives at it on through its other face as antiradiance A, in the same
direction, which cancels the light that should not have got through.

Fixed point, from A = 0: L⁽ⁱ⁺¹⁾ = E + K U(L⁽ⁱ⁾ − A⁽ⁱ⁾), A⁽ⁱ⁺¹⁾ = J U(L⁽ⁱ⁾ − A⁽ⁱ⁾), with E = ρ ⊙ D
(D the direct lighting of ``core.direct``, already shadowed by rays, as the reference and the
hierarchical solvers inject it), U unoccluded transport over the links (``core.links`` with
``visibility=False, sides=2``: pairs linked whichever faces they show, transfers from both faces
of the sender), K diffuse reflection and J pass-through. What is propagated is L − A, signed.

Each tree node holds a directional table ``[nodes × bins]`` (vec3, ``core.directions``' bins in
the node's frame) of what it shows: a leaf's holds −A (A per bin, in its propagation direction;
what arrived at the front leaves by the back half, what arrived at the back — a one-sided
emitter's back lit by the ceiling 1 mm above it — by the front half) and it shows its radiance
L = ρ ⊙ (D + I), isotropic (diffuse), in its front bins besides, unless it is hidden
(``directions.visible``: its element point under a surface in contact, as that ceiling's cells
over the emitter — antiradiance from 1 mm away, cancelling their light, leaked round the
emitter's rim); an inner node's bin is the mean
over its leaves, weighted by their projected area |cos| in the bin's centre direction, of what
each shows that way. One iteration (a launch each):

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
  over its root path (ancestors' tables read at the bin's centre direction) and divided by the
  net coverage where that exceeds 1 (round cones overlap).

Iterations stop when the largest change of I is below ``tolerance`` × the largest lighting value,
at most ``bounces``; each iteration's change is kept (``counts["changes"]``). Values stay signed
(``cache["signed"]``); the solution, which is output, is clamped at 0. The tables take
nodes × bins × 28 bytes (``table_bytes``, ``counts["table_bytes"]``; a warning before the solve
above TABLE_WARN), float32: tables rounded to half precision after every pass measured the same
errors (README), but the incoming table accumulates every link's deposit and would accumulate in
half; kept float32.
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
from . import base
from .base import Solution, iterate, reconstruct_with_detail
from .implicit import bins_of, links_of, path_gather, path_weights

wp.set_module_options({"enable_backward": False})  # no gradients: halves compile time

# Table memory (bytes) above which the bake warns (and says what fewer bins would take).
TABLE_WARN = 2 << 30


@wp.func
def shown(t: Nodes, table: wp.array(dtype=wp.vec3), exitance: wp.array(dtype=wp.vec3), node: int, b: int,
          size: int) -> wp.vec3:
    """The signed radiance node ``node`` shows in its bin b: its table's value (−A for a leaf),
    plus a leaf's radiance ρ ⊙ (D + I) (``exitance``, per element) in its front bins."""
    v = table[node * size * size + b]
    if t.descend[node] < 0 and directions.front(b, size):
        v += exitance[t.element[node]]
    return v


@wp.kernel
def _pull_kernel(offset: int, node0: int, t: Nodes, first_leaf: wp.array(dtype=wp.int32), size: int,
                 exitance: wp.array(dtype=wp.vec3), table: wp.array(dtype=wp.vec3)):
    """Inner node bin i: the |cos|-weighted mean of what the node's leaves show in the bin's
    centre direction."""
    i = wp.tid() + offset
    bins = size * size
    x = node0 + i // bins
    w = directions.to_world(t.normal[x], directions.bin_dir(i % bins, size))
    acc = wp.vec3(0.0)
    total = float(0.0)
    lo = first_leaf[x]
    for leaf in range(lo, lo + int(t.leaves[x] + 0.5)):
        n = t.normal[leaf]
        weight = t.area[leaf] * wp.abs(wp.dot(n, w))
        acc += shown(t, table, exitance, leaf, directions.bin_of(directions.frame_dir(n, w), size), size) * weight
        total += weight
    out = wp.vec3(0.0)
    if total > 0.0:
        out = acc / total
    table[node0 * bins + i] = out


@wp.kernel
def _transport_kernel(offset: int, t: Nodes, ls: LinkSet, masks: Masks, size: int, bin_omega: float,
                      exitance: wp.array(dtype=wp.vec3), table: wp.array(dtype=wp.vec3),
                      sent: wp.array(dtype=wp.vec3), incoming: wp.array(dtype=wp.vec3),
                      coverage: wp.array(dtype=wp.float32)):
    """U at receiver node x: each link's signed radiance (``sent``) and the radiance arriving per
    bin at either face of x (its own row of ``incoming``), and the bin's net coverage (its own row
    of ``coverage``: senders showing their fronts count +1, their backs −1 — the way out of a
    closed object — by the share of the bin their cones cover)."""
    x = wp.tid() + offset
    bins = size * size
    row = x * bins
    for b in range(bins):
        incoming[row + b] = wp.vec3(0.0)
        coverage[row + b] = 0.0
    for j in range(ls.offsets[x], ls.offsets[x + 1]):
        sender = ls.sender[j]
        v = wp.vec3(0.0)
        lo = masks.send_offsets[j]
        hi = masks.send_offsets[j + 1]
        for k in range(lo, hi):
            v += shown(t, table, exitance, sender, int(masks.send[k]), size)
        v /= float(hi - lo)
        sent[j] = v
        lo = masks.receive_offsets[j]
        hi = masks.receive_offsets[j + 1]
        share = masks.omega[j] / (float(hi - lo) * bin_omega)
        facing = t.spread[sender] * wp.sign(wp.dot(t.normal[sender], t.position[x] - t.position[sender]))
        for k in range(lo, hi):
            b = row + int(masks.receive[k])
            incoming[b] = incoming[b] + v * (share * masks.gain[j])
            coverage[b] = coverage[b] + facing * share


@wp.kernel
def _through_kernel(offset: int, t: Nodes, size: int, incoming: wp.array(dtype=wp.vec3),
                    coverage: wp.array(dtype=wp.float32), table: wp.array(dtype=wp.vec3)):
    """J at leaf bin i: −(the radiance arriving from the opposite direction, at either face),
    from the incoming tables of the leaf's root path. The senders' cones, round where the nodes
    are not, overlap each other in places: where the net coverage exceeds 1 it divides."""
    i = wp.tid() + offset
    bins = size * size
    k = i // bins
    arrival = -directions.to_world(t.normal[k], directions.bin_dir(i % bins, size))
    acc = wp.vec3(0.0)
    covered = float(0.0)
    x = k
    while x >= 0:
        b = x * bins + directions.bin_of(directions.frame_dir(t.normal[x], arrival), size)
        acc += incoming[b]
        covered += coverage[b]
        x = t.parent[x]
    table[i] = -acc / wp.max(covered, 1.0)


def table_bytes(nodes: int, bins: int) -> int:
    """Bytes of the directional tables of ``nodes`` nodes at ``bins`` bins: what each shows and
    what arrives at it (float32 RGB each) and the arrivals' coverage (float32)."""
    return nodes * bins * (2 * 3 * 4 + 4)


def check(problem) -> list[str]:
    """A warning before the solve when the tables would be large."""
    bins = bins_of(problem.settings)
    nodes = problem.tree.count
    need = table_bytes(nodes, bins)
    if need < TABLE_WARN:
        return []
    return [f"antiradiance tables of {problem.elements.count} elements ({nodes} tree nodes) at {bins} bins "
            f"take {need / 2**30:.1f} GiB; --directional-bins 64 takes {table_bytes(nodes, 64) / 2**30:.2f} GiB"]


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
    n, m = problem.elements.count, tree.count
    table = wp.zeros(m * bins, dtype=wp.vec3, device=d)
    incoming = wp.zeros(m * bins, dtype=wp.vec3, device=d)
    sent = wp.zeros(max(links.count, 1), dtype=wp.vec3, device=d)
    exitance = wp.empty(n, dtype=wp.vec3, device=d)
    coverage = wp.empty(m * bins, dtype=wp.float32, device=d)
    first_leaf = links_mod.sampling(tree).first_leaf
    inner = m - n
    bin_omega = directions.solid_angle(bins)

    def sweep(direct, current, out, k):
        base.exitance(problem, direct, current, exitance)
        directions.hide(problem, links, exitance)
        device_mod.launch(_pull_kernel, inner * bins, [n, tree.nodes, first_leaf, size, exitance, table], dev)
        device_mod.launch(_transport_kernel, m, [tree.nodes, links.set, masks, size, bin_omega, exitance, table,
                                                 sent, incoming, coverage], dev)
        path_gather(problem, links, paths, sent, out)
        device_mod.launch(_through_kernel, n * bins, [tree.nodes, size, incoming, coverage, table], dev)

    changes = []
    t0 = time.perf_counter()
    signed, iterations, _, _ = iterate(problem, sweep, settings.bounces, changes)
    seconds = (time.perf_counter() - t0) / max(iterations, 1)
    memory = table_bytes(m, bins)
    return Solution(np.maximum(signed, 0.0), {
        "iterations": iterations, "links": links.count, "link_threshold": links.threshold,
        "directional_bins": bins, "table_bytes": memory, "changes": changes, "seconds_per_iteration": seconds,
        "negative_elements": int((signed < 0).any(axis=1).sum())}, cache={"signed": signed})


def evaluate(problem, solution: Solution, receivers) -> np.ndarray:
    """Indirect lighting at ``receivers``: the solution at the vertices; at other points (lightmap
    texels) interpolated, plus the detail of the tree's final gather (``texel_indirect``)."""
    return reconstruct_with_detail(problem, solution, receivers)
