"""The shading vertices: the values color attributes hold, one per shading vertex (the elements
themselves, so the solver's per-element values serve as they are)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import receivers as receivers_mod


@dataclass
class VertexLight:
    """Per shading vertex, float32[S,3] linear RGB (radiance units, W m⁻² sr⁻¹): lighting
    (irradiance/π at the shading normal, direct + indirect), its parts direct and indirect, and
    output, the content the settings asked for (lighting, combined, indirect, or ao: accessibility
    in all three channels). shading: the ``core.elements.ShadingVertices`` they are per (its
    ``corner``: the shading vertex of each scene triangle corner)."""

    lighting: np.ndarray
    direct: np.ndarray
    indirect: np.ndarray
    output: np.ndarray
    shading: object


class Target:
    """The problem's shading vertices."""

    def receivers(self, problem) -> receivers_mod.Receivers:
        return receivers_mod.at_elements(problem)

    def finish(self, problem, receivers, light: receivers_mod.Light) -> VertexLight:
        # the elements the solver added near contacts (``core.refine``) come after the shading
        # vertices: none of them is on the scene's own vertices
        s = slice(problem.shading.count)
        return VertexLight(lighting=(light.direct[s] + light.indirect[s]).astype(np.float32),
                           direct=light.direct[s], indirect=light.indirect[s], output=light.output[s],
                           shading=problem.shading)
