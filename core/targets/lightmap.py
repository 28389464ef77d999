"""Lightmap pages: every covered texel sample of each page is a receiver on the triangle it lies
on; the pages are made from the values there (``core.lightmap.pages``)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import directional
from .. import receivers as receivers_mod
from ..lightmap import Layout, LightmapRequest, LightmapResult, pages


@dataclass
class PageReceivers(receivers_mod.Receivers):
    """The texel samples of a request's pages (``grids``: each page's ``raster.Texels``) and the
    ``layout`` they were rasterised from."""

    layout: Layout = None


class Target:
    """The lightmaps of ``request`` (``core.lightmap.LightmapRequest``: the objects, their
    existing UVs, where the unwrapper runs); its result is a ``core.lightmap.LightmapResult``."""

    def __init__(self, request: LightmapRequest):
        self.request = request

    def receivers(self, problem) -> PageReceivers:
        """Lay the pages out (stage ``unwrap`` where UVs are made), rasterise them (``raster``)."""
        layout = pages.lay_out(self.request, problem)
        rastered = problem.stages.run("raster", pages.rasterize, layout, problem)
        grids = [r[0] for r in rastered]
        texels = receivers_mod.on_triangles(
            problem, np.concatenate([r[1] for r in rastered]),
            np.concatenate([g.bary for g in grids]), np.concatenate([r[2] for r in rastered]),
            np.concatenate([r[3] for r in rastered]),
            np.concatenate([r[4] for r in rastered]).astype(np.float32), label="texel", grids=grids)
        return PageReceivers(**vars(texels), layout=layout)

    def finish(self, problem, receivers: PageReceivers, light: receivers_mod.Light) -> LightmapResult:
        """The pages; with ``directional`` sh each page also holds its texels' L1
        (``core.directional``)."""
        values = light.output
        if problem.settings.directional == "sh":
            l1 = directional.texel_l1(problem, receivers, light)
            values = np.concatenate([values, l1.transpose(0, 2, 1).reshape(len(values), 9)], axis=1)
        result = pages.assemble(receivers.layout, receivers.grids, values, problem)
        problem.counts["texels"] = result.texels
        return result
