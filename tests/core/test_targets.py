"""The target contract: every output gets its receivers from the problem and its light through one
shared path, the pipeline loops over the targets asked for without a branch on their kind, and a
new target is one module plus one registry line."""
import inspect
import math
import sys
import types

import numpy as np
import pytest

import shapes
from radiosity_baker.core import Settings, bake, pipeline, receivers, targets
from radiosity_baker.core.scene import LAMP_POINT
from radiosity_baker.core.targets import TARGETS, TargetInfo

POWER, HEIGHT = 80.0, 1.5


def lit_floor():
    p, n, t = shapes.grid(2.0, 6)
    return shapes.scene([(p, n, t, (0.5, 0.4, 0.3), (0,) * 3)],
                        shapes.lamp(LAMP_POINT, (0, 0, HEIGHT), power=(POWER,) * 3))


def test_the_pipeline_holds_no_branch_per_target():
    source = inspect.getsource(pipeline.Sequence.bake)
    for name in TARGETS:
        assert f'"{name}"' not in source and f"'{name}'" not in source
    assert "isinstance" not in source


class Centroids:
    """A target as the manual's Development page shows: the light at each triangle's centroid."""

    def receivers(self, problem):
        scene = problem.scene
        corners = scene.positions[scene.triangles]
        normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        normals /= np.linalg.norm(normals, axis=1, keepdims=True)
        tris = np.arange(scene.num_triangles, dtype=np.int32)
        sizes = np.sqrt(scene.triangle_areas()).astype(np.float32)
        return receivers.on_triangles(problem, tris, np.full((len(tris), 3), 1 / 3, np.float32),
                                      corners.mean(axis=1).astype(np.float32),
                                      normals.astype(np.float32), sizes, label="centroid")

    def finish(self, problem, at, light):
        return {"points": at.points + problem.scene.origin, "lighting": light.direct + light.indirect,
                "output": light.output}


@pytest.fixture
def centroid_target(monkeypatch):
    module = types.ModuleType("radiosity_baker.core.targets.centroids")
    module.Target = Centroids
    monkeypatch.setitem(sys.modules, module.__name__, module)
    monkeypatch.setitem(TARGETS, "centroids", TargetInfo("centroids", "the light at each triangle's centroid"))


def test_a_new_target_is_one_module_and_one_registry_line(centroid_target):
    scene = lit_floor()
    r = bake(scene, Settings(method="direct", content="combined", device="cpu", light_samples=16),
             targets=[targets.make("vertices"), targets.make("centroids")])
    at = r["centroids"]
    d2 = (at["points"][:, 0] ** 2 + at["points"][:, 1] ** 2 + HEIGHT ** 2)
    analytic = POWER / (4 * math.pi ** 2 * d2) * HEIGHT / np.sqrt(d2)  # a point lamp, cos θ / d²
    np.testing.assert_allclose(at["lighting"][:, 0], analytic, rtol=1e-3)
    np.testing.assert_allclose(at["output"], np.array([0.5, 0.4, 0.3]) * at["lighting"], rtol=1e-5)
    assert r.output.shape == (r.counts["elements"], 3)  # the vertices were baked beside it
    assert "centroid direct" in r.timings


def test_every_target_gets_its_light_through_the_one_shared_path(centroid_target, monkeypatch):
    seen = []

    def spy(problem, solver, solution, at):
        seen.append(at.label)
        return receivers.light_at(problem, solver, solution, at)

    monkeypatch.setattr(pipeline, "light_at", spy)
    bake(lit_floor(), Settings(method="bunnell", device="cpu", light_samples=4),
         targets=[targets.make("vertices"), targets.make("centroids")])
    assert seen == ["vertex", "centroid"]


def test_a_bake_without_targets_bakes_the_vertices_and_names_what_it_lacks():
    r = bake(lit_floor(), Settings(method="direct", device="cpu", light_samples=4))
    assert list(r.targets) == ["vertices"] and r.lighting is r["vertices"].lighting
    with pytest.raises(KeyError, match="made no 'lightmap' result"):
        r["lightmap"]
    with pytest.raises(KeyError, match="no target 'nope'"):
        targets.make("nope")
