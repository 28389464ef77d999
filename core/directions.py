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

Once per link build, ``masks`` lists for every directed link the bins its two cones cover (what
antiradiance gathers from and deposits into); ``capacity`` gives each bin's form factor from
its element (what implicit visibility fills a bin up to).
"""
from __future__ import annotations

import math

import warp as wp

from . import device as device_mod
from .formfactor import tangent_frame
from .gather import fan_centre
from .hierarchy import Nodes
from .problem import Surfels

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
    return cone_sample_of(k, CONE_SAMPLES, axis, cos_half)


@wp.func
def cone_sample_of(k: int, count: int, axis: wp.vec3, cos_half: float) -> wp.vec3:
    """Direction k of ``count`` spread evenly over the cone (as ``cone_sample``)."""
    t1, t2 = tangent_frame(axis)
    z = 1.0 - (float(k) + 0.5) / float(count) * (1.0 - cos_half)
    r = wp.sqrt(wp.max(1.0 - z * z, 0.0))
    phi = float(k) * GOLDEN
    return axis * z + t1 * (r * wp.cos(phi)) + t2 * (r * wp.sin(phi))


@wp.func
def cone_cos_half(solid_angle: float) -> float:
    """cos of the half angle of the cone of ``solid_angle`` (sr): Ω = 2π(1 − cos α)."""
    return wp.clamp(1.0 - solid_angle / 6.283185307179586, -1.0, 1.0)


def solid_angle(bins: int) -> float:
    """The solid angle (sr) of one of ``bins`` bins."""
    return 4.0 * math.pi / bins


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
def subtended(p: wp.vec3, q: wp.vec3, nq: wp.vec3, area: float, spread: float) -> float:
    """Solid angle (sr) that disks of total ``area`` (m²) at q, mean unit normal nq and normal
    ``spread`` (1 aligned, 0 an isotropic blob), subtend at p, either face: the cone of a disk of
    their projected area facing p, 2π(1 − d / √(d² + A_proj/π)) — exact on a disk's axis, A_proj/d²
    far away — or, where p lies over the disk close to its plane (a ceiling 1 mm above a lamp),
    at least what the part of the disk right under p subtends, which fills the hemisphere."""
    d = q - p
    d2 = wp.dot(d, d)
    c = float(1.0)
    h = wp.abs(wp.dot(nq, d))
    if d2 > 0.0:
        c = h / wp.sqrt(d2)
    r2 = area * (spread * c + (1.0 - spread) * 0.25) * 0.3183098861837907
    if r2 <= 0.0:
        return 0.0
    omega = 6.283185307179586 * (1.0 - wp.sqrt(d2 / (d2 + r2)))
    under = spread * area * 0.3183098861837907 - (d2 - h * h)  # radius² of the disk part under p
    if under > 0.0:
        omega = wp.max(omega, 6.283185307179586 * (1.0 - h / wp.sqrt(h * h + under)))
    return omega


@wp.func
def cone_bin(k: int, count: int, n: wp.vec3, axis: wp.vec3, omega: float, size: int) -> int:
    """The bin, in the frame of unit normal n, of direction k of ``count`` over the cone around
    unit ``axis`` of solid angle ``omega`` (sr): a link's deposits go 1/count to each.
    Directions on the other side of the surface than the axis are mirrored back across it: a
    near node's cone, wider than the node, must not spill over the horizon."""
    local = frame_dir(n, cone_sample_of(k, count, axis, cone_cos_half(omega)))
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
    (where the light leaves to); omega: float32[E] the receiving cone's solid angle (sr). Each
    direction stands for an equal share of its cone."""

    receive_offsets: wp.array(dtype=wp.int32)
    receive: wp.array(dtype=wp.uint16)
    send_offsets: wp.array(dtype=wp.int32)
    send: wp.array(dtype=wp.uint16)
    omega: wp.array(dtype=wp.float32)


@wp.func
def centre(t: Nodes, s: Surfels, x: int) -> wp.vec3:
    """Where node x's cones start: a leaf's surface centre (the middle of its share of its
    triangles: its element sits on a vertex, which at a mesh's rim is the surface's corner), an
    inner node's centre."""
    if t.descend[x] < 0:
        e = t.element[x]
        return fan_centre(e, s.vertex, s.fan_offsets, s.fan_triangles, s.tris, s.points)
    return t.position[x]


@wp.func
def _link_cones(t: Nodes, s: Surfels, x: int, b: int):
    """(unit direction from x to b, b's solid angle at x, x's solid angle at b) between the
    centres (``centre``) of nodes x and b."""
    p = centre(t, s, x)
    q = centre(t, s, b)
    d = q - p
    length = wp.length(d)
    u = wp.vec3(t.normal[x])
    if length > 0.0:
        u = d / length
    return u, subtended(p, q, t.normal[b], t.area[b], t.spread[b]), subtended(q, p, t.normal[x], t.area[x],
                                                                          t.spread[x])


@wp.kernel
def _mask_count_kernel(offset: int, t: Nodes, s: Surfels, offsets: wp.array(dtype=wp.int32), sender: wp.array(dtype=wp.int32),
                       bin_omega: float, receive: wp.array(dtype=wp.int32), send: wp.array(dtype=wp.int32)):
    """Receiver node x's links: how many directions each side's cone gets."""
    x = wp.tid() + offset
    for j in range(offsets[x], offsets[x + 1]):
        u, omega_b, omega_x = _link_cones(t, s, x, sender[j])
        receive[j] = cone_count(omega_b * COVER, bin_omega)
        send[j] = cone_count(omega_x, bin_omega)


@wp.kernel
def _masks_kernel(offset: int, t: Nodes, s: Surfels, offsets: wp.array(dtype=wp.int32), sender: wp.array(dtype=wp.int32),
                  size: int, out: Masks):
    """Receiver node x's links (one thread over its CSR range)."""
    x = wp.tid() + offset
    for j in range(offsets[x], offsets[x + 1]):
        b = sender[j]
        u, omega_b, omega_x = _link_cones(t, s, x, b)
        omega_b = wp.min(omega_b * COVER, 6.283185307179586)
        out.omega[j] = omega_b
        lo = out.receive_offsets[j]
        count = out.receive_offsets[j + 1] - lo
        for k in range(count):
            out.receive[lo + k] = wp.uint16(cone_bin(k, count, t.normal[x], u, omega_b, size))
        lo = out.send_offsets[j]
        count = out.send_offsets[j + 1] - lo
        for k in range(count):
            out.send[lo + k] = wp.uint16(cone_bin(k, count, t.normal[b], -u, omega_x, size))


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
        device_mod.launch(_mask_count_kernel, tree.count, [*args, solid_angle(bins), receive, send], dev)
        out = Masks()
        out.receive_offsets, out.send_offsets = _offsets(receive), _offsets(send)
        out.receive = wp.empty(max(int(out.receive_offsets.numpy()[-1]), 1), dtype=wp.uint16, device=d)
        out.send = wp.empty(max(int(out.send_offsets.numpy()[-1]), 1), dtype=wp.uint16, device=d)
        out.omega = wp.empty(count, dtype=wp.float32, device=d)
        device_mod.launch(_masks_kernel, tree.count, [*args, side(bins), out], dev)
        links.derived[key] = out
    return links.derived[key]
