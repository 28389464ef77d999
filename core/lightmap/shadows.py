"""Adaptive shadow rays for lightmap texels: few where the texels around agree, more in penumbrae.

The schedule works on each page's (supersampled) texel grid:

1. Probe: every texel traces one ray, its own sample of one stratified set of light samples over
   its TILE × TILE tile (so a tile's probes spread over the emitters and over each emitter).
2. A tile whose probes all saw light, as did every probe of the tiles around it (8-neighbourhood),
   is lit: its texels get the unoccluded light of ``light_samples`` emitter samples, without rays.
   All shadowed, with the tiles around: dark (0). Every other texel (near a shadow edge, in a
   penumbra, where a probe found no light) traces ``light_samples`` rays.
3. Texels whose estimate is noisy (its standard error, from the spread of its samples, above
   NOISE of it: a penumbra, lights both seen and hidden) and the texels next to them trace up to
   ``shadow_budget`` rays in all, both estimates averaged by their sample counts.
4. Where the light tree chose the emitters (``light_selection`` auto on many emitters), texels
   whose first estimate is very noisy (``direct.exact_again``: beside an emitter the tree's bounds
   under-rate) are estimated again weighing every emitter exactly, their extra samples too.

Where weighing every emitter at every texel is too dear (``direct.exact_selection``), the texels
of one triangle within a GROUP × GROUP square share exact weights (``core.emitter_weights``)
instead of the light tree choosing for them (squares near an emitter keep the tree): on the
emissive room's 512 page the tree's estimates were noisy enough that 98 % of the texels traced
the whole budget; on its 256 page at supersample 2, texel direct 29.1 s with the tree, 9.0 s shared,
both 1.5 % from weighing every texel exactly.

What it can miss: a shadow too faint for a whole neighbourhood of probes (3 × 3 tiles, 144 rays)
to see, covering a fraction f of the light everywhere there, with probability about (1 − f)^144.
"""
from __future__ import annotations

from typing import Callable, Optional

import numpy as np

from .. import direct, emitter_weights

# Side of a tile in texels of the supersampled grid.
TILE = 4
# A texel whose first estimate's relative standard error exceeds this traces up to the budget.
NOISE = 0.05
# Tile classes.
_EMPTY, _LIT, _DARK, _MIXED = 0, 1, 2, 3
# Side (texels of the supersampled grid) of the squares whose texels on one triangle share their
# emitter weights; doubled, up to GROUP_MAX, while the weights of the groups that many texels
# would make (about twice as many as squares, triangles cutting them) pass direct.KEPT_FLOATS.
# Chosen from the whole set's texel count, so a page baked alone groups as the whole does.
GROUP = 4
GROUP_MAX = 32


def _around(grid: np.ndarray):
    """The 9 shifted views (3 × 3 neighbourhood, edges padded with 0) of a 2-D array."""
    pad = np.pad(grid, 1)
    h, w = grid.shape
    return [pad[1 + dy:1 + dy + h, 1 + dx:1 + dx + w] for dy in (-1, 0, 1) for dx in (-1, 0, 1)]


def _tile_classes(flags: np.ndarray, tile: np.ndarray, shape: tuple) -> np.ndarray:
    """int8[TY,TX] class of each tile from its texels' probe flags (int[N], their tiles int[N])."""
    seen = np.zeros((shape[0] * shape[1], 4), bool)
    seen[tile, flags] = True
    cls = np.full(seen.shape[0], _MIXED, np.int8)
    cls[~seen.any(axis=1)] = _EMPTY
    cls[seen[:, 1] & ~seen[:, [0, 2, 3]].any(axis=1)] = _LIT
    cls[seen[:, 2] & ~seen[:, [0, 1, 3]].any(axis=1)] = _DARK
    return cls.reshape(shape)


def _settled(cls: np.ndarray) -> np.ndarray:
    """int8[TY,TX]: a tile's class where it and every non-empty tile around it are lit, or all
    dark; _MIXED elsewhere."""
    out = cls.copy()
    for near in _around(cls):
        out[(near != _EMPTY) & (near != cls)] = _MIXED
    return out


def tile_grid(width: int, height: int) -> tuple[int, int]:
    """(rows, columns) of TILE × TILE tiles over a ``width`` × ``height`` sample grid."""
    return -(-height // TILE), -(-width // TILE)


def _group_side(texels: int, leaves: int) -> int:
    """The side of the weight-sharing squares for ``texels`` texels in all and ``leaves``
    emitters, 0 where even GROUP_MAX would keep too many weights."""
    side = GROUP
    while 2 * texels / side ** 2 * (leaves + 1) > direct.KEPT_FLOATS:
        side *= 2
        if side > GROUP_MAX:
            return 0
    return side


def _groups(pages: list, side: int) -> np.ndarray:
    """int64[N] group of each texel of ``pages`` (in their order): its page, its ``side`` ×
    ``side`` square of the page and its triangle."""
    keys = []
    for k, texels in enumerate(pages):
        y, x = np.divmod(texels.index, texels.width)
        square = (y // side) * -(-texels.width // side) + x // side
        keys.append(np.stack([np.full(len(square), k), square, texels.triangle], 1))
    if not keys:
        return np.zeros(0, np.int64)
    return np.unique(np.concatenate(keys), axis=0, return_inverse=True)[1].ravel()


def _shared(problem, pages: list, points, normals, sizes, whole: int):
    """Shared emitter weights for the texels of ``pages`` where the light tree would choose for
    them (``light_selection`` auto, too many emitters to weigh at each), else None."""
    leaves = problem.lights.num_lamps + problem.lights.num_emitters
    if problem.settings.light_selection != "auto" or direct.exact_selection(problem, whole):
        return None
    side = _group_side(whole, leaves)
    if not side:
        return None
    group = _groups(pages, side)
    if (int(group.max(initial=-1)) + 1) * (leaves + 1) > 2 * direct.KEPT_FLOATS:
        return None  # triangles far finer than the squares: the tree chooses
    return emitter_weights.shared_weights(problem, points, normals, sizes, group)


def texel_direct(problem, pages: list, points: np.ndarray, normals: np.ndarray, sizes: np.ndarray,
                 progress: Optional[Callable[[float], None]] = None, part=None):
    """Direct lighting at the texels of ``pages`` (``raster.Texels`` each, their texels in this
    order in points, normals float32[N,3] and sizes float32[N], as ``direct.estimate`` takes
    them) with adaptive shadow rays (see the module); part: where these pages' texels lie among
    all pages' (``receivers.Part``: tiles and texels before them), None when they are all. Returns
    (float32[N,3] lighting, rays)."""
    settings = problem.settings
    report = progress or (lambda fraction: None)
    seeding = part.seeding() if part is not None else {}
    n = int(points.shape[0])
    grids, tile, start = [], [], 0
    base = part.tiles if part is not None else 0
    for texels in pages:
        y, x = np.divmod(texels.index, texels.width)
        shape = tile_grid(texels.width, texels.height)
        tile.append(base + (y // TILE) * shape[1] + x // TILE)
        grids.append((texels, shape, base, slice(start, start + texels.count)))
        base += shape[0] * shape[1]
        start += texels.count
    tile = np.concatenate(tile) if tile else np.zeros(0, np.int64)
    order = np.argsort(tile, kind="stable")
    per_tile = np.bincount(tile, minlength=base)
    index = np.empty(n, np.int64)
    index[order] = np.arange(n) - np.repeat(np.cumsum(per_tile) - per_tile, per_tile)
    # a probe only tells lit from shadowed: the light tree picks its emitter (any choice would
    # do), where weighing every emitter exactly would cost as much as a full estimate
    _, probe_rays, flags, _ = direct.estimate(problem, points, normals, sizes,
                                           np.full(n, direct.MODE_PROBE, np.int32), 1, settings.seed,
                                           (tile, index, per_tile[tile]),
                                           progress=lambda f: report(0.2 * f), exact=False, **seeding)
    mode = np.full(n, direct.MODE_FULL, np.int32)
    for texels, shape, first, rows in grids:
        cls = _settled(_tile_classes(flags[rows], tile[rows] - first, shape)).ravel()[tile[rows] - first]
        mode[rows] = np.where(cls == _LIT, direct.MODE_UNSHADOWED,
                              np.where(cls == _DARK, direct.MODE_SKIP, direct.MODE_FULL))
    samples = settings.light_samples
    shared = _shared(problem, pages, points, normals, sizes, seeding.get("whole", n))
    out, rays, flags, noise = direct.estimate(problem, points, normals, sizes, mode, samples, settings.seed,
                                       progress=lambda f: report(0.2 + 0.5 * f), shared=shared, **seeding)
    # texels the light tree sampled poorly (beside an emitter), weighing every emitter exactly
    exact, again, exact_rays = direct.exact_again(problem, points, normals, sizes, mode, noise, samples,
                                                  settings.seed + 2, seeding)
    out[exact] = again[exact]
    rays = rays + exact_rays
    more = settings.shadow_budget - samples
    penumbra = np.zeros(n, bool)
    for texels, _, _, rows in grids:
        grid = np.zeros(texels.width * texels.height, bool)
        grid[texels.index] = noise[rows] > NOISE
        grown = np.zeros_like(grid.reshape(texels.height, texels.width))
        for near in _around(grid.reshape(texels.height, texels.width)):
            grown |= near
        penumbra[rows] = grown.ravel()[texels.index] & (mode[rows] == direct.MODE_FULL)
    # penumbra texels get more samples, chosen as their first ones were
    for these, weighed in ((penumbra & ~exact, None), (penumbra & exact, True)):
        if more <= 0 or not these.any():
            continue
        extra, extra_rays, _, _ = direct.estimate(problem, points, normals, sizes,
                                               np.where(these, direct.MODE_FULL, direct.MODE_SKIP),
                                               more, settings.seed + 1,
                                               progress=lambda f: report(0.7 + 0.3 * f), exact=weighed,
                                               shared=None if weighed else shared, **seeding)
        out[these] = (samples * out[these] + more * extra[these]) / (samples + more)
        rays = rays + extra_rays
    return out, int(probe_rays.sum() + rays.sum())
