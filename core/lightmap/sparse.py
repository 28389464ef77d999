"""Supersampled texels gathered sparsely: one sub-sample per texel, all of them where the texels
around disagree.

At ``supersample`` s > 1 each texel holds up to s² receivers. What the final gather adds to the
interpolated solution (its detail, ``solvers.base.reconstruct_with_detail``) changes little within
most texels, so it is gathered at one sub-sample per texel (the first in receiver order) and
shared by the others; a texel whose detail differs from one of its 8 neighbours' by more than
SPREAD of its own indirect light (a contact, an indirect shadow's edge) is gathered at every
sub-sample. Measured on the furnished room of ``bench/real_scenes.py`` (a 126×127 page at
supersample 2, against Cycles' footprint truth, ``bench/lightmap_errors.py``): every sub-sample
2.99 %, one per texel 3.07 %, SPREAD 0.05 2.99 % with a quarter of the texels gathered again.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

# A texel whose detail differs from a neighbour's by more than this share of its indirect light
# gathers at each of its sub-samples.
SPREAD = 0.05


def texels_of(grids: list, supersample: int) -> tuple[np.ndarray, list]:
    """int64[R] the texel of each receiver of ``grids`` (``raster.Texels`` per page at
    ``supersample``² samples per texel, receivers in their order) numbered over all pages, and
    per page (first texel, width, height) in texels."""
    s = supersample
    keys, pages, start = [], [], 0
    for g in grids:
        w, h = g.width // s, g.height // s
        y, x = np.divmod(g.index, g.width)
        keys.append(start + (y // s) * w + x // s)
        pages.append((start, w, h))
        start += w * h
    return (np.concatenate(keys) if keys else np.zeros(0, np.int64)), pages


def _spread(values: np.ndarray, pages: list) -> np.ndarray:
    """float64[T]: per texel the largest |difference| of ``values`` (float64[T], NaN where no
    value) to its 8 neighbours on its page (0 with none)."""
    out = np.zeros(values.shape[0])
    for start, w, h in pages:
        grid = values[start:start + w * h].reshape(h, w)
        pad = np.pad(grid, 1, constant_values=np.nan)
        most = np.zeros((h, w))
        for dy in (0, 1, 2):
            for dx in (0, 1, 2):
                most = np.fmax(most, np.abs(pad[dy:dy + h, dx:dx + w] - grid))  # NaN: no neighbour
        out[start:start + w * h] = most.ravel()
    return out


def gather(grids: list, supersample: int, detail_at: Callable, base: np.ndarray,
           progress: Callable[[float], None]) -> tuple[np.ndarray, float]:
    """(float32[R,3] detail at every receiver of ``grids``, share of texels gathered at each
    sub-sample): ``detail_at(index int64[k], progress)`` gives float32[k,3] at those receivers;
    ``base`` float32[R,3] the indirect light interpolated at the receivers, against which a
    texel's spread is weighed."""
    key, pages = texels_of(grids, supersample)
    texels = pages[-1][0] + pages[-1][1] * pages[-1][2] if pages else 0
    _, first, inverse = np.unique(key, return_index=True, return_inverse=True)
    sparse = detail_at(first, lambda f: progress(0.5 * f))
    detail = sparse[inverse]
    luminance = np.full(texels, np.nan)
    luminance[key[first]] = sparse.sum(axis=1)
    light = np.zeros(texels)
    light[key[first]] = np.abs(base[first].sum(axis=1) + sparse.sum(axis=1))
    again = _spread(luminance, pages) > SPREAD * light
    gathered = np.zeros(key.shape[0], bool)
    gathered[first] = True
    more = np.nonzero(again[key] & ~gathered)[0]
    if more.size:
        detail[more] = detail_at(more, lambda f: progress(0.5 + 0.5 * f))
    progress(1.0)
    return detail, float(again[key[first]].mean()) if first.size else 0.0
