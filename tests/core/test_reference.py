"""The reference solver: furnace, energy balance and agreement with the direct-only path."""
import numpy as np
import pytest

import shapes
from radiosity_baker.core import Settings, bake
from radiosity_baker.core.problem import Problem
from radiosity_baker.core.solvers import reference
from radiosity_baker.core.solvers.reference import Transport
from radiosity_baker.core.scene import LAMP_POINT


@pytest.fixture(scope="module")
def furnace():
    """Closed inward-facing sphere (2562 vertices), emission E = 1, albedo ρ = 0.5."""
    p, n, t = shapes.icosphere(1.0, 4)
    scene = shapes.scene([(p, n, t, (0.5, 0.5, 0.5), (1.0, 1.0, 1.0))])
    return bake(scene, Settings(method="reference", content="combined", light_samples=1, visibility_rays=1))


def test_furnace_converges_to_analytic_radiosity(furnace):
    # B = E / (1 − ρ) = 2 at every vertex
    np.testing.assert_allclose(furnace.output, 2.0, rtol=0.005)


def test_furnace_lighting_splits_into_direct_and_indirect(furnace):
    # Direct = E·ΣF = 1 and indirect = ρ/(1−ρ)·E = 1 on a true sphere; a polyhedron's vertex sees a
    # little less than its whole hemisphere (its fan dips below the tangent plane): ≈1 % at the 12
    # five-valent vertices of this icosphere.
    np.testing.assert_allclose(furnace.direct, 1.0, rtol=0.012)
    np.testing.assert_allclose(furnace.indirect, 1.0, rtol=0.012)
    np.testing.assert_allclose(furnace.lighting, furnace.direct + furnace.indirect, rtol=1e-6)


def open_box_scene(albedo):
    """A floor and a wall at right angles under a point lamp."""
    fp, fn, ft = shapes.grid(2.0, 10)
    wp_, wn, wt = shapes.grid(2.0, 10)
    # rotate the second grid to stand at x = -1 facing +x
    rot = np.array([[0, 0, 1], [0, 1, 0], [-1, 0, 0]], np.float32)
    wp_ = wp_ @ rot.T + np.array([-1, 0, 1], np.float32)
    wn = wn @ rot.T
    return shapes.scene([(fp, fn, ft, albedo, (0,) * 3), (wp_, wn, wt, albedo, (0,) * 3)],
                        shapes.lamp(LAMP_POINT, (0.2, 0, 1.5), power=(200,) * 3))


def test_black_surfaces_reflect_nothing():
    r = bake(open_box_scene((0, 0, 0)), Settings(method="reference"))
    assert np.all(r.indirect == 0)
    np.testing.assert_allclose(r.lighting, r.direct)


def test_indirect_light_reaches_the_wall_from_the_lit_floor_and_scales_with_albedo():
    lo = bake(open_box_scene((0.2,) * 3), Settings(method="reference"))
    hi = bake(open_box_scene((0.4,) * 3), Settings(method="reference"))
    assert np.all(lo.indirect >= 0)
    assert lo.indirect.mean() > 0
    # first bounce dominates in an open scene: doubling ρ roughly doubles the indirect light
    ratio = hi.indirect.sum() / lo.indirect.sum()
    assert 2.0 < ratio < 2.4


def test_direct_method_matches_reference_direct_part():
    scene = open_box_scene((0.5,) * 3)
    a = bake(scene, Settings(method="direct"))
    b = bake(scene, Settings(method="reference"))
    np.testing.assert_allclose(a.lighting, b.direct)
    assert np.all(a.indirect == 0)


def patch_form_factors(part_a, part_b, **settings):
    """Area-weighted patch-to-patch form factors (F_AB, F_BA) and areas from the transport matrix."""
    sc = shapes.scene([part_a + ((0.5,) * 3, (0,) * 3), part_b + ((0.5,) * 3, (0,) * 3)])
    problem = Problem(sc, Settings(visibility_rays=1, device="cpu", **settings))
    transport = Transport(problem)
    transport.build()
    m = transport.matrix.numpy()
    na, a = len(part_a[0]), problem.elements.area.astype(np.float64)
    f_ab = (a[:na, None] * m[:na, na:]).sum() / a[:na].sum()
    f_ba = (a[na:, None] * m[na:, :na]).sum() / a[na:].sum()
    return f_ab, f_ba, a[:na].sum(), a[na:].sum()


def test_parallel_unit_squares_form_factor_is_exact():
    f_ab, f_ba, _, _ = patch_form_factors(shapes.grid(1.0, 32), shapes.grid(1.0, 32, z=1.0, flip=True))
    assert f_ab == pytest.approx(0.19982, rel=0.01)
    assert f_ba == pytest.approx(0.19982, rel=0.01)


def test_perpendicular_unit_squares_sharing_an_edge_form_factor_is_exact():
    p, n, t = shapes.grid(1.0, 32)
    rot = np.array([[1, 0, 0], [0, 0, 1], [0, -1, 0]], np.float32)  # +Z normal → +Y, standing up
    wall = (p @ rot.T + np.array([0, -0.5, 0.5], np.float32), n @ rot.T, t)
    f_ab, _, _, _ = patch_form_factors((p, n, t), wall)
    assert f_ab == pytest.approx(0.20004, rel=0.01)


def test_coaxial_unit_disks_form_factor_is_exact():
    f_ab, _, _, _ = patch_form_factors(shapes.disk(1.0, 16, 64), shapes.disk(1.0, 16, 64, z=1.0, flip=True))
    assert f_ab == pytest.approx(0.38197, rel=0.01)


def test_form_factors_are_reciprocal_between_unequal_patches():
    small = shapes.grid(0.5, 16)
    big = shapes.grid(2.0, 32, z=0.7, flip=True)
    f_ab, f_ba, a_a, a_b = patch_form_factors(small, big)
    assert a_a * f_ab == pytest.approx(a_b * f_ba, rel=0.01)


def test_every_transport_mode_gives_the_same_solution_as_the_held_matrix():
    """Within the memory budget the float32 matrix is held; below it the visibility alone (one
    byte a pair, form factors recomputed each sweep); below that nothing (traced every sweep)."""
    scene = open_box_scene((0.6,) * 3)
    held = bake(scene, Settings(method="reference"))
    n = held.counts["elements"]
    assert held.counts["transport"] == "matrix"
    for mode, pairs in (("visibility", n * n // 4), ("traced", n * n // 4 - 1)):
        other = bake(scene, Settings(method="reference", max_pairs=pairs))
        assert other.counts["transport"] == mode
        np.testing.assert_allclose(other.indirect, held.indirect, rtol=2e-3, atol=1e-6)
    assert other.counts["rays"] > held.counts["rays"]  # traced again every sweep


def test_a_transport_larger_than_free_memory_is_refused_with_a_message(monkeypatch):
    from radiosity_baker.core import device as device_mod
    from radiosity_baker.core.errors import BakeError

    monkeypatch.setattr(device_mod, "free_memory", lambda dev: 1000)
    with pytest.raises(BakeError, match="GiB of memory are free: lower --max-pairs"):
        bake(open_box_scene((0.5,) * 3), Settings(method="reference"))


def test_bruteforce_is_another_name_for_the_reference_solver():
    scene = open_box_scene((0.5,) * 3)
    np.testing.assert_array_equal(bake(scene, Settings(method="bruteforce")).lighting,
                                  bake(scene, Settings(method="reference")).lighting)


def test_a_large_scene_is_announced_with_its_pairs_time_and_a_faster_method():
    """20 k elements would keep the reference busy for a long time: say so before starting."""
    p, n, t = shapes.grid(10.0, 140)
    problem = Problem(shapes.scene([(p, n, t, (0.5,) * 3, (0,) * 3)]), Settings(method="reference", device="cpu"))
    (message,) = reference.check(problem)
    assert f"{problem.elements.count} elements" in message and "predicted" in message
    assert "--method bunnell" in message


def test_the_announcement_comes_before_the_solve(monkeypatch):
    monkeypatch.setattr(reference, "SLOW_SECONDS", 0.0)
    events = []
    bake(open_box_scene((0.5,) * 3), Settings(method="reference", device="cpu"),
         progress=lambda stage, f: events.append(stage), notify=lambda m: events.append("warning"))
    assert "warning" in events and events.index("warning") < events.index("form factors")
