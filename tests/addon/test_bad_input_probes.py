"""Probe grids that cannot be baked are refused before baking, and nothing is written (no
Probes.json, no ``RB Probes``): a flat or zero-size Light Probe Volume, naming it; a grid whose
probes would not fit in the bake's memory, saying what fits."""
import math
import re

import bpy
import pytest

from radiosity_baker.addon import probes
from radiosity_baker.core.targets import probes as core_probes

from scenes import fast_settings
from test_reliability import FAST, blend, fails, save  # noqa: F401  (blend: the fixture)

BUDGET = 8 << 30  # the bake's memory budget in these tests, whatever this machine has


def _volume(scene, scale=(3.0, 3.0, 1.4), resolution=(4, 4, 4), rotation=(0.0, 0.0, 0.0)):
    volume = bpy.data.objects.new("Volume", bpy.data.lightprobes.new("Volume", 'VOLUME'))
    volume.location, volume.scale, volume.rotation_euler = (0.0, 0.0, 1.5), scale, rotation
    volume.data.resolution_x, volume.data.resolution_y, volume.data.resolution_z = resolution
    scene.collection.objects.link(volume)
    return volume


def _no_probes(maps) -> None:
    assert not (maps / "Probes.json").exists()
    assert not any(ob.get(probes.PROBES_TAG) or ob.name == probes.NAME for ob in bpy.data.objects)


@pytest.mark.parametrize("scale, rotation", [((3.0, 3.0, 0.0), (0.0, 0.0, 0.0)),
                                             ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0)),
                                             ((3.0, 3.0, 0.0), (math.pi / 4, 0.0, 0.0))],
                         ids=["flat", "zero-size", "flat and turned"])
def test_a_flat_or_zero_size_light_probe_volume_is_refused_naming_it(blend, tmp_path, capsys,
                                                                     scale, rotation):
    _volume(bpy.context.scene, scale=scale, rotation=rotation)
    path = save(tmp_path / "volume.blend")
    fails(capsys, tmp_path, path, 1, ["Light Probe Volume 'Volume'", "no volume"],
          *FAST, "--probes", "grid", "--output", tmp_path / "maps", started=False)
    _no_probes(tmp_path / "maps")


def test_the_operator_refuses_a_flat_light_probe_volume_and_makes_no_probe_object(blend, tmp_path):
    _volume(bpy.context.scene, scale=(3.0, 3.0, 0.0))
    fast_settings(bpy.context.scene, probes="grid", output=str(tmp_path / "maps"))
    with pytest.raises(RuntimeError, match="Volume"):
        bpy.ops.object.radiosity_bake()
    _no_probes(tmp_path / "maps")


@pytest.fixture
def budget(monkeypatch):
    monkeypatch.setattr(core_probes, "memory_budget", lambda: BUDGET)


def test_a_probe_spacing_too_dense_for_memory_is_refused_saying_which_spacing_fits(
        blend, tmp_path, capsys, budget):
    path = save(tmp_path / "dense.blend")
    run = fails(capsys, tmp_path, path, 2, ["light probes: a grid of", "probes would take about",
                                            "a --probe-spacing of"],
                *FAST, "--probes", "grid", "--probe-spacing", "0.01", "--output", tmp_path / "maps",
                started=False)
    _no_probes(tmp_path / "maps")
    fit = float(re.search(r"a --probe-spacing of ([0-9.e+-]+) m fits", run.message).group(1))
    scene = bpy.context.scene  # the grid covers the scene's meshes: check the suggestion fits
    lo, hi = _mesh_bounds(scene)

    def size(spacing):  # bytes of the grid at ``spacing``
        return int(core_probes.grid_counts(lo, hi, spacing).prod()) * core_probes.BYTES_PER_PROBE

    assert size(fit) <= BUDGET < size(0.01)
    assert size(fit * 0.98) > BUDGET  # the finest that fits, to the three digits given


def test_a_light_probe_volume_of_too_high_a_resolution_is_refused_saying_which_fits(
        blend, tmp_path, capsys, budget):
    _volume(bpy.context.scene, resolution=(256, 256, 256))
    path = save(tmp_path / "volume.blend")
    run = fails(capsys, tmp_path, path, 2, ["256×256×256 = 16,777,216 probes", "a resolution of at most"],
                *FAST, "--probes", "grid", "--output", tmp_path / "maps", started=False)
    _no_probes(tmp_path / "maps")
    fit = [int(c) for c in re.search(r"at most (\d+)×(\d+)×(\d+) fits", run.message).groups()]
    assert math.prod(fit) * core_probes.BYTES_PER_PROBE <= BUDGET
    assert math.prod(c + 1 for c in fit) * core_probes.BYTES_PER_PROBE > BUDGET  # the most that fits


def _mesh_bounds(scene):
    """(lo, hi) float64[3]: the world bounds of ``scene``'s mesh objects' vertices."""
    import numpy as np

    points = np.concatenate([np.array([ob.matrix_world @ v.co for v in ob.data.vertices])
                             for ob in scene.objects if ob.type == 'MESH'])
    return points.min(axis=0), points.max(axis=0)
