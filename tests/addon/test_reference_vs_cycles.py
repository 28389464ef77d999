"""The reference solver, hierarchical radiosity (and Bunnell's bounce) against Cycles on the
sample scenes (DIFFUSE, Direct + Indirect, no Color), from the same Cycles bakes.

Tolerances (issues #3, #10): relative RMSE of lighting ≤ 5 %, mean bias within ±2 %, over all
vertices of the scene's receivers, for the reference and for hierarchical radiosity, which must
also lie within 3 % relative RMSE of the reference. The Cycles reference uses 2048 samples and 64
bounces; its own noise is part of the measured error. Figures are written to
out/test-figures/reference_vs_cycles.json.
"""
from pathlib import Path

import bpy
import pytest

from harness.compare import bake_vertex_values, stack
from harness.cycles import cycles_bake_vertex_colors
from radiosity_baker.core import Settings
from harness import metrics

import figures as figures_file

ROOT = Path(__file__).resolve().parents[2]
CYCLES_SAMPLES = 2048
MAX_RMSE, MAX_BIAS = 0.05, 0.02
HIERARCHICAL_VS_REFERENCE = 0.03
# Bunnell's one bounce misses the later ones (docs/benchmarks.md): most in the white
# Cornell box (measured 19.8 % RMSE, −16.9 % bias), little in the open lamp scene (7.5 %, −3.2 %).
# Its bounds say what it is: (largest RMSE, lowest bias, highest bias) per scene.
BUNNELL = {"cornell_box.blend": (0.25, -0.20, 0.0), "lamp_scene.blend": (0.10, -0.05, 0.02)}


def receivers(scene):
    """Visible meshes with a reflecting surface: Cycles' DIFFUSE lighting pass of a black
    (albedo 0) emitter is 0 whatever reaches it, so emitters like the Cornell light are left out."""
    out = []
    for ob in scene.objects:
        if ob.type != "MESH" or ob.hide_render:
            continue
        mat = ob.active_material
        bsdf = mat.node_tree.nodes.get("Principled BSDF") if mat and mat.node_tree else None
        if bsdf is not None and max(bsdf.inputs["Base Color"].default_value[:3]) == 0.0:
            continue
        out.append(ob.name)
    return sorted(out)


@pytest.mark.slow
@pytest.mark.parametrize("blend", ["cornell_box.blend", "lamp_scene.blend"])
def test_reference_and_hierarchical_match_cycles_on_sample_scene(blend):
    """Hierarchical radiosity against the same Cycles bake and against the reference; and
    Bunnell's bounce against the Cycles bake, within its own (wider) bounds."""
    bpy.ops.wm.open_mainfile(filepath=str(ROOT / "sample_blends" / blend))
    names = receivers(bpy.context.scene)
    reference = cycles_bake_vertex_colors(names, samples=CYCLES_SAMPLES)
    ours, result, seconds = bake_vertex_values(names, Settings(method="reference"))
    figures = metrics.summary(stack(ours, names), stack(reference, names))
    figures.update({"cycles_samples": CYCLES_SAMPLES, "vertices": int(stack(ours, names).shape[0]),
                    "elements": result.counts["elements"], "seconds": round(seconds, 2)})
    hierarchical, h_result, h_seconds = bake_vertex_values(names, Settings(method="hierarchical"))
    figures["hierarchical"] = {**metrics.summary(stack(hierarchical, names), stack(reference, names)),
                               "vs_reference": metrics.summary(stack(hierarchical, names), stack(ours, names)),
                               "links": h_result.counts["links"], "seconds": round(h_seconds, 2)}
    bunnell, _, bunnell_seconds = bake_vertex_values(names, Settings(method="bunnell"))
    figures["bunnell"] = {**metrics.summary(stack(bunnell, names), stack(reference, names)),
                          "seconds": round(bunnell_seconds, 2)}
    print(f"\n{blend}: {figures}")
    figures_file.record("reference_vs_cycles", blend, figures)
    assert figures["relative_rmse"] <= MAX_RMSE
    assert abs(figures["mean_bias"]) <= MAX_BIAS
    h = figures["hierarchical"]
    assert h["relative_rmse"] <= MAX_RMSE
    assert abs(h["mean_bias"]) <= MAX_BIAS
    assert h["vs_reference"]["relative_rmse"] <= HIERARCHICAL_VS_REFERENCE
    max_rmse, low, high = BUNNELL[blend]
    assert figures["bunnell"]["relative_rmse"] <= max_rmse
    assert low <= figures["bunnell"]["mean_bias"] <= high
