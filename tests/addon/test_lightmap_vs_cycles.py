"""The Cornell box lightmap (reference solver) against a Cycles image bake on the same UVs.

Cycles: DIFFUSE, Direct + Indirect, no Color, into an image through the ``Lightmap`` UV map the
bake made (no margin: only texels whose centre lies on a triangle). Compared over the texels both
baked, except
- texels next to a lighting jump: the light quad hangs 1 mm under the ceiling, so the ceiling's
  lighting leaps from ~0.2 to ~16 across its outline within a fraction of a texel, and where in
  such a texel one samples decides its value (Cycles and we sample differently there);
- texels no light reaches in Cycles (exactly 0: the floor under the blocks, hidden inside them):
  our leak guard moves samples within 0.7 texel of a block's side out of it on purpose, so that
  hidden darkness does not bleed into visible texels under bilinear filtering.
The error over all texels both baked is recorded too. Figures go to
out/test-figures/lightmap_vs_cycles.json.
"""
import time
from pathlib import Path

import bpy
import numpy as np
import pytest

from harness.cycles import cycles_bake_image
from radiosity_baker.addon.job import BakeJob
from radiosity_baker.core import Settings
from harness import metrics

import figures as figures_file

ROOT = Path(__file__).resolve().parents[2]
CYCLES_SAMPLES = 1536
MAX_SIZE = 128
MAX_RMSE = 0.05
# A texel is next to a jump when the covered texels around it (3×3) span more than this many
# times the page's mean lighting (only the light's outline does in the Cornell box).
JUMP = 4.0


def _next_to_a_jump(rgb: np.ndarray, covered: np.ndarray) -> np.ndarray:
    lum = np.where(covered, rgb.max(axis=2), np.nan)
    h, w = lum.shape
    pad = np.pad(lum, 1, constant_values=np.nan)
    around = np.stack([pad[1 + dy:1 + dy + h, 1 + dx:1 + dx + w] for dy in (-1, 0, 1) for dx in (-1, 0, 1)])
    spread = np.nanmax(around, axis=0, initial=-np.inf) - np.nanmin(around, axis=0, initial=np.inf)
    return covered & (spread > JUMP * np.nanmean(lum))


def _user_state():
    meshes = {}
    for me in bpy.data.meshes:
        layers = {}
        for layer in me.uv_layers:
            if layer.name != "Lightmap":
                uv = np.empty(len(me.loops) * 2, np.float32)
                layer.uv.foreach_get("vector", uv)
                layers[layer.name] = uv.tobytes()
        meshes[me.name] = layers
    materials = {m.name: sorted((l.from_node.name, l.to_node.name) for l in m.node_tree.links)
                 for m in bpy.data.materials if m.node_tree}
    return meshes, materials, sorted(bpy.data.images.keys())


def _figures(page, reference):
    """Errors of ``page`` against the Cycles image ``reference`` float32[H,W,4] and the masks used."""
    baked = page.covered & (reference[..., 3] > 0.5)
    jump = _next_to_a_jump(page.rgb, page.covered)
    hidden = reference[..., :3].max(axis=2) == 0.0
    mask = baked & ~jump & ~hidden
    figures = metrics.summary(page.rgb[mask], reference[..., :3][mask])
    figures.update({"texels_compared": int(mask.sum()), "texels_on_the_light_outline": int((baked & jump).sum()),
                    "texels_hidden": int((baked & hidden & ~jump).sum()),
                    "relative_rmse_all_baked": round(metrics.relative_rmse(page.rgb[baked],
                                                                           reference[..., :3][baked]), 5)})
    return figures, baked, jump | hidden


@pytest.mark.slow
def test_cornell_lightmap_matches_a_cycles_image_bake(tmp_path):
    """With the final gather per texel (the default) and with interpolation alone, both within
    the tolerance, on the same UVs."""
    bpy.ops.wm.open_mainfile(filepath=str(ROOT / "sample_blends" / "cornell_box.blend"))
    names = sorted(o.name for o in bpy.context.scene.objects if o.type == "MESH" and o.name != "Light")
    before = _user_state()
    settings = Settings(method="reference", target="lightmap", output=str(tmp_path), max_size=MAX_SIZE,
                        atlas_pages="one", texel_density=1000.0, padding=2, supersample=2)
    assert settings.texel_indirect == "gather"
    t0 = time.perf_counter()
    job = BakeJob(settings, names)
    job.run_sync(bpy.context)
    seconds = time.perf_counter() - t0
    page, = job.result["lightmap"].pages
    w, h = page.size

    after = _user_state()
    assert after[0] == before[0] and after[1] == before[1]  # user UV maps and materials untouched
    assert after[2] == sorted(before[2] + ["Lightmap"])

    # re-unwrapped: xatlas lays the same meshes out the same way, on the same page size
    rebake = BakeJob(Settings(**{**settings.as_dict(), "texel_indirect": "interpolate", "reunwrap": True,
                                 "output": str(tmp_path / "interpolated")}), names)
    rebake.run_sync(bpy.context)
    interpolated, = rebake.result["lightmap"].pages
    assert interpolated.size == page.size

    reference = cycles_bake_image(names, "Lightmap", w, h, samples=CYCLES_SAMPLES)
    figures, baked, left_out = _figures(page, reference)
    figures.update({"cycles_samples": CYCLES_SAMPLES, "size": [w, h], "density": round(page.density, 2),
                    "supersample": settings.supersample, "seconds": round(seconds, 2),
                    "texel_indirect": settings.texel_indirect,
                    "interpolated": _figures(interpolated, reference)[0]})
    print(f"\nCornell lightmap vs Cycles: {figures}")
    figures_file.record("lightmap_vs_cycles", None, figures)
    assert (baked & left_out).sum() < 0.05 * baked.sum()
    assert figures["relative_rmse"] <= MAX_RMSE
    assert figures["interpolated"]["relative_rmse"] <= MAX_RMSE
