"""Links between cluster-tree nodes, created data-parallel level by level (ALGORITHMS.md §4, §7, §9).

A link joins two nodes of the element tree (``hierarchy.Tree``) that exchange light as wholes.
Links are made top-down from a queue of candidate node pairs, starting with (root, root). Per
round, one kernel evaluates the *oracle* of every candidate and decides:

- drop: the pair cannot exchange light (one side faces away from the other entirely, bounded by
  the nodes' normal cones and bounding spheres; or their surfaces lie in one plane,
  ``coplanar``, at any depth: a flat wall's clusters with each other and themselves), or a leaf
  paired with itself;
- link: the pair's transfer estimate (``pair_need``: each side's size as the other sees it, a
  form factor, and its normal spread as a receiver), times the pair's brightness weight when a
  radiance estimate is given, is below the threshold — unless, while its estimate exceeds
  PARTIAL × the threshold, the link's rays find it partly visible (so shadow boundaries get finer
  links) or none of its sample pairs has a form factor either way (with visibility: a crate's
  side cluster sampled on its other faces would drop the ground at its foot, which its bottom
  row sees): it is split instead; two leaves always link (their near field is exact);
- split: the side with the larger estimate (a leaf never): its children are paired with the
  other side; a node paired with itself becomes all pairs of its children (each unordered pair
  once). Pairs hold leaves or nodes with several children (``canonical``).

An exclusive scan (``wp.utils.array_scan``) of the decisions' output counts gives the write
offsets; a second kernel scatters the links (in place, after the earlier rounds' ones) and the
next queue. On a GPU this repeats until the queue is empty (about two rounds per tree level). On
the CPU, whose few threads need no rounds to keep busy, the build turns depth first once a round's
queue holds DEPTH_FIRST pairs: the queue is cut into runs, each thread takes runs in turn, and a
run walks the pairs below its own with a stack, writing its links straight into its own region
of the link arrays (``_depth_first``): the same oracle (``_decide``) and the same links, without
the rounds' candidate arrays, scans and launches. Pairs are unordered — the oracle is symmetric —
so each link carries both directions.

A link's transfer both ways is estimated where it is made (``sampled_transfer``): ``rays`` sample
pairs, one leaf of each node (a leaf node is its own), stratified; per sample the element form
factor from the receiving leaf's point to the sending leaf (``surfels.point_ff``: disk far,
exact triangles near) per unit area, times one of the reference's visibility rays between the two
leaves (``element_ray``; with visibility). Given a radiance estimate, leaves are drawn in proportion to area × (radiance
+ a floor), and each direction's mean is weighted by the radiance at its sending end over the
sampling density (self-normalised), so what a link carries is Σ A·B·F·V over the sender — a hot
spot hidden in a cluster (the ceiling 1 mm above the Cornell light) does not leak through the
cluster's visible parts. Two leaves get the element form factors of ``core.surfels`` and
``pair_hits``: with leaves only, links are the reference's transport. Solvers without explicit
visibility (antiradiance, implicit visibility) ask for ``visibility=False``; antiradiance, whose
antiradiance crosses surfaces, also for ``sides=2``: pairs whose faces see each other either way
link (even with no transfer to either front: what arrives at a back goes on through), and
transfers are to both faces of the sender.

Finally both directions are sorted by receiver into CSR (``LinkSet``; ``wp.utils.radix_sort_pairs``
on a GPU, a counting sort on the CPU): a gather is one thread per receiver node over a contiguous
range, no atomics.

Memory: the links and candidates in flight are held to ``budget`` bytes (BYTES_PER_LINK per link
at the peak, while sorting; BYTES_PER_CANDIDATE per queued pair). A scene that would exceed it is
rebuilt with the threshold raised (×RAISE per try, found by trial builds without rays) and a
warning says how many links were made and at what threshold; only when even the coarsest links
(threshold ≥ COARSEST: every pair links at first sight) do not fit does the bake stop with a
message.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
import warp as wp

from . import device as device_mod
from .errors import BakeError
from .formfactor import cluster_ff, disk_ff
from .hierarchy import Nodes
from .rays import lift, visible
from .surfels import Surfels, face_ff, fan_sample, pair_hits, ray_ends

# No gradients (halves compile time). On the CPU, LLVM inlines more than Warp's defaults (9000,
# 3000): the oracle kernel inlines the form factors at a dozen call sites, and a call left out of
# line copies the kernel's structs (a kilobyte each) by value. At the defaults, a larger
# ``surfels.fan_ff`` made link creation 1.6× slower, dropped pairs included (room20k: 121 →
# 191 ms); these thresholds give the fully inlined speed.
wp.set_module_options({"enable_backward": False, "cpu_compiler_flags": (
    "-march=native -mllvm=-inline-threshold=40000 -mllvm=-inline-cold-callsite-threshold=20000"
    " -mllvm=-slp-recursion-max-depth=4")})

DROP, LINK, SPLIT_A, SPLIT_B, SPLIT_SELF = 0, 1, 2, 3, 4
# Peak bytes per link (both directions): the pair and its six values while it is made, then two
# sort keys and values at twice their count, and the CSR entries (sender, transfer, normaliser,
# visibility) of both directions.
BYTES_PER_LINK = 82
# Bytes per candidate pair in flight: the pair, its decision and values, the next queue.
BYTES_PER_CANDIDATE = 42
# Bytes of a link in the arrays it is made in (a, b, four values, two visible fractions as bytes:
# what the CSR keeps of them; as floats the link arrays' fresh pages cost 19 % more faults).
LINK_ARRAYS_BYTES = 26
# Brightness weights of the oracle (a node's brightest leaf over the scene's mean radiance) are
# clamped to [WEIGHT_LOW, WEIGHT_HIGH]; sample leaves are drawn in proportion to area ×
# (radiance + SAMPLE_FLOOR × the mean), so dim leaves keep some samples.
WEIGHT_LOW, WEIGHT_HIGH = 0.25, 4.0
SAMPLE_FLOOR = 0.25
# The normal-spread term of a receiver's need is weighted by this: a cluster folded round a corner
# receives one value for leaves that see a sender very differently, and its per-leaf correction
# rests on a few samples, so such clusters are split sooner than flat ones.
CONE_WEIGHT = 4.0
# Links of a node with an element in a contact (``core.refine``) are refined this much further
# (measured on the open scene with two contact levels: 1 → 0.74 %, 4 → 0.56 %, 10 → 0.53 %,
# 40 → 0.51 % from Cycles).
CONTACT_WEIGHT = 10.0
# A partly visible link, or one whose samples saw no form factor (with visibility), is split
# while its estimate exceeds this fraction of the threshold. (Dropping the latter lost light:
# 5.9 % of the indirect light of three crates on a sunlit ground against the reference, 4.0 %
# after; on the level 9.5 → 7.5 % of all indirect light, its crates 19 → 17 %.)
PARTIAL = 0.25
# The largest ratio of a link's sampled unoccluded transfer over its centroid form factor that a
# single receiving point keeps (see _normaliser).
JENSEN = 1.2
# Each try over the budget multiplies the threshold by this; the trial builds that find the
# threshold (no rays) must fit the budget over this margin.
RAISE = 2.0
TRIAL_MARGIN = 1.5
# Candidates per oracle thread on the CPU: a thread starts by copying the kernel's arguments (the
# tree, element and sampling structs, some kilobytes), more than a typical candidate's work, so each
# takes a run of candidates (measured: the 10 k room's 948 k candidates, 0.27 → 0.18 CPU s). On a
# GPU one each.
GRAIN = 64
# Threads per core below which a round's launch stays on the calling thread (``device.launch``'s
# min_split; the pool's ~80 µs exceed a few hundred candidates' work): the oracle's threads
# (GRAIN candidates, 3–5 µs), the scatter's (GRAIN candidates, ~0.5 µs).
# (The lamp scene's 17 rounds: link creation 21 → 16 ms.)
SPLIT_ORACLE, SPLIT_SCATTER = 32, 256
# On the CPU, once a breadth-first round's queue holds DEPTH_FIRST candidates, the rest of the
# build goes depth first (``_depth_first``), in DEPTH_RUNS runs taken in turn by the threads (so a
# core that drew light runs takes more), each run's links into its own region of at least
# MIN_REGION links where the room allows; with rays (minutes on large scenes) in DEPTH_WAVES
# waves, between which a bake can be cancelled. Without rays a run's launch (~50 µs, mostly
# packing the kernel's arguments) weighs against small scenes' work: then a run per RUN_ELEMENTS
# elements, between MIN_RUNS and GEOMETRIC_RUNS (measured, link creation: the Cornell box 14.2 →
# 10.9 ms with 9 runs instead of 64, room9k 38.6 → 36.3 ms and room100k 233 → 230 ms with 32).
# No count depends on the number of threads, so neither do the links' order and the sums over
# them.
DEPTH_FIRST, DEPTH_RUNS, MIN_REGION, DEPTH_WAVES = 256, 64, 4096, 8
RUN_ELEMENTS, MIN_RUNS, GEOMETRIC_RUNS = 300, 4, 32
# Nodes whose surfaces lie within this fraction of their extents and distance of one plane are
# coplanar (``coplanar``), as ``formfactor.PLANE_EPS`` sees a triangle edge-on from a point in its
# plane: such pairs are dropped at first sight instead of being split down to their leaves, whose
# exact form factors are all 0 (a 100 k-element room: 917 k of its 1.06 M leaf pairs dropped).
FLAT = 1.0e-5
# No estimate of pair_need exceeds this: at this threshold every pair of distinct nodes links.
COARSEST = 2.0
PI = math.pi


@dataclass(frozen=True)
class Oracle:
    """How links are chosen, and the key they are cached under (``Problem.links``).

    threshold: the largest estimate (``pair_need``, a form factor) a link may have; smaller gives
    more, finer links. rays: sample pairs a link's transfer is estimated from (0: the form factor
    between the nodes' centres, ``centroid_ff``). visibility: trace a ray per sample (False: links
    carry unoccluded transfer, for implicit visibility or antiradiance). seed: of the sample
    jitter. budget: bytes the links may take. brightness: a label of the radiance estimate passed
    to ``build`` (None: none: geometric refinement, samples by area), so links made with one are
    cached apart. sides: 1, senders send from their fronts; 2, from both faces (antiradiance).
    """

    threshold: float
    rays: int = 0
    visibility: bool = True
    seed: int = 1
    budget: int = 4 << 30
    brightness: str | None = None
    sides: int = 1


@wp.struct
class LinkSet:
    """The directed links as kernels read them, sorted by receiver node.

    offsets: int32[m+1], receiver r's links are offsets[r] … offsets[r+1]−1; sender: int32[E] the
    sending node; transfer: float32[E] the transfer (lighting at the receiver per unit radiance of
    the sender's front) averaged over the receiver, with visibility when traced; form_factor:
    float32[E] the normaliser: the sender's ``centroid_ff`` averaged over the same receiving
    points (exact for two leaves), so transfer × centroid_ff(at a point of the receiver) /
    form_factor is the transfer at that point; visible: uint8[E] the visible fraction of the
    transfer × 255 (the sampled transfer over its unoccluded value; 255 without visibility):
    0 < visible < 255 marks a link across a shadow boundary.
    """

    offsets: wp.array(dtype=wp.int32)
    sender: wp.array(dtype=wp.int32)
    transfer: wp.array(dtype=wp.float32)
    form_factor: wp.array(dtype=wp.float32)
    visible: wp.array(dtype=wp.uint8)


@dataclass
class Links:
    """Links over ``problem.tree``: ``set`` (``LinkSet`` on the device), ``pairs`` unordered links
    (``count`` = 2 × pairs directed ones), the ``threshold`` used (raised from the oracle's when
    the budget asked for it), the build's breadth-first ``rounds``, ``rays_traced``, ``seconds``
    the build took (creation with its transfers and visibility, and the sort into CSR)."""

    set: LinkSet
    pairs: int
    threshold: float
    rounds: int
    rays_traced: int
    seconds: float
    # What solvers derive from these links once per build (direction masks), by their own keys.
    derived: dict = field(default_factory=dict)

    @property
    def count(self) -> int:
        return 2 * self.pairs


@wp.struct
class Sampling:
    """How the sample leaves of a link are drawn: first_leaf int32[m] of each node; cum
    float64[n+1] the running sum over the leaves (leaf order) of area × (glow + floor); glow
    float32[n] each leaf's radiance estimate (1 without one); floor: the added floor (0 without an
    estimate); open float32[n] each leaf's share of its view not inside a closed surface
    (``enclosure``; 1 without visibility): what a cluster's receiving samples are weighted by."""

    first_leaf: wp.array(dtype=wp.int32)
    cum: wp.array(dtype=wp.float64)
    glow: wp.array(dtype=wp.float32)
    floor: float
    open: wp.array(dtype=wp.float32)


@wp.func
def cos_bound(dn: float, d2: float, cone: wp.vec3, beta: wp.vec2, inv_d2: float) -> float:
    """An upper bound of n'·u' over normals n' within a cone of unit n and directions u' within
    angle β of a vector v, from dn = n·v, d2 = v·v and inv_d2 = 1/d2: the cosine of the angle
    between n and v less the cone's and β's (1 when that is negative); cone as (cos, sin, …) of
    its half-angle, beta as |v|·(cos, sin) of β. Written in n·v and v·v so that the square roots
    and the division are independent of each other, not a chain (``pair_need`` on room20k's
    linked pairs: 28 → 23 ns)."""
    c = cone[0] * beta[0] - cone[1] * beta[1]  # |v|·cos and |v|·sin of the half-angles' sum γ
    g = cone[1] * beta[0] + cone[0] * beta[1]
    if g < 0.0 or dn >= c:  # γ > π, or the angle to v is within γ
        return 1.0
    return (dn * c + wp.sqrt(wp.max(d2 - dn * dn, 0.0)) * g) * inv_d2


@wp.func
def facing(dn_a: float, cone_a: wp.vec3, dn_b: float, cone_b: wp.vec3, d2: float, inv_d2: float,
           beta: wp.vec2, sides: int) -> wp.vec2:
    """(bound of a's cosine, of b's) over their normal cones and the directions from a to b within
    angle β of v = b − a (``cos_bound``: dn_a = n_a·v, dn_b = −n_b·v, d2 = v·v, beta = |v|·(cos,
    sin) of β), either face with ``sides`` 2."""
    ca = cos_bound(dn_a, d2, cone_a, beta, inv_d2)
    cb = cos_bound(dn_b, d2, cone_b, beta, inv_d2)
    if sides == 2:
        ca = wp.max(ca, cos_bound(-dn_a, d2, cone_a, beta, inv_d2))
        cb = wp.max(cb, cos_bound(-dn_b, d2, cone_b, beta, inv_d2))
    return wp.vec2(ca, cb)


@wp.func
def pair_need(pa: wp.vec3, na: wp.vec3, ra: float, area_a: float, cone_a: wp.vec3, pb: wp.vec3,
              nb: wp.vec3, rb: float, area_b: float, cone_b: wp.vec3, reach: float, sides: int) -> wp.vec3:
    """How much nodes a and b — centres p, unit normals n, bounding radii r (m) of their disks,
    areas (m²), normal cones ((cos, sin, 2 sin(·/2)) of the half-angle), the sum of the bounding
    radii of their surfaces (``Nodes.reach``, m) — must be refined to exchange light as wholes:
    (need of a, need of b, 1 if they can exchange light at all else 0).

    Dropped (0) when the cosines bounded over the cones and the directions between the bounding
    spheres show one side facing away, those of the surfaces as well as the disks (the disks'
    alone drop a floor vertex hidden under a box whose triangles reach out in front of it); 1 each
    when the disks' spheres overlap. Else the need of a is the larger of its size as b sees it,
    A_a·cos·cos / (π d² + A_a) with the bounded cosines (the disks', or the surfaces' where the
    disks face away) and the centres' distance d, and its normal spread as a receiver: b's form
    factor from a without a's cosine times 2 sin(cone_a / 2) — how far a's leaves' normals may
    differ from its own — times CONE_WEIGHT. A point
    (r = 0, area 0, cone (1, 0)) as a needs nothing itself. With ``sides`` 2 either face counts
    (antiradiance crosses surfaces both ways): the cosines are bounded over both faces."""
    v = pb - pa
    d2 = wp.dot(v, v)
    r = ra + rb
    if d2 <= r * r:
        return wp.vec3(1.0, 1.0, 1.0)
    inv_d2 = 1.0 / d2
    dn_a = wp.dot(na, v)
    dn_b = -wp.dot(nb, v)
    # the spheres' directions lie within asin(r / d) of v
    cosines = facing(dn_a, cone_a, dn_b, cone_b, d2, inv_d2, wp.vec2(wp.sqrt(d2 - r * r), r), sides)
    if cosines[0] <= 0.0 or cosines[1] <= 0.0:
        # the disks face away; the surfaces around them may not
        rs = wp.min(reach, wp.sqrt(d2))
        beta = wp.vec2(wp.sqrt(wp.max(d2 - rs * rs, 0.0)), rs)
        cosines = facing(dn_a, cone_a, dn_b, cone_b, d2, inv_d2, beta, sides)
        if cosines[0] <= 0.0 or cosines[1] <= 0.0:
            return wp.vec3(0.0, 0.0, 0.0)
    ca = cosines[0]
    cb = cosines[1]
    g2 = PI * d2
    g_ab = area_b * cb / (g2 + area_b)  # b seen from a, without a's cosine
    g_ba = area_a * ca / (g2 + area_a)
    need_a = wp.max(g_ba * cb, g_ab * CONE_WEIGHT * cone_a[2])
    need_b = wp.max(g_ab * ca, g_ba * CONE_WEIGHT * cone_b[2])
    return wp.vec3(need_a, need_b, 1.0)


@wp.func
def coplanar(t: Nodes, plane: wp.array(dtype=wp.vec2), a: int, b: int) -> bool:
    """Whether the surfaces of nodes a and b (``hierarchy.Tree.plane``: their thickness and extent
    around their planes) lie in one plane, to FLAT of their extents and distance: then no point
    of either sees the other but edge-on, and the pair exchanges no light at any depth (a flat
    wall's clusters with each other, a node with itself)."""
    pa = plane[a]
    pb = plane[b]
    if a == b:
        return pa[0] <= FLAT * pa[1]
    d = t.position[b] - t.position[a]
    # most pairs have a side thicker than the tolerance: tell them without its square root
    over = wp.max(pa[0], pb[0]) - FLAT * (pa[1] + pb[1])
    if over > 0.0 and over * over > (FLAT * FLAT) * wp.dot(d, d):
        return False
    na = t.normal[a]
    nb = t.normal[b]
    tilt = wp.length(na - nb)
    tol = FLAT * (pa[1] + pb[1] + wp.length(d))
    return (pa[0] <= tol and pb[0] <= tol and wp.abs(wp.dot(d, na)) + pb[0] + pb[1] * tilt <= tol
            and wp.abs(wp.dot(d, nb)) + pa[0] + pa[1] * tilt <= tol)


@wp.func
def children(t: Nodes, node: int) -> wp.vec2i:
    """The child range [first, end) a split of inner ``node`` gives: past cells with one child."""
    c0 = t.descend[node]
    return wp.vec2i(c0, t.child_end[t.parent[c0]])


@wp.func
def canonical(t: Nodes, node: int) -> int:
    """The node a pair holds for ``node``: a leaf, or the first node at or below it with more than
    one child (a chain of one-child cells stands for the same disks; a chain over a single leaf is
    that leaf, whose near field is exact)."""
    x = t.descend[node]
    if x < 0:
        return node
    p = t.parent[x]
    if t.child_end[p] - x == 1:
        return x
    return p


@wp.func
def centroid_ff(t: Nodes, s: Surfels, p: wp.vec3, n: wp.vec3, b: int) -> float:
    """Unoccluded form factor from point p (unit normal n) to the front of node b: a leaf's element
    form factor (``surfels.point_ff``), else the cluster form factor of b's disks gathered at
    its centre (``formfactor.cluster_ff``)."""
    return face_centroid_ff(t, s, p, n, b, 1.0)


@wp.func
def face_centroid_ff(t: Nodes, s: Surfels, p: wp.vec3, n: wp.vec3, b: int, side: float) -> float:
    """``centroid_ff`` to one face of node b: the front for side 1, the back for side −1."""
    if t.descend[b] < 0:
        return face_ff(s, p, n, t.element[b], side)
    return cluster_ff(p, n, t.position[b], t.normal[b] * side, t.area[b], t.spread[b], t.leaves[b])


@wp.func
def sided_ff(t: Nodes, s: Surfels, p: wp.vec3, n: wp.vec3, b: int, sides: int) -> float:
    """``centroid_ff`` to the front of node b, plus its back when ``sides`` is 2."""
    f = face_centroid_ff(t, s, p, n, b, 1.0)
    if sides == 2:
        f += face_centroid_ff(t, s, p, n, b, -1.0)
    return f


@wp.func
def centre_ff(t: Nodes, s: Surfels, a: int, b: int, sides: int) -> float:
    """Unoccluded form factor from node a's centre (with its normal) to node b, as ``sided_ff``,
    except that from a cluster's centre a leaf is taken as its disk: that centre is no point of a
    surface, where the leaf's exact triangles (``surfels.face_ff`` near a leaf) would be worth
    their cost — several times the oracle's other work per pair (measured: 35 % of link creation
    without rays on a 10 k-element room). What a link carries to a cluster's leaves is evaluated
    at each leaf in the final gather (exactly, through ``centroid_ff``)."""
    if t.descend[a] < 0 or t.descend[b] >= 0:
        return sided_ff(t, s, t.position[a], t.normal[a], b, sides)
    p = t.position[a]
    n = t.normal[a]
    f = disk_ff(p, n, t.position[b], t.normal[b], t.area[b])
    if sides == 2:
        f += disk_ff(p, n, t.position[b], -t.normal[b], t.area[b])
    return f


@wp.func
def sided_element_ff(s: Surfels, p: wp.vec3, n: wp.vec3, e: int, sides: int) -> float:
    """``surfels.point_ff`` to the front of element e, plus its back when ``sides`` is 2."""
    f = face_ff(s, p, n, e, 1.0)
    if sides == 2:
        f += face_ff(s, p, n, e, -1.0)
    return f


@wp.func
def sample_leaf(t: Nodes, sm: Sampling, node: int, u: float) -> int:
    """A leaf (node index) of node's subtree (node itself for a leaf) chosen with u ∈ [0, 1) in
    proportion to the weights whose running sum is ``sm.cum`` (the leaves of a subtree are
    consecutive in leaf order)."""
    if t.descend[node] < 0:
        return node
    lo = sm.first_leaf[node]
    hi = lo + int(t.leaves[node] + 0.5)
    base = sm.cum[lo]
    target = base + wp.float64(u) * (sm.cum[hi] - base)
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if sm.cum[mid] <= target:
            lo = mid
        else:
            hi = mid
    return lo


@wp.func
def leaf_point(t: Nodes, s: Surfels, leaf: int) -> wp.vec3:
    """Where rays to and from a leaf start: its element's point, lifted off its surface."""
    e = t.element[leaf]
    return lift(s.pos[e], s.nrm[e], wp.sqrt(s.area[e]))


@wp.func
def element_ray(s: Surfels, ends: wp.vec2i, u0: float, u1: float, u2: float) -> float:
    """1 if one of the reference's visibility rays between two elements is free (``pair_hits``:
    from element ends[0]'s point to a point of element ends[1]'s own surface, both lifted off
    their surfaces; ``surfels.ray_ends``), else 0."""
    i = ends[0]
    j = ends[1]
    origin = lift(s.pos[i], s.nrm[i], wp.sqrt(s.area[i]))
    return visible(s.mesh, origin, lift(fan_sample(s, j, u0, u1, u2), s.nrm[j], wp.sqrt(s.area[j])))


@wp.func
def _sample_terms(f: float, w: float, hit: float) -> wp.vec4:
    """One sample pair's part of a direction of ``sampled_transfer``: (weight w, weighted visible
    form factor, weighted form factor, plain visible form factor), f the form factor per sender
    area, hit the ray's visibility."""
    return wp.vec4(w, w * f * hit, w * f, f * hit)


@wp.func
def _sample_pair(t: Nodes, sm: Sampling, a: int, b: int, k: int, rays: int, shift: int, ua: float,
                 ub: float) -> wp.vec2i:
    """The leaves (node indices) of sample k of ``rays`` of link (a, b): from stratum k of a's
    leaves and stratum k + shift (cyclic) of b's, jittered by ua, ub ∈ [0, 1)."""
    return wp.vec2i(sample_leaf(t, sm, a, (float(k) + ua) / float(rays)),
                    sample_leaf(t, sm, b, (float((k + shift) % rays) + ub) / float(rays)))


@wp.func
def sampled_transfer(t: Nodes, s: Surfels, sm: Sampling, a: int, b: int, rays: int, visibility: int,
                     seed: int, sides: int, probe: bool):
    """Link (a, b) from ``rays`` sample pairs (see the module docstring): ((transfer to a, to b,
    normaliser to a, to b), (visible fraction of the transfer to a, to b, plain visible fraction
    of the rays), rays traced). The normalisers (``centroid_ff`` of the sender from the receiving
    samples) are averaged over the receiving end by area, as the transfer is.

    Only the rays that can change the link are traced. ``probe``: the caller splits the pair when
    the plain fraction is strictly between 0 and 1; then the rays stop at the first sample that
    makes it so (the values returned are then partial: the pair is no link). Otherwise a sample
    whose form factors are 0 both ways adds nothing to the transfers, whatever its ray finds; its
    ray is traced only where the plain fraction stands for a direction's visible fraction (that
    direction's unoccluded transfer is 0) of a pair that links. Either way the oracle decides, and
    a link carries, what tracing every ray gives."""
    state = wp.rand_init(seed + wp.max(a, b), wp.min(a, b))
    shift = int(wp.randf(state) * float(rays))
    # per direction (a receives from b, b from a): ``_sample_terms`` summed over the samples
    s_ab = wp.vec4(0.0)
    s_ba = wp.vec4(0.0)
    r_a = float(0.0)  # receiving-end weights and centroid form factors
    c_ab = float(0.0)
    r_b = float(0.0)
    c_ba = float(0.0)
    seen = float(0.0)  # the rays' hits, a sample whose ray is skipped counted as one
    traced = int(0)
    skipped = int(0)
    for k in range(rays):
        ua = wp.randf(state)
        ub = wp.randf(state)
        pair = _sample_pair(t, sm, a, b, k, rays, shift, ua, ub)
        la = pair[0]
        lb = pair[1]
        # each end's density relative to area: ∝ glow + floor on a cluster, one point on a leaf
        da = float(1.0)
        db = float(1.0)
        if la != a:
            da = sm.glow[la] + sm.floor
        if lb != b:
            db = sm.glow[lb] + sm.floor
        # a cluster's receiving samples count as much as their leaf's view is open (``enclosure``)
        oa = float(1.0)
        ob = float(1.0)
        if la != a:
            oa = sm.open[la]
        if lb != b:
            ob = sm.open[lb]
        ea = t.element[la]
        eb = t.element[lb]
        f_ab = sided_element_ff(s, s.pos[ea], s.nrm[ea], eb, sides)
        f_ba = sided_element_ff(s, s.pos[eb], s.nrm[eb], ea, sides)
        hit = float(1.0)
        if visibility != 0:
            u0 = wp.randf(state)
            u1 = wp.randf(state)
            u2 = wp.randf(state)
            if probe or f_ab > 0.0 or f_ba > 0.0:
                hit = element_ray(s, ray_ends(ea, eb, f_ab, f_ba), u0, u1, u2)
                traced += 1
            else:
                skipped += 1
        seen += hit
        s_ab += _sample_terms(f_ab / s.area[eb], oa * sm.glow[lb] / (da * db), hit)
        s_ba += _sample_terms(f_ba / s.area[ea], ob * sm.glow[la] / (da * db), hit)
        # the centroid form factors: a leaf's is the element form factor just evaluated
        if lb != b:
            f_ab = sided_ff(t, s, s.pos[ea], s.nrm[ea], b, sides)
        if la != a:
            f_ba = sided_ff(t, s, s.pos[eb], s.nrm[eb], a, sides)
        r_a += oa / da
        c_ab += oa * f_ab / da
        r_b += ob / db
        c_ba += ob * f_ba / db
        if probe and seen > 0.0 and seen < float(k + 1):  # a hit and a miss: the pair is split
            break
    t_ab = s_ab[3] / float(rays)
    u_ab = s_ab[2]
    if s_ab[0] > 0.0:
        t_ab = s_ab[1] / s_ab[0]
        u_ab = s_ab[2] / s_ab[0]
    t_ba = s_ba[3] / float(rays)
    u_ba = s_ba[2]
    if s_ba[0] > 0.0:
        t_ba = s_ba[1] / s_ba[0]
        u_ba = s_ba[2] / s_ba[0]
    out = wp.vec4(t_ab * t.area[b], t_ba * t.area[a], _normaliser(u_ab * t.area[b], c_ab / wp.max(r_a, 1.0e-30)),
                  _normaliser(u_ba * t.area[a], c_ba / wp.max(r_b, 1.0e-30)))
    if skipped > 0 and (not (u_ab > 0.0) or not (u_ba > 0.0)) and (out[0] > 0.0 or out[1] > 0.0 or sides == 2):
        # ``_fraction`` falls back on the plain fraction: the skipped samples' rays, drawn again
        state = wp.rand_init(seed + wp.max(a, b), wp.min(a, b))
        wp.randf(state)
        for k in range(rays):
            ua = wp.randf(state)
            ub = wp.randf(state)
            pair = _sample_pair(t, sm, a, b, k, rays, shift, ua, ub)
            u0 = wp.randf(state)
            u1 = wp.randf(state)
            u2 = wp.randf(state)
            ea = t.element[pair[0]]
            eb = t.element[pair[1]]
            if not (sided_element_ff(s, s.pos[ea], s.nrm[ea], eb, sides) > 0.0
                    or sided_element_ff(s, s.pos[eb], s.nrm[eb], ea, sides) > 0.0):
                seen += element_ray(s, ray_ends(ea, eb, 0.0, 0.0), u0, u1, u2) - 1.0
                traced += 1
    plain = seen / float(rays)
    return out, wp.vec3(_fraction(t_ab, u_ab, plain), _fraction(t_ba, u_ba, plain), plain), traced


@wp.func
def _fraction(occluded: float, unoccluded: float, plain: float) -> float:
    """The visible fraction of a transfer: its sampled value over the unoccluded one (the rays'
    plain fraction where that is 0)."""
    if unoccluded > 0.0:
        return wp.clamp(occluded / unoccluded, 0.0, 1.0)
    return plain


@wp.func
def _normaliser(unoccluded: float, centroid: float) -> float:
    """What a link's transfer is divided by before it is scaled by ``centroid_ff`` at one point of
    the receiver: the centroid form factor averaged over the receiving samples, kept within
    [unoccluded / JENSEN, unoccluded] of the sampled unoccluded transfer (the samples' mean of
    1/d² exceeds its value at the centre, by a few per cent; an average near 0 — a receiver cluster
    folded round a near sender — must not blow the ratio up)."""
    return wp.clamp(centroid, unoccluded / JENSEN, unoccluded)


@wp.kernel
def _first_leaf_kernel(offset: int, t: Nodes, first_leaf: wp.array(dtype=wp.int32)):
    node = wp.tid() + offset
    k = node
    while t.descend[k] >= 0:
        k = t.descend[k]
    first_leaf[node] = k


@wp.kernel
def _max_kernel(offset: int, node0: int, t: Nodes, values: wp.array(dtype=wp.float32)):
    node = node0 + wp.tid() + offset
    v = float(0.0)
    for c in range(t.first_child[node], t.child_end[node]):
        v = wp.max(v, values[c])
    values[node] = v


@wp.kernel
def _canonical_kernel(offset: int, t: Nodes, node: int, out: wp.array(dtype=wp.int32)):
    out[0] = canonical(t, node)


@wp.func(inline=True)  # one copy per kernel: out of line, the structs would be copied per call
def _decide(t: Nodes, s: Surfels, sm: Sampling, cone: wp.array(dtype=wp.vec3), plane: wp.array(dtype=wp.vec2),
            a: int, b: int, threshold: float, weighted: int, weight: wp.array(dtype=wp.float32), rays: int,
            visibility: int, seed: int, sides: int):
    """The oracle on candidate pair (a, b) (see the module docstring): (decision, pairs its split
    adds, for a link its (transfer to a, to b, normaliser to a, to b), its visible fractions
    (to a, to b, plain), rays traced)."""
    dec = DROP
    count = int(0)
    out = wp.vec4(0.0)
    seen = wp.vec3(1.0)
    ray_count = int(0)
    leaf_a = t.descend[a] < 0
    leaf_b = t.descend[b] < 0
    if t.area[a] > 0.0 and t.area[b] > 0.0 and (sides == 2 or not coplanar(t, plane, a, b)):
        if a == b:
            if not leaf_a:
                r = children(t, a)
                k = r[1] - r[0]
                dec = SPLIT_SELF
                count = k * (k + 1) // 2
        elif leaf_a and leaf_b:
            ea = t.element[a]
            eb = t.element[b]
            f_ab = sided_element_ff(s, s.pos[ea], s.nrm[ea], eb, sides)
            f_ba = sided_element_ff(s, s.pos[eb], s.nrm[eb], ea, sides)
            if f_ab > 0.0 or f_ba > 0.0 or sides == 2:
                dec = LINK
                v = float(1.0)
                if visibility != 0 and rays > 0:
                    v = float(pair_hits(s, ray_ends(ea, eb, f_ab, f_ba), rays, seed)) / float(rays)
                    ray_count = rays
                out = wp.vec4(f_ab * v, f_ba * v, f_ab, f_ba)
                seen = wp.vec3(v, v, v)
        else:
            need = pair_need(t.position[a], t.normal[a], t.radius[a], t.area[a], cone[a],
                             t.position[b], t.normal[b], t.radius[b], t.area[b], cone[b],
                             t.reach[a] + t.reach[b], sides)
            if need[2] > 0.0:
                w = float(1.0)
                if weighted != 0:
                    w = wp.max(weight[a], weight[b])
                need_a = need[0] * w
                need_b = need[1] * w
                largest = wp.max(need_a, need_b)
                split = largest > threshold
                if not split:
                    if rays > 0:
                        probe = largest > PARTIAL * threshold
                        out, seen, ray_count = sampled_transfer(t, s, sm, a, b, rays, visibility, seed,
                                                                sides, probe)
                        # partly visible, or no sample saw a form factor: the samples know
                        # too little of the pair to link it or drop it
                        split = probe and ((seen[2] > 0.0 and seen[2] < 1.0)
                                           or (visibility != 0 and not (out[2] > 0.0)
                                               and not (out[3] > 0.0)))
                    else:
                        f_ab = centre_ff(t, s, a, b, sides)
                        f_ba = centre_ff(t, s, b, a, sides)
                        out = wp.vec4(f_ab, f_ba, f_ab, f_ba)
                    if not split and (out[0] > 0.0 or out[1] > 0.0 or sides == 2):
                        dec = LINK
                if split:
                    if leaf_a or (not leaf_b and need_b >= need_a):
                        dec = SPLIT_B
                        r = children(t, b)
                        count = r[1] - r[0]
                    else:
                        dec = SPLIT_A
                        r = children(t, a)
                        count = r[1] - r[0]
    return dec, count, out, seen, ray_count


@wp.func
def _visible_bytes(seen: wp.vec3) -> wp.vec2ub:
    """A link's visible fractions (to a, to b) as ``LinkSet.visible`` keeps them: × 255, rounded."""
    return wp.vec2ub(wp.uint8(wp.int32(seen[0] * 255.0 + 0.5)),
                     wp.uint8(wp.int32(seen[1] * 255.0 + 0.5)))


@wp.func
def _put_split(t: Nodes, dec: int, a: int, b: int, out_a: wp.array(dtype=wp.int32),
               out_b: wp.array(dtype=wp.int32), o: int) -> int:
    """The pairs a split of (a, b) (decision ``dec``) makes, written to out_a, out_b from o on;
    returns where the next goes."""
    if dec == SPLIT_A:
        r = children(t, a)
        for c in range(r[0], r[1]):
            out_a[o] = canonical(t, c)
            out_b[o] = b
            o += 1
    elif dec == SPLIT_B:
        r = children(t, b)
        for c in range(r[0], r[1]):
            out_a[o] = a
            out_b[o] = canonical(t, c)
            o += 1
    elif dec == SPLIT_SELF:
        r = children(t, a)
        for c in range(r[0], r[1]):
            for c2 in range(c, r[1]):
                out_a[o] = canonical(t, c)
                out_b[o] = canonical(t, c2)
                o += 1
    return o


def _specialised(geometric: bool) -> tuple:
    """(KEEP, ONE_FACE, name suffix): what a kernel made for the geometric oracle (no rays, one
    face: ``Oracle`` with rays 0 and sides 1) or for any passes ``_decide`` as its rays,
    visibility and sides (rays·KEEP, visibility·KEEP, sides·KEEP + ONE_FACE). As constants (0, 1)
    they let the compiler drop the samples, rays and back faces from the geometric kernels, which
    then make the same links in less time (room20k's link build 88 → 64 ms on the 2-core VM);
    a second call site in one kernel instead slowed the oracle with rays by ~5 %."""
    return (0, 1, "_geometric") if geometric else (1, 0, "")


def _geometric(oracle: Oracle) -> bool:
    """Whether ``oracle`` is the geometric one (no rays, one face): see ``_specialised``."""
    return oracle.rays == 0 and oracle.sides == 1


def _oracle_kernel_for(geometric: bool):
    """The breadth-first oracle kernel for the geometric oracle or any (``_specialised``)."""
    KEEP, ONE_FACE, suffix = _specialised(geometric)

    @wp.kernel(name=f"_oracle{suffix}_kernel")
    def kernel(offset: int, grain: int, size: int, qa: wp.array(dtype=wp.int32),
               qb: wp.array(dtype=wp.int32), t: Nodes, s: Surfels, sm: Sampling,
               cone: wp.array(dtype=wp.vec3), plane: wp.array(dtype=wp.vec2), threshold: float,
               weighted: int,
               weight: wp.array(dtype=wp.float32), rays: int, visibility: int, seed: int, sides: int,
               decision: wp.array(dtype=wp.int32), values: wp.array(dtype=wp.vec4),
               visible_out: wp.array(dtype=wp.vec2ub), block_next: wp.array(dtype=wp.int32),
               block_links: wp.array(dtype=wp.int32), traced: wp.array(dtype=wp.int32)):
        """A breadth-first round: each thread takes a block of ``grain`` consecutive candidate pairs
        of the ``size`` queued. Per candidate: its decision (``_decide``), and for a link its
        (transfer to a, to b, normaliser to a, to b) and the visible fractions of its transfers. Per
        block: the pairs it adds to the next queue, its links and the rays it traced (Warp's CPU
        atomics are not atomic across our threads, so no shared counter)."""
        block = wp.tid() + offset
        first = block * grain
        adds = int(0)
        made = int(0)
        block_rays = int(0)
        for i in range(first, wp.min(first + grain, size)):
            a = qa[i]
            b = qb[i]
            dec, count, out, seen, ray_count = _decide(t, s, sm, cone, plane, a, b, threshold, weighted,
                                                       weight, rays * KEEP, visibility * KEEP, seed,
                                                       sides * KEEP + ONE_FACE)
            decision[i] = dec
            adds += count
            block_rays += ray_count
            if dec == LINK:  # what the scatter reads of a link only
                made += 1
                values[i] = out
                visible_out[i] = _visible_bytes(seen)
        block_next[block] = adds
        block_links[block] = made
        traced[block] = block_rays

    return kernel


_ORACLE_KERNELS = {geometric: _oracle_kernel_for(geometric) for geometric in (False, True)}


@wp.kernel
def _scatter_kernel(offset: int, grain: int, size: int, qa: wp.array(dtype=wp.int32),
                    qb: wp.array(dtype=wp.int32), t: Nodes, decision: wp.array(dtype=wp.int32),
                    next_offset: wp.array(dtype=wp.int32), link_offset: wp.array(dtype=wp.int32),
                    values: wp.array(dtype=wp.vec4), visible_in: wp.array(dtype=wp.vec2ub), base: int,
                    next_a: wp.array(dtype=wp.int32), next_b: wp.array(dtype=wp.int32),
                    la: wp.array(dtype=wp.int32), lb: wp.array(dtype=wp.int32),
                    lvalues: wp.array(dtype=wp.vec4), lvisible: wp.array(dtype=wp.vec2ub)):
    """Block k of the oracle's blocks: its candidates' links (after the ``base`` links of earlier
    rounds) and their pairs of the next queue, in order from the block's scanned offsets."""
    block = wp.tid() + offset
    o = next_offset[block]
    j = base + link_offset[block]
    for i in range(block * grain, wp.min(block * grain + grain, size)):
        dec = decision[i]
        if dec == LINK:
            la[j] = qa[i]
            lb[j] = qb[i]
            lvalues[j] = values[i]
            lvisible[j] = visible_in[i]
            j += 1
        else:
            o = _put_split(t, dec, qa[i], qb[i], next_a, next_b, o)


# What a depth-first run (``_depth_first_kernel_for``) ends with: all its seeds done, its region of
# the link arrays full, its stack full (a bound that cannot be reached; see ``_depth_first``).
DONE, FULL, DEEP = 0, 1, 2


def _depth_first_kernel_for(geometric: bool):
    """The depth-first kernel for the geometric oracle or any (``_specialised``)."""
    KEEP, ONE_FACE, suffix = _specialised(geometric)

    @wp.kernel(name=f"_depth_first{suffix}_kernel")
    def kernel(offset: int, runs: wp.array(dtype=wp.int32), seeds_a: wp.array(dtype=wp.int32),
               seeds_b: wp.array(dtype=wp.int32), seed_next: wp.array(dtype=wp.int32),
               seed_end: wp.array(dtype=wp.int32), stack_a: wp.array(dtype=wp.int32),
               stack_b: wp.array(dtype=wp.int32), stack_top: wp.array(dtype=wp.int32),
               stack_cap: int, region: wp.array(dtype=wp.vec2i), status: wp.array(dtype=wp.int32),
               t: Nodes, s: Surfels, sm: Sampling, cone: wp.array(dtype=wp.vec3),
               plane: wp.array(dtype=wp.vec2), threshold: float, weighted: int,
               weight: wp.array(dtype=wp.float32), rays: int, visibility: int, seed: int, sides: int,
               traced: wp.array(dtype=wp.int32), la: wp.array(dtype=wp.int32),
               lb: wp.array(dtype=wp.int32), lvalues: wp.array(dtype=wp.vec4),
               lvisible: wp.array(dtype=wp.vec2ub)):
        """Run ``runs[k]``: the links below its seeds (seed_next … seed_end − 1 of seeds_a,
        seeds_b), made depth first from its own stack (stack_cap pairs from run × stack_cap;
        stack_top pairs on it) into its own region [start, end) of the link arrays, with no
        candidate arrays, scans or rounds between. Stops when done, or when its region is full (the
        pair it could not place back on its stack: a later launch goes on with a new region).
        region[run] becomes the part it filled; seed_next, stack_top and traced (rays, added) are
        kept for that launch."""
        run = runs[wp.tid() + offset]
        base = run * stack_cap
        top = stack_top[run]
        next_seed = seed_next[run]
        j = region[run][0]
        end = region[run][1]
        state = DONE
        run_rays = int(0)
        while top > 0 or next_seed < seed_end[run]:
            if top == 0:
                stack_a[base] = seeds_a[next_seed]
                stack_b[base] = seeds_b[next_seed]
                next_seed += 1
                top = 1
            top -= 1
            a = stack_a[base + top]
            b = stack_b[base + top]
            if j == end:  # no room for a link of this pair: a later launch takes it from here
                top += 1
                state = FULL
                break
            dec, count, out, seen, ray_count = _decide(t, s, sm, cone, plane, a, b, threshold, weighted,
                                                       weight, rays * KEEP, visibility * KEEP, seed,
                                                       sides * KEEP + ONE_FACE)
            run_rays += ray_count
            if dec == LINK:
                la[j] = a
                lb[j] = b
                lvalues[j] = out
                lvisible[j] = _visible_bytes(seen)
                j += 1
            elif dec != DROP:
                if top + count > stack_cap:
                    state = DEEP
                    break
                top = _put_split(t, dec, a, b, stack_a, stack_b, base + top) - base
        region[run] = wp.vec2i(region[run][0], j)
        stack_top[run] = top
        seed_next[run] = next_seed
        status[run] = state
        traced[run] += run_rays

    return kernel


_DEPTH_FIRST_KERNELS = {geometric: _depth_first_kernel_for(geometric)
                        for geometric in (False, True)}


@wp.kernel
def _directed_kernel(offset: int, la: wp.array(dtype=wp.int32), lb: wp.array(dtype=wp.int32),
                     keys: wp.array(dtype=wp.int32), values: wp.array(dtype=wp.int32)):
    """Both directions of link i: receiver a (value 2i), receiver b (value 2i + 1)."""
    i = wp.tid() + offset
    keys[2 * i] = la[i]
    values[2 * i] = 2 * i
    keys[2 * i + 1] = lb[i]
    values[2 * i + 1] = 2 * i + 1


@wp.kernel
def _csr_kernel(offset: int, count: int, m: int, keys: wp.array(dtype=wp.int32),
                values: wp.array(dtype=wp.int32), la: wp.array(dtype=wp.int32), lb: wp.array(dtype=wp.int32),
                lvalues: wp.array(dtype=wp.vec4), lvisible: wp.array(dtype=wp.vec2ub), out: LinkSet):
    """Sorted directed link j: its sender, transfer and form factor; row starts where the
    receiver changes."""
    j = wp.tid() + offset
    v = values[j]
    i = v // 2
    x = lvalues[i]
    if v % 2 == 0:
        out.sender[j] = lb[i]
        out.transfer[j] = x[0]
        out.form_factor[j] = x[2]
    else:
        out.sender[j] = la[i]
        out.transfer[j] = x[1]
        out.form_factor[j] = x[3]
    out.visible[j] = lvisible[i][v % 2]
    r = keys[j]
    prev = int(-1)
    if j > 0:
        prev = keys[j - 1]
    for q in range(prev + 1, r + 1):
        out.offsets[q] = j
    if j == count - 1:
        for q in range(r + 1, m + 1):
            out.offsets[q] = count


def leaf_luminance(tree, radiance: np.ndarray) -> np.ndarray:
    """float64[n]: the luminance of ``radiance`` (float32[n,3] per element) in leaf order."""
    lum = np.asarray(radiance, np.float64) @ np.array([0.2126, 0.7152, 0.0722])
    return lum[tree.order.numpy()]


def _leaf_area(tree) -> np.ndarray:
    return tree.nodes.area.numpy()[:int(tree.level_offsets[1])].astype(np.float64)


def weights(tree, lum: np.ndarray, contact: np.ndarray | None = None) -> wp.array:
    """float32[m] per-node weights of the oracle: the largest leaf luminance ``lum`` (float64[n],
    leaf order) in each node's subtree over the scene's area-weighted mean, clamped to
    [WEIGHT_LOW, WEIGHT_HIGH]: links touching bright nodes are refined further, links between dim
    ones stay coarser; × CONTACT_WEIGHT for a node with a leaf in a contact (``contact``: bool[n]
    per element, ``Problem.contact``), where light changes within millimetres."""
    dev = tree.device
    area = _leaf_area(tree)
    mean = float((lum * area).sum() / max(area.sum(), 1e-30))
    leaves = lum / mean if mean > 0 else np.ones(len(lum))
    weight = np.clip(_subtree_max(tree, leaves), WEIGHT_LOW, WEIGHT_HIGH)
    if contact is not None and contact.any():
        weight *= np.where(_subtree_max(tree, contact[tree.order.numpy()]) > 0, CONTACT_WEIGHT, 1.0)
    return wp.array(weight.astype(np.float32), dtype=wp.float32, device=dev.name)


def _subtree_max(tree, leaves: np.ndarray) -> np.ndarray:
    """float32[m]: the largest of ``leaves`` (per leaf, leaf order) in each node's subtree."""
    dev = tree.device
    values = np.zeros(tree.count, np.float32)
    values[:len(leaves)] = leaves
    out = wp.array(values, dtype=wp.float32, device=dev.name)
    offs = tree.level_offsets
    for lv in range(1, len(offs) - 1):
        device_mod.launch(_max_kernel, int(offs[lv + 1] - offs[lv]), [int(offs[lv]), tree.nodes, out], dev)
    return out.numpy()


def sampling(tree, lum: np.ndarray | None = None, floor: float = 0.0,
             open_fraction: np.ndarray | None = None) -> Sampling:
    """How sample leaves are drawn (``Sampling``): in proportion to area × (lum + floor × the
    area-weighted mean of lum), lum float64[n] a radiance estimate per leaf (leaf order); by area
    alone without one. ``open_fraction``: float32[n] per element (``enclosure``), 1 without."""
    dev = tree.device
    d = dev.name
    area = _leaf_area(tree)
    sm = Sampling()
    order = tree.order.numpy()
    sm.open = wp.array(np.ones(len(area), np.float32) if open_fraction is None else open_fraction[order],
                       dtype=wp.float32, device=d)
    sm.first_leaf = wp.empty(tree.count, dtype=wp.int32, device=d)
    device_mod.launch(_first_leaf_kernel, tree.count, [tree.nodes, sm.first_leaf], dev)
    if lum is None:
        glow, sm.floor = np.ones_like(area), 0.0
    else:
        glow = np.asarray(lum, np.float64)
        sm.floor = floor * float((glow * area).sum() / max(area.sum(), 1e-30))
    sm.glow = wp.array(glow.astype(np.float32), dtype=wp.float32, device=d)
    sm.cum = wp.array(np.concatenate([[0.0], np.cumsum(area * (glow + sm.floor))]), dtype=wp.float64, device=d)
    return sm


def _unsampled(device: str) -> Sampling:
    """The ``Sampling`` of an oracle without rays, which draws no sample leaves: one-element arrays
    (the first leaves and running sums cost 1.3 ms of room20k's 85 ms link build)."""
    sm = Sampling()
    sm.first_leaf = wp.zeros(1, dtype=wp.int32, device=device)
    sm.cum = wp.zeros(1, dtype=wp.float64, device=device)
    sm.glow, sm.open = (wp.zeros(1, dtype=wp.float32, device=device) for _ in range(2))
    sm.floor = 0.0
    return sm


def _int(a: wp.array, i: int) -> int:
    return int(a[i:i + 1].numpy()[0])


def _canonical_root(tree) -> int:
    out = wp.empty(1, dtype=wp.int32, device=tree.device.name)
    wp.launch(_canonical_kernel, dim=1, inputs=[0, tree.nodes, tree.root, out], device=tree.device.name)
    return _int(out, 0)


def _create(problem, oracle: Oracle, threshold: float, sm: Sampling, weight, traced: list):
    """One top-down build at ``threshold``: the link arrays (int32 a, b, vec4 values, vec2ub visible
    fractions: device arrays), the segments [start, end) of them that hold links, in order, and
    the breadth-first rounds taken; or None when the budget was exceeded on the way. ``traced[0]``
    counts the rays traced.

    Breadth first, a round per level of pairs; on the CPU, once a round's queue holds
    DEPTH_FIRST candidates, the rest depth first from them (``_depth_first``)."""
    tree, dev, stages = problem.tree, problem.device, problem.stages
    d = dev.name
    t = tree.nodes
    weighted = weight is not None
    if weight is None:
        weight = wp.zeros(1, dtype=wp.float32, device=d)
    decide = [t, problem.surfels, sm, tree.cone, tree.plane, float(threshold), int(weighted), weight,
              int(oracle.rays), int(oracle.visibility), int(oracle.seed) + 7919, int(oracle.sides)]
    root = _canonical_root(tree)
    grain = 1 if dev.is_cuda else GRAIN
    qa = wp.full(1, root, dtype=wp.int32, device=d)
    qb = wp.full(1, root, dtype=wp.int32, device=d)
    found = _link_buffers(problem, oracle)
    total, rounds = 0, 0
    while qa.size > 0:
        stages.check()
        if not dev.is_cuda and qa.size >= DEPTH_FIRST:
            made = _depth_first(problem, oracle, decide, qa, qb, found, total, traced)
            return None if made is None else (*made, rounds)
        rounds += 1
        q = qa.size
        blocks = -(-q // grain)
        decision = wp.empty(q, dtype=wp.int32, device=d)
        values = wp.empty(q, dtype=wp.vec4, device=d)
        seen = wp.empty(q, dtype=wp.vec2ub, device=d)
        block_next, block_links, rays, next_offset, link_offset = (
            wp.empty(blocks, dtype=wp.int32, device=d) for _ in range(5))
        device_mod.launch(_ORACLE_KERNELS[_geometric(oracle)], blocks,
                          [grain, q, qa, qb, *decide, decision, values, seen, block_next, block_links, rays],
                          dev, chunks=max(1, min(16, q // 262144)), on_chunk=lambda f: stages.check(),
                          uneven=True, min_split=SPLIT_ORACLE)
        with device_mod.section("links.scan", dev):
            if oracle.visibility and oracle.rays > 0:
                traced[0] += int(rays.numpy().sum(dtype=np.int64))
            wp.utils.array_scan(block_next, next_offset, inclusive=False)
            wp.utils.array_scan(block_links, link_offset, inclusive=False)
            n_next = _int(next_offset, blocks - 1) + _int(block_next, blocks - 1)
            n_links = _int(link_offset, blocks - 1) + _int(block_links, blocks - 1)
        if (total + n_links) * BYTES_PER_LINK + (q + n_next) * BYTES_PER_CANDIDATE > oracle.budget:
            return None
        next_a, next_b = (wp.empty(n_next, dtype=wp.int32, device=d) for _ in range(2))
        if found[0].shape[0] < total + n_links:
            with device_mod.section("links.grow", dev):
                found = _grown(found, total + n_links, total)
        device_mod.launch(_scatter_kernel, blocks,
                          [grain, q, qa, qb, t, decision, next_offset, link_offset, values, seen, total,
                           next_a, next_b, *found], dev, min_split=SPLIT_SCATTER)
        total += n_links
        qa, qb = next_a, next_b
    return found, [(0, total)], rounds


def _depth_first(problem, oracle: Oracle, decide: list, qa: wp.array, qb: wp.array, found: list,
                 total: int, traced: list):
    """The links below the queued pairs qa, qb (int32[q]) on the CPU, depth first
    (``_depth_first_kernel_for``): the queue cut into runs (``_run_count``), taken in turn by the
    threads;
    each run writes its links to its own region of ``found`` (after the ``total`` made so far), an
    equal share of the room the budget leaves. A run whose region fills up goes on in a
    later launch, in the largest room then left. Returns ``found`` and the segments [start, end)
    of it that hold links, in order (deterministic: every run's links, and the regions they go
    to, follow from the queue alone), or None when the links do not fit the budget.

    This saves the breadth-first rounds' candidate arrays, scans and scatter, and each round's
    launches (room20k's build ~15 % faster; bench/results/history.md)."""
    tree, dev, stages = problem.tree, problem.device, problem.stages
    d = dev.name
    q = qa.size
    n_runs = min(q, _run_count(problem.elements.count, oracle))
    bounds = (np.arange(n_runs + 1, dtype=np.int64) * q) // n_runs
    seed_next = wp.array(bounds[:-1].astype(np.int32), dtype=wp.int32, device=d)
    seed_end = wp.array(bounds[1:].astype(np.int32), dtype=wp.int32, device=d)
    cap = _stack_cap(tree)
    stack_a, stack_b = (wp.empty(n_runs * cap, dtype=wp.int32, device=d) for _ in range(2))
    stack_top, status, rays = (wp.zeros(n_runs, dtype=wp.int32, device=d) for _ in range(3))
    region = wp.zeros(n_runs, dtype=wp.vec2i, device=d)
    # free [start, end) pieces of the link arrays (int32 indices)
    room = [(total, min(found[0].shape[0], oracle.budget // BYTES_PER_LINK, 2**31 - 1))]
    parts = [[] for _ in range(n_runs)]  # per run, the segments it filled, in order
    pending = np.arange(n_runs, dtype=np.int32)
    while pending.size:
        stages.check()
        regions = _regions(room, pending.size)
        if regions is None:
            return None
        runs, waiting = pending[:len(regions)], pending[len(regions):]
        region.numpy()[runs] = regions
        device_mod.launch(_DEPTH_FIRST_KERNELS[_geometric(oracle)], runs.size,
                          [wp.array(runs, dtype=wp.int32, device=d), qa, qb, seed_next, seed_end, stack_a,
                           stack_b, stack_top, cap, region, status, *decide, rays, *found],
                          dev, chunks=1 if oracle.rays == 0 else DEPTH_WAVES,
                          on_chunk=lambda f: stages.check(), one_by_one=True)
        state = status.numpy()[runs]
        if (state == DEEP).any():
            raise RuntimeError("links: a depth-first run outgrew its stack (a bug: it is sized for the "
                               "deepest walk)")
        filled = region.numpy()[runs]
        for run, (start, end), (_, used) in zip(runs, regions, filled):
            parts[run].append((int(start), int(used)))
            if used < end:
                room.append((int(used), int(end)))
        pending = np.concatenate([runs[state == FULL], waiting])
    if oracle.visibility and oracle.rays > 0:
        traced[0] += int(rays.numpy().sum(dtype=np.int64))
    segments = [(0, total)] + [seg for run in parts for seg in run]
    return found, [(a, b) for a, b in segments if b > a]


def _run_count(elements: int, oracle: Oracle) -> int:
    """Depth-first runs of a build over ``elements`` elements: DEPTH_RUNS with rays, else one per
    RUN_ELEMENTS elements within [MIN_RUNS, GEOMETRIC_RUNS] (see DEPTH_RUNS)."""
    if oracle.rays > 0:
        return DEPTH_RUNS
    return int(np.clip(elements // RUN_ELEMENTS, MIN_RUNS, GEOMETRIC_RUNS))


def _regions(room: list, count: int) -> np.ndarray | None:
    """int32[k,2]: regions [start, end) of the link arrays for the first k ≤ ``count`` waiting runs,
    taken from ``room`` (free [start, end) pieces, updated): equal shares of the largest piece
    where each gets MIN_REGION links or the other pieces are smaller than a share, else the
    largest pieces, one each; None when no room is left."""
    room[:] = sorted((r for r in room if r[1] > r[0]), key=lambda r: r[1] - r[0], reverse=True)
    if not room:
        return None
    start, end = room[0]
    share = (end - start) // count
    next_piece = room[count - 1][1] - room[count - 1][0] if len(room) >= count else 0
    if share >= MIN_REGION or (share >= 1 and next_piece < share):
        room.pop(0)
        cuts = start + share * np.arange(count + 1, dtype=np.int64)
        cuts[-1] = end
        return np.stack([cuts[:-1], cuts[1:]], axis=1).astype(np.int32)
    taken, room[:] = room[:count], room[count:]
    return np.array(taken, dtype=np.int32)


def _stack_cap(tree) -> int:
    """Pairs a depth-first run's stack can hold at most: each split (one side one level down)
    leaves at most the most pairs a split makes less one on it, over at most twice the tree's
    levels of splits, plus the seed. A split makes k or k(k + 1)/2 pairs of a node's k children
    (``children``: past one-child cells, the first node below with more than one)."""
    nodes = tree.nodes
    k = int(np.max(nodes.child_end.numpy() - nodes.first_child.numpy()))  # leaves: −1 − (−1)
    most = max(k * (k + 1) // 2, 1)
    return 2 * tree.levels * (most - 1) + 2


def _link_buffers(problem, oracle: Oracle) -> list:
    """Where a build's links go as they are made (int32 a, b, vec4 values, vec2ub visible): on the
    CPU room for as many as the budget allows — memory the operating system hands out only where
    it is written, so each round writes its links in place (no copies: 39 ms of a 100 k-element
    room's 0.56 s went to joining its rounds' links) —, on a GPU a start grown as needed."""
    dev = problem.device
    count = 8 * problem.elements.count
    if not dev.is_cuda:
        available = device_mod.free_memory(dev) or 0
        count = max(count, min(oracle.budget // BYTES_PER_LINK, available // LINK_ARRAYS_BYTES))
    return [wp.empty(count, dtype=dt, device=dev.name) for dt in (wp.int32, wp.int32, wp.vec4, wp.vec2ub)]


def _grown(arrays: list, need: int, keep: int) -> list:
    """New arrays like ``arrays`` with room for ``need`` items (at least twice as many as before)
    holding their first ``keep``."""
    grown = [wp.empty(max(need, 2 * a.shape[0]), dtype=a.dtype, device=a.device) for a in arrays]
    for g, a in zip(grown, arrays):
        wp.copy(g, a, count=keep)
    return grown


@wp.func
def _segment_of(seg_rank: wp.array(dtype=wp.int32), r: int) -> int:
    """The segment holding the link of rank r: the last k with seg_rank[k] ≤ r."""
    lo = int(0)
    hi = seg_rank.shape[0] - 1
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if seg_rank[mid] <= r:
            lo = mid
        else:
            hi = mid
    return lo


@wp.func
def _segment_from(seg_rank: wp.array(dtype=wp.int32), g: int, r: int) -> int:
    """The segment holding the link of rank r, looked for from segment g (at or before it) on."""
    while r >= seg_rank[g + 1]:
        g += 1
    return g


@wp.kernel
def _count_kernel(offset: int, run: int, pairs: int, m: int, seg_start: wp.array(dtype=wp.int32),
                  seg_rank: wp.array(dtype=wp.int32), la: wp.array(dtype=wp.int32),
                  lb: wp.array(dtype=wp.int32), counts: wp.array(dtype=wp.int32)):
    """Run t (the links of rank t·run … t·run + run − 1, in the segments seg_start of the link
    arrays, seg_rank the ranks they start at): how many of its directed links each node
    receives, in row t of counts (int32[runs·m], no other thread writes it)."""
    t = wp.tid() + offset
    row = t * m
    r0 = t * run
    g = _segment_of(seg_rank, r0)
    for r in range(r0, wp.min(r0 + run, pairs)):
        g = _segment_from(seg_rank, g, r)
        i = seg_start[g] + r - seg_rank[g]
        counts[row + la[i]] += 1
        counts[row + lb[i]] += 1


@wp.kernel
def _total_kernel(offset: int, runs: int, m: int, counts: wp.array(dtype=wp.int32),
                  totals: wp.array(dtype=wp.int32)):
    """Node r: the directed links it receives, over all runs."""
    r = wp.tid() + offset
    total = int(0)
    for t in range(runs):
        total += counts[t * m + r]
    totals[r] = total


@wp.kernel
def _cursor_kernel(offset: int, runs: int, m: int, offsets: wp.array(dtype=wp.int32),
                   counts: wp.array(dtype=wp.int32)):
    """Node r: where run t's first link to it goes (after those of the runs before), in place of
    run t's count."""
    r = wp.tid() + offset
    at = offsets[r]
    for t in range(runs):
        k = counts[t * m + r]
        counts[t * m + r] = at
        at += k


@wp.kernel
def _place_kernel(offset: int, run: int, pairs: int, m: int, seg_start: wp.array(dtype=wp.int32),
                  seg_rank: wp.array(dtype=wp.int32), la: wp.array(dtype=wp.int32),
                  lb: wp.array(dtype=wp.int32), lvalues: wp.array(dtype=wp.vec4),
                  lvisible: wp.array(dtype=wp.vec2ub), cursor: wp.array(dtype=wp.int32), out: LinkSet):
    """Run t's directed links (as ``_count_kernel``), in order, at their receivers' next places
    (``cursor``: row t of ``_cursor_kernel``'s places, advanced as they fill): sender, transfer,
    normaliser, visible."""
    t = wp.tid() + offset
    row = t * m
    r0 = t * run
    g = _segment_of(seg_rank, r0)
    for r in range(r0, wp.min(r0 + run, pairs)):
        g = _segment_from(seg_rank, g, r)
        i = seg_start[g] + r - seg_rank[g]
        a = la[i]
        b = lb[i]
        x = lvalues[i]
        v = lvisible[i]
        _place(out, cursor, row + a, b, x[0], x[2], v[0])
        _place(out, cursor, row + b, a, x[1], x[3], v[1])


@wp.func
def _place(out: LinkSet, cursor: wp.array(dtype=wp.int32), slot: int, sender: int, transfer: float,
           form_factor: float, visible: wp.uint8):
    """One directed link at its receiver's next place (``cursor[slot]``, then advanced)."""
    j = cursor[slot]
    cursor[slot] = j + 1
    out.sender[j] = sender
    out.transfer[j] = transfer
    out.form_factor[j] = form_factor
    out.visible[j] = visible


def _by_receiver(dev, n: int, found: list, segments: list) -> LinkSet:
    """Both directions of the links in ``segments`` ([start, end) pieces, in order) of ``found``
    (int32 node pairs a, b, vec4 values, vec2ub visible fractions × 255; see ``_scatter_kernel``) sorted
    by receiver into the ``LinkSet`` over n nodes; a receiver's links in the order of the
    directed links, 2i (receiver a[i]) and 2i + 1 (b[i]), i in segment order.

    On a GPU (one segment) a radix sort of the directed links by receiver. On the CPU a stable
    counting sort, one run of the links per thread: each thread counts its run's links per
    receiver, the counts give each run's place in every row, and each thread places its run there
    (measured on a 10 k room: 0.015–0.019 CPU s against 0.042–0.048 for the radix sort, same
    links)."""
    d = dev.name
    pairs = sum(end - start for start, end in segments)
    count = 2 * pairs
    out = LinkSet()
    out.offsets = wp.zeros(n + 1, dtype=wp.int32, device=d)
    out.sender = wp.empty(max(count, 1), dtype=wp.int32, device=d)
    out.transfer = wp.empty(max(count, 1), dtype=wp.float32, device=d)
    out.form_factor = wp.empty(max(count, 1), dtype=wp.float32, device=d)
    out.visible = wp.empty(max(count, 1), dtype=wp.uint8, device=d)
    if dev.is_cuda:
        la, lb, lvalues, lvisible = (x[:pairs] for x in found)
        keys = wp.empty(max(2 * count, 2), dtype=wp.int32, device=d)
        values = wp.empty(max(2 * count, 2), dtype=wp.int32, device=d)
        device_mod.launch(_directed_kernel, pairs, [la, lb, keys, values], dev)
        with device_mod.section("links.sort", dev):
            wp.utils.radix_sort_pairs(keys, values, count, end_bit=max(1, int(n).bit_length()))
        device_mod.launch(_csr_kernel, count, [count, n, keys, values, la, lb, lvalues, lvisible, out], dev)
        return out
    starts = np.array([start for start, _ in segments] or [0], np.int32)
    ranks = np.concatenate([[0], np.cumsum([end - start for start, end in segments], dtype=np.int64)])
    seg_start = wp.array(starts, dtype=wp.int32, device=d)
    seg_rank = wp.array(ranks.astype(np.int32) if len(segments) else np.zeros(2, np.int32), dtype=wp.int32,
                        device=d)
    runs = dev.threads
    run = max(1, -(-pairs // runs))
    counts = wp.zeros(runs * n, dtype=wp.int32, device=d)  # [run, receiver], then where each run's links go
    totals = wp.zeros(n + 1, dtype=wp.int32, device=d)
    la, lb, lvalues, lvisible = found
    device_mod.launch(_count_kernel, runs, [run, pairs, n, seg_start, seg_rank, la, lb, counts], dev)
    device_mod.launch(_total_kernel, n, [runs, n, counts, totals], dev)
    with device_mod.section("links.sort", dev):
        wp.utils.array_scan(totals, out.offsets, inclusive=False)
    device_mod.launch(_cursor_kernel, n, [runs, n, out.offsets, counts], dev)
    device_mod.launch(_place_kernel, runs,
                      [run, pairs, n, seg_start, seg_rank, la, lb, lvalues, lvisible, counts, out], dev)
    return out


def build(problem, oracle: Oracle, radiance: np.ndarray | None = None) -> Links:
    """The links of ``problem``'s tree chosen by ``oracle``. ``radiance`` (float32[n,3] per
    element, a first estimate; None: geometric only) weights the oracle (``weights``) and draws
    the sample leaves (``sampling``). Warns through ``problem.stages`` when the budget raised the
    threshold; BakeError when not even the coarsest links fit."""
    tree, dev, stages = problem.tree, problem.device, problem.stages
    d = dev.name
    t0 = time.perf_counter()
    lum = None if radiance is None else leaf_luminance(tree, radiance)
    weight = None if lum is None else weights(tree, lum, problem.contact)
    # a cluster's visibility is sampled over its open leaves: those buried inside a closed
    # surface get their own share at the push (``enclosure``)
    sm = (sampling(tree, lum, SAMPLE_FLOOR, problem.open_fraction.numpy() if oracle.visibility else None)
          if oracle.rays > 0 else _unsampled(d))
    threshold = float(oracle.threshold)
    traced = [0]
    # Over the budget, the threshold is raised in trial builds without rays (cheap; the links a
    # partial visibility splits need a margin), then the links are made for real.
    trial = Oracle(threshold, rays=0, visibility=False, budget=int(oracle.budget / TRIAL_MARGIN),
                   sides=oracle.sides)
    made = _create(problem, oracle, threshold, sm, weight, traced)
    while made is None:
        if threshold >= COARSEST:
            raise BakeError(f"the links of {problem.elements.count} elements do not fit the link "
                            f"budget of {oracle.budget / 2**20:.0f} MB even at the coarsest "
                            f"threshold: raise the link memory (--link-memory)")
        threshold = min(threshold * RAISE, COARSEST)
        if threshold < COARSEST and _create(problem, trial, threshold, sm, weight, traced) is None:
            continue
        made = _create(problem, oracle, threshold, sm, weight, traced)
    found, segments, rounds = made
    pairs = sum(end - start for start, end in segments)
    if threshold > oracle.threshold:
        stages.warn(f"the links did not fit the link budget of {oracle.budget / 2**20:.0f} MB at "
                    f"threshold {oracle.threshold:g}: {2 * pairs} links made at threshold "
                    f"{threshold:g} (coarser, less accurate); raise --link-memory for the finer links")

    out = _by_receiver(dev, tree.count, found, segments)
    if dev.is_cuda:
        wp.synchronize_device(d)
    return Links(set=out, pairs=pairs, threshold=threshold, rounds=rounds,
                 rays_traced=traced[0],
                 seconds=time.perf_counter() - t0)
