"""A light probe in the sample Cornell box against Cycles.

Cycles bakes the lighting E(n)/π on a small diffuse icosphere at the probe's point (one value per
vertex normal n). Irradiance is radiance convolved with the clamped cosine, which is diagonal in
SH (Â_l = π, 2π/3, π/4 for l = 0, 1, 2), so the L0–L2 coefficients of Cycles' E(n) are exactly
Â_l × the L0–L2 coefficients of the true radiance: projecting Cycles' values onto bands 0–2
(quadrature over the sphere, each vertex weighted by its share of the surface) gives the
band-limited lighting our probe's L2 SH should reproduce in every direction. The test compares the
two along ±x, ±y, ±z within 5 %; it also prints (and records) how far our L2 (and L1) lighting is
from Cycles' full, unlimited values there — a few bands cannot follow a bright, small ceiling
light's clamped cosine (docs/directional-probes.md). Figures go to out/test-figures/probes_vs_cycles.json.

The point lies at least 9 cm from every surface and the sphere's radius is 2 mm: the lighting on a
sphere's side is that at its surface point, not at its centre, and a 1 cm sphere 1 cm from a wall
measures the wall's near field, not the probe's.
"""
from pathlib import Path

import bpy
import numpy as np
import pytest

from harness.cycles import cycles_bake_vertex_colors
from radiosity_baker.addon.extract import extract_scene
from radiosity_baker.core import Settings, bake, targets
from radiosity_baker.core.sh import sh9_numpy

import figures as figures_file

ROOT = Path(__file__).resolve().parents[2]
CYCLES_SAMPLES = 256
TOLERANCE = 0.05
AXES = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], np.float64)
# Where the probe lies, as fractions of the box's bounds (x, y, z): beside the blocks, in front of
# the tall one, half-way up.
WHERE = np.array([0.35, 0.3, 0.5])
SPHERE_RADIUS = 0.002
# The Cycles values whose normals lie within this angle of an axis are its "full" value.
FULL_CONE_DEGREES = 10.0


def _sphere_weights(mesh) -> np.ndarray:
    """float64[V]: each vertex's share of the sphere (a third of its triangles' area), summing to
    4π: quadrature weights over the directions of its normals."""
    mesh.calc_loop_triangles()
    tris = np.array([t.vertices[:] for t in mesh.loop_triangles])
    p = np.array([v.co for v in mesh.vertices], np.float64)
    area = 0.5 * np.linalg.norm(np.cross(p[tris[:, 1]] - p[tris[:, 0]], p[tris[:, 2]] - p[tris[:, 0]]), axis=1)
    weights = np.zeros(len(p))
    np.add.at(weights, tris.ravel(), np.repeat(area / 3.0, 3))
    return weights * 4.0 * np.pi / weights.sum()


def _errors(ours: np.ndarray, theirs: np.ndarray) -> list:
    """Per axis, the mean absolute RGB difference relative to the mean of ``theirs`` (float[6,3])."""
    return [round(float(np.abs(o - t).mean() / t.mean()), 4) for o, t in zip(ours, theirs)]


@pytest.mark.slow
def test_a_probe_matches_cycles_band_limited_irradiance_on_a_small_sphere_in_the_cornell_box():
    bpy.ops.wm.open_mainfile(filepath=str(ROOT / "sample_blends" / "cornell_box.blend"))
    try:
        sc = extract_scene(bpy.context.evaluated_depsgraph_get()).scene
        lo, hi = sc.positions.min(axis=0) + sc.origin, sc.positions.max(axis=0) + sc.origin
        point = lo + WHERE * (hi - lo)
        grid = bake(sc, Settings(method="reference", device="cpu", light_samples=64),
                    targets=[targets.make("probes", box=(point - 1e-3, point + 1e-3), spacing=1.0)])["probes"]
        assert grid.valid.all() and len(grid.points) == 1

        bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=4, radius=SPHERE_RADIUS, location=tuple(point))
        sphere = bpy.context.object
        sphere.name = "ProbeSphere"
        bpy.ops.object.shade_smooth()
        sphere.data.materials.append(bpy.data.materials.new("ProbeWhite"))
        cycles = cycles_bake_vertex_colors([sphere.name], samples=CYCLES_SAMPLES)[sphere.name].astype(np.float64)
        normals = np.array([v.normal for v in sphere.data.vertices], np.float64)

        # Cycles' lighting projected onto bands 0–2, evaluated along the axes
        coefficients = (sh9_numpy(normals) * _sphere_weights(sphere.data)[:, None]).T @ cycles
        band_limited = sh9_numpy(AXES) @ coefficients
        ours = grid.lighting(AXES)[0]
        near = normals @ AXES.T > np.cos(np.radians(FULL_CONE_DEGREES))  # [V, 6]
        full = np.stack([cycles[near[:, k]].mean(axis=0) for k in range(len(AXES))])
        ours_full = {order: np.stack([grid.lighting(normals[near[:, k]], order=order)[0].mean(axis=0)
                                      for k in range(len(AXES))]) for order in (1, 2)}
        figures = {"band_limited_L2": _errors(ours, band_limited),
                   "full_L2": _errors(ours_full[2], full), "full_L1": _errors(ours_full[1], full),
                   "point": np.round(point, 4).tolist(), "cycles_samples": CYCLES_SAMPLES,
                   "sphere_vertices": len(normals)}
        print(f"\nprobe at {np.round(point, 3)}: relative error per direction (+x −x +y −y +z −z) "
              f"against Cycles' band-limited lighting {figures['band_limited_L2']}; against its full "
              f"lighting: L2 {figures['full_L2']}, L1 {figures['full_L1']}")
        figures_file.record("probes_vs_cycles", "cornell probe", figures)
        assert max(figures["band_limited_L2"]) <= TOLERANCE
    finally:
        bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
