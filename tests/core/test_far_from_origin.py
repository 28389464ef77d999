"""A scene far from the world origin bakes as it does at the origin: the core works relative to
the scene's centre (``SceneData.recentred``) and offsets rays by the float32 spacing at each point
(``core.rays``), not by a fraction of the scene size."""
import numpy as np
import pytest

import shapes
from radiosity_baker.core import Settings, bake
from harness import metrics
from radiosity_baker.core.scene import LAMP_POINT, LAMP_SUN, Lamps

TOLERANCE = 0.005  # relative RMSE and bias against the bake at the origin


def lit_yard(offset: float):
    """A 10 m ground of 0.5 m quads with a 2 m box on it, under a low sun and a point lamp, the
    whole scene moved by (offset, offset, 0) m — in float32 world coordinates, as a naive caller
    would give them (origin 0)."""
    ground = shapes.grid(10.0, 20)
    box = shapes.icosphere(1.0, 2, inward=False)
    box = (box[0] * np.array([1.0, 1.0, 0.6], np.float32) + np.array([1.0, 0.5, 0.6], np.float32),
           box[1], box[2])
    sun = shapes.lamp(LAMP_SUN, direction=(-0.6, -0.3, -0.74), size=(0.05, 0.0), power=(4.0,) * 3)
    point = shapes.lamp(LAMP_POINT, position=(-2.0, -1.0, 2.5), size=(0.1, 0.0), power=(400.0,) * 3)
    sc = shapes.scene([(*ground, (0.6,) * 3, (0,) * 3), (*box, (0.7, 0.5, 0.3), (0,) * 3)],
                      Lamps.concat([sun, point]))
    shift = np.array([offset, offset, 0.0])
    sc.positions = (sc.positions.astype(np.float64) + shift).astype(np.float32)
    sc.lamps.position = (sc.lamps.position.astype(np.float64) + shift).astype(np.float32)
    return sc


@pytest.fixture(scope="module")
def at_origin():
    return {m: bake(lit_yard(0.0), Settings(method=m, device="cpu", light_samples=16))
            for m in ("direct", "reference")}


@pytest.mark.parametrize("offset", [1e3, 1e4, 1e5])
@pytest.mark.parametrize("method", ["direct", "reference"])
def test_a_scene_far_from_the_origin_bakes_as_at_the_origin(at_origin, method, offset):
    far = bake(lit_yard(offset), Settings(method=method, device="cpu", light_samples=16))
    near = at_origin[method]
    assert near.direct.max() > 0.5 and (near.direct == 0).any()  # lit and shadowed vertices
    rmse = metrics.relative_rmse(far.lighting, near.lighting)
    bias = metrics.mean_bias(far.lighting, near.lighting)
    print(f"\n{method} at {offset:g} m: relative RMSE {rmse:.5f}, bias {bias:+.5f}")
    assert rmse <= TOLERANCE and abs(bias) <= TOLERANCE


def lamp_over_floor(depth: float):
    """A 4 m floor with a 1 m ball above it under a point lamp (the ball's shadow on the floor),
    and, for ``depth`` > 0, one plane 2·depth wide ``depth`` m below: a huge far object whose
    bounds would put the scene's centre ``depth``/2 away from everything lit."""
    floor = shapes.grid(4.0, 16)
    ball = shapes.icosphere(0.5, 2, inward=False)
    ball = (ball[0] + np.array([0.0, 0.0, 0.8], np.float32), ball[1], ball[2])
    lamp = shapes.lamp(LAMP_POINT, position=(0.3, 0.2, 2.5), size=(0.05, 0.0), power=(300.0,) * 3)
    parts = [(*floor, (0.6,) * 3, (0,) * 3), (*ball, (0.7,) * 3, (0,) * 3)]
    if depth:
        parts.append((*shapes.grid(2.0 * depth, 1, z=-depth), (0.5,) * 3, (0,) * 3))
    return shapes.scene(parts, lamp)


@pytest.fixture(scope="module")
def without_plane():
    return {m: bake(lamp_over_floor(0.0), Settings(method=m, device="cpu", light_samples=16))
            for m in ("direct", "hierarchical")}


@pytest.mark.parametrize("depth", [1e3, 1e4, 1e5, 1e6])
@pytest.mark.parametrize("method", ["direct", "hierarchical"])
def test_a_huge_far_plane_keeps_the_shadows_of_a_small_scene(without_plane, method, depth):
    """The scene's coordinates are taken from amid its detail (``core.scene.detail_centre``)
    where the centre of its bounds would lose it: before, a 2 000 km plane 1 000 km below erased
    the ball's shadow (the floor's darkest vertex lit at a quarter of the brightest)."""
    near = without_plane[method]
    result = bake(lamp_over_floor(depth), Settings(method=method, device="cpu", light_samples=16))
    small = result.lighting[:len(near.lighting)]  # the floor's and ball's vertices come first
    floor = slice(0, 17 * 17)
    assert near.lighting[floor].min() < 0.02 * near.lighting[floor].max()  # a shadow to keep
    rmse = metrics.relative_rmse(small, near.lighting)
    bias = metrics.mean_bias(small, near.lighting)
    print(f"\n{method}, plane {depth:g} m below: relative RMSE {rmse:.5f}, bias {bias:+.5f}")
    assert rmse <= TOLERANCE and abs(bias) <= TOLERANCE
    assert small[floor].min() <= near.lighting[floor].min() + 0.01 * near.lighting[floor].max()
    assert not result.warnings
    if method == "hierarchical":
        # The plane does not stretch the cluster tree's grid over the small scene (there, in one
        # cell of it, its elements linked leaf to leaf: 38 k links for 2.2 k without the plane).
        print(f"links {result.counts['links']} ({near.counts['links']} without the plane)")
        assert result.counts["links"] <= 2 * near.counts["links"]


def test_an_object_too_far_for_float32_detail_is_named_in_a_warning():
    """A 1 m ball 1 000 km from a lit 4 m floor: its rays would start metres above it."""
    floor = shapes.grid(4.0, 16)
    ball = shapes.icosphere(0.5, 1, inward=False)
    ball = (ball[0] + np.array([1e6, 0.0, 1.0], np.float32), ball[1], ball[2])
    lamp = shapes.lamp(LAMP_POINT, position=(0.3, 0.2, 2.5), size=(0.05, 0.0), power=(300.0,) * 3)
    sc = shapes.scene([(*floor, (0.6,) * 3, (0,) * 3), (*ball, (0.5,) * 3, (0,) * 3)], lamp)
    result = bake(sc, Settings(method="direct", device="cpu"))
    said = [w for w in result.warnings if "too far from the rest of the scene" in w]
    assert len(said) == 1 and "'part1' (" in said[0] and "lost" in said[0], result.warnings
    assert not [w for w in bake(lit_yard(0.0), Settings(method="direct", device="cpu")).warnings
                if "too far" in w]
