"""The walk up a node's root path in the cluster tree (``hierarchy.Nodes``), as Warp functions.

A root path is a node and its ancestors up to the root, cut below the first ancestor with more
than ``limit`` leaves (``WHOLE``: never cut). The walk over its nodes:

    x = k
    while x >= 0:
        ...                                  # node x
        x = path_up(t, x, limit)

and over their links (``links.LinkSet``) in root-path order, the node's own first:

    walk = path_link_begin(t, ls, k, limit)
    while walk.node >= 0:
        ...                                  # link walk.link, received by node walk.node
        walk = path_link_next(t, ls, walk)
"""
import warp as wp

from .hierarchy import Nodes
from .links import LinkSet

wp.set_module_options({"enable_backward": False})  # no gradients: halves compile time

# A leaf count above every node's: the limit of an uncut root path.
WHOLE = wp.constant(1.0e30)


@wp.func
def path_up(t: Nodes, x: int, limit: float) -> int:
    """The node after x on its root path: x's parent; −1 at the root or where the parent has more
    than ``limit`` leaves."""
    p = t.parent[x]
    if limit < WHOLE and p >= 0 and t.leaves[p] > limit:  # (an uncut path compiles to parent alone)
        return -1
    return p


@wp.func
def path_top(t: Nodes, x: int, limit: float) -> int:
    """The last node of x's root path (the root, or the highest ancestor with at most ``limit``
    leaves)."""
    top = x
    up = path_up(t, x, limit)
    while up >= 0:
        top = up
        up = path_up(t, up, limit)
    return top


@wp.struct
class PathLink:
    """A walk over the links of a root path in progress: ``link`` it stands at, received by
    ``node`` (−1 when done), ``end`` one past that node's last link, the path's ``limit``."""

    node: int
    link: int
    end: int
    limit: float


@wp.func
def _settle(t: Nodes, ls: LinkSet, c: PathLink) -> PathLink:
    """``c`` while its link is one of its node's; past them, the first link of the next node up
    that has any (node −1 at the end of the path)."""
    out = c
    while out.link >= out.end:
        out.node = path_up(t, out.node, out.limit)
        if out.node < 0:
            return out
        out.link = ls.offsets[out.node]
        out.end = ls.offsets[out.node + 1]
    return out


@wp.func
def path_link_begin(t: Nodes, ls: LinkSet, x: int, limit: float) -> PathLink:
    """The walk at the first link of x's root path (cut above ``limit`` leaves; x itself is
    always on it)."""
    c = PathLink()
    c.node = x
    c.link = ls.offsets[x]
    c.end = ls.offsets[x + 1]
    c.limit = limit
    return _settle(t, ls, c)


@wp.func
def path_link_next(t: Nodes, ls: LinkSet, c: PathLink) -> PathLink:
    """The walk at the link after ``c``'s on its root path."""
    out = c
    out.link = c.link + 1
    return _settle(t, ls, out)
