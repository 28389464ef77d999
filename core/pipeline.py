"""The one orchestrator: SceneData + Settings -> BakeResult, for the operator, the CLI and the tests."""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from functools import partial
from typing import Callable, Optional

import numpy as np

from .errors import BakeCancelled, BakeError
from .scene import SceneData
from .settings import Settings


ProgressFn = Callable[[str, float], None]


@dataclass
class BakeResult:
    """Per-shading-vertex results, all float32[V,3] in linear RGB (radiance units, W m⁻² sr⁻¹).

    lighting: irradiance/π at the shading normal (direct + indirect).
    direct, indirect: its two parts.
    output: the content the settings asked for (lighting, combined, indirect or ao: accessibility
    in all three channels).
    timings: seconds per stage; counts: objects, triangles, elements, lamps, rays, pairs, iterations.
    lightmap: the lightmap pages (``core.lightmap.LightmapResult``) when a lightmap was requested.
    """

    lighting: np.ndarray
    direct: np.ndarray
    indirect: np.ndarray
    output: np.ndarray
    device: str
    timings: dict = field(default_factory=dict)
    counts: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)
    peak_memory_bytes: int = 0
    lightmap: object = None


class _Stages:
    """Times stages, forwards progress, and checks cancellation between launches."""

    def __init__(self, progress: Optional[ProgressFn], cancel):
        self._progress = progress
        self._cancel = cancel
        self.timings: dict[str, float] = {}

    def check(self) -> None:
        if self._cancel is not None and self._cancel.is_set():
            raise BakeCancelled("bake cancelled")

    def report(self, stage: str, fraction: float) -> None:
        self.check()
        if self._progress is not None:
            self._progress(stage, float(fraction))

    def run(self, stage: str, fn, *args, **kwargs):
        self.report(stage, 0.0)
        t0 = time.perf_counter()
        out = fn(*args, **kwargs)
        self.timings[stage] = self.timings.get(stage, 0.0) + time.perf_counter() - t0
        self.report(stage, 1.0)
        return out


def bake(scene: SceneData, settings: Settings, progress: Optional[ProgressFn] = None,
         cancel=None, lightmap=None) -> BakeResult:
    """Bake ``scene`` with ``settings``.

    progress(stage, fraction) is called as stages advance; ``cancel`` is an object with ``is_set()``
    (e.g. threading.Event) checked between kernel launches: when set, BakeCancelled is raised.
    Raises BakeError (clear message) for input that cannot be baked.
    lightmap: a ``core.lightmap.LightmapRequest``: its objects are also unwrapped, rasterised and
    lit per texel (direct light with shadow rays per texel, indirect interpolated from the
    solution, with the detail of a final gather over the hierarchy when ``texel_indirect`` is
    ``gather``) into ``BakeResult.lightmap``.
    """
    from . import device as device_mod
    from . import direct, elements, hierarchy
    from .solvers import ao, bunnell, reference

    settings.validate()
    if settings.ao_distance == 0.0:  # 0 stands for the scene world's AO distance
        settings = replace(settings, ao_distance=float(scene.ao_distance))
    try:
        scene.validate()
    except ValueError as exc:
        raise BakeError(str(exc)) from None
    if scene.num_triangles == 0:
        raise BakeError("nothing to bake: the scene has no triangles")

    stages = _Stages(progress, cancel)
    dev = stages.run("device", device_mod.select, settings.device)
    warnings = []
    areas = scene.triangle_areas()
    degenerate = ~(areas > 0)
    if degenerate.any():
        names = sorted({scene.object_names[i] for i in np.unique(scene.tri_object[degenerate])})
        warnings.append(f"{int(degenerate.sum())} zero-area triangles ignored in {', '.join(names)}")
    els = stages.run("elements", elements.build, scene)
    geometry = stages.run("bvh", direct.SceneGeometry, scene, dev)

    def direct_progress(f):
        stages.report("direct", f)

    if settings.content == "ao":  # AO needs no light
        lit_direct, direct_rays = np.zeros((els.count, 3), np.float32), 0
    else:
        lit_direct, direct_rays = stages.run(
            "direct", direct.direct_lighting, geometry, scene, els.position, els.normal, settings,
            dev, direct_progress)
    counts = {"objects": len(scene.object_names), "triangles": scene.num_triangles,
              "vertices": scene.num_vertices, "elements": els.count, "lamps": len(scene.lamps),
              "emissive_triangles": int(geometry.num_emitters), "rays": int(direct_rays)}
    # The lightmap's final gather needs the tree too (and light to gather: not for AO or direct).
    texel_gather = (lightmap is not None and settings.texel_indirect == "gather"
                    and settings.content != "ao" and settings.solver != "direct")
    hier = None
    if settings.content == "ao" or settings.solver == "bunnell" or texel_gather:
        hier = stages.run("hierarchy", hierarchy.build, els, dev, geometry)
        counts["nodes"] = hier.count

    solvers = {"reference": reference.solve, "bunnell": partial(bunnell.solve, hier=hier)}
    if settings.content != "ao" and settings.solver in solvers:  # AO needs no light transport
        def solve_progress(stage, f):
            stages.report(stage, f)

        solution = stages.run("solve", solvers[settings.solver], geometry, els, lit_direct, settings,
                              dev, solve_progress)
        indirect = solution.indirect
        solver_counts = dict(solution.counts)
        counts["rays"] += int(solver_counts.pop("rays", 0))
        counts.update(solver_counts)
    else:
        indirect = np.zeros_like(lit_direct)

    lightmap_result = None
    if lightmap is not None:
        from .lightmap import bake_lightmaps

        def texel_ao(points, normals):
            access = stages.run("texel ao", ao.accessibility, hier, els, points, normals, settings,
                                dev, lambda f: stages.report("texel ao", f))
            return {"ao": np.repeat(access[:, None], 3, axis=1)}

        per_vertex, gather = {"indirect": indirect}, None
        if texel_gather:
            gather = stages.run("final gather", bunnell.final_gather, hier, els, lit_direct + indirect,
                                geometry, dev)
            per_vertex["gathered"] = stages.run("final gather", gather, els.position, els.normal)
        lightmap_result = bake_lightmaps(lightmap, scene, geometry, per_vertex, settings, dev, stages,
                                         texel_ao if settings.content == "ao" else None, gather)
        warnings += lightmap_result.warnings
        counts["texels"] = lightmap_result.texels

    lighting = lit_direct + indirect
    if settings.content == "ao":
        access = stages.run("ao", ao.accessibility, hier, els, els.position, els.normal, settings, dev,
                            lambda f: stages.report("ao", f))
        output = np.repeat(access[:, None], 3, axis=1)
    else:
        output = {"lighting": lighting,
                  "combined": els.emission + els.albedo * lighting,
                  "indirect": indirect}[settings.content]
    return BakeResult(lighting=lighting.astype(np.float32), direct=lit_direct.astype(np.float32),
                      indirect=indirect.astype(np.float32), output=output.astype(np.float32),
                      device=dev.name, timings=stages.timings, counts=counts, warnings=warnings,
                      peak_memory_bytes=_peak_rss_bytes(), lightmap=lightmap_result)


def _peak_rss_bytes() -> int:
    """Peak resident memory of this process so far (bytes); 0 where the OS does not tell."""
    try:
        import resource
    except ImportError:  # Windows
        return 0
    return int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss) * 1024
