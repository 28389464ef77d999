"""Stackless traversal of the cluster tree (``hierarchy.Nodes``), as Warp functions.

A traversal visits a *cut* of the tree: at each node the caller decides which fraction ``take`` of
the node it uses as a whole (1: the node stands for its subtree, which is skipped; 0: open it; in
between: a blend, the children carrying the rest of the node's weight). The weight of the node a
traversal stands at is kept per tree level, so one ``while`` loop per receiver needs no stack:

    cut = cut_begin(nodes)
    while cut.node >= 0:
        w = cut_weight(nodes, cut)
        take = ...           # an opening criterion, e.g. opening(...)
        ...                  # accumulate the node's contribution × w × take
        cut = cut_advance(nodes, cut, take)

Gathers (AO, Bunnell, final gathers) and link creation share these pieces.
"""
import warp as wp

from .hierarchy import MAX_LEVELS, Nodes

levels_vec = wp.types.vector(length=MAX_LEVELS, dtype=wp.float32)


@wp.struct
class Cut:
    """A traversal in progress: ``node`` it stands at (−1 when done) and ``weights`` per tree level
    (the weight of the node of that level on the current path)."""

    node: int
    weights: levels_vec


@wp.func
def cut_begin(t: Nodes) -> Cut:
    """A traversal at the root, with weight 1."""
    c = Cut()
    c.node = t.root
    c.weights = levels_vec()
    c.weights[t.level[t.root]] = 1.0
    return c


@wp.func
def cut_weight(t: Nodes, c: Cut) -> float:
    """The weight of the node ``c`` stands at: the product of (1 − take) of its blended ancestors."""
    return c.weights[t.level[c.node]]


@wp.func
def cut_advance(t: Nodes, c: Cut, take: float) -> Cut:
    """Move on from ``c.node``, having used the fraction ``take`` of it: past its subtree for a leaf
    or take ≥ 1, else down to its children with the rest of its weight."""
    out = c
    node = c.node
    child = t.descend[node]
    if child < 0 or take >= 1.0:
        out.node = t.next[node]
    else:
        out.weights[t.level[child]] = c.weights[t.level[node]] * (1.0 - take)
        out.node = child
    return out


@wp.func
def cut_skip(t: Nodes, c: Cut) -> Cut:
    """Move past ``c.node``'s subtree without using it (culled)."""
    out = c
    out.node = t.next[c.node]
    return out


@wp.func
def opening(d2: float, radius: float, floor: float, open_k: float) -> float:
    """The opening criterion: the fraction of a node at squared distance d2 used whole. 1 beyond
    d² = open_k·radius² (or ``floor``, a least squared distance, if larger), 0 inside 0.9 of it,
    blended linearly over the ±10 % between so the switch of level leaves no visible step."""
    return wp.clamp((d2 / wp.max(open_k * radius * radius, floor) - 0.9) * 5.0, 0.0, 1.0)
