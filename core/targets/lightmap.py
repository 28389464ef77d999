"""Lightmap pages: every covered texel sample of each page is a receiver on the triangle it lies
on; the pages are made from the values there (``core.lightmap.pages``).

A target can also bake a run of the pages of a layout made beforehand (a farm bakes each page as a
task, ``core.farm``): its texels are then seeded as among all pages' (``receivers.Part``), so the
pages come out as a bake of them all makes them."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

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
    existing UVs, where the unwrapper runs); its result is a ``core.lightmap.LightmapResult``.

    layout, counts, only: to bake the pages ``only`` (a range of page indices) of a ``layout``
    already made, whose pages have ``counts`` texel samples each (both from :meth:`split`); the
    result then holds those pages alone. None: lay out and bake all.
    """

    def __init__(self, request: Optional[LightmapRequest], layout: Optional[Layout] = None,
                 counts: Optional[list] = None, only: Optional[range] = None):
        self.request, self.layout, self.counts, self.only = request, layout, counts, only

    def split(self, problem) -> tuple[Layout, list]:
        """The pages as parts to bake apart (a farm's tasks): the layout (stage ``unwrap`` where UVs
        are made) and each page's texel samples; page k is then baked by
        ``Target(None, layout, counts, range(k, k + 1))`` and the parts joined by :meth:`join`."""
        layout = pages.lay_out(self.request, problem)
        return layout, problem.stages.run("raster", pages.texel_counts, layout, problem)

    def join(self, problem, layout: Layout, parts: list) -> LightmapResult:
        """The result of all pages of ``layout`` from the parts' results (LightmapResult each, in
        page order)."""
        result = pages.collect(layout, [p for r in parts for p in r.pages],
                               max((r.seam_error for r in parts), default=0.0), problem)
        problem.counts["texels"] = result.texels
        return result

    def receivers(self, problem) -> PageReceivers:
        """Lay the pages out (stage ``unwrap`` where UVs are made), rasterise them (``raster``)."""
        layout = self.layout if self.layout is not None else pages.lay_out(self.request, problem)
        rastered = problem.stages.run("raster", pages.rasterize, layout, problem, self.only)
        grids = [r[0] for r in rastered]
        texels = receivers_mod.on_triangles(
            problem, np.concatenate([r[1] for r in rastered]),
            np.concatenate([g.bary for g in grids]), np.concatenate([r[2] for r in rastered]),
            np.concatenate([r[3] for r in rastered]),
            np.concatenate([r[4] for r in rastered]).astype(np.float32), label="texel", grids=grids,
            part=self._part(layout, problem.settings.supersample))
        return PageReceivers(**vars(texels), layout=layout)

    def _part(self, layout: Layout, supersample: int) -> Optional[receivers_mod.Part]:
        """Where the texels of pages ``only`` lie among all pages' (None when baking them all)."""
        if self.only is None:
            return None
        first = self.only.start
        return receivers_mod.Part(first=int(sum(self.counts[:first])),
                                  tiles=sum(pages.page_tiles(layout, k, supersample) for k in range(first)),
                                  whole=int(sum(self.counts)))

    def finish(self, problem, receivers: PageReceivers, light: receivers_mod.Light) -> LightmapResult:
        """The pages; with ``directional`` (sh, godot, unity) each page also holds its texels' L1
        (``core.directional``; the writer lays it out)."""
        values = light.output
        if problem.settings.directional != "none":
            l1 = directional.texel_l1(problem, receivers, light)
            values = np.concatenate([values, l1.transpose(0, 2, 1).reshape(len(values), 9)], axis=1)
        result = pages.assemble(receivers.layout, receivers.grids, values, problem, self.only)
        problem.counts["texels"] = result.texels
        return result
