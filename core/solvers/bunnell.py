"""Bunnell-style one-bounce indirect light over the disk tree: O(n log n), no rays.

Each element's front face sends radiance ρ ⊙ D (D its direct lighting from ``core.direct``, which
already holds lamps and emissive triangles with ray-traced shadows). One gather traverses the
hierarchy from every element with the transfer term of the AO (``ao.gather``: disk form factors
far away, exact triangle form factors near, the tree's clusters in between) and is shadowed the
way the accessibility is: senders landing in the same direction cell of the receiver's
hemisphere share the cell's measure instead of adding up, and near-field senders take their part
of a cell first. Occlusion finer than a cell (1/32 of the hemisphere) is not resolved: a small
occluder in front of a bright surface hides only as much as it fills its cell. So, as Bunnell
shadows senders by their accessibility, each sender's radiance is weighted by its accessibility
within LOCAL element sizes: a surface closed in at close range (the ceiling 1 mm above the Cornell
box's light panel, lit hard by the panel's back) is hidden from everything farther away, while
the open surfaces that carry most light keep it (their accessibility over the whole scene would
darken every corner twice, measured: see README). Back faces send nothing.
"""
from __future__ import annotations

import numpy as np
import warp as wp

from .. import device as device_mod
from .. import hierarchy as hierarchy_mod
from ..elements import Elements
from . import ao
from .reference import Solution

# Distance of the senders' accessibility, in median element sizes (√area): measured on the sample
# scenes against the reference, 2 removes the Cornell box's hidden hot spot (lighting relative
# RMSE 0.44 → 0.06) and changes the lamp scene little (0.048 → 0.047).
LOCAL = 2.0


def sender_radiance(hier, els: Elements, lighting: np.ndarray, dev: device_mod.Device) -> wp.array:
    """vec3[hier.count]: radiance leaving each node's front, ρ ⊙ lighting weighted by each
    element's accessibility within LOCAL element sizes (hides surfaces closed in at close range),
    averaged over the node's subtree. lighting: float32[n,3] irradiance/π per element."""
    size = float(np.sqrt(np.median(els.area)))
    local = ao.gather(hier, els, els.position, els.normal, LOCAL * size, dev).accessibility
    return hierarchy_mod.node_means(hier, (els.albedo * lighting * local[:, None]).astype(np.float32))


def solve(geometry, els: Elements, direct: np.ndarray, settings, dev: device_mod.Device,
          progress=None, hier=None) -> Solution:
    """One bounce of indirect lighting per element (float32[n,3], irradiance/π) from direct
    lighting ``direct`` (float32[n,3]): ``I = G(a ⊙ ρ ⊙ D)``, G the gather above, a the senders'
    local accessibility. ``settings.bounces``
    is not used: the method is one bounce (more bounces of the same gather compound its error,
    see README). ``hier``: the hierarchy over ``els`` (built here when None); progress(stage,
    fraction).
    """
    if hier is None:
        hier = hierarchy_mod.build(els, dev, geometry)
    g = ao.gather(hier, els, els.position, els.normal, geometry.far, dev,
                  radiance=sender_radiance(hier, els, direct, dev),
                  progress=None if progress is None else (lambda f: progress("gather", f)))
    return Solution(g.light.astype(np.float32), {"nodes": hier.count, "iterations": 1})


def final_gather(hier, els: Elements, lighting: np.ndarray, geometry, dev: device_mod.Device):
    """A gather of the converged solution at any points (lightmap texels): returns
    ``gather(points float32[N,3], normals float32[N,3] unit, progress=None) -> float32[N,3]``, the
    indirect lighting (irradiance/π) that the elements' reflected light ρ ⊙ ``lighting``
    (float32[n,3], direct + indirect per element) sends to each point over the tree."""
    radiance = sender_radiance(hier, els, lighting, dev)

    def gather(points, normals, progress=None):
        return ao.gather(hier, els, points, normals, geometry.far, dev, radiance=radiance,
                         progress=progress).light.astype(np.float32)

    return gather
