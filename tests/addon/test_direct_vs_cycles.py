"""Direct light against Cycles: one lamp type at a time over a grid plane with a shadow-casting cube.

Our value: the ``direct`` method through extraction, the pipeline and writing the color attribute.
Cycles': a DIFFUSE bake with the Direct pass only (no Color), i.e. irradiance/π from lamps and
emissive meshes. Measured figures are printed and written to out/test-figures/direct_vs_cycles.json.
"""
import math

import bpy
import numpy as np
import pytest

from harness.cycles import cycles_bake_vertex_colors
from radiosity_baker.addon.extract import extract_scene
from radiosity_baker.addon.write import write_color_attributes
from radiosity_baker.core import Settings, bake
from harness import metrics

import figures as figures_file

TOLERANCE = 0.03        # relative RMSE, per lamp type
CYCLES_SAMPLES = 1024
LIGHT_SAMPLES = 64
PLANE_CUTS = 20         # 20×20 quads, 441 vertices


def _mesh(name, location=(0.0, 0.0, 0.0), rotation=(0.0, 0.0, 0.0), *, cuts=0, size=2.0,
          kind="plane", material=None):
    """Add a plane (``cuts``×``cuts`` quads) or cube of edge ``size`` (m); return the object."""
    if kind == "plane":
        bpy.ops.mesh.primitive_grid_add(x_subdivisions=cuts, y_subdivisions=cuts, size=size,
                                        location=location, rotation=rotation)
    else:
        bpy.ops.mesh.primitive_cube_add(size=size, location=location, rotation=rotation)
    ob = bpy.context.object
    ob.name = name
    if material is not None:
        ob.data.materials.append(material)
    return ob


def _lamp(kind, location, rotation_deg=(0.0, 0.0, 0.0), **settings):
    data = bpy.data.lights.new(kind.title(), kind)
    for key, value in settings.items():
        setattr(data, key, value)
    ob = bpy.data.objects.new(kind.title(), data)
    ob.location = location
    ob.rotation_euler = [math.radians(a) for a in rotation_deg]
    bpy.context.scene.collection.objects.link(ob)
    return ob


def _emissive_material(strength):
    mat = bpy.data.materials.new("Emitter")
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    bsdf.inputs["Emission Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    bsdf.inputs["Emission Strength"].default_value = strength
    return mat


# Each case adds its light source above the receiver plane (z = 0, 2 m wide) and the occluder cube
# (0.4 m at z = 0.7), placed so the shadow and, for the spot, the cone's edge fall on the plane.
CASES = {
    "point": lambda: _lamp("POINT", (0.3, 0.2, 2.0), energy=200.0, shadow_soft_size=0.05),
    # a 10 cm lamp 30 cm over the plane: Cycles' P·cosθ/(4π²(d² + r²)), 10 % under a point's there
    "point_near": lambda: _lamp("POINT", (0.5, -0.5, 0.3), energy=30.0, shadow_soft_size=0.1),
    "spot": lambda: _lamp("SPOT", (0.0, 0.0, 2.5), (12.0, 0.0, 0.0), energy=600.0,
                          shadow_soft_size=0.05, spot_size=math.radians(45.0), spot_blend=0.3),
    "sun": lambda: _lamp("SUN", (0.0, 0.0, 3.0), (25.0, 10.0, 0.0), energy=3.0,
                         angle=math.radians(5.0)),
    "area_rectangle": lambda: _lamp("AREA", (0.2, 0.0, 1.8), (15.0, 0.0, 0.0), energy=150.0,
                                    shape="RECTANGLE", size=0.6, size_y=0.3),
    "area_disk": lambda: _lamp("AREA", (0.0, 0.2, 1.8), (0.0, 15.0, 0.0), energy=150.0, shape="DISK",
                               size=0.5),
    "emissive_quad": lambda: _mesh("Emitter", (0.1, 0.1, 1.6), (math.pi, 0.0, 0.0), size=0.4,
                                   material=_emissive_material(10.0)),
}


def _our_direct(receiver_name: str, **settings) -> np.ndarray:
    """float32[V,3]: our direct lighting per original vertex of the receiver, via the color attribute."""
    receiver = bpy.data.objects[receiver_name]
    extraction = extract_scene(bpy.context.evaluated_depsgraph_get(), receivers=[receiver])
    settings = Settings(**{**dict(method="direct", content="lighting", attribute="Ours",
                                  light_samples=LIGHT_SAMPLES, device="cpu"), **settings})
    result = bake(extraction.scene, settings)
    write_color_attributes(extraction, result.output, settings.attribute, settings)
    rgba = np.empty(len(receiver.data.vertices) * 4, np.float32)
    receiver.data.color_attributes[settings.attribute].data.foreach_get("color", rgba)
    return rgba.reshape(-1, 4)[:, :3]


def _record(case: str, figures: dict) -> None:
    figures_file.record("direct_vs_cycles", case, figures)


def test_cycles_harness_reads_sun_irradiance_over_pi(empty_scene):
    """A sun of strength S straight above a plane gives S/π with the Direct pass (DESIGN.md Units)."""
    strength = 2.5
    _mesh("Receiver", cuts=2, size=0.5)
    _lamp("SUN", (0.0, 0.0, 2.0), energy=strength, angle=0.0)
    baked = cycles_bake_vertex_colors(["Receiver"], passes=("DIRECT",), samples=16)["Receiver"]
    assert baked.shape == (9, 3)
    np.testing.assert_allclose(baked, strength / math.pi, rtol=1e-3)
    # The harness leaves nothing behind.
    assert "CyclesRef" not in bpy.data.objects["Receiver"].data.attributes
    assert empty_scene.render.engine != "CYCLES"


def test_cycles_harness_ao_is_unoccluded_fraction(empty_scene):
    """AO: 1 for a lone plane, about 0 under a large plane facing it (within the AO distance)."""
    _mesh("Receiver", cuts=2, size=0.5)
    open_sky = cycles_bake_vertex_colors(["Receiver"], bake_type="AO", samples=16)["Receiver"]
    np.testing.assert_allclose(open_sky, 1.0)
    _mesh("Cover", (0.0, 0.0, 0.5), (math.pi, 0.0, 0.0), size=50.0)
    covered = cycles_bake_vertex_colors(["Receiver"], bake_type="AO", samples=64)["Receiver"]
    assert covered.max() < 0.05


@pytest.mark.slow
@pytest.mark.parametrize("case", sorted(CASES))
def test_direct_light_matches_cycles(empty_scene, case):
    receiver = _mesh("Receiver", cuts=PLANE_CUTS, size=2.0)
    _mesh("Occluder", (0.1, 0.05, 0.7), size=0.4, kind="cube")
    CASES[case]()
    assert len(receiver.data.vertices) == (PLANE_CUTS + 1) ** 2

    reference = cycles_bake_vertex_colors(["Receiver"], passes=("DIRECT",),
                                          samples=CYCLES_SAMPLES)["Receiver"]
    ours = _our_direct("Receiver")
    rmse = metrics.relative_rmse(ours, reference)
    ratio = float(ours.sum() / reference.sum())
    print(f"\n{case}: relative RMSE {rmse:.4f}, mean ours/Cycles {ratio:.4f}, "
          f"Cycles mean {reference.mean():.4f}")
    _record(case, {"relative_rmse": round(rmse, 5), "mean_ratio": round(ratio, 5),
                   "cycles_samples": CYCLES_SAMPLES, "light_samples": LIGHT_SAMPLES,
                   "vertices": int(reference.shape[0])})
    assert reference.mean() > 0.01, "the lamp does not reach the receiver"
    assert rmse <= TOLERANCE, f"{case}: relative RMSE {rmse:.4f} > {TOLERANCE}"


# The emissive mesh: a wavy 32 × 32-quad panel (2048 triangles), sampled through the light tree.
MESH_QUADS = 32
MESH_LIGHT_SAMPLES = 256


@pytest.mark.slow
def test_direct_light_of_a_2048_triangle_emissive_mesh_matches_cycles(empty_scene):
    receiver = _mesh("Receiver", cuts=PLANE_CUTS, size=2.0)
    _mesh("Occluder", (0.1, 0.05, 0.7), size=0.4, kind="cube")
    panel = _mesh("Sign", (0.1, 0.1, 1.6), (math.pi, 0.0, 0.0), cuts=MESH_QUADS, size=0.8,
                  material=_emissive_material(10.0))
    co = np.empty(len(panel.data.vertices) * 3, np.float32)
    panel.data.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3)
    co[:, 2] += 0.04 * np.sin(co[:, 0] * 25.0)  # a wave: the triangles face many ways
    panel.data.vertices.foreach_set("co", co.ravel())
    panel.data.update()

    reference = cycles_bake_vertex_colors(["Receiver"], passes=("DIRECT",),
                                          samples=CYCLES_SAMPLES)["Receiver"]
    extraction = extract_scene(bpy.context.evaluated_depsgraph_get(), receivers=[receiver])
    emitters = int((extraction.scene.emission.max(axis=1) > 0).sum())
    ours = _our_direct("Receiver", light_selection="tree", light_samples=MESH_LIGHT_SAMPLES)
    rmse = metrics.relative_rmse(ours, reference)
    ratio = float(ours.sum() / reference.sum())
    print(f"\nemissive mesh ({emitters} triangles, light tree): relative RMSE {rmse:.4f}, "
          f"mean ours/Cycles {ratio:.4f}")
    _record("emissive_mesh_2048", {"relative_rmse": round(rmse, 5), "mean_ratio": round(ratio, 5),
                                   "emissive_triangles": emitters, "cycles_samples": CYCLES_SAMPLES,
                                   "light_samples": MESH_LIGHT_SAMPLES, "light_selection": "tree"})
    assert emitters >= 2000
    assert reference.mean() > 0.01
    assert rmse <= TOLERANCE, f"emissive mesh: relative RMSE {rmse:.4f} > {TOLERANCE}"


# Suns of every width, tilted 25° so the widest cones dip below the horizon: Cycles samples the
# cone uniformly with the radiance S/(π sin²half), so a plane facing the sun gets S whatever the
# angle; a 180° sun is half the sky, and the cube's shadow is soft.
SUN_ANGLES = (0.0, 90.0, 179.0, 180.0)
SUN_CUTS = 8            # 8×8 quads, 81 vertices
SUN_LIGHT_SAMPLES = 512


@pytest.mark.slow
@pytest.mark.parametrize("degrees", SUN_ANGLES)
def test_sun_of_any_angle_matches_cycles(empty_scene, degrees):
    _mesh("Receiver", cuts=SUN_CUTS, size=1.2)
    _mesh("Occluder", (0.05, 0.0, 0.4), size=0.3, kind="cube")
    _lamp("SUN", (0.0, 0.0, 3.0), (25.0, 0.0, 0.0), energy=3.0, angle=math.radians(degrees))
    reference = cycles_bake_vertex_colors(["Receiver"], passes=("DIRECT",),
                                          samples=CYCLES_SAMPLES)["Receiver"]
    ours = _our_direct("Receiver", light_samples=SUN_LIGHT_SAMPLES)
    rmse = metrics.relative_rmse(ours, reference)
    ratio = float(ours.sum() / reference.sum())
    shaded = int(np.argmin(reference[:, 0]))
    print(f"\nsun {degrees:g}°: relative RMSE {rmse:.4f}, mean ours/Cycles {ratio:.4f}, darkest "
          f"vertex Cycles {reference[shaded, 0]:.4f} ours {ours[shaded, 0]:.4f}")
    _record(f"sun_{degrees:g}deg", {"relative_rmse": round(rmse, 5), "mean_ratio": round(ratio, 5),
                                     "darkest_cycles": round(float(reference[shaded, 0]), 5),
                                     "darkest_ours": round(float(ours[shaded, 0]), 5),
                                     "cycles_samples": CYCLES_SAMPLES,
                                     "light_samples": SUN_LIGHT_SAMPLES})
    assert rmse <= TOLERANCE, f"sun {degrees:g}°: relative RMSE {rmse:.4f} > {TOLERANCE}"


# Emitters touching their receivers (issue 20): a 20 cm emissive square 1 mm in front of a wall, an
# emissive 24-sided tube (r = 5 cm) lying on a floor on one of its edges, 1 mm above it. The
# receiver is a 0.6 m grid of 2.5 cm cells (625 vertices); compared are its vertices within
# CONTACT_REACH of the emitter's footprint on it (those behind the panel or under the tube, lit
# through the 1 mm gap, and those around it, lit at grazing angles), as relative RMSE over them
# and the worst vertex's error relative to their mean.
CONTACT_CUTS = 24
CONTACT_SIZE = 0.6
CONTACT_REACH = 0.1
CONTACT_CYCLES_SAMPLES = 4096
GAP = 0.001


def _contact_figures(case: str, receiver: str, near: np.ndarray, **settings) -> float:
    """Bake ``receiver`` both ways; record and return the relative RMSE over the vertices ``near``."""
    reference = cycles_bake_vertex_colors([receiver], passes=("DIRECT",),
                                          samples=CONTACT_CYCLES_SAMPLES)[receiver]
    ours = _our_direct(receiver, **settings)
    rmse = metrics.relative_rmse(ours[near], reference[near])
    mean = float(np.linalg.norm(reference[near], axis=1).mean())
    worst = float(np.linalg.norm(ours[near] - reference[near], axis=1).max() / mean)
    everywhere = metrics.relative_rmse(ours, reference)
    print(f"\n{case}: {int(near.sum())} vertices near the contact: relative RMSE {rmse:.4f}, worst "
          f"vertex {worst:.4f} of their mean {mean:.3f}; all {len(ours)} vertices {everywhere:.4f}")
    _record(case, {"relative_rmse_near_contact": round(rmse, 5), "worst_vertex_near_contact": round(worst, 5),
                   "relative_rmse_all": round(everywhere, 5), "vertices_near_contact": int(near.sum()),
                   "mean_near_contact": round(mean, 5), "cycles_samples": CONTACT_CYCLES_SAMPLES,
                   "light_samples": settings.get("light_samples", LIGHT_SAMPLES)})
    assert reference[near].mean() > 0.1
    return rmse


def _positions(ob) -> np.ndarray:
    """float64[V,3] world positions of ``ob``'s vertices."""
    co = np.empty(len(ob.data.vertices) * 3, np.float64)
    ob.data.vertices.foreach_get("co", co)
    m = np.array(ob.matrix_world)
    return co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]


@pytest.mark.slow
def test_emissive_panel_flush_with_a_wall_matches_cycles_at_the_contact(empty_scene):
    """The wall faces −y; the panel's x edges fall between vertex columns, its z edges on rows."""
    wall = _mesh("Wall", rotation=(0.5 * math.pi, 0.0, 0.0), cuts=CONTACT_CUTS, size=CONTACT_SIZE)
    half, centre = 0.1, np.array([0.00625, -GAP, 0.0])
    _mesh("Panel", tuple(centre), (0.5 * math.pi, 0.0, 0.0), size=2 * half, material=_emissive_material(10.0))
    bpy.context.view_layer.update()
    offset = np.abs(_positions(wall) - centre)[:, [0, 2]]
    near = (offset <= half + CONTACT_REACH).all(axis=1)
    assert _contact_figures("contact_panel_on_wall", "Wall", near) <= TOLERANCE


@pytest.mark.slow
def test_emissive_tube_lying_on_a_floor_matches_cycles_at_the_contact(empty_scene):
    """A 0.4 m tube along x resting on an edge, GAP above the floor's vertex row y = 0."""
    floor = _mesh("Floor", cuts=CONTACT_CUTS, size=CONTACT_SIZE)
    radius, length = 0.05, 0.4
    bpy.ops.mesh.primitive_cylinder_add(vertices=24, radius=radius, depth=length,
                                        location=(0.0, 0.0, radius + GAP), rotation=(0.0, 0.5 * math.pi, 0.0))
    bpy.context.object.data.materials.append(_emissive_material(10.0))
    bpy.context.view_layer.update()
    p = _positions(floor)
    near = (np.abs(p[:, 0]) <= 0.5 * length + CONTACT_REACH) & (np.abs(p[:, 1]) <= radius + CONTACT_REACH)
    assert _contact_figures("contact_tube_on_floor", "Floor", near) <= TOLERANCE
