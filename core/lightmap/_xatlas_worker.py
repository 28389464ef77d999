"""xatlas in its own process: ``python _xatlas_worker.py IN.npz OUT.npz``.

xatlas holds the GIL for its whole run and can crash on bad input, so it never runs inside Blender's
process. This script imports nothing of the package (nor bpy): only numpy and xatlas.

IN holds ``atlases`` (count) and per atlas ``a`` / mesh ``m``: ``a{a}_m{m}_pos`` float32[N,3]
(metres), ``a{a}_m{m}_idx`` uint32[M,3], ``a{a}_meshes``, ``a{a}_density`` (texels per metre),
``a{a}_max_size``, ``a{a}_padding`` (texels). OUT holds per atlas ``a{a}_size`` (width, height),
``a{a}_density`` (the density used: lowered until the atlas fits one page of max_size), and per
mesh ``a{a}_m{m}_vmap`` uint32[K], ``a{a}_m{m}_idx`` uint32[M,3], ``a{a}_m{m}_uv`` float32[K,2]
in [0,1] of the page.
"""
import sys

import numpy as np
import xatlas

# Each retry lowers the density a little more than the overshoot, so few retries are needed.
SHRINK_MARGIN = 0.98
MAX_TRIES = 16
# xatlas drops faces under its fixed epsilons (an area of about 1e-7 and lengths of 1e-4 in its
# units), so a mesh measured in millimetres gets no chart at all. Such meshes are scaled up by a
# power of two (exact in floating point) until the median triangle has at least this area (m²);
# the density is scaled down alike, so the layout in texels is the same.
MIN_MEDIAN_AREA = 1e-4


def _generate(meshes, density: float, padding: int):
    atlas = xatlas.Atlas()
    for pos, idx in meshes:
        atlas.add_mesh(pos, idx)
    pack = xatlas.PackOptions()
    pack.resolution = 0  # the smallest page at this density
    pack.texels_per_unit = density
    pack.padding = padding
    pack.bilinear = True
    atlas.generate(xatlas.ChartOptions(), pack)
    return atlas


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


def main(path_in: str, path_out: str) -> int:
    data = np.load(path_in)
    out = {}
    for a in range(int(data["atlases"])):
        meshes = [(np.ascontiguousarray(data[f"a{a}_m{m}_pos"], np.float32),
                   np.ascontiguousarray(data[f"a{a}_m{m}_idx"], np.uint32))
                  for m in range(int(data[f"a{a}_meshes"]))]
        max_size = int(data[f"a{a}_max_size"])
        padding = int(data[f"a{a}_padding"])
        areas = np.concatenate([_areas(pos, idx) for pos, idx in meshes])
        scale = _scale(areas)
        meshes = [(pos * np.float32(scale), idx) for pos, idx in meshes]
        # No page can hold more texels than max_size²: start at most at the density that fills
        # it exactly (a far too high density makes xatlas build enormous charts first). From here
        # on the density is per unit of the scaled positions.
        area = float(areas.sum()) * scale * scale
        density = min(float(data[f"a{a}_density"]) / scale, max_size / max(area, 1e-30) ** 0.5)
        for _ in range(MAX_TRIES):
            atlas = _generate(meshes, density, padding)
            side = max(atlas.width, atlas.height)
            if atlas.atlas_count <= 1 and side <= max_size:
                break
            density *= SHRINK_MARGIN * max_size / max(side, max_size + 1) / max(1, atlas.atlas_count) ** 0.5
        else:
            print(f"xatlas: no single page of {max_size} texels found", file=sys.stderr)
            return 3
        out[f"a{a}_size"] = np.array([atlas.width, atlas.height], np.int64)
        out[f"a{a}_density"] = np.array(density * scale)
        for m in range(len(meshes)):
            vmap, idx, uv = atlas[m]
            out[f"a{a}_m{m}_vmap"] = vmap
            out[f"a{a}_m{m}_idx"] = idx
            out[f"a{a}_m{m}_uv"] = uv
    np.savez(path_out, **out)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1], sys.argv[2]))
