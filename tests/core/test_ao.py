"""Accessibility over the disk tree: the analytic cases of ALGORITHMS.md §8, the tree against the
all-pairs sum, the AO distance, bent normals, and the pipeline's ``ao`` content."""
import numpy as np
import pytest

import shapes
from radiosity_baker.core import Settings, bake, elements, gather
from radiosity_baker.core.problem import Problem

GREY = ((0.5,) * 3, (0.0,) * 3)
UP = np.array([[0.0, 0.0, 1.0]], np.float32)
ORIGIN = np.zeros((1, 3), np.float32)


def _gather(parts, points, normals, distance=100.0, open_k=gather.OPEN):
    """The gather at world ``points`` with unit ``normals`` (float[N,3]) over the parts."""
    sc = shapes.scene([(*p, *GREY) for p in parts])
    problem = Problem(sc, Settings(device="cpu"))
    local = (np.asarray(points, np.float64) - problem.scene.origin).astype(np.float32)
    return gather.gather(problem, local, np.asarray(normals, np.float32), distance, open_k=open_k), problem


def _ceiling_disk(radius, height):
    """A disk facing down (towards the receiver at the origin), finely tessellated."""
    return shapes.disk(radius, 16, 64, z=height, flip=True)


def test_accessibility_inside_a_closed_sphere_is_zero():
    p, n, t = shapes.icosphere(1.0, 4, inward=True)
    els = elements.build(shapes.scene([(p, n, t, *GREY)]))
    g, _ = _gather([(p, n, t)], els.position, els.normal)
    assert g.accessibility.mean() < 0.03
    assert g.accessibility.max() < 0.05


def test_receiver_under_an_on_axis_disk_with_radius_equal_height_is_half_occluded():
    g, _ = _gather([_ceiling_disk(1.0, 1.0)], ORIGIN, UP)
    assert 1.0 - g.accessibility[0] == pytest.approx(0.5, abs=0.03)


@pytest.mark.parametrize("radius, height", [(0.5, 1.0), (2.0, 1.0)])
def test_on_axis_disk_occludes_r2_over_h2_plus_r2(radius, height):
    g, _ = _gather([_ceiling_disk(radius, height)], ORIGIN, UP)
    assert 1.0 - g.accessibility[0] == pytest.approx(radius ** 2 / (height ** 2 + radius ** 2), abs=0.03)


def test_two_stacked_coaxial_disks_occlude_only_as_much_as_the_nearer():
    """Unit disks at h=1 and h=2: the upper one hides wholly behind the lower (0.5), where a naive
    sum of form factors gives 0.5 + 0.2 = 0.7."""
    g, _ = _gather([_ceiling_disk(1.0, 1.0), _ceiling_disk(1.0, 2.0)], ORIGIN, UP)
    assert 1.0 - g.accessibility[0] == pytest.approx(0.5, abs=0.05)


def test_senders_beyond_the_ao_distance_do_not_occlude():
    lid = shapes.grid(40.0, 20, z=2.0, flip=True)
    near, _ = _gather([lid], ORIGIN, UP, distance=10.0)
    far, _ = _gather([lid], ORIGIN, UP, distance=1.5)
    assert near.accessibility[0] < 0.1
    assert far.accessibility[0] == pytest.approx(1.0, abs=1e-6)


def test_a_disk_seen_from_behind_still_occludes():
    """Cycles' AO rays stop at either face: a disk turned away blocks as much as one facing."""
    g, _ = _gather([shapes.disk(1.0, 16, 64, z=1.0, flip=False)], ORIGIN, UP)
    assert 1.0 - g.accessibility[0] == pytest.approx(0.5, abs=0.03)


def test_a_closed_ball_overhead_occludes_its_solid_angle_once():
    """Radius 0.5 at 1.5 m on the axis: occlusion sin²α = (0.5/1.5)² = 1/9; its near (front) and
    far (back) faces lie in the same directions and must not add up to 2/9."""
    p, n, t = shapes.icosphere(0.5, 3, inward=False)
    g, _ = _gather([(p + np.array([0.0, 0.0, 1.5], np.float32), n, t)], ORIGIN, UP)
    assert 1.0 - g.accessibility[0] == pytest.approx(1.0 / 9.0, abs=0.02)


def test_surfaces_in_contact_occlude_each_other():
    """A box face lying on the floor and the floor under it are dark (as Cycles' offset rays see
    them); the floor away from the box is not."""
    floor = shapes.grid(4.0, 20)
    lid = shapes.grid(1.0, 5, z=0.0, flip=True)  # the bottom face of a box, touching the floor
    top = shapes.grid(1.0, 5, z=0.5)
    points = np.array([[0.1, 0.05, 0.0], [0.1, 0.05, 0.0], [1.9, 1.9, 0.0]], np.float32)
    normals = np.array([[0, 0, 1], [0, 0, -1], [0, 0, 1]], np.float32)
    g, _ = _gather([floor, lid, top], points, normals)
    assert g.accessibility[0] < 0.05 and g.accessibility[1] < 0.05
    assert g.accessibility[2] > 0.9


def _cluttered():
    """A floor, a ball resting above it and a wall: occlusion at all scales."""
    floor = shapes.grid(4.0, 40)
    ball = shapes.icosphere(0.6, 3, inward=False)
    ball = (ball[0] + np.array([0.0, 0.0, 0.7], np.float32), ball[1], ball[2])
    wall = shapes.grid(4.0, 30)
    wall = (wall[0][:, [2, 1, 0]] + np.array([1.5, 0.0, 2.0], np.float32),
            np.tile(np.array([-1.0, 0.0, 0.0], np.float32), (len(wall[0]), 1)), wall[2])
    return [floor, ball, wall]


def test_tree_traversal_agrees_with_the_all_pairs_sum_within_two_percent():
    parts = _cluttered()
    els = elements.build(shapes.scene([(*p, *GREY) for p in parts]))
    tree, _ = _gather(parts, els.position, els.normal)
    pairs, _ = _gather(parts, els.position, els.normal, open_k=gather.ALL_PAIRS)
    occlusion = 1.0 - pairs.accessibility
    assert occlusion.mean() > 0.2  # a scene with something to get right
    diff = np.abs(tree.accessibility - pairs.accessibility)
    assert diff.mean() <= 0.02 * occlusion.mean()
    assert diff.max() <= 0.05


def test_bent_normal_leans_away_from_an_occluding_wall():
    """Beside a wall rising on the +x side, the least occluded direction tilts towards −x."""
    wall = shapes.grid(4.0, 20)
    wall = (wall[0][:, [2, 1, 0]] + np.array([0.5, 0.0, 2.0], np.float32),
            np.tile(np.array([-1.0, 0.0, 0.0], np.float32), (len(wall[0]), 1)), wall[2])
    g, _ = _gather([wall], ORIGIN, UP)
    bent = g.bent_normal[0]
    assert np.linalg.norm(bent) == pytest.approx(1.0, abs=1e-5)
    assert bent[0] < -0.1 and bent[2] > 0.5
    assert 0.5 < g.accessibility[0] < 0.9


def test_pipeline_bakes_accessibility_into_all_three_channels_within_the_worlds_distance():
    floor = shapes.grid(4.0, 8)
    lid = shapes.grid(4.0, 8, z=1.0, flip=True)
    sc = shapes.scene([(*floor, *GREY), (*lid, *GREY)])
    sc.ao_distance = 10.0
    covered = bake(sc, Settings(content="ao", device="cpu"))
    sc.ao_distance = 0.5
    open_sky = bake(sc, Settings(content="ao", device="cpu"))
    short = bake(sc, Settings(content="ao", device="cpu", ao_distance=0.5))
    centre = np.argmin(np.linalg.norm(sc.positions[:81, :2], axis=1))
    assert np.array_equal(covered.output[:, 0], covered.output[:, 2])
    assert covered.output[centre, 0] < 0.6
    assert open_sky.output[centre, 0] == pytest.approx(1.0)
    np.testing.assert_allclose(short.output, open_sky.output)
    assert covered.counts["nodes"] > covered.counts["elements"]
    assert "hierarchy" in covered.timings and "direct" not in covered.timings
