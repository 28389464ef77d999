"""Light probes: SH of the light arriving at points in space; probes inside geometry are invalid."""
import math

import numpy as np
import pytest

import shapes
from radiosity_baker.core import Settings, bake, targets
from radiosity_baker.core.errors import SettingsError
from radiosity_baker.core.scene import LAMP_POINT
from radiosity_baker.core.targets import probes as probes_mod
from radiosity_baker.core.targets.probes import grid_points


def test_the_grid_covers_the_box_with_cells_at_most_the_spacing_apart():
    points, shape, cell = grid_points(np.zeros(3), np.array([1.0, 2.0, 0.5]), 0.4)
    assert shape == (3, 5, 2) and len(points) == 30 and np.all(cell <= 0.4)
    np.testing.assert_allclose(points[0], cell / 2)
    np.testing.assert_allclose(points[1] - points[0], [cell[0], 0, 0], atol=1e-6)


def test_a_probe_sees_the_lamp_above_and_inside_a_box_is_invalid():
    p, n, t = shapes.grid(2.0, 6)
    parts = [(p, n, t, (0.5, 0.5, 0.5), (0,) * 3)]
    parts += [(*face, (0.5, 0.5, 0.5), (0,) * 3) for face in shapes.box(0.4, 2, centre=(0.6, 0.0, 0.3))]
    sc = shapes.scene(parts, shapes.lamp(LAMP_POINT, (0, 0, 1.5), power=(80.0,) * 3))
    grid = bake(sc, Settings(method="reference", device="cpu", light_samples=4),
                targets=[targets.make("probes", box=((-0.8, -0.2, 0.2), (0.8, 0.2, 0.4)), spacing=0.4)])["probes"]
    assert grid.shape == (4, 1, 1)
    assert list(grid.valid) == [True, True, True, False]  # the last lies inside the box
    k = 1
    d = np.array([0, 0, 1.5]) - grid.points[k]
    lamp = 80 / (4 * math.pi ** 2 * (d @ d)) * d[2] / np.linalg.norm(d)  # point lamp, facing up
    up, down = grid.lighting(np.array([[0, 0, 1.0], [0, 0, -1.0]]))[k, :, 0]
    print(f"facing the lamp: {up:.4f} (lamp alone {lamp:.4f}); facing the floor {down:.4f}")
    assert abs(up / lamp - 1) < 0.1 and 0 < down < up


def test_a_grid_over_a_2_km_scene_that_would_not_fit_in_memory_is_refused_before_allocating(monkeypatch):
    """The default 1 m spacing over a 2 km ground holds 4 million probes, 16 GB: refused before the
    grid is made (before, a MemoryError after the solve), with the spacing that fits."""
    monkeypatch.setattr(probes_mod, "memory_budget", lambda: 8 << 30)
    made = []
    monkeypatch.setattr(probes_mod, "grid_points", lambda *a: made.append(a))
    p, n, t = shapes.grid(2000.0, 4)
    box = shapes.box(1.0, 1, centre=(0.0, 0.0, 0.5))
    sc = shapes.scene([(p, n, t, (0.5,) * 3, (0,) * 3), *[(*f, (0.5,) * 3, (0,) * 3) for f in box]],
                      shapes.lamp(LAMP_POINT, (0, 0, 3.0), power=(80.0,) * 3))
    target = targets.make("probes")
    with pytest.raises(SettingsError, match=r"2000×2000×1 = 4,000,000 probes .* a --probe-spacing "
                                            r"of 1\.39 m fits"):
        target.check(sc, Settings())
    with pytest.raises(SettingsError, match="4,000,000 probes"):
        bake(sc, Settings(method="direct", device="cpu", light_samples=1), targets=[target])
    assert not made
    assert target.check(sc, Settings(probe_spacing=1.39)) * probes_mod.BYTES_PER_PROBE <= 8 << 30
