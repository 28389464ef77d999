"""Shadow and visibility rays: where a ray may start off a surface, and whether a segment is free.

A ray leaving a surface starts a little above it, by OFFSET of the float32 spacing that matters at
that point: the magnitude of its coordinates (the rounding of the point itself) plus the local
feature size (the rounding of the ray–triangle test against the triangles around it). A fixed
fraction of the scene size fails both ways: far from the origin it falls below the coordinates'
rounding (every ray hits its own surface), and in a large scene it lifts small objects' rays through
their neighbours.
"""
import warp as wp

from .scene import RAY_LIFT

wp.set_module_options({"enable_backward": False})  # no gradients: halves compile time

# ≈ 128 float32 ulps of the point's magnitude plus its feature size (core.scene judges, from the
# same share, which objects lie too far from the scene's detail).
OFFSET = RAY_LIFT


@wp.func
def lift(p: wp.vec3, n: wp.vec3, size: float) -> wp.vec3:
    """p moved off its surface along the unit normal n; size: the local feature size (m)."""
    m = wp.max(wp.max(wp.abs(p[0]), wp.abs(p[1])), wp.abs(p[2]))
    return p + n * (OFFSET * (m + size))


@wp.func
def lift_towards(q: wp.vec3, nq: wp.vec3, to: wp.vec3, size: float) -> wp.vec3:
    """q moved off its surface (normal nq, any length, either sign) as ``lift`` does, to the side
    of the point ``to``: where a shadow ray from ``to`` to a point of an emitter's own surface
    ends, so it cannot hit that surface (float32 rounding of the ray–triangle test grows as the
    ray grazes it, and a fixed fraction of the ray's length is too short for near emitters)."""
    u = wp.normalize(nq)
    if wp.dot(to - q, u) < 0.0:
        u = -u
    return lift(q, u, size)


@wp.func
def visible(mesh: wp.uint64, origin: wp.vec3, target: wp.vec3) -> float:
    """1 if nothing blocks the segment origin→target (stopping just short of target), else 0."""
    d = target - origin
    dist = wp.length(d)
    if dist <= 0.0:
        return 1.0
    if wp.mesh_query_ray_anyhit(mesh, origin, d / dist, dist * 0.9999):
        return 0.0
    return 1.0
