"""How much of each element's view is shut inside a closed surface (issue 21).

A vertex of one object buried inside another (Suzanne's head under her eyes, a table leg's end
inside the table top) sees only the inner side of what encloses it: back faces, which send nothing
(elements are one-sided, ``core.elements``) and are dark in Cycles too. A link between clusters
carries visibility sampled between other leaves, so such an element received as much indirect
light as its open neighbours (measured in the furnished room of ``bench/real_scenes.py``: 113 of
Suzanne's 2 012 vertices had ≥ 90 % of their view on back faces, Cycles gave them 0.05 where we
gave 1.5, half of Suzanne's squared error and 28 % of the scene's).

``open_fraction`` traces RAYS cosine-distributed rays from each element and counts those whose
first hit is not a back face; the hierarchical solver scales the light an element gets over its
ancestors' links (whose rays left from other leaves) by it. Its own links' rays left from it.

``enclosed_lamps`` finds the point and spot lamps inside a closed surface (a bulb inside an opaque
emissive globe): every ray from them hits a back face, so their light cannot leave it, in Cycles
either. A shadow ray would still reach them from a receiver touching that surface, whose lifted
origin lies inside it (in the level of ``bench/real_scenes.py`` the tops of the lamp posts, inside
the globes, got 10× Cycles' light and held 96 % of the scene's squared error).
"""
from __future__ import annotations

import numpy as np
import warp as wp

from . import device as device_mod
from .directions import cone_sample_of, cosine_r2
from .formfactor import tangent_frame
from .rays import lift
from .scene import LAMP_POINT, LAMP_SPOT, Lamps

wp.set_module_options({"enable_backward": False})  # no gradients: halves compile time

# Rays per element: a buried element is told from an open one by all its rays hitting back faces,
# so a few suffice; partly buried ones (at an intersection line) get their fraction to ±1/RAYS.
RAYS = 16
# Rays per lamp, spread evenly over the sphere: one that escapes makes the lamp count as open.
LAMP_RAYS = 64


@wp.kernel
def _open_kernel(offset: int, mesh: wp.uint64, pos: wp.array(dtype=wp.vec3), nrm: wp.array(dtype=wp.vec3),
                 size: wp.array(dtype=wp.float32), rays: int, far: float, seed: int,
                 out: wp.array(dtype=wp.float32)):
    """Element e: the fraction of ``rays`` cosine-distributed rays from its lifted point whose
    first hit within ``far`` (m) is a front face, or nothing."""
    e = wp.tid() + offset
    n = nrm[e]
    tu, tv = tangent_frame(n)
    origin = lift(pos[e], n, size[e])
    state = wp.rand_init(seed, e)
    shift0 = wp.randf(state)
    shift = wp.vec2(shift0, wp.randf(state))
    free = float(0.0)
    for k in range(rays):
        d = cosine_r2(n, tu, tv, shift, k)
        q = wp.mesh_query_ray(mesh, origin, d, far)
        if not q.result or wp.dot(q.normal, d) < 0.0:
            free += 1.0
    out[e] = free / float(rays)


def open_fraction(problem) -> np.ndarray:
    """float32[n]: for each element, the share of its cosine-weighted view whose first hit is a
    front face or nothing (1 for an element in the open, 0 for one inside a closed surface)."""
    dev, s = problem.device, problem.surfels
    n = problem.elements.count
    out = wp.empty(n, dtype=wp.float32, device=dev.name)
    sizes = wp.array(problem.element_sizes.astype(np.float32), dtype=wp.float32, device=dev.name)
    device_mod.launch(_open_kernel, n, [problem.mesh.id, s.pos, s.nrm, sizes, RAYS, float(problem.far),
                                        int(problem.settings.seed) + 15485863, out], dev)
    problem.counts["rays"] += n * RAYS
    return out.numpy()


@wp.kernel
def _lamp_kernel(mesh: wp.uint64, pos: wp.array(dtype=wp.vec3), rays: int, far: float,
                 out: wp.array(dtype=wp.int32)):
    """Lamp l: 1 when every one of ``rays`` directions over the sphere from its position first hits
    a back face within ``far`` (m), else 0."""
    l = wp.tid()
    inside = int(1)
    for k in range(rays):
        d = cone_sample_of(k, rays, wp.vec3(0.0, 0.0, 1.0), -1.0, 0.0)  # the whole sphere
        q = wp.mesh_query_ray(mesh, pos[l], d, far)
        if not q.result or wp.dot(q.normal, d) < 0.0:
            inside = 0
            break
    out[l] = inside


def enclosed_lamps(lamps: Lamps, mesh: wp.Mesh, far: float, device: str) -> np.ndarray:
    """bool[L]: the point and spot lamps of ``lamps`` whose every ray (LAMP_RAYS, over the sphere)
    first hits a back face of ``mesh`` within ``far`` (m): inside a closed surface."""
    out = np.zeros(len(lamps), bool)
    point = np.flatnonzero(np.isin(lamps.kind, (LAMP_POINT, LAMP_SPOT)))
    if len(point):
        hit = wp.zeros(len(point), dtype=wp.int32, device=device)
        pos = wp.array(np.ascontiguousarray(lamps.position[point], np.float32), dtype=wp.vec3,
                       device=device)
        wp.launch(_lamp_kernel, dim=len(point), inputs=[mesh.id, pos, LAMP_RAYS, float(far), hit],
                  device=device)
        out[point] = hit.numpy() > 0
    return out
