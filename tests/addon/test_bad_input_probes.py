"""A flat or zero-size Light Probe Volume is refused before baking, naming it, and nothing is
written: no Probes.json, no ``RB Probes``."""
import math

import bpy
import pytest

from radiosity_baker.addon import probes

from scenes import fast_settings
from test_reliability import FAST, blend, fails, save  # noqa: F401  (blend: the fixture)

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
