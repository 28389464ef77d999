"""Lightmap pages: which objects share a page and their UVs (:func:`lay_out`), the texels of each
page (:func:`rasterize`), and the pages made from the values at those texels (:func:`assemble`:
resolve, dilation, seams). The lightmap target (``core.targets.lightmap``) runs them as stages of
the one orchestrator, the light at the texels coming through the path every target shares.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional

import numpy as np

from ..errors import BakeError
from . import raster, shadows, unwrap

ATLAS_NAME = "Lightmap"
# The UDIM tile of an atlas's first page.
UDIM_FIRST = 1001


@dataclass
class LightmapObject:
    """One object to lightmap (the add-on's ``TargetMesh`` plus its existing UVs).

    object_name, mesh_name: Blender names; objects sharing ``mesh_name`` share its UV map.
    corner_vert: int32[C] mesh vertex of each face corner; corner_triangles: int32[T,3] face
    corners of the object's triangles, which are SceneData triangles ``triangle_offset … + T``
    (in their corner order). corner_uv: float32[C,2] the mesh's existing ``Lightmap`` UVs to reuse,
    None to unwrap. density: its own texel density (texels per metre), None for the settings'.
    """

    object_name: str
    mesh_name: str
    corner_vert: np.ndarray
    corner_triangles: np.ndarray
    triangle_offset: int
    corner_uv: Optional[np.ndarray] = None
    density: Optional[float] = None


@dataclass
class LightmapRequest:
    """What to lightmap. python: interpreter for the xatlas worker (default sys.executable);
    cache_dir: unwrap cache (default ``cache.default_dir()``); sizes: {layout group: {page
    index: (page size, density)}} to keep for reused UVs (an animation's later frames keep the
    first frame's pages, ``LightmapResult.sizes``), None to size them by the density."""

    targets: list
    python: Optional[str] = None
    cache_dir: Optional[Path] = None
    sizes: Optional[dict] = None


@dataclass
class Page:
    """One lightmap page: ``rgb`` float32[H,W,3] linear (row 0 = v 0, Blender's bottom row),
    ``covered`` bool[H,W] texels on a chart (the rest is dilated padding or empty), the
    ``objects`` whose ``Lightmap`` UVs point into it and the lowest texel ``density`` among them
    (texels/m). ``name`` is its image's; ``tile`` its UDIM tile number when the image is a tile set
    (an atlas of several pages), else None. ``l1``: a directional bake's float32[H,W,9] L1 per
    texel (``core.sh``: channels L1x.R, L1x.G, L1x.B, L1y.R … L1z.B; ``rgb`` is its L0), else
    None."""

    name: str
    objects: list
    rgb: np.ndarray
    covered: np.ndarray
    density: float
    tile: Optional[int] = None
    l1: Optional[np.ndarray] = None

    @property
    def size(self) -> tuple:
        return int(self.rgb.shape[1]), int(self.rgb.shape[0])

    @property
    def stem(self) -> str:
        """Its file name without extension: ``Lightmap``, or ``Lightmap.1002`` for a tile."""
        return self.name if self.tile is None else f"{self.name}.{self.tile}"


@dataclass
class LightmapResult:
    """pages; uv: {mesh name: float32[C,2]} layouts made by this bake (to write as ``Lightmap``;
    a tile set's UVs lie in their tiles, u + k for the k-th page); seam_error: largest difference
    across smooth UV seams relative to the brightest texel of its page (0 without seams); texels:
    covered texels; warnings; densities: {object: (asked, used)} texels per metre; sizes: {layout
    group: {page index: (page size, density)}} (see ``LightmapRequest.sizes``)."""

    pages: list
    uv: dict
    seam_error: float = 0.0
    texels: int = 0
    warnings: list = field(default_factory=list)
    densities: dict = field(default_factory=dict)
    sizes: dict = field(default_factory=dict)

    def report(self) -> dict:
        """What a bake report says of the lightmaps: each page (image, UDIM tile, size, objects)
        and each object's texel density, as asked or lowered."""
        return {"pages": [{"image": p.name, "tile": p.tile, "size": list(p.size), "objects": p.objects}
                          for p in self.pages],
                "density": {name: {"asked": round(asked, 4), "used": round(used, 4),
                                   "note": "as asked" if used >= asked * 0.999 else "lowered"}
                            for name, (asked, used) in self.densities.items()}}


@dataclass
class _Group:
    """Meshes laid out together (one unwrap) and the pages made from that layout: one page for
    all objects (``per_object`` False) or one per object."""

    name: str
    owners: list            # LightmapObject per mesh (the first object using it)
    objects: dict           # mesh name -> [LightmapObject] using it
    unwrap: bool
    per_object: bool


def _plan(targets: list, settings) -> tuple[list, list]:
    """Groups of meshes to lay out together, and warnings.

    atlas: meshes unwrapped now share one page; meshes with reused ``Lightmap`` UVs share one page
    when every mesh reuses (a rebake), else each gets its own (their UVs were not laid out with the
    new ones). A mesh shared by several objects has one UV map: in an atlas only its first object
    is baked (the others would overlap it); per_object gives each object its own page.
    """
    warnings = []
    owners: dict[str, LightmapObject] = {}
    users: dict[str, list] = {}
    for t in targets:
        owners.setdefault(t.mesh_name, t)
        users.setdefault(t.mesh_name, []).append(t)
    if settings.layout == "per_object":
        return [_Group(f"{ATLAS_NAME}_{o.mesh_name}", [o], {o.mesh_name: users[o.mesh_name]},
                       o.corner_uv is None or settings.reunwrap, True) for o in owners.values()], warnings
    for mesh, objs in users.items():
        if len(objs) > 1:
            warnings.append(f"mesh {mesh} is shared by {', '.join(o.object_name for o in objs)}: in a "
                            f"shared atlas only {objs[0].object_name} is lightmapped; use the "
                            f"per-object layout or make them single-user")
    fresh = [o for o in owners.values() if o.corner_uv is None or settings.reunwrap]
    kept = [o for o in owners.values() if not (o.corner_uv is None or settings.reunwrap)]
    groups = []
    if fresh:
        groups.append(_Group(ATLAS_NAME, fresh, {o.mesh_name: [o] for o in fresh}, True, False))
    if kept and not fresh:
        groups.append(_Group(ATLAS_NAME, kept, {o.mesh_name: [o] for o in kept}, False, False))
    else:
        groups += [_Group(f"{ATLAS_NAME}_{o.object_name}", [o], {o.mesh_name: [o]}, False, False)
                   for o in kept]
    return groups, warnings


def _triangles(t: LightmapObject) -> slice:
    """The target's triangles among the scene's."""
    return slice(t.triangle_offset, t.triangle_offset + t.corner_triangles.shape[0])


def _mesh_vertices(t: LightmapObject, scene) -> np.ndarray:
    """float32[N,3] position of each mesh vertex (from any of its corners)."""
    n = int(t.corner_vert.max()) + 1 if t.corner_vert.size else 0
    out = np.zeros((n, 3), np.float32)
    out[t.corner_vert[t.corner_triangles]] = scene.positions[scene.triangles[_triangles(t)]]
    return out


def _corner_uv(t: LightmapObject, tri_uv: np.ndarray) -> tuple[np.ndarray, int]:
    """Per-corner UVs float32[C,2] from per-triangle-corner UVs, and how many triangles disagree
    with them (a polygon cut by a chart seam: its corners can hold one UV each)."""
    c = t.corner_vert.shape[0]
    uv = np.zeros((c, 2), np.float32)
    ok = np.isfinite(tri_uv).all(axis=(1, 2))
    uv[t.corner_triangles[ok].ravel()] = tri_uv[ok].reshape(-1, 2)
    conflicts = int((np.abs(uv[t.corner_triangles[ok]] - tri_uv[ok]) > 1e-6).any(axis=(1, 2)).sum())
    return uv, conflicts


def _page_side(owners: list, scene, uvs: dict, settings) -> tuple[tuple, float]:
    """Size of a square page for reused UVs at the owners' asked densities (capped by
    max_size), and the density it gives."""
    world, texture, asked = 0.0, 0.0, 0.0
    for o in owners:
        p = scene.positions[scene.triangles[_triangles(o)]].astype(np.float64)
        q = uvs[o.mesh_name][o.corner_triangles].astype(np.float64)
        area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1).sum()
        world += area
        asked += area * _asked(o, settings) ** 2
        e1, e2 = q[:, 1] - q[:, 0], q[:, 2] - q[:, 0]
        texture += 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]).sum()
    if texture <= 0.0:
        raise BakeError(f"the Lightmap UVs of {owners[0].object_name} have no area")
    side = np.sqrt(asked / texture)
    side = int(min(settings.max_size, max(16, 4 * np.ceil(side / 4))))
    return (side, side), side / np.sqrt(world / texture)


def _asked(target: LightmapObject, settings) -> float:
    """The texel density asked for ``target`` (texels per metre): its own, else the settings'."""
    return float(target.density) if target.density else float(settings.texel_density)


def _tile_offset(index: int) -> np.ndarray:
    """float32[2]: where UDIM tile ``UDIM_FIRST + index`` starts in UV space (10 tiles a row)."""
    return np.array([index % 10, index // 10], np.float32)


def _tile_of(tri_uv: np.ndarray) -> int:
    """The UDIM tile index (0 for UVs in [0,1]²) a mesh's reused UVs (float32[T,3,2]) lie in."""
    centre = np.nanmedian(tri_uv.reshape(-1, 2), axis=0) if tri_uv.size else np.zeros(2)
    u, v = (max(0, int(np.floor(c))) for c in np.nan_to_num(centre))
    return min(u, 9) + 10 * v


def _pages(group, tile, members: list, size: tuple, density: float) -> list:
    """Page entries (image name, UDIM tile, objects, size, density, targets) of one page of
    ``group``'s layout holding ``members``: one for the atlas, one per object using the mesh in
    the per-object layout (a mesh shared by several objects gives each its own image)."""
    if group.per_object:
        return [(f"{ATLAS_NAME}_{t.object_name}", None, [t.object_name], size, density, [t])
                for o in members for t in group.objects[o.mesh_name]]
    return [(group.name, tile, [o.object_name for o in members], size, density, members)]


@dataclass
class Layout:
    """A request's pages laid out (:func:`lay_out`). pages: per page (image name, UDIM tile or None,
    objects, (width, height) texels, density texels/m, the LightmapObjects on it); uvs: {mesh:
    float32[C,2] corner UVs within its page}; made: {mesh: float32[C,2]} the UVs laid out now, to
    write (tile offsets in); densities: {object: (asked, used)} texels/m; sizes: {layout group:
    {page index: (size, density)}}; warnings."""

    pages: list
    uvs: dict
    made: dict
    densities: dict
    sizes: dict
    warnings: list


def lay_out(request: LightmapRequest, problem) -> Layout:
    """Group the objects of ``request`` into pages, unwrapping (xatlas, stage ``unwrap``) those
    without reusable ``Lightmap`` UVs and sizing the pages of the others by their texel density."""
    settings, stages, scene = problem.settings, problem.stages, problem.source
    if not request.targets:
        raise BakeError("no object to lightmap")
    groups, warnings = _plan(request.targets, settings)
    uvs: dict[str, np.ndarray] = {}  # per mesh: its corner UVs within its page
    made: dict[str, np.ndarray] = {}  # per mesh laid out now: its corner UVs to write (tile offsets in)
    densities: dict[str, tuple] = {}  # per object: (asked, used) texels per metre
    pages = []  # (image name, UDIM tile or None, objects, size, density, targets on it)
    sizes: dict[str, dict] = {}  # per layout group: {page index: (size, density)}
    fresh = [g for g in groups if g.unwrap]
    if fresh:
        layouts = stages.run("unwrap", unwrap.unwrap,
                             [[unwrap.ChartMesh(o.object_name, _mesh_vertices(o, scene),
                                                o.corner_vert[o.corner_triangles], _asked(o, settings),
                                                o.corner_triangles)
                               for o in g.owners] for g in fresh],
                             settings.max_size, settings.padding, settings.atlas_pages == "many",
                             request.python, request.cache_dir, check=stages.check)
        for g, layout in zip(fresh, layouts):
            tiled = len(layout.sizes) > 1
            for o, index, density, tri_uv in zip(g.owners, layout.page, layout.density, layout.tri_uv):
                uvs[o.mesh_name], conflicts = _corner_uv(o, tri_uv)
                made[o.mesh_name] = uvs[o.mesh_name] + (_tile_offset(index) if tiled else 0.0)
                for t in g.objects[o.mesh_name]:
                    densities[t.object_name] = (_asked(o, settings), density)
                if conflicts:
                    warnings.append(f"{o.object_name}: {conflicts} triangles of polygons cut by a lightmap "
                                    f"chart seam are distorted; triangulate the mesh for exact charts")
            for index, size in enumerate(layout.sizes):
                members = [o for o, k in zip(g.owners, layout.page) if k == index]
                sizes.setdefault(g.name, {})[index] = (size, min(densities[o.object_name][1] for o in members))
                pages += _pages(g, UDIM_FIRST + index if tiled else None, members, *sizes[g.name][index])
    for g in groups:
        if g.unwrap:
            continue
        tiles: dict[int, list] = {}
        for o in g.owners:
            uv = np.asarray(o.corner_uv, np.float32)
            tile = _tile_of(uv[o.corner_triangles])
            uvs[o.mesh_name] = uv - _tile_offset(tile)
            tiles.setdefault(tile, []).append(o)
        kept = (request.sizes or {}).get(g.name, {})
        if set(tiles) <= set(kept):  # an animation's later frame: the first frame's pages
            sizes[g.name] = {tile: kept[tile] for tile in tiles}
        else:
            sides = {tile: _page_side(members, scene, uvs, settings) for tile, members in tiles.items()}
            side = max(size[0] for size, _ in sides.values())
            sizes[g.name] = {tile: ((side, side), sides[tile][1] * side / sides[tile][0][0]) for tile in tiles}
        for tile, members in sorted(tiles.items()):
            size, density = sizes[g.name][tile]
            for o in members:
                for t in g.objects[o.mesh_name]:
                    densities[t.object_name] = (_asked(o, settings), density)
            pages += _pages(g, UDIM_FIRST + tile if len(tiles) > 1 else None, members, size, density)
    for name, (asked, used) in densities.items():
        if used < asked * 0.999:
            others = "" if settings.atlas_pages == "many" else " with the others"
            warnings.append(f"lightmap of {name}: {asked:g} texels/m would not fit {settings.max_size}² "
                            f"texels{others}: {used:.3g} texels/m used")
    return Layout(pages, uvs, made, densities, sizes, warnings)


def _page_triangles(layout: Layout, page: int) -> tuple[np.ndarray, np.ndarray]:
    """The triangles on page ``page`` of ``layout``: float32[T,3,2] their UVs in the page, int[T]
    their scene triangles."""
    members = layout.pages[page][5]
    return (np.concatenate([layout.uvs[m.mesh_name][m.corner_triangles] for m in members]),
            np.concatenate([np.arange(m.triangle_offset, m.triangle_offset + m.corner_triangles.shape[0])
                            for m in members]))


def rasterize(layout: Layout, problem, only: Optional[range] = None) -> list:
    """Each page's texels (stage ``raster``): per page (``raster.Texels`` at ``supersample``² samples
    per texel, int[N] scene triangle of each, float32[N,3] surface points and normals, float32[N]
    metres per sample there); only: the indices of the pages to rasterise (default all)."""
    scene, dev, s = problem.source, problem.device, problem.settings.supersample
    out = []
    for k in range(len(layout.pages)) if only is None else only:
        (w, h) = layout.pages[k][3]
        tri_uv, tri_scene = _page_triangles(layout, k)
        texels = raster.rasterize(tri_uv, w * s, h * s, dev)
        pos = scene.positions[scene.triangles[tri_scene]]
        world = 0.5 * np.linalg.norm(np.cross(pos[:, 1] - pos[:, 0], pos[:, 2] - pos[:, 0]), axis=1)
        q = tri_uv.astype(np.float64) * (w * s, h * s)
        e1, e2 = q[:, 1] - q[:, 0], q[:, 2] - q[:, 0]
        uv_area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
        metres = np.nan_to_num(np.sqrt(world / np.where(uv_area > 0, uv_area, np.inf)))
        points, normals = raster.surface_points(texels, pos, scene.corner_normals[tri_scene],
                                                metres, problem)
        out.append((texels, tri_scene[texels.triangle], points, normals, metres[texels.triangle]))
    return out


def texel_counts(layout: Layout, problem) -> list[int]:
    """The texel samples (receivers) of each page of ``layout``, as :func:`rasterize` makes them,
    from the coverage alone (no surface points): where each page's receivers start among all
    pages', for baking pages apart (``receivers.Part``)."""
    s = problem.settings.supersample
    return [raster.rasterize(_page_triangles(layout, k)[0], w * s, h * s, problem.device).count
            for k, (_, _, _, (w, h), _, _) in enumerate(layout.pages)]


def page_tiles(layout: Layout, page: int, supersample: int) -> int:
    """The adaptive-shadow tiles (``shadows.tile_grid``) of page ``page`` at ``supersample``."""
    w, h = layout.pages[page][3]
    ty, tx = shadows.tile_grid(w * supersample, h * supersample)
    return ty * tx


def assemble(layout: Layout, grids: list, values: np.ndarray, problem,
             only: Optional[range] = None) -> LightmapResult:
    """The pages of ``layout`` (only: the indices of those ``grids`` are of, default all) from
    float32[N,3] ``values`` at the texel samples of ``grids`` (each page's ``raster.Texels``, in
    order): resolved, dilated into padding, seams measured (stage ``dilate``). float32[N,12] values
    are a directional bake's: RGB, then the page's ``l1``."""
    settings, s = problem.settings, problem.settings.supersample
    uvs = layout.uvs

    def assemble_pages():
        out, start, seam_error = [], 0, 0.0
        for k, texels in zip(range(len(layout.pages)) if only is None else only, grids):
            name, tile, objects, (w, h), density, members = layout.pages[k]
            texel_values, covered = _resolve(texels, values[start:start + texels.count], w, h, s)
            start += texels.count
            texel_values = dilate(texel_values, covered, settings.padding)
            rgb = texel_values[..., :3]
            l1 = texel_values[..., 3:] if texel_values.shape[2] > 3 else None
            out.append(Page(name, objects, rgb, covered, density, tile, l1))
            for m in members:
                seam_error = max(seam_error, seam_difference(
                    rgb, uvs[m.mesh_name], m.corner_triangles, problem.shading.corner[_triangles(m)]))
        return out, seam_error

    return collect(layout, *problem.stages.run("dilate", assemble_pages), problem)


def collect(layout: Layout, made: list, seam_error: float, problem) -> LightmapResult:
    """The result of ``layout`` from its pages ``made`` (``Page`` each, in layout order, made
    here or apart) and their largest seam error; its warnings go to the problem's stages and its
    report into ``problem.counts``."""
    for message in layout.warnings:
        problem.stages.warn(message)
    result = LightmapResult(pages=made, uv=layout.made, seam_error=seam_error,
                            texels=int(sum(p.covered.sum() for p in made)),
                            warnings=layout.warnings, densities=layout.densities, sizes=layout.sizes)
    problem.counts["lightmap"] = result.report()
    return result


def _resolve(texels: raster.Texels, values: np.ndarray, w: int, h: int, s: int):
    """Page float32[H,W,C] and coverage bool[H,W] from supersampled texel values float32[N,C]
    (mean of each texel's covered sub-samples)."""
    c = values.shape[1]
    acc = np.zeros((h * s * w * s, c), np.float64)
    cnt = np.zeros(h * s * w * s, np.float64)
    acc[texels.index] = values
    cnt[texels.index] = 1.0
    acc = acc.reshape(h, s, w, s, c).sum(axis=(1, 3))
    cnt = cnt.reshape(h, s, w, s).sum(axis=(1, 3))
    covered = cnt > 0
    rgb = np.where(covered[..., None], acc / np.maximum(cnt, 1.0)[..., None], 0.0)
    return rgb.astype(np.float32), covered


def dilate(rgb: np.ndarray, covered: np.ndarray, rings: int) -> np.ndarray:
    """Grow charts ``rings`` texels into the empty texels around them: each ring sets an empty texel
    next to filled ones (8-neighbourhood) to their mean, so bilinear filtering at chart borders never
    mixes in black. rgb: float32[H,W,C]; covered: bool[H,W]. Returns a new array."""
    out = np.where(covered[..., None], rgb, 0.0).astype(np.float32)
    filled = covered.copy()
    h, w = filled.shape
    for _ in range(rings):
        pv = np.pad(out * filled[..., None], ((1, 1), (1, 1), (0, 0)))
        pw = np.pad(filled.astype(np.float32), 1)
        total = np.zeros_like(out)
        count = np.zeros((h, w), np.float32)
        for dy in (0, 1, 2):
            for dx in (0, 1, 2):
                if dy == 1 and dx == 1:
                    continue
                total += pv[dy:dy + h, dx:dx + w]
                count += pw[dy:dy + h, dx:dx + w]
        grow = ~filled & (count > 0)
        if not grow.any():
            break
        out[grow] = total[grow] / count[grow][:, None]
        filled |= grow
    return out


def bilinear(rgb: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Bilinear lookup (as a GPU samples with texel centres at half-integers, clamped at the
    border) of float32[H,W,C] at float[N,2] UVs in [0,1]; returns float32[N,C]."""
    h, w = rgb.shape[:2]
    x = np.clip(uv[:, 0] * w - 0.5, 0, w - 1)
    y = np.clip(uv[:, 1] * h - 0.5, 0, h - 1)
    x0, y0 = np.floor(x).astype(np.int64), np.floor(y).astype(np.int64)
    x1, y1 = np.minimum(x0 + 1, w - 1), np.minimum(y0 + 1, h - 1)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    return ((rgb[y0, x0] * (1 - fx) + rgb[y0, x1] * fx) * (1 - fy)
            + (rgb[y1, x0] * (1 - fx) + rgb[y1, x1] * fx) * fy)


# Points along each seam edge where both sides are compared (fractions of the edge).
_SEAM_SAMPLES = np.linspace(0.1, 0.9, 5)


def seam_difference(rgb: np.ndarray, corner_uv: np.ndarray, corner_triangles: np.ndarray,
                    shading: np.ndarray) -> float:
    """Largest difference across smooth UV seams of one object in the page ``rgb``, relative to
    the page's brightest texel.

    corner_uv: float32[C,2] the object's UVs per face corner; corner_triangles: int32[T,3] face
    corners of its triangles; shading: int32[T,3] the shading vertex of each triangle corner. A
    smooth seam edge joins two triangles through the same two shading vertices (same normals on
    both sides) while their UVs differ; both sides are sampled bilinearly at matching points along
    the edge. Edges across hard edges (different shading vertices) are not seams of the lighting.
    """
    tris = corner_triangles
    a_idx, b_idx = [0, 1, 2], [1, 2, 0]
    sa, sb = shading[:, a_idx].ravel(), shading[:, b_idx].ravel()
    ca, cb = tris[:, a_idx].ravel(), tris[:, b_idx].ravel()
    lo, hi = np.minimum(sa, sb), np.maximum(sa, sb)
    flip = sa > sb
    first = np.where(flip, cb, ca)  # corner at the lower shading vertex
    second = np.where(flip, ca, cb)
    order = np.lexsort((hi, lo))
    lo, hi, first, second = lo[order], hi[order], first[order], second[order]
    pair = (lo[:-1] == lo[1:]) & (hi[:-1] == hi[1:])
    i = np.flatnonzero(pair)
    if i.size == 0:
        return 0.0
    u0a, u1a = corner_uv[first[i]], corner_uv[second[i]]
    u0b, u1b = corner_uv[first[i + 1]], corner_uv[second[i + 1]]
    seam = (np.abs(u0a - u0b).max(axis=1) > 1e-6) | (np.abs(u1a - u1b).max(axis=1) > 1e-6)
    if not seam.any():
        return 0.0
    f = _SEAM_SAMPLES[None, :, None]
    pa = (u0a[seam, None] * (1 - f) + u1a[seam, None] * f).reshape(-1, 2)
    pb = (u0b[seam, None] * (1 - f) + u1b[seam, None] * f).reshape(-1, 2)
    diff = np.abs(bilinear(rgb, pa) - bilinear(rgb, pb)).max()
    return float(diff / max(float(rgb.max()), 1e-30))
