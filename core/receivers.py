"""Receivers: the points where results are wanted, how each is rebuilt from the elements, and the
light at them.

Shading vertices (for color attributes) and lightmap texels are both receivers. Each has a
position, a normal, a local feature size (for ray offsets), the albedo and emission of the surface
it lies on (for ``combined``) and a reconstruction from the solver's elements: element indices and
weights, used by ``evaluate`` to interpolate per-element values. ``aligned`` receivers are the
elements themselves (weight 1 each, in element order), so per-element values serve as they are.

:func:`light_at` is the one path from a solution to the values every target writes: direct light
at the receivers, the solver's ``evaluate`` there, and the content composed once.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np

from . import direct
from .lightmap import shadows
from .solvers import SOLVERS


@dataclass(frozen=True)
class Part:
    """Where receivers cut from a larger set lie in it (a lightmap page baked alone, e.g. as a farm
    task): first, the index of their first receiver in the whole set; tiles, the adaptive-shadow
    tiles (``core.lightmap.shadows``) of the grids before theirs; whole, the receivers in the whole
    set. Their sample jitter is seeded as in the whole set, so a part gets the light the whole
    would give it, bit for bit."""

    first: int
    tiles: int
    whole: int

    def seeding(self) -> dict:
        """The arguments of ``direct.estimate`` that place its receivers in the whole set."""
        return {"first": self.first, "whole": self.whole}


@dataclass
class Receivers:
    """R receivers.

    points, normals: float32[R,3] (m in the problem's frame, unit); sizes: float32[R] local feature
    size (m); albedo, emission: float32[R,3]; elements: int32[R,K] and weights: float32[R,K], each
    receiver as a weighted sum of elements; aligned: receiver r is element r; label: what they
    are, naming their stages (``texel`` → ``texel direct``); grids: for receivers that are the
    samples of raster grids (lightmap pages), each grid's ``lightmap.raster.Texels`` in receiver
    order, over which direct light is traced adaptively; None elsewhere. part: where they lie in
    a larger set they were cut from (``Part``), None for a whole set.
    """

    points: np.ndarray
    normals: np.ndarray
    sizes: np.ndarray
    albedo: np.ndarray
    emission: np.ndarray
    elements: np.ndarray
    weights: np.ndarray
    aligned: bool = False
    label: str = "receiver"
    grids: Optional[list] = None
    part: Optional[Part] = None

    def __len__(self) -> int:
        return int(self.points.shape[0])

    def reconstruct(self, per_element: np.ndarray, index=slice(None)) -> np.ndarray:
        """float32[R,C]: Σ_k weights[:,k] · per_element[elements[:,k]] (per_element float32[n,C]);
        index: of the receivers wanted (default all), their rows alone."""
        if self.aligned:
            return np.asarray(per_element, np.float32)[index]
        return np.einsum("rk,rkc->rc", self.weights[index],
                         per_element[self.elements[index]]).astype(np.float32)


def at_elements(problem) -> Receivers:
    """The shading vertices of ``problem`` as receivers: its elements are one disk per shading
    vertex (``core.elements``), so they are aligned."""
    els = problem.elements
    n = els.count
    return Receivers(points=els.position, normals=els.normal, sizes=problem.element_sizes,
                     albedo=els.albedo, emission=els.emission,
                     elements=np.arange(n, dtype=np.int32)[:, None],
                     weights=np.ones((n, 1), np.float32), aligned=True, label="vertex")


def on_triangles(problem, triangles: np.ndarray, bary: np.ndarray, points: np.ndarray,
                 normals: np.ndarray, sizes: np.ndarray, label: str = "receiver",
                 grids: Optional[list] = None, part: Optional[Part] = None) -> Receivers:
    """Receivers on the scene's triangles (lightmap texels): ``triangles`` int32[R] triangle of
    ``problem.source`` of each, ``bary`` float32[R,3] its barycentric coordinates there
    (interpolation weights of the triangle's corner elements, its shading vertices); points,
    normals float32[R,3] and sizes float32[R] as sampled; label, grids, part: see ``Receivers``."""
    scene = problem.source
    return Receivers(points=points, normals=normals, sizes=sizes, albedo=scene.albedo[triangles],
                     emission=scene.emission[triangles],
                     elements=problem.shading.corner[triangles],
                     weights=np.asarray(bary, np.float32), label=label, grids=grids, part=part)


def compose(content: str, field: np.ndarray, direct: np.ndarray, receivers: Receivers) -> np.ndarray:
    """The baked quantity ``content`` at receivers, float32[R,3], from a solver's field at them
    (indirect lighting, or accessibility for ``ao``) and the direct lighting there (irradiance/π).

    lighting = direct + indirect; combined = emission + albedo × lighting; indirect; ao.
    """
    if content in ("ao", "indirect"):
        return np.asarray(field, np.float32)
    lighting = direct + field
    if content == "lighting":
        return lighting.astype(np.float32)
    return (receivers.emission + receivers.albedo * lighting).astype(np.float32)


@dataclass
class Light:
    """The light at R receivers, float32[R,3] each: direct (irradiance/π; 0 for a solver that
    moves no light, AO), indirect (the solver's indirect lighting; 0 for AO and direct-only) and
    output, the content the settings ask for (``compose``); solved: (solver module, solution) it
    came from, for targets that gather more from the solution (``core.directional``)."""

    direct: np.ndarray
    indirect: np.ndarray
    output: np.ndarray
    solved: Optional[tuple] = None


def direct_at(problem, receivers: Receivers) -> np.ndarray:
    """float32[R,3] direct lighting at ``receivers``: the problem's own per element for aligned
    receivers; traced per receiver elsewhere (stage ``<label> direct``), adaptively over the
    receivers' grids when they have them and ``texel_shadows`` is ``adaptive``."""
    if receivers.aligned:
        return problem.direct
    stage = f"{receivers.label} direct"
    args = (receivers.points, receivers.normals, receivers.sizes, problem.stages.reporter(stage),
            receivers.part)
    if receivers.grids is not None and problem.settings.texel_shadows == "adaptive":
        light, rays = problem.stages.run(stage, shadows.texel_direct, problem, receivers.grids, *args)
    else:
        light, rays = problem.stages.run(stage, direct.direct_lighting, problem, *args)
    problem.counts["rays"] += rays
    return light


def light_at(problem, solver, solution, receivers: Receivers) -> Light:
    """The light of ``solution`` (from ``solver``, a ``core.solvers`` module) at ``receivers``:
    direct light there (``direct_at``; none for a solver that moves no light), the solver's
    ``evaluate`` there, and the content composed once. Every target gets its values here."""
    info = SOLVERS[problem.settings.solver]
    none = np.zeros((len(receivers), 3), np.float32)
    direct = direct_at(problem, receivers) if info.light else none  # AO needs no light
    field = solver.evaluate(problem, solution, receivers)
    indirect = field if info.light else none
    return Light(direct=direct, indirect=indirect,
                 output=compose(problem.settings.baked_content, field, direct, receivers),
                 solved=(solver, solution))
