"""Directional lightmaps: where each texel's light comes from, as the L1 of ``core.sh``.

The plain bake says how much light arrives (``receivers.light_at``); this adds from where, for
every solver alike, from the two parts the plain bake is made of:

- direct light: the direct estimator's own samples (``direct.estimate`` with moments: each
  emitter's shadowed light over cosθ times its direction), one more pass at the texels;
- indirect light: a final gather over the cluster tree (``gather.gather`` with moments) of the
  radiance the solved elements send (ρ × their lighting, ``gather.sender_radiance``).

Each part's moment is scaled per channel so that its lighting at the texel's normal is the plain
bake's part (the solver's ``evaluate`` for the indirect part), the two are summed, and the sum is
scaled to the texel's baked value: L1 · n = L0 exactly, L0 being the plain lightmap.
"""
from __future__ import annotations

import numpy as np

from . import direct, gather, sh
from .receivers import Light, Receivers, at_elements, light_at
from .solvers import SOLVERS


def texel_l1(problem, receivers: Receivers, light: Light) -> np.ndarray:
    """float32[R,3,3] L1 at R receivers (rows R, G, B; world vectors, irradiance/π units; see
    ``core.sh``), from ``light`` (``receivers.light_at`` there: its output is L0). Stages
    ``<label> direction`` (direct) and ``<label> indirect direction`` (the gather)."""
    stages = problem.stages
    points, normals, sizes = receivers.points, receivers.normals, receivers.sizes
    parts = []
    content = problem.settings.baked_content
    if SOLVERS[problem.settings.solver].light and content != "ao":
        if content != "indirect":
            n = len(receivers)
            stage = f"{receivers.label} direction"
            _, rays, _, _, moment = stages.run(
                stage, direct.estimate, problem, points, normals, sizes,
                np.full(n, direct.MODE_FULL, np.int32), problem.settings.light_samples,
                problem.settings.seed, progress=stages.reporter(stage), with_moments=True)
            problem.counts["rays"] += int(rays.sum())
            parts.append((moment, light.direct))
        if np.any(light.indirect > 0.0):
            parts.append((stages.run(f"{receivers.label} indirect direction", _indirect_moment,
                                     problem, light, points, normals), light.indirect))
    return sh.directional_texels(light.output, parts, normals)


def _indirect_moment(problem, light: Light, points: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """float32[R,3,3]: the moment of the light the solved elements reflect to the points."""
    solver, solution = light.solved
    at = light_at(problem, solver, solution, at_elements(problem))
    radiance = gather.sender_radiance(problem, at.direct + at.indirect)
    return gather.gather(problem, points, normals, problem.far, radiance=radiance,
                         with_moment=True).moment
