"""Frames of an animation: the problem carries over (device arrays moved, tree refitted) while the
topology stays, each frame bakes what a fresh bake of it gives, and an iterating solver starts from
the previous frame's solution."""
import numpy as np
import pytest

import shapes
from radiosity_baker.core import Settings, bake
from harness import metrics
from radiosity_baker.core.pipeline import Sequence
from radiosity_baker.core.scene import LAMP_POINT


def frame(k: int, balls=(((0.2, 0.1, 0.35), 0.3, 2),)):
    """Frame k of a room corner whose balls ((centre at frame 0, radius, icosphere subdivisions),
    each its own object) rise 5 cm a frame under a lamp that slides along x."""
    floor = shapes.grid(2.0, 12)
    wall = shapes.grid(2.0, 12)
    rot = np.array([[0, 0, 1], [0, 1, 0], [-1, 0, 0]], np.float32)
    wall = (wall[0] @ rot.T + np.array([-1.0, 0.0, 1.0], np.float32), wall[1] @ rot.T, wall[2])
    objects = [(*floor, (0.7,) * 3, (0,) * 3), (*wall, (0.8, 0.3, 0.2), (0,) * 3)]
    for centre, radius, subdivisions in balls:
        ball = shapes.icosphere(radius, subdivisions, inward=False)
        at = np.asarray(centre, np.float32) + np.array([0.0, 0.0, 0.05 * k], np.float32)
        objects.append((ball[0] + at, ball[1], ball[2], (0.6,) * 3, (0,) * 3))
    return shapes.scene(objects, shapes.lamp(LAMP_POINT, (0.3 + 0.05 * k, 0.0, 1.6), size=(0.05, 0.0),
                                             power=(150.0,) * 3))


@pytest.mark.parametrize("method", ["reference", "hierarchical", "bunnell", "ao"])
def test_each_frame_bakes_what_a_fresh_bake_of_it_gives(method):
    settings = Settings(method=method, device="cpu", light_samples=4)
    seq = Sequence(settings)
    first = seq.bake(frame(0), label="frame 0")
    problem = seq.problem
    for k in (1, 2):
        ours = seq.bake(frame(k), label=f"frame {k}")
        assert seq.problem is problem and "move" in ours.timings  # moved, not rebuilt
        fresh = bake(frame(k), settings)
        assert metrics.relative_rmse(ours.output, fresh.output) <= 0.01
        assert not np.allclose(ours.output, first.output)  # the frames differ: the test can fail


def test_a_warm_start_converges_in_fewer_sweeps_than_a_cold_one():
    settings = Settings(method="reference", device="cpu", light_samples=4, tolerance=1e-5)
    seq = Sequence(settings)
    seq.bake(frame(0))
    warm = seq.bake(frame(1))
    cold = bake(frame(1), settings)
    print(f"\nsweeps to the tolerance: cold {cold.counts['iterations']}, warm {warm.counts['iterations']}")
    assert warm.counts["iterations"] < cold.counts["iterations"]
    assert metrics.relative_rmse(warm.indirect, cold.indirect) <= 0.002


def test_a_frame_with_other_topology_builds_a_new_problem():
    seq = Sequence(Settings(method="direct", device="cpu"))
    seq.bake(frame(0))
    first = seq.problem
    other = frame(0)
    other.triangles = other.triangles[:, [0, 2, 1]].copy()
    seq.bake(other)
    assert seq.problem is not first


def test_progress_of_a_frame_names_it():
    stages = []
    Sequence(Settings(method="direct", device="cpu"), progress=lambda s, f: stages.append(s)).bake(
        frame(0), label="frame 7")
    assert stages and all(s.startswith("frame 7: ") for s in stages)


def test_antiradiance_starts_a_frame_from_the_previous_frames_antiradiance():
    """The leaves' antiradiance carries over with the indirect light (the refitted tree keeps its
    leaves): measured 8 sweeps to the tolerance where a cold start takes 11 (11 with the indirect
    light alone), both 1.5 % from the reference. The same frame again converges at once."""
    settings = Settings(method="antiradiance", device="cpu", light_samples=4, tolerance=1e-4)
    seq = Sequence(settings)
    seq.bake(frame(0))
    warm = seq.bake(frame(1))
    cold = bake(frame(1), settings)
    again = seq.bake(frame(1))
    ref = bake(frame(1), Settings(method="reference", device="cpu", light_samples=4))
    print(f"\nsweeps: cold {cold.counts['iterations']}, warm {warm.counts['iterations']}, "
          f"again {again.counts['iterations']}")
    assert warm.counts["iterations"] < cold.counts["iterations"]
    assert again.counts["iterations"] <= 2
    for result in (warm, again):
        assert metrics.relative_rmse(result.lighting, ref.lighting) <= 0.02
    assert metrics.relative_rmse(again.indirect, warm.indirect) <= 0.01
