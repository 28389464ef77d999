"""Directional bins: a partition of the sphere into near-equal cells whose front half is the
element's front hemisphere; cones spread over the cells they overlap."""
import numpy as np
import pytest
import warp as wp

from radiosity_baker.core import device as device_mod
from radiosity_baker.core import directions


@wp.kernel
def _bins(dirs: wp.array(dtype=wp.vec3), normal: wp.vec3, size: int, out: wp.array(dtype=wp.int32),
          is_front: wp.array(dtype=wp.int32)):
    i = wp.tid()
    b = directions.bin_of(directions.frame_dir(normal, dirs[i]), size)
    out[i] = b
    is_front[i] = wp.where(directions.front(b, size), 1, 0)


@wp.kernel
def _cone(axis: wp.vec3, cos_half: float, out: wp.array(dtype=wp.vec3)):
    k = wp.tid()
    out[k] = directions.cone_sample(k, axis, cos_half)


@pytest.fixture(scope="module")
def dev():
    return device_mod.select("cpu")


def random_dirs(count, seed=1):
    d = np.random.default_rng(seed).normal(size=(count, 3))
    return (d / np.linalg.norm(d, axis=1, keepdims=True)).astype(np.float32)


@pytest.mark.parametrize("bins", [64, 256, 1024])
def test_bins_partition_the_sphere_into_equal_cells(bins):
    count = 400 * bins
    d = random_dirs(count, seed=bins)
    out = wp.zeros(count, dtype=wp.int32)
    front = wp.zeros(count, dtype=wp.int32)
    wp.launch(_bins, count, inputs=[wp.array(d, dtype=wp.vec3), wp.vec3(0.0, 0.0, 1.0),
                                    directions.side(bins), out, front])
    share = np.bincount(out.numpy(), minlength=bins) / count
    # each bin holds 1/bins of uniformly random directions, within the sampling noise (~5σ)
    assert np.abs(share * bins - 1.0).max() < 5.0 / np.sqrt(400)
    assert directions.solid_angle(bins) * bins == pytest.approx(4 * np.pi)


@pytest.mark.parametrize("bins", [64, 256, 1024])
def test_the_front_half_of_the_bins_is_the_front_hemisphere(dev, bins):
    normal = np.array([0.3, -0.5, 0.81], np.float32)
    normal /= np.linalg.norm(normal)
    d = random_dirs(20000)
    out = wp.zeros(len(d), dtype=wp.int32)
    front = wp.zeros(len(d), dtype=wp.int32)
    wp.launch(_bins, len(d), inputs=[wp.array(d, dtype=wp.vec3), wp.vec3(*normal), directions.side(bins), out, front])
    assert np.array_equal(front.numpy() == 1, d @ normal >= 0)
    assert len(np.unique(out.numpy())) == bins  # every bin gets directions


def test_a_cones_directions_lie_in_it_and_spread_evenly(dev):
    axis = np.array([0.0, 0.6, 0.8], np.float32)
    cos_half = directions_cos = float(np.cos(0.3))
    out = wp.zeros(directions.CONE_SAMPLES, dtype=wp.vec3)
    wp.launch(_cone, directions.CONE_SAMPLES, inputs=[wp.vec3(*axis), directions_cos, out])
    d = out.numpy()
    assert (d @ axis >= cos_half - 1e-5).all() and np.allclose(np.linalg.norm(d, axis=1), 1, atol=1e-5)
    mean = d.mean(axis=0)
    assert mean @ axis / np.linalg.norm(mean) > 0.999  # centred on the axis


def test_bin_counts_other_than_64_256_1024_are_refused():
    with pytest.raises(ValueError, match="64, 256, 1024"):
        directions.side(100)


def test_elements_under_a_surface_in_contact_are_hidden_and_no_others():
    """A 0.6 m plate 1 mm under a 2 m ceiling of 0.2 m cells, both facing down, over a floor: the
    ceiling's elements whose points lie over the plate (the 3 × 3 inside its rim) are hidden
    (``directions.visible`` 0: they show none of their light); the ceiling's others, the plate
    (the ceiling lies behind it) and the floor are not."""
    import shapes
    from radiosity_baker.core import Settings
    from radiosity_baker.core.problem import Problem
    from radiosity_baker.core.solvers.implicit import links_of

    parts = [(*shapes.grid(2.0, 10, z=2.0, flip=True), (0.5,) * 3, (0,) * 3),
             (*shapes.grid(0.6, 3, z=1.999, flip=True), (0.5,) * 3, (0,) * 3),
             (*shapes.grid(2.0, 10), (0.5,) * 3, (0,) * 3)]
    problem = Problem(shapes.scene(parts), Settings(method="antiradiance", device="cpu"))
    shown = directions.visible(problem, links_of(problem)).numpy()
    pos, nrm = problem.elements.position, problem.elements.normal
    ceiling = (pos[:, 2] > pos[:, 2].max() - 5e-4) & (nrm[:, 2] < 0)  # the scene may be moved
    over = ceiling & (np.abs(pos[:, :2]) < 0.25).all(axis=1)
    assert over.sum() == 9
    assert (shown[over] == 0).all()
    assert (shown[~over] == 1).all()
