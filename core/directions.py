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
"""
from __future__ import annotations

import math

import warp as wp

from .formfactor import tangent_frame

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
    t1, t2 = tangent_frame(axis)
    z = 1.0 - (float(k) + 0.5) / float(CONE_SAMPLES) * (1.0 - cos_half)
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
