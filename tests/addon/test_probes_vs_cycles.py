"""A light probe in the sample Cornell box against Cycles: the probe's SH evaluated for six
directions against the lighting Cycles bakes on a small diffuse sphere at that point (its
vertices whose normals lie near each direction). Measured figures are printed and written to
out/test-figures/probes_vs_cycles.json."""
from pathlib import Path

import bpy
import numpy as np
import pytest

from harness.cycles import cycles_bake_vertex_colors
from radiosity_baker.addon.extract import extract_scene
from radiosity_baker.core import Settings, bake, targets

import figures as figures_file

ROOT = Path(__file__).resolve().parents[2]
CYCLES_SAMPLES = 256
TOLERANCE = 0.05
AXES = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], np.float64)


@pytest.mark.slow
@pytest.mark.xfail(reason="measured 3–23 % per direction: L2 SH of the bright ceiling light rings "
                          "into the side and floor directions (see README, Light probes)", strict=False)
def test_a_probe_matches_cycles_irradiance_on_a_small_sphere_in_the_cornell_box():
    bpy.ops.wm.open_mainfile(filepath=str(ROOT / "sample_blends" / "cornell_box.blend"))
    try:
        scene = bpy.context.scene
        extraction = extract_scene(bpy.context.evaluated_depsgraph_get())
        sc = extraction.scene
        lo = sc.positions.min(axis=0) + sc.origin
        hi = sc.positions.max(axis=0) + sc.origin
        point = np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2] + 0.4 * (hi[2] - lo[2])])
        grid = bake(sc, Settings(method="reference", device="cpu", light_samples=64),
                    targets=[targets.make("probes", box=(point - 1e-3, point + 1e-3), spacing=1.0)])["probes"]
        assert grid.valid.all() and len(grid.points) == 1

        bpy.ops.mesh.primitive_uv_sphere_add(segments=24, ring_count=12, radius=0.01,
                                             location=tuple(point))
        sphere = bpy.context.object
        sphere.name = "ProbeSphere"
        bpy.ops.object.shade_smooth()
        mat = bpy.data.materials.new("ProbeWhite")
        sphere.data.materials.append(mat)
        cycles = cycles_bake_vertex_colors([sphere.name], samples=CYCLES_SAMPLES)[sphere.name]
        normals = np.array([v.normal for v in sphere.data.vertices], np.float64)
        figures = {}
        for order in (1, 2):
            ours_v = grid.lighting(normals, order=order)[0]
            errors = []
            for axis in AXES:
                near = normals @ axis > np.cos(np.radians(25))
                theirs = cycles[near].mean(axis=0)
                ours = ours_v[near].mean(axis=0)
                errors.append(float(np.abs(ours - theirs).mean() / theirs.mean()))
            figures[f"L{order}"] = [round(e, 4) for e in errors]
        print(f"\nprobe at {np.round(point, 3)}: relative error per direction (+x −x +y −y +z −z) "
              f"L1 {figures['L1']}, L2 {figures['L2']}")
        figures_file.record("probes_vs_cycles", "cornell probe", {**figures, "cycles_samples": CYCLES_SAMPLES})
        assert max(figures["L2"]) <= TOLERANCE
    finally:
        bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
