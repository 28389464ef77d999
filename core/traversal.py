"""Stackless traversal of the cluster tree (``hierarchy.Nodes``), as Warp functions.

A traversal visits a *cut* of the tree: at each node the caller decides which fraction ``take`` of
the node it uses as a whole (1: the node stands for its subtree, which is skipped; 0: open it; in
between: a blend, the children carrying the rest of the node's weight). The weight of the node a
traversal stands at is kept per tree level, so one ``while`` loop per receiver needs no stack:

    cut = cut_begin(t.root, t.level[t.root])
    while cut.node >= 0:
        node = cut.node
        level = t.level[node]
        w = cut_weight(cut, level)
        take = ...           # an opening criterion, e.g. opening(...)
        ...                  # accumulate the node's contribution × w × take
        child = t.descend[node]
        cut = cut_advance(cut, level, child, t.level[wp.max(child, 0)], t.next[node], take)

The functions take the few node fields they need rather than the ``Nodes`` struct: Warp passes
structs by value, and copying a dozen array handles at every visited node costs more than the
visit. Gathers (AO, Bunnell, final gathers) and link creation share these pieces.
"""
import warp as wp

from .hierarchy import MAX_LEVELS

wp.set_module_options({"enable_backward": False})  # no gradients: halves compile time

levels_vec = wp.types.vector(length=MAX_LEVELS, dtype=wp.float32)


@wp.struct
class Cut:
    """A traversal in progress: ``node`` it stands at (−1 when done) and ``weights`` per tree level
    (the weight of the node of that level on the current path)."""

    node: int
    weights: levels_vec


@wp.func
def cut_begin(root: int, root_level: int) -> Cut:
    """A traversal at the root (its index and level), with weight 1."""
    c = Cut()
    c.node = root
    c.weights = levels_vec()
    c.weights[root_level] = 1.0
    return c


@wp.func
def cut_weight(c: Cut, level: int) -> float:
    """The weight of the node ``c`` stands at (of tree level ``level``): the product of (1 − take)
    of its blended ancestors."""
    return c.weights[level]


@wp.func
def cut_advance(c: Cut, level: int, child: int, child_level: int, nxt: int, take: float) -> Cut:
    """Move on from ``c.node`` (of ``level``; its ``descend`` child, of ``child_level``, −1 for a
    leaf; ``nxt`` its ``next``), having used the fraction ``take`` of it: past its subtree for a
    leaf or take ≥ 1, else down to its children with the rest of its weight."""
    out = c
    if child < 0 or take >= 1.0:
        out.node = nxt
    else:
        out.weights[child_level] = c.weights[level] * (1.0 - take)
        out.node = child
    return out


@wp.func
def cut_skip(c: Cut, nxt: int) -> Cut:
    """Move past ``c.node``'s subtree without using it (culled); ``nxt`` its ``next``."""
    out = c
    out.node = nxt
    return out


@wp.func
def opening(d2: float, radius: float, floor: float, open_k: float) -> float:
    """The opening criterion: the fraction of a node at squared distance d2 used whole. 1 beyond
    d² = open_k·radius² (or ``floor``, a least squared distance, if larger), 0 inside 0.9 of it,
    blended linearly over the ±10 % between so the switch of level leaves no visible step."""
    return wp.clamp((d2 / wp.max(open_k * radius * radius, floor) - 0.9) * 5.0, 0.0, 1.0)
