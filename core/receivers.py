"""Receivers: the points where results are wanted, and how each is rebuilt from the elements.

Shading vertices (for color attributes) and lightmap texels are both receivers. Each has a
position, a normal, a local feature size (for ray offsets), the albedo and emission of the surface
it lies on (for ``combined``) and a reconstruction from the solver's elements: element indices and
weights, used by ``evaluate`` to interpolate per-element values. ``aligned`` receivers are the
elements themselves (weight 1 each, in element order), so per-element values serve as they are.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Receivers:
    """R receivers.

    points, normals: float32[R,3] (m in the problem's frame, unit); sizes: float32[R] local feature
    size (m); albedo, emission: float32[R,3]; elements: int32[R,K] and weights: float32[R,K], each
    receiver as a weighted sum of elements; aligned: receiver r is element r.
    """

    points: np.ndarray
    normals: np.ndarray
    sizes: np.ndarray
    albedo: np.ndarray
    emission: np.ndarray
    elements: np.ndarray
    weights: np.ndarray
    aligned: bool = False

    def __len__(self) -> int:
        return int(self.points.shape[0])

    def reconstruct(self, per_element: np.ndarray) -> np.ndarray:
        """float32[R,C]: Σ_k weights[:,k] · per_element[elements[:,k]] (per_element float32[n,C])."""
        if self.aligned:
            return np.asarray(per_element, np.float32)
        return np.einsum("rk,rkc->rc", self.weights, per_element[self.elements]).astype(np.float32)


def at_elements(problem) -> Receivers:
    """The shading vertices of ``problem`` as receivers: its elements are one disk per shading
    vertex (``core.elements``), so they are aligned."""
    els = problem.elements
    n = els.count
    return Receivers(points=els.position, normals=els.normal, sizes=problem.element_sizes,
                     albedo=els.albedo, emission=els.emission,
                     elements=np.arange(n, dtype=np.int32)[:, None],
                     weights=np.ones((n, 1), np.float32), aligned=True)


def on_triangles(problem, triangles: np.ndarray, bary: np.ndarray, points: np.ndarray,
                 normals: np.ndarray, sizes: np.ndarray) -> Receivers:
    """Receivers on the scene's triangles (lightmap texels): ``triangles`` int32[R] scene triangle
    of each, ``bary`` float32[R,3] its barycentric coordinates there (interpolation weights of the
    triangle's corner elements); points, normals float32[R,3] and sizes float32[R] as sampled."""
    scene = problem.scene
    return Receivers(points=points, normals=normals, sizes=sizes, albedo=scene.albedo[triangles],
                     emission=scene.emission[triangles],
                     elements=problem.elements.corner[triangles],
                     weights=np.asarray(bary, np.float32))


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
