"""xatlas in its own process: ``python _xatlas_worker.py charts|pack IN.npz OUT.npz``.

xatlas holds the GIL for its whole run and can crash on bad input, so it never runs inside Blender's
process. This script imports nothing of the package (nor bpy): only numpy and xatlas.

``charts``: IN holds ``meshes`` (count) and per mesh ``m{m}_pos`` float32[N,3] (metres),
``m{m}_idx`` uint32[M,3], ``m{m}_density`` (texels per metre), optionally ``m{m}_corners``
int64[M,3] (the face corner of each triangle corner: triangles sharing one are of one polygon), and
``padding``, ``max_size`` (texels). Each mesh is cut into charts and laid out alone, at most at the
density whose charts' area fills a page (a far too high one makes xatlas build enormous charts
first); a polygon xatlas cut by a seam is put whole into one chart (see ``_whole_polygons``); OUT
holds per mesh
``m{m}_uv`` float32[K,2] (texels), ``m{m}_idx`` uint32[M,3] (the triangles over those UV
vertices, in the input's order), ``m{m}_chart`` int32[K] (the chart of each UV vertex) and
``m{m}_density`` (the density laid out at).

``pack``: IN holds ``max_size``, ``padding``, ``many`` (1: as many pages as needed, each mesh
whole on one; 0: one page, everything scaled down until it fits) and ``groups``, each packed by
itself, its names prefixed ``g{g}_``: ``meshes`` and per mesh ``m{m}_uv``, ``m{m}_idx``,
``m{m}_chart``, ``m{m}_density`` (as ``charts`` gave them, texels). OUT holds per group (prefixed
alike) ``pages``, ``p{p}_size`` (width, height) and per mesh ``m{m}_page``, ``m{m}_scale`` (of its
charts: 1, or less where it was scaled down to fit), ``m{m}_uv`` float32[K,2] in [0,1] of its
page and ``m{m}_idx`` uint32[M,3].
"""
import os
import sys

import numpy as np
import xatlas

# xatlas drops faces under its fixed epsilons (an area of about 1e-7 and lengths of 1e-4 in its
# units), so a mesh measured in millimetres gets no chart at all. Such meshes are scaled up by a
# power of two (exact in floating point) until the median triangle has at least this area (m²);
# the density is scaled down alike, so the layout in texels is the same.
MIN_MEDIAN_AREA = 1e-4
# Pages are filled up to this share of their texels by the charts' bounding boxes before xatlas
# packs them; a page that overflows hands its smallest meshes on to the next.
FILL = 0.7
# Each retry of a layout that does not fit shrinks it a little more than the overshoot.
SHRINK_MARGIN = 0.98
MAX_TRIES = 48


def _pack_options(resolution: int, density: float, padding: int):
    pack = xatlas.PackOptions()
    pack.resolution = resolution  # 0: the smallest page at this density
    pack.texels_per_unit = density
    pack.padding = padding
    pack.bilinear = True
    return pack


def _areas(pos: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """float64[M]: the area of each triangle idx over pos."""
    p = pos.astype(np.float64)[idx.astype(np.int64)]
    return 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)


def _scale(areas: np.ndarray) -> float:
    """The power of two positions are multiplied by so that the median triangle area (``areas``,
    float64[M], m²) reaches MIN_MEDIAN_AREA; 1 for meshes that need none."""
    median = float(np.median(areas)) if areas.size else 0.0
    if median <= 0.0 or median >= MIN_MEDIAN_AREA:
        return 1.0
    return 2.0 ** np.ceil(0.5 * np.log2(MIN_MEDIAN_AREA / median))


def charts(data) -> dict:
    out = {}
    padding, max_size = int(data["padding"]), int(data["max_size"])
    for m in range(int(data["meshes"])):
        pos = np.ascontiguousarray(data[f"m{m}_pos"], np.float32)
        idx = np.ascontiguousarray(data[f"m{m}_idx"], np.uint32)
        areas = _areas(pos, idx)
        scale = _scale(areas)
        density = min(float(data[f"m{m}_density"]), max_size / max(float(areas.sum()), 1e-30) ** 0.5)
        atlas = xatlas.Atlas()
        atlas.add_mesh(pos * np.float32(scale), idx)
        atlas.generate(xatlas.ChartOptions(), _pack_options(0, density / scale, padding))
        vert, tri, uv = atlas[0]
        _, chart = atlas.get_mesh_vertex_assignment(0)
        uv = uv * np.array([atlas.width, atlas.height], np.float64)
        tri, chart = tri.astype(np.int64), chart.astype(np.int64)
        if f"m{m}_corners" in data.files:
            uv, tri, chart = _whole_polygons(pos.astype(np.float64), uv, tri, vert.astype(np.int64), chart,
                                             np.asarray(data[f"m{m}_corners"], np.int64))
        out[f"m{m}_uv"] = uv.astype(np.float32)
        out[f"m{m}_idx"] = tri.astype(np.uint32)
        out[f"m{m}_chart"] = chart.astype(np.int32)
        out[f"m{m}_density"] = np.array(density)
    return out


def _polygons(corners: np.ndarray) -> np.ndarray:
    """int64[M]: a label per triangle, the same for the triangles of one polygon (int64[M,3] face
    corners: a polygon's triangles are joined by the corners they share)."""
    _, corner = np.unique(corners.ravel(), return_inverse=True)
    corner = corner.reshape(-1, 3)
    label = np.arange(corner.shape[0])
    while True:  # the smallest label spreads through shared corners until nothing changes
        least = np.full(int(corner.max()) + 1, corner.shape[0])
        np.minimum.at(least, corner.ravel(), np.repeat(label, 3))
        new = least[corner].min(axis=1)
        if np.array_equal(new, label):
            return label
        label = new


def _unfold(pos: np.ndarray, uv: np.ndarray, edge: np.ndarray, apex: np.ndarray, opposite: np.ndarray):
    """float64[P,2] UVs (texels) of the ``apex`` mesh vertices (int64[P]) of triangles hinged on
    the UV edges ``edge`` (int64[P,2,2]: mesh vertex and UV vertex of each end), laid flat on the
    side of the edge away from the UV vertex ``opposite`` (int64[P]: the hinge triangle's third),
    at the edge's own texels per metre: each triangle keeps its shape (pos float64[N,3] metres)."""
    a, b, p = pos[edge[:, 0, 0]], pos[edge[:, 1, 0]], pos[apex]
    e = b - a
    length = np.maximum(np.linalg.norm(e, axis=1), 1e-30)
    along = np.einsum("ij,ij->i", p - a, e) / length
    across = np.linalg.norm(np.cross(p - a, e), axis=1) / length
    ua, ub, q = uv[edge[:, 0, 1]], uv[edge[:, 1, 1]], uv[opposite]
    d = ub - ua
    texels = np.maximum(np.linalg.norm(d, axis=1), 1e-30)
    unit = d / texels[:, None]
    normal = np.stack([-unit[:, 1], unit[:, 0]], axis=1)
    side = np.sign(_side(uv, edge, q))
    normal *= np.where(side == 0, 1.0, -side)[:, None]
    k = (texels / length)[:, None]
    return ua + k * (along[:, None] * unit + across[:, None] * normal)


def _side(uv: np.ndarray, edge: np.ndarray, point: np.ndarray) -> np.ndarray:
    """float64[P]: positive on the left of each UV edge (``edge`` as in ``_unfold``), negative on
    its right, of ``point`` float64[P,2] (texels)."""
    a, b = uv[edge[:, 0, 1]], uv[edge[:, 1, 1]]
    d, q = b - a, point - a
    return d[:, 0] * q[:, 1] - d[:, 1] * q[:, 0]


def _whole_polygons(pos, uv, tri, vert, chart, corners):
    """Charts that keep each polygon whole: a face corner holds one UV, so a polygon that xatlas
    cut by a chart seam would otherwise be drawn from two charts at once, a sliver across the page
    over other charts. Each triangle of a cut polygon that is not in the chart of the polygon's
    largest triangle is moved into it, unfolded across the edge it shares with a triangle already
    there; its far corner takes that chart's UV vertex of the same mesh vertex where there is one.

    pos float64[N,3] mesh vertices (m); uv float64[K,2] UV vertices (texels); tri int64[M,3] UV
    vertex of each triangle corner; vert int64[K] mesh vertex and chart int64[K] chart of each UV
    vertex; corners int64[M,3] face corner of each triangle corner. Returns (uv, tri, chart) as
    given, UV vertices no triangle uses left out.
    """
    poly = _polygons(corners)
    own = chart[tri[:, 0]]
    area = _areas(pos, vert[tri])
    order = np.lexsort((-area, poly))  # per polygon its largest triangle first
    first = order[np.r_[True, poly[order][1:] != poly[order][:-1]]]
    target = np.empty(int(poly.max()) + 1, np.int64)
    target[poly[first]] = own[first]
    want = target[poly]
    pending = own != want
    if not pending.any():
        return uv, tri, chart
    tri = tri.copy()
    span = int(corners.max()) + 1
    # the triangle corners to each side of a triangle's three edges (corner k to corner k + 1)
    ends = np.array([[0, 1], [1, 2], [2, 0]])
    third = np.array([2, 0, 1])
    while pending.any():
        done = np.flatnonzero(~pending & np.isin(poly, poly[pending]))  # settled, in cut polygons
        c = corners[done][:, ends]  # [S,3,2]
        keys = np.minimum(c[..., 0], c[..., 1]) * span + np.maximum(c[..., 0], c[..., 1])
        sort = np.argsort(keys.ravel(), kind="stable")
        sorted_keys = keys.ravel()[sort]
        todo = np.flatnonzero(pending)
        c = corners[todo][:, ends]  # [P,3,2]
        mine = np.minimum(c[..., 0], c[..., 1]) * span + np.maximum(c[..., 0], c[..., 1])
        at = np.minimum(np.searchsorted(sorted_keys, mine), sorted_keys.size - 1)
        found = sorted_keys[at] == mine
        go = found.any(axis=1)
        if not go.any():
            break  # no polygon corner shared with a settled triangle: left as xatlas cut it
        todo, found, at = todo[go], found[go], at[go]
        k = np.argmax(found, axis=1)  # the first edge that hinges on a settled triangle
        row = np.arange(todo.size)
        flat = sort[at[row, k]]
        hinge, hinge_edge = done[flat // 3], flat % 3
        # the hinge triangle's UV vertices at the two shared corners, matched to this triangle's
        hc = corners[hinge][:, ends][row, hinge_edge]  # [P,2] corners of the hinge's edge
        hu = tri[hinge][:, ends][row, hinge_edge]  # [P,2] its UV vertices
        mc = corners[todo][:, ends][row, k]  # [P,2] the same corners, in this triangle's order
        swap = hc[:, 0] != mc[:, 0]
        hu = np.where(swap[:, None], hu[:, ::-1], hu)
        apex = vert[tri[todo, third[k]]]
        edge = np.stack([np.stack([vert[hu[:, 0]], hu[:, 0]], 1), np.stack([vert[hu[:, 1]], hu[:, 1]], 1)], 1)
        opposite = tri[hinge, third[hinge_edge]]
        goal = want[todo]
        # the far corner: the chart's UV vertex of that mesh vertex, else one new per (chart, vertex)
        lookup = chart * pos.shape[0] + vert
        ls = np.argsort(lookup, kind="stable")
        key = goal * pos.shape[0] + apex
        j = np.minimum(np.searchsorted(lookup[ls], key), lookup.size - 1)
        # reused only where it keeps the triangle unflipped: across the hinge from its third corner
        there = (lookup[ls][j] == key) & (_side(uv, edge, uv[ls[j]]) * _side(uv, edge, uv[opposite]) < 0)
        far = np.where(there, ls[j], -1)
        fresh = np.flatnonzero(~there)
        if fresh.size:
            _, pick, inverse = np.unique(key[fresh], return_index=True, return_inverse=True)
            made = _unfold(pos, uv, edge[fresh[pick]], apex[fresh[pick]], opposite[fresh[pick]])
            far[fresh] = uv.shape[0] + inverse
            uv = np.concatenate([uv, made])
            vert = np.concatenate([vert, apex[fresh[pick]]])
            chart = np.concatenate([chart, goal[fresh[pick]]])
        tri[todo, k] = hu[:, 0]
        tri[todo, (k + 1) % 3] = hu[:, 1]
        tri[todo, third[k]] = far
        pending[todo] = False
    used, tri = np.unique(tri, return_inverse=True)
    return uv[used], tri.reshape(-1, 3), chart[used]


def _footprint(uv: np.ndarray, chart: np.ndarray, padding: int):
    """(texels the charts' padded boxes cover, their longest side) of one mesh's charts."""
    n = int(chart.max()) + 1 if chart.size else 0
    lo = np.full((n, 2), np.inf)
    hi = np.full((n, 2), -np.inf)
    np.minimum.at(lo, chart, uv)
    np.maximum.at(hi, chart, uv)
    side = np.maximum(hi - lo, 0.0) + 2 * padding + 1
    return float(np.prod(side, axis=1).sum()), float(side.max()) if n else 0.0


def _layout(meshes: list, scales: list, resolution: int, padding: int):
    """xatlas packing of UV meshes (texels, each scaled by its factor) onto pages of
    ``resolution`` (0: one page, as small as it gets): the atlas."""
    atlas = xatlas.Atlas()
    for (uv, idx, _), s in zip(meshes, scales):
        atlas.add_uv_mesh(np.ascontiguousarray(uv * np.float32(s), np.float32), idx)
    atlas.generate(xatlas.ChartOptions(), _pack_options(resolution, 1.0, padding))
    return atlas


class MeshError(RuntimeError):
    """A layout that failed for one mesh: ``mesh``, its index in the group (or in a charts job)."""

    def __init__(self, mesh: int, message: str):
        super().__init__(message)
        self.mesh = mesh


def _collapsed(atlas, count: int) -> bool:
    """Whether some mesh of the ``count`` in ``atlas`` was shrunk to charts without area."""
    for k in range(count):
        _, idx, uv = atlas[k]
        q = uv.astype(np.float64)[idx.astype(np.int64)]
        e1, e2 = q[:, 1] - q[:, 0], q[:, 2] - q[:, 0]
        if not (np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]) > 0).any():
            return True
    return False


def _no_room(meshes: list, fits, max_size: int, padding: int) -> str:
    """Why ``meshes`` found no room on a page of ``max_size``: their chart count and the padding,
    and the largest smaller padding ``p`` at which ``fits(p)`` finds them room, if any."""
    charts = _chart_count(meshes)
    text = f"{charts} charts {padding} texels apart do not fit a page of {max_size} texels"
    p = next((p for p in range(padding - 1, 0, -1) if fits(p)), None)
    if p is not None:
        return text + f"; with a padding of {p} they fit (--padding {p}), or raise --max-size"
    return text + " even 1 texel apart: raise --max-size"


def _chart_count(meshes: list) -> int:
    """How many charts ``meshes`` (as ``pack`` holds them) have."""
    return sum(len(np.unique(m[2])) for m in meshes)


def _below_floor(meshes: list, max_size: int, padding: int) -> bool:
    """Whether the charts of ``meshes`` cannot share a page of max_size however small they are
    scaled: each keeps at least a texel and its padding all round. (Scaled on regardless, xatlas
    drops the charts that fall below its epsilons and lays the others over where they were.)"""
    return _chart_count(meshes) * (2 * padding + 1) ** 2 > max_size * max_size


def _fits_alone(mesh, max_size: int, padding: int):
    """The scale (≤ 1) at which one mesh's charts fit a page of max_size by themselves, None when
    none is found (the padding alone fills the page)."""
    area, side = _footprint(mesh[0], mesh[2], padding)
    if 2 * side <= max_size and 4 * area <= FILL * max_size * max_size:
        return 1.0  # far smaller than a page
    if _below_floor([mesh], max_size, padding):
        return None
    s = min(1.0, (max_size - 2 * padding - 1) / max(side, 1e-9), max_size / max(area, 1e-9) ** 0.5)
    charts = None
    for _ in range(MAX_TRIES):
        atlas = _layout([mesh], [s], max_size, padding)
        charts = atlas.chart_count if charts is None else charts
        if atlas.chart_count < charts:
            return None  # charts shrunk below xatlas' epsilons: dropped, the rest laid over them
        if atlas.atlas_count <= 1:
            return None if _collapsed(atlas, 1) else s
        s *= 0.95  # a page short: a little smaller each try
    return None


def _one_page(meshes: list, base: list, max_size: int, padding: int):
    """(atlas, scale): ``meshes``, each scaled by its ``base`` × the scale, on one page of at most
    max_size, the scale lowered from 1 until they fit; None when none is found (or charts shrink
    to nothing: the padding alone fills the page)."""
    if _below_floor(meshes, max_size, padding):
        return None
    s = 1.0
    charts = None
    for _ in range(MAX_TRIES):
        atlas = _layout(meshes, [s * b for b in base], 0, padding)
        charts = atlas.chart_count if charts is None else charts
        if atlas.chart_count < charts:
            return None  # charts shrunk below xatlas' epsilons: dropped, the rest laid over them
        longest = max(atlas.width, atlas.height)
        if atlas.atlas_count <= 1 and longest <= max_size:
            return None if _collapsed(atlas, len(meshes)) else (atlas, s)
        s *= SHRINK_MARGIN * max_size / max(longest, max_size + 1)
    return None


def pack(data) -> dict:
    max_size, padding, many = int(data["max_size"]), int(data["padding"]), bool(int(data["many"]))
    count = int(data["meshes"])
    meshes = [(np.asarray(data[f"m{m}_uv"], np.float32), np.ascontiguousarray(data[f"m{m}_idx"], np.uint32),
               np.asarray(data[f"m{m}_chart"], np.int64)) for m in range(count)]
    out = {}
    if not many:  # one density for all: each mesh's charts scaled to the lowest first
        density = [float(data[f"m{m}_density"]) for m in range(count)]
        base = [min(density) / d for d in density]
        found = _one_page(meshes, base, max_size, padding)
        if found is None:
            raise RuntimeError(_no_room(meshes, lambda p: _one_page(meshes, base, max_size, p),
                                        max_size, padding))
        atlas, s = found
        pages = [(list(range(count)), atlas)]
        scales = [s * b for b in base]
    else:
        scales = [_fits_alone(mesh, max_size, padding) for mesh in meshes]
        for m, mesh in enumerate(meshes):
            if scales[m] is None:
                raise MeshError(m, _no_room([mesh], lambda p: _fits_alone(mesh, max_size, p),
                                            max_size, padding))
        atlas = _layout(meshes, scales, 0, padding)
        pages = []
        if atlas.atlas_count <= 1 and max(atlas.width, atlas.height) <= max_size:
            pages.append((list(range(len(meshes))), atlas))  # one page, as small as it gets
        area = [_footprint(mesh[0] * s, mesh[2], padding)[0] for mesh, s in zip(meshes, scales)]
        todo = [] if pages else sorted(range(len(meshes)), key=lambda m: -area[m])
        while todo:
            group, used = [], 0.0
            for m in todo:  # first fit: largest first, up to the fill
                if not group or used + area[m] <= FILL * max_size * max_size:
                    group.append(m)
                    used += area[m]
            while True:
                atlas = _layout([meshes[m] for m in group], [scales[m] for m in group], max_size, padding)
                if atlas.atlas_count <= 1 or len(group) == 1:
                    break
                group = group[:max(1, (len(group) * 3) // 4)]  # hand the smallest on
            pages.append((group, atlas))
            todo = [m for m in todo if m not in set(group)]
    out["pages"] = np.array(len(pages))
    for p, (group, atlas) in enumerate(pages):
        out[f"p{p}_size"] = np.array([atlas.width, atlas.height], np.int64)
        for k, m in enumerate(group):
            _, idx, uv = atlas[k]
            out[f"m{m}_page"] = np.array(p)
            out[f"m{m}_scale"] = np.array(scales[m])
            out[f"m{m}_uv"] = uv
            out[f"m{m}_idx"] = idx
    return out


def _die_with_parent() -> None:
    """Exit when the bake that started this worker is gone: on Linux the kernel kills this
    process when its parent dies (PR_SET_PDEATHSIG, even by ``kill -9``); a parent that died
    before that was set is seen in the parent pid (``RADIOSITY_BAKER_PARENT``). Elsewhere the
    parent kills its workers when it stops by an exception (Ctrl-C, cancel)."""
    if sys.platform.startswith("linux"):
        import ctypes
        import signal

        pr_set_pdeathsig = 1
        ctypes.CDLL(None).prctl(pr_set_pdeathsig, int(signal.SIGKILL))
    parent = os.environ.get("RADIOSITY_BAKER_PARENT")
    if parent is not None and os.getppid() != int(parent):
        sys.exit(4)


def main(command: str, path_in: str, path_out: str) -> int:
    """Run ``command``; on a layout that fails, the last line on stderr is ``failed: job J mesh M:
    why`` (J: the group, or the mesh of a charts job; M: the mesh in the group, -1 for all of it)
    and the exit status 3."""
    data = np.load(path_in)
    g = 0
    try:
        if command == "charts":
            out = charts(data)
        else:  # several groups, each packed by itself: g{g}_ before every name of one
            out = {}
            for g in range(int(data["groups"])):
                prefix = f"g{g}_"
                group = {k[len(prefix):]: data[k] for k in data.files if k.startswith(prefix)}
                group.update({k: data[k] for k in ("max_size", "padding", "many")})
                out.update({prefix + k: v for k, v in pack(group).items()})
    except RuntimeError as exc:
        print(f"failed: job {g} mesh {getattr(exc, 'mesh', -1)}: {exc}", file=sys.stderr)
        return 3
    np.savez(path_out, **out)
    return 0


if __name__ == "__main__":
    _die_with_parent()
    sys.exit(main(sys.argv[1], sys.argv[2], sys.argv[3]))
