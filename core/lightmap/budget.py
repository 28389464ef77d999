"""How many texels lightmaps will take, estimated before unwrapping, so that a bake whose pages
would not fit in memory stops at once with a density that fits (instead of running out of
memory, or running for hours, halfway through).
"""
from __future__ import annotations

import os

import numpy as np

from ..errors import SettingsError
from .pages import _asked

# Memory a covered texel (a sub-sample with supersampling) takes at the peak of a lightmap bake:
# rasterised sample, receiver point, normal and size, direct light, the solver's value, the
# composed content, the page and its dilation. Measured: 320 bytes with --method direct (3.3
# million texels: 1.05 GB more than a bake of 1000); gathers need more.
BYTES_PER_TEXEL = 400
# The share of the machine's memory lightmaps may take; without a way to ask the OS, this much.
MEMORY_SHARE = 0.5
FALLBACK_MEMORY = 16 << 30


def memory_budget() -> int:
    """Bytes the lightmaps of one bake may take: MEMORY_SHARE of the physical memory."""
    try:
        total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (AttributeError, ValueError, OSError):  # Windows has no sysconf
        total = FALLBACK_MEMORY
    return int(MEMORY_SHARE * total)


def _texels(area: np.ndarray, density: np.ndarray, settings, scale: float) -> float:
    """Covered texels (sub-samples) of meshes of world ``area`` (float64[M], m²) at ``density``
    × ``scale`` (float64[M], texels per metre): each mesh at most one page (max_size²), an atlas
    of one page at most one page in all."""
    pages = float(settings.max_size) ** 2
    texels = np.minimum(area * (density * scale) ** 2, pages).sum()
    if settings.layout == "atlas" and settings.atlas_pages == "one":
        texels = min(texels, pages)
    return float(texels) * settings.supersample ** 2


def check(targets: list, scene, settings) -> float:
    """Estimate the covered lightmap texels of ``targets`` (``LightmapObject``, over the
    ``SceneData`` ``scene``) at their asked densities and return it; raise SettingsError, saying
    which texel density fits, when they would take more than :func:`memory_budget`."""
    area = np.empty(len(targets))
    for i, t in enumerate(targets):
        tri = scene.triangles[t.triangle_offset:t.triangle_offset + t.corner_triangles.shape[0]]
        p = scene.positions[tri].astype(np.float64)
        area[i] = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1).sum()
    density = np.array([_asked(t, settings) for t in targets], np.float64)
    texels, budget = _texels(area, density, settings, 1.0), memory_budget()
    if texels * BYTES_PER_TEXEL <= budget:
        return texels
    low, high = 0.0, 1.0  # the largest scale of every density that fits (texels grow with it)
    for _ in range(64):
        mid = 0.5 * (low + high)
        fits = _texels(area, density, settings, mid) * BYTES_PER_TEXEL <= budget
        low, high = (mid, high) if fits else (low, mid)
    fit = settings.texel_density * low
    step = 10.0 ** (np.floor(np.log10(fit)) - 2)  # three digits, rounded down: it still fits
    own = " (objects' own densities scaled alike)" if any(t.density for t in targets) else ""
    fewer = "" if settings.supersample == 1 else f", at --supersample {settings.supersample}"
    raise SettingsError(
        f"lightmaps at {settings.texel_density:g} texels/m (--max-size {settings.max_size}{fewer}) "
        f"would hold about {texels / 1e6:,.0f} million texels, {texels * BYTES_PER_TEXEL / 2**30:,.1f} "
        f"GB, more than the {budget / 2**30:,.1f} GB a bake may use (half this machine's memory): "
        f"a texel density of {np.floor(fit / step) * step:g}{own} fits")
