"""Emitter weights shared by a group of receivers, and where a group may not share them."""
import numpy as np

import shapes
from radiosity_baker.core import Settings, direct, emitter_weights
from radiosity_baker.core.problem import Problem


def _square(centre, half=0.02):
    """Four receivers (m, the scene's frame) at the corners of a square of side 2 × half on the floor."""
    offsets = np.array([[-half, -half], [half, -half], [-half, half], [half, half]])
    return np.column_stack([np.asarray(centre) + offsets, np.zeros(4)])


def test_a_group_beside_an_emitter_keeps_the_light_tree_and_a_far_one_shares_exact_weights():
    """A floor 1 mm under an emissive sphere (r = 0.3 m, 320 triangles): four receivers right under
    it lie within REACH × their group's radius of an emitter, four at the floor's corner do not.
    The near group's weights are marked unshared (sum −1) and its light is the tree's, bit for
    bit; the far group's weights are every emitter's exact weight at its centroid."""
    scene, _, _ = shapes.floor_under_emissive_sphere(1.0, 16)
    problem = Problem(scene, Settings(method="direct", light_selection="auto"))
    at = (np.concatenate([_square([0.0, 0.0]), _square([0.45, 0.45])]) - problem.scene.origin).astype(np.float32)
    up = np.tile(np.float32([0, 0, 1]), (8, 1))
    sizes = np.full(8, 0.01, np.float32)
    group = np.repeat([0, 1], 4)
    shared = emitter_weights.shared_weights(problem, at, up, sizes, group)
    kept = shared.kept.numpy()
    assert kept[0, -1] == -1.0 and kept[1, -1] > 0.0
    np.testing.assert_allclose(kept[1, -1], kept[1, :-1].sum(), rtol=1e-5)
    mode = np.full(8, direct.MODE_FULL, np.int32)
    light = direct.estimate(problem, at, up, sizes, mode, 64, 3, shared=shared)[0]
    tree = direct.estimate(problem, at, up, sizes, mode, 64, 3, exact=False)[0]
    np.testing.assert_array_equal(light[:4], tree[:4])
    assert not np.array_equal(light[4:], tree[4:])
    exact = direct.estimate(problem, at, up, sizes, mode, 4096, 3, exact=True)[0]
    np.testing.assert_allclose(light[4:, 0], exact[4:, 0], rtol=0.05)
