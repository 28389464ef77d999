"""The solvers, one module each, and their registry.

Every solver module provides::

    solve(problem) -> base.Solution                    # per element
    evaluate(problem, solution, receivers) -> float32[R,3]   # at any receivers
    check(problem) -> list[str]                         # optional: warnings before solving

``solve`` reads the problem (``core.problem.Problem``: elements, device arrays, direct light, the
tree) and returns per-element values; ``evaluate`` maps them to receivers (``core.receivers``):
shading vertices for color attributes, lightmap texels. A light solver's values are indirect
lighting (irradiance/π; the pipeline adds the direct part), the AO solver's accessibility.

Adding a solver: write ``core/solvers/<name>.py`` with ``solve`` and ``evaluate`` and add one
``SolverInfo`` line to ``SOLVERS`` below. This module imports no solver (nor Warp) until one is
asked for, so settings and the Blender UI can read the registry cheaply.
"""
from __future__ import annotations

import importlib
from dataclasses import dataclass


@dataclass(frozen=True)
class SolverInfo:
    """name: the ``--method`` value; description: one line for the UI; reads: the settings the
    solver reads beyond the common ones (the panel greys out the others); light: it transports
    light (direct light is computed for it); indirect: it computes indirect light; live: fast
    enough for the live preview to follow the user's edits (others preview with ``PREVIEW``)."""

    name: str
    description: str
    reads: tuple = ()
    light: bool = True
    indirect: bool = True
    live: bool = False


SOLVERS = {info.name: info for info in (
    SolverInfo("direct", "Lamps and emissive surfaces only, with shadows (fast)", indirect=False,
               live=True),
    SolverInfo("reference", "Direct light plus multi-bounce indirect light over all element pairs "
               "with ray-cast visibility (ground truth, small scenes)",
               reads=("visibility_rays", "bounces", "tolerance", "max_pairs", "texel_indirect")),
    SolverInfo("hierarchical", "Direct light plus multi-bounce indirect light over links between "
               "element clusters with ray-cast visibility (accurate, large scenes)",
               reads=("visibility_rays", "bounces", "tolerance", "link_threshold", "link_memory",
                      "texel_indirect", "texel_links"), live=True),
    SolverInfo("implicit", "Direct light plus multi-bounce indirect light over unoccluded links "
               "where, per receiver and direction bin, only the nearest layer of senders counts (implicit "
               "visibility: no rays, approximate)",
               reads=("visibility_rays", "bounces", "tolerance", "link_threshold", "link_memory",
                      "directional_bins", "texel_indirect")),
    SolverInfo("antiradiance", "Direct light plus multi-bounce indirect light over unoccluded links, "
               "shadows made by antiradiance sent on through every surface (no rays)",
               reads=("visibility_rays", "bounces", "tolerance", "link_threshold", "link_memory",
                      "directional_bins", "texel_indirect")),
    SolverInfo("bunnell", "Direct light plus one bounce of indirect light gathered over a disk "
               "hierarchy (fast, large scenes, approximate)", reads=("texel_indirect",), live=True),
    SolverInfo("ao", "Ambient occlusion: the unoccluded fraction of the hemisphere within the AO "
               "distance (what Cycles' AO bake gives)", reads=("ao_distance",), light=False,
               indirect=False, live=True),
)}
# The method the live preview uses for methods that are not ``live``.
PREVIEW = "bunnell"


def get(name: str):
    """The solver module registered as ``name``."""
    if name not in SOLVERS:
        raise KeyError(f"no solver {name!r}; known: {', '.join(SOLVERS)}")
    return importlib.import_module(f"{__name__}.{name}")
