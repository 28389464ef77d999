"""The bruteforce gather: furnace, energy balance and agreement with the direct-only path."""
import numpy as np
import pytest

import shapes
from radiosity_baker.core import Settings, bake
from radiosity_baker.core.scene import LAMP_POINT


@pytest.fixture(scope="module")
def furnace():
    """Closed inward-facing sphere (2562 vertices), emission E = 1, albedo ρ = 0.5."""
    p, n, t = shapes.icosphere(1.0, 4)
    scene = shapes.scene([(p, n, t, (0.5, 0.5, 0.5), (1.0, 1.0, 1.0))])
    return bake(scene, Settings(method="bruteforce", content="combined", light_samples=1, visibility_rays=1))


def test_furnace_converges_to_analytic_radiosity(furnace):
    # B = E / (1 − ρ) = 2 at every vertex
    np.testing.assert_allclose(furnace.output, 2.0, rtol=0.01)


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
    r = bake(open_box_scene((0, 0, 0)), Settings(method="bruteforce"))
    assert np.all(r.indirect == 0)
    np.testing.assert_allclose(r.lighting, r.direct)


def test_indirect_light_reaches_the_wall_from_the_lit_floor_and_scales_with_albedo():
    lo = bake(open_box_scene((0.2,) * 3), Settings(method="bruteforce"))
    hi = bake(open_box_scene((0.4,) * 3), Settings(method="bruteforce"))
    assert np.all(lo.indirect >= 0)
    assert lo.indirect.mean() > 0
    # first bounce dominates in an open scene: doubling ρ roughly doubles the indirect light
    ratio = hi.indirect.sum() / lo.indirect.sum()
    assert 2.0 < ratio < 2.4


def test_direct_method_matches_bruteforce_direct_part():
    scene = open_box_scene((0.5,) * 3)
    a = bake(scene, Settings(method="direct"))
    b = bake(scene, Settings(method="bruteforce"))
    np.testing.assert_allclose(a.lighting, b.direct)
    assert np.all(a.indirect == 0)
