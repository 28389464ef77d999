"""Ambient occlusion: the accessibility of each receiver, gathered over the disk tree
(``core.gather``): the cosine-weighted fraction of the hemisphere not covered by the scene's
surfaces within the AO distance, what Cycles' AO bake gives. No light is transported."""
from __future__ import annotations

import numpy as np

from .. import gather
from .base import Solution

# Cycles' default AO distance (world.light_settings.distance), m.
DEFAULT_DISTANCE = 10.0


def distance(problem) -> float:
    """The AO distance (m): ``settings.ao_distance``, else the scene world's, else Cycles' default."""
    for value in (problem.settings.ao_distance, problem.scene.ao_distance):
        if value and value > 0:
            return float(value)
    return DEFAULT_DISTANCE


def accessibility(problem, points: np.ndarray, normals: np.ndarray, progress=None) -> np.ndarray:
    """float32[N,3]: the accessibility in [0,1] (1: open sky) at N points (float32[N,3], m) with
    unit normals, in all three channels."""
    access = gather.gather(problem, points, normals, distance(problem), progress=progress).accessibility
    return np.repeat(access[:, None], 3, axis=1).astype(np.float32)


def solve(problem) -> Solution:
    """The accessibility of every element."""
    els = problem.elements
    return Solution(problem.stages.run("ao", accessibility, problem, els.position, els.normal,
                                       problem.stages.reporter("ao")))


def evaluate(problem, solution: Solution, receivers) -> np.ndarray:
    """The accessibility at ``receivers``: the solution where they are the elements, else gathered
    at each receiver (lightmap texels: as sharp as the texels, not the mesh)."""
    if receivers.aligned:
        return receivers.reconstruct(solution.values)
    return problem.stages.run("texel ao", accessibility, problem, receivers.points, receivers.normals,
                              problem.stages.reporter("texel ao"))
