"""Directional bins over the sphere of directions around a surface element (antiradiance, implicit
visibility).

The bins are the cells of an N×N equal-area octahedral map of the unit sphere (Clarberg 2008: a
direction d with r = √(1 − |d.z|) and φ = atan2(|d.y|, |d.x|) goes to (a, b) = (r − b, 2rφ/π)
where d.z ≥ 0, (1 − b, 1 − a) below, signed by d.x and d.y), taken in the element's frame with its
normal as the map's x axis: the front hemisphere (along the normal) is then exactly the half u ≥ 0
of the square and the back hemisphere the other half, so no bin straddles the surface, and every
bin covers the same solid angle, 4π/N². N = 8, 16, 32 give 64, 256, 1024 bins.

A sender seen from a receiver is not one direction but a cone: deposits spread over the bins the
cone (its centre direction, the half angle of its solid angle) overlaps, weighted by the overlap,
estimated with CONE_SAMPLES directions spread evenly over the cone — not by the centre direction
alone, which aliases as bins get small (ALGORITHMS.md §6).

Close up a cone from a node's centre says little: a lamp element 1 mm under a ceiling element
sees it fill its hemisphere where the two overlap and nowhere else. A leaf near a node and nearly
parallel to it (``near``) has its cone made from points spread over its own surface
(``cell_point``), each point's around the perpendicular to the node's plane where it lies under
the node. Two leaves in contact (``contact``: one's points over the other's surface within a
tenth of its size) exchange what the reference solver's rays would let through: an element
whose element point lies over a leaf in contact before its face is hidden (``visible``) and
shows none of its radiance — a ceiling cell lit hot at its vertex by the lamp's back 1 mm below,
reaching past the lamp's rim; cancelling its light by the lamp's antiradiance leaked round the
rim — and the leaves under a hidden element stop the rest of what it shows (its antiradiance),
shared by how many of its surface's points lie over each.

Once per link build, ``masks`` lists for every directed link the bins its two cones cover (what
antiradiance gathers from and deposits into) and what its arrivals count for (``Masks.gain``);
``capacity`` gives each bin's form factor from its element (what implicit visibility fills a bin
up to).
"""
from __future__ import annotations

import math

import warp as wp

from . import device as device_mod
from .formfactor import tangent_frame
from .hierarchy import Nodes
from .surfels import Surfels, fan_centre, fan_sample, fan_triangle

wp.set_module_options({"enable_backward": False})  # no gradients: halves compile time

SIZES = {64: 8, 256: 16, 1024: 32}
# Directions a cone is sampled with: a centre and rings of a Fibonacci spiral over the cone's cap.
CONE_SAMPLES = 16
GOLDEN = math.pi * (3.0 - math.sqrt(5.0))


def side(bins: int) -> int:
    """N of an N×N map of ``bins`` bins (64, 256 or 1024)."""
    if bins not in SIZES:
        raise ValueError(f"directional bins must be one of {', '.join(map(str, SIZES))}, not {bins}")
    return SIZES[bins]


@wp.func
def frame_dir(n: wp.vec3, d: wp.vec3) -> wp.vec3:
    """World direction d in the frame of an element with unit normal n: (along n, t1, t2)."""
    t1, t2 = tangent_frame(n)
    return wp.vec3(wp.dot(d, n), wp.dot(d, t1), wp.dot(d, t2))


@wp.func
def bin_of(local: wp.vec3, size: int) -> int:
    """The bin of a unit direction given in an element's frame (x along the normal); front
    hemisphere bins are those whose column (bin % size) is at least size / 2."""
    r = wp.sqrt(wp.max(1.0 - wp.abs(local[2]), 0.0))
    phi = wp.atan2(wp.abs(local[1]), wp.abs(local[0]))
    b = r * phi * 0.6366197723675814  # 2/π
    a = r - b
    if local[2] < 0.0:
        a, b = 1.0 - b, 1.0 - a
    u = wp.where(local[0] < 0.0, -a, a)
    v = wp.where(local[1] < 0.0, -b, b)
    i = wp.clamp(int(wp.floor((u + 1.0) * 0.5 * float(size))), 0, size - 1)
    j = wp.clamp(int(wp.floor((v + 1.0) * 0.5 * float(size))), 0, size - 1)
    return j * size + i


@wp.func
def front(b: int, size: int) -> bool:
    """Whether bin b looks into the front hemisphere (along the normal)."""
    return b % size >= size / 2


@wp.func
def cone_sample(k: int, axis: wp.vec3, cos_half: float) -> wp.vec3:
    """Direction k of CONE_SAMPLES spread evenly (equal solid angle) over the cone around unit
    ``axis`` whose half angle has cosine ``cos_half``."""
    return cone_sample_of(k, CONE_SAMPLES, axis, cos_half, 0.0)


@wp.func
def cone_sample_of(k: int, count: int, axis: wp.vec3, cos_half: float, turn: float) -> wp.vec3:
    """Direction k of ``count`` spread evenly over the cone (as ``cone_sample``), the spiral
    turned by ``turn`` (radians) about the axis."""
    t1, t2 = tangent_frame(axis)
    z = 1.0 - (float(k) + 0.5) / float(count) * (1.0 - cos_half)
    r = wp.sqrt(wp.max(1.0 - z * z, 0.0))
    phi = float(k) * GOLDEN + turn
    return axis * z + t1 * (r * wp.cos(phi)) + t2 * (r * wp.sin(phi))


@wp.func
def cone_cos_half(solid_angle: float) -> float:
    """cos of the half angle of the cone of ``solid_angle`` (sr): Ω = 2π(1 − cos α)."""
    return wp.clamp(1.0 - solid_angle / 6.283185307179586, -1.0, 1.0)


def solid_angle(bins: int) -> float:
    """The solid angle (sr) of one of ``bins`` bins."""
    return 4.0 * math.pi / bins


# The R2 sequence's generator (the plastic number): low-discrepancy points of the unit square.
PLASTIC = 1.32471795724474602596


@wp.func
def cosine_r2(n: wp.vec3, tu: wp.vec3, tv: wp.vec3, shift: wp.vec2, k: int) -> wp.vec3:
    """Direction k of a cosine-distributed R2 set about unit n (tangents tu, tv), the set shifted
    by ``shift`` (in [0, 1)², one per receiver so receivers' sets differ)."""
    u0 = wp.mod(shift[0] + float(k) / PLASTIC, 1.0)
    u1 = wp.mod(shift[1] + float(k) / (PLASTIC * PLASTIC), 1.0)
    r = wp.sqrt(u0)
    phi = 2.0 * math.pi * u1
    return tu * (r * wp.cos(phi)) + tv * (r * wp.sin(phi)) + n * wp.sqrt(wp.max(1.0 - u0, 0.0))


@wp.func
def to_world(n: wp.vec3, local: wp.vec3) -> wp.vec3:
    """``frame_dir``'s inverse: a direction given in the frame of unit normal n, in world axes."""
    t1, t2 = tangent_frame(n)
    return n * local[0] + t1 * local[1] + t2 * local[2]


@wp.func
def bin_dir(b: int, size: int) -> wp.vec3:
    """The unit direction at the centre of bin b, in the element's frame (``bin_of``'s inverse)."""
    return cell_dir(b, size, 0.5, 0.5)


@wp.func
def cell_dir(b: int, size: int, fu: float, fv: float) -> wp.vec3:
    """The unit direction at (fu, fv) ∈ [0, 1)² within bin b, in the element's frame (the map is
    equal-area: uniform (fu, fv) are uniform directions over the bin)."""
    u = (float(b % size) + fu) / float(size) * 2.0 - 1.0
    v = (float(b // size) + fv) / float(size) * 2.0 - 1.0
    a = wp.abs(u)
    c = wp.abs(v)
    z = float(1.0)
    if a + c > 1.0:  # the folded lower half (local z < 0)
        a, c = 1.0 - c, 1.0 - a
        z = -1.0
    r = a + c
    phi = float(0.0)
    if r > 0.0:
        phi = c / r * 1.5707963267948966
    q = r * wp.sqrt(wp.max(2.0 - r * r, 0.0))
    return wp.vec3(wp.where(u < 0.0, -1.0, 1.0) * q * wp.cos(phi),
                   wp.where(v < 0.0, -1.0, 1.0) * q * wp.sin(phi), z * (1.0 - r * r))


# Directions per bin a cone's solid angle is sampled with where it covers many bins (``cone_count``),
# and the most directions one cone gets.
PER_BIN = 8
MAX_SAMPLES = 4096
# Sub-cells per side over which a bin's cosine-weighted solid angle is integrated.
CELL_STEPS = 8


@wp.kernel
def _capacity_kernel(offset: int, size: int, bin_omega: float, out: wp.array(dtype=wp.float32)):
    b = wp.tid() + offset
    acc = float(0.0)
    for i in range(CELL_STEPS):
        for j in range(CELL_STEPS):
            d = cell_dir(b, size, (float(i) + 0.5) / float(CELL_STEPS), (float(j) + 0.5) / float(CELL_STEPS))
            acc += wp.max(d[0], 0.0)
    out[b] = acc / float(CELL_STEPS * CELL_STEPS) * bin_omega * 0.3183098861837907


def capacity(bins: int, device) -> wp.array:
    """float32[bins]: each bin's form factor from its element, (1/π)∫ max(cos, 0) dω over the bin
    (0 for back bins; the front bins sum to 1): the most lighting per unit radiance a bin passes."""
    out = wp.empty(bins, dtype=wp.float32, device=device.name)
    device_mod.launch(_capacity_kernel, bins, [side(bins), solid_angle(bins), out], device)
    return out


@wp.func
def cone_count(omega: float, bin_omega: float) -> int:
    """Directions to sample a cone of solid angle ``omega`` with against bins of ``bin_omega``
    (sr): PER_BIN per bin it covers, at least CONE_SAMPLES, at most MAX_SAMPLES."""
    return wp.clamp(int(wp.ceil(float(PER_BIN) * omega / bin_omega)), CONE_SAMPLES, MAX_SAMPLES)


@wp.func
def cone_to(p: wp.vec3, q: wp.vec3, nq: wp.vec3, area: float, spread: float, lean: float):
    """(unit axis, solid angle (sr)) of the cone that disks of total ``area`` (m²) at q, mean unit
    normal nq and normal ``spread`` (1 aligned, 0 an isotropic blob), subtend at p, either face:
    toward q, a disk of their projected area facing p, 2π(1 − d / √(d² + A_proj/π)) — exact on a
    disk's axis, A_proj/d² far away — or, where p lies over the disk close to its plane (a ceiling
    1 mm above a lamp), at least ``lean`` × what the part of the disk right under p subtends,
    which fills the hemisphere: then with the axis leaning by ``lean`` from the direction to q
    toward the perpendicular from p to the plane (from over a disk's rim, q lies near the
    horizon; straight across is what the part under p fills). ``lean`` ∈ [0, 1]: 1 where p's own
    surface is parallel to the disk's, 0 where it is at right angles (then the disk's part
    "under" p would lie beside p's surface, not over it)."""
    d = q - p
    d2 = wp.dot(d, d)
    c = float(1.0)
    height = wp.dot(nq, d)
    h = wp.abs(height)
    u = nq
    if d2 > 0.0:
        c = h / wp.sqrt(d2)
        u = d / wp.sqrt(d2)
    r2 = area * (spread * c + (1.0 - spread) * 0.25) * 0.3183098861837907
    if r2 <= 0.0:
        return u, 0.0
    omega = 6.283185307179586 * (1.0 - wp.sqrt(d2 / (d2 + r2)))
    under = spread * area * 0.3183098861837907 - (d2 - h * h)  # radius² of the disk part under p
    if under > 0.0:
        below = lean * 6.283185307179586 * (1.0 - h / wp.sqrt(h * h + under))
        if below > omega:
            omega = below
            if h > 0.0:
                u = wp.normalize(u * (1.0 - lean) + nq * (wp.sign(height) * lean))
    return u, omega


@wp.func
def subtended(p: wp.vec3, q: wp.vec3, nq: wp.vec3, area: float, spread: float) -> float:
    """The solid angle (sr) of ``cone_to`` with the full part under p."""
    u, omega = cone_to(p, q, nq, area, spread, 1.0)
    return omega


@wp.func
def cone_bin(k: int, count: int, n: wp.vec3, axis: wp.vec3, omega: float, size: int, turn: float) -> int:
    """The bin, in the frame of unit normal n, of direction k of ``count`` over the cone around
    unit ``axis`` of solid angle ``omega`` (sr, at most the hemisphere), turned by ``turn``
    (``cone_sample_of``): a link's deposits go 1/count to each.
    Directions on the other side of the surface than the axis are mirrored back across it: a
    near node's cone, wider than the node, must not spill over the horizon."""
    local = frame_dir(n, cone_sample_of(k, count, axis, cone_cos_half(wp.min(omega, 6.283185307179586)), turn))
    if (local[0] < 0.0) != (wp.dot(axis, n) < 0.0):
        local = wp.vec3(-local[0], local[1], local[2])
    return bin_of(local, size)


# A receiving cone is widened to this many times its sender's solid angle: round cones leave gaps
# between neighbouring senders that their shapes do not, and a widened cone covers the gaps (the
# overlaps are divided out by the bins' coverage, ``antiradiance``).
COVER = 2.0


@wp.struct
class Masks:
    """The bins each directed link j of a ``links.LinkSet`` spreads over, made once per link build
    (``masks``), as lists (CSR): receive[receive_offsets[j] … receive_offsets[j+1]−1] (uint16)
    the bins, in the receiver node's frame, of ``cone_count`` directions over the cone the sender
    subtends at the receiver's centre (where the light arrives from), widened by COVER;
    send[send_offsets[j] …]
    the bins, in the sender node's frame, of the cone the receiver subtends at the sender's centre
    (where the light leaves to); omega: float32[E] the receiving cone's solid angle (sr); gain:
    float32[E] what the arriving radiance counts for against the coverage it claims (``contact``;
    1 for all but leaves in contact). Each direction stands for an equal share of its cone."""

    receive_offsets: wp.array(dtype=wp.int32)
    receive: wp.array(dtype=wp.uint16)
    send_offsets: wp.array(dtype=wp.int32)
    send: wp.array(dtype=wp.uint16)
    omega: wp.array(dtype=wp.float32)
    gain: wp.array(dtype=wp.float32)


@wp.func
def centre(t: Nodes, s: Surfels, x: int) -> wp.vec3:
    """Where node x's cones start: a leaf's surface centre (the middle of its share of its
    triangles: its element sits on a vertex, which at a mesh's rim is the surface's corner), an
    inner node's centre."""
    if t.descend[x] < 0:
        e = t.element[x]
        return fan_centre(e, s.vertex, s.fan_offsets, s.fan_triangles, s.tris, s.points)
    return t.position[x]


# A leaf closer to a node than NEAR × their radii summed has its cone toward that node made from
# NEAR_POINTS points spread over the leaf's own surface, not from its centre: under a ceiling
# element 1 mm above, a lamp element sees it fill the hemisphere where the two overlap and not at
# all beyond, which the centre's single, nearly edge-on cone does not show (the light the lamp
# sends on as antiradiance would leave sideways and leak past it).
NEAR = 2.0
NEAR_POINTS = 16
# ... and when their planes are within 60° of parallel: a node at right angles (a wall over a
# floor) fills no more of the view close up, and its centre cone measured best there.
NEAR_PARALLEL = 0.5
# ... and when x lies off b's plane by more than NEAR_GAP × b's radius: a node in x's own plane
# (its neighbours on one surface) sends it nothing.
NEAR_GAP = 1e-3
# The R2 sequence's steps (Roberts 2018): evenly spread points of the unit square.
R2_U, R2_V = 0.7548776662466927, 0.5698402909980532


@wp.func
def cell_point(s: Surfels, e: int, k: int, count: int) -> wp.vec3:
    """Point k of ``count`` spread evenly over element e's own share of its triangles (where its
    vertex's barycentric coordinate is the largest: the shares of a mesh's elements tile it); its
    vertex when it has no triangles."""
    v = s.vertex[e]
    if s.fan_offsets[e + 1] == s.fan_offsets[e]:
        return s.points[v]
    tri = fan_triangle(s, e, (float(k) + 0.5) / float(count))
    u1 = wp.mod(float(k) * R2_U + 0.5, 1.0)
    u2 = wp.mod(float(k) * R2_V + 0.5, 1.0)
    r = wp.sqrt(u1)
    w = wp.vec3(1.0 - r, r * (1.0 - u2), r * u2)  # a uniform point's barycentric coordinates
    top = 0
    if w[1] > w[top]:
        top = 1
    if w[2] > w[top]:
        top = 2
    own = 0
    if s.tris[3 * tri + 1] == v:
        own = 1
    if s.tris[3 * tri + 2] == v:
        own = 2
    # rotate the coordinates so the largest falls on e's vertex: the third where another corner's
    # coordinate is the largest maps onto e's third, area for area
    q = wp.vec3(0.0)
    for c in range(3):
        q += s.points[s.tris[3 * tri + (c - top + own + 3) % 3]] * w[c]
    return q


@wp.func
def near(t: Nodes, x: int, b: int) -> bool:
    """Whether leaf x's cone toward node b is made from points over x's surface: b within NEAR ×
    their radii, its plane within 60° of parallel to x's (NEAR_PARALLEL) and x off it
    (NEAR_GAP)."""
    if t.descend[x] >= 0 or wp.abs(wp.dot(t.normal[x], t.normal[b])) < NEAR_PARALLEL:
        return False
    reach = NEAR * (wp.sqrt(t.area[x] * 0.3183098861837907) + t.radius[b])
    d = t.position[b] - t.position[x]
    return wp.dot(d, d) < reach * reach and wp.abs(wp.dot(t.normal[b], d)) > NEAR_GAP * t.radius[b]


@wp.func
def point_cone(t: Nodes, s: Surfels, p: wp.vec3, n: wp.vec3, b: int, widen: float):
    """(unit direction from point p to node b's centre, b's solid angle at p × ``widen``, at most
    2π sr) (``subtended``); n the direction used when p is the centre itself."""
    q = centre(t, s, b)
    d = q - p
    length = wp.length(d)
    u = wp.vec3(n)
    if length > 0.0:
        u = d / length
    return u, wp.min(subtended(p, q, t.normal[b], t.area[b], t.spread[b]) * widen, 6.283185307179586)


@wp.func
def near_cone(t: Nodes, s: Surfels, x: int, k: int, b: int, widen: float):
    """(unit axis, solid angle (sr) × ``widen``) of the cone node b subtends at leaf x's point k of
    NEAR_POINTS (``cone_to``, leaning as far as x's and b's planes are parallel, and not where b's
    plane lies on the other side of x's surface than b's centre: neighbours on a curved surface).
    The solid angle is not capped at the hemisphere the directions are drawn from (``cone_bin``):
    a cone that fills it claims more, so the bins' coverage exceeds 1 despite the sampling's
    noise, and divides out (``antiradiance``)."""
    p = cell_point(s, t.element[x], k, NEAR_POINTS)
    n = t.normal[x]
    q = centre(t, s, b)
    d = q - p
    if wp.length_sq(d) == 0.0:
        return n, subtended(p, q, t.normal[b], t.area[b], t.spread[b]) * widen
    lean = wp.abs(wp.dot(n, t.normal[b]))
    if wp.dot(n, t.normal[b]) * wp.dot(t.normal[b], d) * wp.dot(n, d) <= 0.0:
        lean = 0.0  # the way to b's plane and to b's centre lie on either side of x's surface
    u, omega = cone_to(p, q, t.normal[b], t.area[b], t.spread[b], lean)
    return u, omega * widen


# Two leaves are in contact where one's points lie over the other's surface closer than
# CONTACT_GAP × its size (√area): a lamp 1 mm under a ceiling of 3 cm cells.
CONTACT_GAP = 0.1
# Points over each leaf that decide a contact's shares.
CONTACT_POINTS = 64


@wp.func
def in_cell(s: Surfels, e: int, p: wp.vec3) -> bool:
    """Whether point p, projected onto element e's triangles, falls in e's own share of one of them
    (where e's vertex's barycentric coordinate is the largest) within CONTACT_GAP × √area of its
    plane."""
    v = s.vertex[e]
    gap = CONTACT_GAP * wp.sqrt(s.area[e])
    for k in range(s.fan_offsets[e], s.fan_offsets[e + 1]):
        tri = s.fan_triangles[k]
        ia = s.tris[3 * tri]
        ib = s.tris[3 * tri + 1]
        ic = s.tris[3 * tri + 2]
        a = s.points[ia]
        b = s.points[ib]
        c = s.points[ic]
        n = wp.cross(b - a, c - a)
        nn = wp.dot(n, n)
        if nn > 0.0 and wp.abs(wp.dot(p - a, n)) <= gap * wp.sqrt(nn):
            wa = wp.dot(wp.cross(c - b, p - b), n) / nn
            wb = wp.dot(wp.cross(a - c, p - c), n) / nn
            wc = 1.0 - wa - wb
            own = wa
            if ib == v:
                own = wb
            if ic == v:
                own = wc
            if wp.min(wp.min(wa, wb), wc) >= 0.0 and own >= wp.max(wp.max(wa, wb), wc):
                return True
    return False


@wp.func
def inner_over(s: Surfels, x: int, b: int) -> int:
    """How many of CONTACT_POINTS points of element b's surface the reference's visibility rays aim
    at (the half of its triangles nearest its vertex, ``fan_sample``) lie over element x
    (``in_cell``)."""
    over = int(0)
    for k in range(CONTACT_POINTS):
        u0 = (float(k) + 0.5) / float(CONTACT_POINTS)
        if in_cell(s, x, fan_sample(s, b, u0, wp.mod(float(k) * R2_U + 0.5, 1.0), wp.mod(float(k) * R2_V + 0.5, 1.0))):
            over += 1
    return over


@wp.func
def covers(t: Nodes, s: Surfels, y: int, b: int) -> bool:
    """Whether leaf b's element point (where its direct light was found, and the reference's rays
    start) lies over leaf y's surface, y ``near`` b (``in_cell``)."""
    return near(t, y, b) and in_cell(s, t.element[y], s.pos[t.element[b]])


@wp.func
def contact(t: Nodes, s: Surfels, offsets: wp.array(dtype=wp.int32), sender: wp.array(dtype=wp.int32), x: int,
            b: int) -> wp.vec2:
    """Leaves x and b in contact (``CONTACT_GAP``): (the share of x under b's surface — of x's
    points, ``cell_point`` —, the light of b that x stops per unit of b's radiance, as x's area).
    Where b's element point (where its direct light was found, and the reference's rays start)
    lies over a leaf in contact with it, b is hidden and all its light is stopped by the leaves
    under it, shared in proportion to how many of its surface's points lie over each
    (``inner_over``), × b's area over x's; else none. x then sends on as antiradiance all that
    a hidden b shows it (b's own radiance, if x lies before b's face, b shows no one: ``visible``).
    (−1, 0) when they are not in contact. b's other contacts are found among its own links
    (``offsets``, ``sender``: CSR)."""
    if t.descend[x] >= 0 or t.descend[b] >= 0:
        return wp.vec2(-1.0, 0.0)
    ex = t.element[x]
    eb = t.element[b]
    under = int(0)
    for k in range(CONTACT_POINTS):
        if in_cell(s, eb, cell_point(s, ex, k, CONTACT_POINTS)):
            under += 1
    over = inner_over(s, ex, eb)
    if over == 0 and under == 0:
        return wp.vec2(-1.0, 0.0)
    total = int(0)
    hidden = bool(False)
    for i in range(offsets[b], offsets[b + 1]):
        y = sender[i]
        if near(t, y, b):
            total += inner_over(s, t.element[y], eb)
            if in_cell(s, t.element[y], s.pos[eb]):  # ``covers``, y already near
                hidden = True
    power = float(0.0)
    if hidden and total > 0:
        power = float(over) / float(total) * t.area[b] / t.area[x]
    return wp.vec2(float(under) / float(CONTACT_POINTS), power)


@wp.func
def receive_cone(t: Nodes, s: Surfels, offsets: wp.array(dtype=wp.int32), sender: wp.array(dtype=wp.int32),
                 x: int, b: int) -> wp.vec3:
    """(solid angle (sr) the light x receives from b claims, × COVER; its ``Masks.gain``; 1 if it
    spreads over the whole hemisphere toward b, 0 over the cone(s) of ``fill_cone``). Leaves in
    ``contact`` (b's other contacts found through the CSR links ``offsets``, ``sender``) spread
    over the hemisphere, claiming its share under b and carrying the light x stops: the shares
    cancel, so neither count's sampling noise reaches the radiance."""
    if near(t, x, b):
        c = contact(t, s, offsets, sender, x, b)
        if c[0] >= 0.0:
            under = wp.max(c[0], 1.0 / float(CONTACT_POINTS))
            return wp.vec3(COVER * 6.283185307179586 * under, c[1] / under, 1.0)
    return wp.vec3(cone_omega(t, s, x, b, COVER), 1.0, 0.0)


@wp.func
def cone_omega(t: Nodes, s: Surfels, x: int, b: int, widen: float) -> float:
    """The solid angle (sr) node b subtends at node x, × ``widen`` (``point_cone``): at x's
    centre, or for a ``near`` leaf the mean over its points."""
    if near(t, x, b):
        acc = float(0.0)
        for k in range(NEAR_POINTS):
            u, omega = near_cone(t, s, x, k, b, widen)
            acc += omega
        return acc / float(NEAR_POINTS)
    u, omega = point_cone(t, s, centre(t, s, x), t.normal[x], b, widen)
    return omega


@wp.func
def fill_cone(t: Nodes, s: Surfels, x: int, b: int, widen: float, omega_x: float, size: int,
              out: wp.array(dtype=wp.uint16), lo: int, count: int):
    """out[lo … lo+count−1] ← the bins, in node x's frame, of ``count`` directions spread over the
    cone(s) toward node b, whose solid angle ``cone_omega`` gave as ``omega_x``: for a ``near``
    leaf shared among its points in proportion to their cones' solid angles, so each direction
    stands for an equal share."""
    total = float(0.0)
    if near(t, x, b):
        total = omega_x * float(NEAR_POINTS)
    if total > 0.0:
        acc = float(0.0)
        i = int(0)
        for k in range(NEAR_POINTS):
            u, omega = near_cone(t, s, x, k, b, widen)
            acc += omega
            end = count
            if k < NEAR_POINTS - 1:
                end = wp.min(int(acc / total * float(count) + 0.5), count)
            for j in range(end - i):
                # each point's spiral turned its own way: points under one disk share an axis
                out[lo + i + j] = wp.uint16(cone_bin(j, end - i, t.normal[x], u, omega, size,
                                                     float(k) * GOLDEN))
            i = wp.max(i, end)
    else:
        u, omega = point_cone(t, s, centre(t, s, x), t.normal[x], b, widen)
        for k in range(count):
            out[lo + k] = wp.uint16(cone_bin(k, count, t.normal[x], u, omega, size, 0.0))


@wp.kernel
def _mask_count_kernel(offset: int, t: Nodes, s: Surfels, offsets: wp.array(dtype=wp.int32), sender: wp.array(dtype=wp.int32),
                       bin_omega: float, receive: wp.array(dtype=wp.int32), send: wp.array(dtype=wp.int32),
                       omega: wp.array(dtype=wp.float32), gain: wp.array(dtype=wp.float32),
                       whole: wp.array(dtype=wp.uint8), send_omega: wp.array(dtype=wp.float32)):
    """Receiver node x's links: how many directions each side's cone gets, and what the masks
    kernel spreads them by (``receive_cone``; the sending cone's ``cone_omega``)."""
    x = wp.tid() + offset
    for j in range(offsets[x], offsets[x + 1]):
        b = sender[j]
        cone = receive_cone(t, s, offsets, sender, x, b)
        omega[j] = cone[0]
        gain[j] = cone[1]
        whole[j] = wp.uint8(cone[2])
        receive[j] = cone_count(wp.where(cone[2] > 0.0, 6.283185307179586, cone[0]), bin_omega)
        send_omega[j] = cone_omega(t, s, b, x, 1.0)
        send[j] = cone_count(send_omega[j], bin_omega)


@wp.kernel
def _masks_kernel(offset: int, t: Nodes, s: Surfels, offsets: wp.array(dtype=wp.int32), sender: wp.array(dtype=wp.int32),
                  size: int, whole: wp.array(dtype=wp.uint8), send_omega: wp.array(dtype=wp.float32), out: Masks):
    """Receiver node x's links (one thread over its CSR range): their bins."""
    x = wp.tid() + offset
    for j in range(offsets[x], offsets[x + 1]):
        b = sender[j]
        lo = out.receive_offsets[j]
        count = out.receive_offsets[j + 1] - lo
        if whole[j] > wp.uint8(0):
            n = t.normal[x]
            side = wp.where(wp.dot(n, centre(t, s, b) - centre(t, s, x)) < 0.0, -1.0, 1.0)
            for k in range(count):
                out.receive[lo + k] = wp.uint16(cone_bin(k, count, n, n * side, 6.283185307179586, size, 0.0))
        else:
            fill_cone(t, s, x, b, COVER, out.omega[j], size, out.receive, lo, count)
        lo = out.send_offsets[j]
        fill_cone(t, s, b, x, 1.0, send_omega[j], size, out.send, lo, out.send_offsets[j + 1] - lo)


@wp.kernel
def _hidden_kernel(offset: int, t: Nodes, s: Surfels, offsets: wp.array(dtype=wp.int32),
                   sender: wp.array(dtype=wp.int32), visible: wp.array(dtype=wp.float32)):
    """Leaf x (the tree's first n nodes): 0 in ``visible`` where x is hidden, its element point
    over a leaf linked with it that lies before its face (``covers``)."""
    x = wp.tid() + offset
    e = t.element[x]
    visible[e] = 1.0
    for j in range(offsets[x], offsets[x + 1]):
        y = sender[j]
        if wp.dot(t.normal[x], t.position[y] - s.pos[e]) > 0.0 and covers(t, s, y, x):
            visible[e] = 0.0


def _offsets(counts: wp.array) -> wp.array:
    """int32[E+1]: the exclusive running sum of ``counts`` (int32[E]) and the total."""
    out = wp.zeros(counts.size + 1, dtype=wp.int32, device=counts.device)
    wp.utils.array_scan(counts, out[1:], inclusive=True)
    return out


def masks(problem, links, bins: int) -> Masks:
    """The direction masks (``Masks``) of ``links`` (``links.Links`` over ``problem.tree``) for
    ``bins`` bins, made the first time they are asked for and kept with the links."""
    key = ("masks", bins)
    if key not in links.derived:
        tree, dev = problem.tree, problem.device
        d = dev.name
        count = max(links.count, 1)
        args = [tree.nodes, problem.surfels, links.set.offsets, links.set.sender]
        receive = wp.zeros(count, dtype=wp.int32, device=d)
        send = wp.zeros(count, dtype=wp.int32, device=d)
        out = Masks()
        out.omega = wp.zeros(count, dtype=wp.float32, device=d)
        out.gain = wp.zeros(count, dtype=wp.float32, device=d)
        # made by the counting pass for the filling pass (contacts are costly to find)
        whole = wp.zeros(count, dtype=wp.uint8, device=d)
        send_omega = wp.zeros(count, dtype=wp.float32, device=d)
        device_mod.launch(_mask_count_kernel, tree.count,
                          [*args, solid_angle(bins), receive, send, out.omega, out.gain, whole, send_omega], dev)
        out.receive_offsets, out.send_offsets = _offsets(receive), _offsets(send)
        out.receive = wp.empty(max(int(out.receive_offsets.numpy()[-1]), 1), dtype=wp.uint16, device=d)
        out.send = wp.empty(max(int(out.send_offsets.numpy()[-1]), 1), dtype=wp.uint16, device=d)
        device_mod.launch(_masks_kernel, tree.count, [*args, side(bins), whole, send_omega, out], dev)
        links.derived[key] = out
    return links.derived[key]


def visible(problem, links) -> wp.array:
    """float32[n] per element: 0 where it is hidden — its element point over the surface of a
    leaf linked with it and before its face, in contact (``covers``): a ceiling cell 1 mm above
    a lamp — else 1, made the first time it is asked for and kept with ``links``. A hidden
    element shows none of its radiance: what the reference's rays from its point would find is
    the surface over it, and cancelling its light by antiradiance from a surface 1 mm away leaks
    round that surface's rim wherever the cones are round."""
    if "visible" not in links.derived:
        tree = problem.tree
        out = wp.empty(problem.elements.count, dtype=wp.float32, device=problem.device.name)
        device_mod.launch(_hidden_kernel, problem.elements.count,
                          [tree.nodes, problem.surfels, links.set.offsets, links.set.sender, out], problem.device)
        links.derived["visible"] = out
    return links.derived["visible"]


@wp.kernel
def _hide_kernel(offset: int, visible: wp.array(dtype=wp.float32), exitance: wp.array(dtype=wp.vec3)):
    e = wp.tid() + offset
    exitance[e] = exitance[e] * visible[e]


def hide(problem, links, exitance: wp.array) -> wp.array:
    """exitance (vec3[n], what each element reflects) ← 0 where the element is hidden
    (``visible``)."""
    device_mod.launch(_hide_kernel, problem.elements.count, [visible(problem, links), exitance], problem.device)
    return exitance
