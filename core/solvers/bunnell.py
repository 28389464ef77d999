"""Bunnell-style one-bounce indirect light over the disk tree: O(n log n), no rays.

Each element's front face sends radiance ρ ⊙ D (D its direct lighting from ``core.direct``, which
already holds lamps and emissive triangles with ray-traced shadows). One gather traverses the
tree from every element with the transfer of the AO gather (``core.gather``: disk form factors
far away, exact triangle form factors near, the tree's clusters in between), shadowed the way the
accessibility is: senders landing in the same direction cell of the receiver's hemisphere share
the cell's measure instead of adding up, and near-field senders take their part of a cell first.
Occlusion finer than a cell (1/32 of the hemisphere) is not resolved: a small occluder in front of
a bright surface hides only as much as it fills its cell. So, as Bunnell shadows senders by their
accessibility, each sender's radiance is weighted by its accessibility within a few element sizes
(``gather.sender_radiance``). Back faces send nothing.
"""
from __future__ import annotations

from .. import gather
from .base import Solution, reconstruct_with_detail


def solve(problem) -> Solution:
    """One bounce of indirect lighting per element (float32[n,3], irradiance/π) from the
    problem's direct lighting: ``I = G(a ⊙ ρ ⊙ D)``, G the gather, a the senders' local
    accessibility. ``bounces`` is not read: the method is one bounce (more bounces of the same
    gather compound its error, see docs/ao-bunnell.md)."""
    els = problem.elements
    radiance = gather.sender_radiance(problem, problem.direct)
    light = problem.stages.run("gather", gather.light_at, problem, radiance, els.position, els.normal,
                               problem.stages.reporter("gather"))
    return Solution(light, {"iterations": 1})


def evaluate(problem, solution: Solution, receivers):
    """Indirect lighting at ``receivers``: the solution at the vertices; at lightmap texels
    interpolated, plus the detail of the same gather of ρ(D + I) (``texel_indirect``)."""
    return reconstruct_with_detail(problem, solution, receivers)
