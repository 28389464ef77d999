"""The light tree: its nodes bound their emitters, and sampling by it is unbiased at a cost per
receiver that does not grow with the number of emitters."""
import numpy as np
import pytest

import shapes
from radiosity_baker.core import Settings, bake, lighttree
from radiosity_baker.core.scene import LAMP_AREA, LAMP_POINT, LAMP_SPOT, LAMP_SUN, Lamps, SHAPE_ELLIPSE


def _leaves(count, seed=0, distant=0):
    rng = np.random.default_rng(seed)
    c = rng.random((count, 3)).astype(np.float32) * 10.0
    axis = rng.normal(size=(count, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    far = np.zeros(count, bool)
    far[:distant] = True
    return lighttree.Leaves(kind=np.ones(count, np.int32), index=np.arange(count, dtype=np.int32),
                            lo=c - 0.1, hi=c + 0.1, axis=axis.astype(np.float32),
                            theta_o=np.zeros(count, np.float32),
                            theta_e=np.full(count, np.pi / 2, np.float32),
                            two_sided=rng.random(count) < 0.5, power=rng.random(count).astype(np.float32),
                            distant=far)


@pytest.mark.parametrize("count, distant", [(1, 0), (7, 3), (1000, 0), (5000, 20)])
def test_nodes_bound_their_emitters_and_buckets_partition_them(count, distant):
    leaves = _leaves(count, distant=distant)
    t = lighttree.build(leaves)
    bucket = t.left < 0
    assert (t.count[bucket] <= lighttree.BUCKET).all() and t.depth < lighttree.MAX_DEPTH
    assert (t.left >= 0).sum() == (t.right >= 0).sum() == (~bucket).sum()
    covered = np.zeros(count, int)
    for first, n in zip(t.first[bucket], t.count[bucket]):
        covered[t.order[first:first + n]] += 1
    assert (covered == 1).all()
    inner = ~bucket
    assert (t.count[t.left[inner]] + t.count[t.right[inner]] == t.count[inner]).all()
    assert (t.first[t.left[inner]] == t.first[inner]).all()
    assert t.count[t.root] == count
    assert np.isclose(t.power[t.root], leaves.power.sum(), rtol=1e-5)
    for node in np.flatnonzero(~t.distant):
        leaf = t.order[t.first[node]:t.first[node] + t.count[node]]
        assert (t.lo[node] <= leaves.lo[leaf]).all() and (t.hi[node] >= leaves.hi[leaf]).all()
        cos = leaves.axis[leaf] @ t.axis[node]
        cos = np.where(leaves.two_sided[leaf], np.abs(cos), cos)
        assert (np.arccos(np.clip(cos, -1, 1)) <= t.theta_o[node] + 1e-4).all()
    # distant lamps sit beside the local tree, under the root
    assert t.distant.any() == (distant > 0)
    if distant and count > distant:
        assert t.distant[t.right[t.root]] and not t.distant[t.left[t.root]]


def _panel(quads=32):
    """A wavy emissive panel of 2·quads² triangles facing down at 1.2 m over a 3 m floor with an
    occluder between them."""
    fp, fn, ft = shapes.grid(3.0, 16)
    op, on, ot = shapes.grid(0.4, 1, z=0.6, flip=True)
    sp, sn, st = shapes.grid(0.8, quads, z=1.2, flip=True)
    sp[:, 2] += 0.05 * np.sin(sp[:, 0] * 20)
    parts = [(fp, fn, ft, (0.5,) * 3, (0,) * 3), (op, on, ot, (0.5,) * 3, (0,) * 3),
             (sp, sn, st, (0,) * 3, (5.0, 3.0, 1.0))]
    return shapes.scene(parts), len(fp)


def _lamps():
    """One lamp of each kind, and a second spot without radius (its cone alone picks it)."""
    kinds = [LAMP_POINT, LAMP_SPOT, LAMP_SPOT, LAMP_SUN, LAMP_AREA, LAMP_AREA]
    pos = [(0.8, 0.3, 1.5), (-0.6, 0.2, 2.0), (0.2, -0.7, 1.6), (0, 0, 5), (0.3, 0.6, 1.4), (-0.8, -0.5, 1.3)]
    direction = [(0, 0, -1), (0.3, 0, -1), (0, 0.2, -1), (0.3, 0.2, -1), (0, -0.2, -1), (0.2, 0, -1)]
    size = [(0.05, 0), (0.1, 0), (0.0, 0), (0.05, 0), (0.4, 0.2), (0.3, 0.3)]
    shape = [0, 0, 0, 0, 0, SHAPE_ELLIPSE]
    power = [(50, 40, 30), (80, 80, 60), (60, 70, 80), (2, 2, 2), (40, 40, 40), (30, 50, 30)]
    d = np.asarray(direction, np.float32)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    u = np.cross(d, [0, 1, 0])
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    return Lamps(kind=np.asarray(kinds, np.int32), position=np.asarray(pos, np.float32), direction=d,
                 axis_u=u.astype(np.float32), axis_v=np.cross(d, u).astype(np.float32),
                 size=np.asarray(size, np.float32), shape=np.asarray(shape, np.int32),
                 power=np.asarray(power, np.float32),
                 spot_size=np.full(6, np.radians(70.0), np.float32),
                 spot_blend=np.full(6, 0.2, np.float32), names=[f"L{k}" for k in range(6)])


def _relative_rmse(a, b):
    return float(np.sqrt(((a - b) ** 2).sum(axis=1).mean()) / np.linalg.norm(b, axis=1).mean())


@pytest.mark.parametrize("with_lamps", [False, True])
def test_sampling_by_the_tree_is_unbiased_over_thousands_of_emitters(with_lamps):
    """Averaged over seeds, the tree's estimate converges to the same light as weighing every
    emitter exactly (2048 emissive triangles; with lamps of every kind besides)."""
    sc, floor = _panel()
    if with_lamps:
        sc.lamps = _lamps()

    def run(selection, samples, seed):
        s = Settings(method="direct", light_samples=samples, light_selection=selection, seed=seed,
                     device="cpu")
        return bake(sc, s).direct[:floor].astype(np.float64)

    truth = run("exact", 512, 99)
    seeds = 12
    mean = sum(run("tree", 32, seed) for seed in range(seeds)) / seeds
    single = _relative_rmse(run("tree", 32, 100), truth)
    averaged = _relative_rmse(mean, truth)
    bias = abs(mean.sum() / truth.sum() - 1)
    print(f"\ntree, 32 samples: relative RMSE one seed {single:.4f}, mean of {seeds} {averaged:.4f}, "
          f"bias {bias:.4f}")
    assert bias < 0.005
    # the mean's error falls as 1/√seeds (what is left of the truth's own noise is far smaller)
    assert averaged < 1.6 * single / np.sqrt(seeds)


def test_rays_per_receiver_do_not_grow_with_the_number_of_emitters():
    rng = np.random.default_rng(5)
    fp, fn, ft = shapes.grid(4.0, 10)
    rays = {}
    for count in (1, 100, 10000):
        centre = rng.random((count, 3)) * (3.0, 3.0, 1.0) + (-1.5, -1.5, 1.0)
        tri = (centre[:, None, :] + rng.normal(scale=0.02, size=(count, 3, 3))).astype(np.float32)
        parts = [(fp, fn, ft, (0.5,) * 3, (0,) * 3),
                 (tri.reshape(-1, 3), np.tile([0, 0, -1.0], (3 * count, 1)).astype(np.float32),
                  np.arange(3 * count, dtype=np.int32).reshape(-1, 3), (0,) * 3, (1, 1, 1))]
        r = bake(shapes.scene(parts), Settings(method="direct", light_samples=16, light_selection="tree"))
        rays[count] = r.counts["rays"] / r.counts["elements"]
    print(f"\nshadow rays per receiver: {rays}")
    assert max(rays.values()) <= 16
