"""A glTF export that cannot carry the lightmaps is an error, never a GLB without them and exit 0:
an animation's lightmaps (image sequences) are refused before baking, a failing exporter hook
(which Blender's exporter only logs) fails the export; a hot spot clipped by an 8-bit encoding is
a warning giving its share."""
import bpy
import numpy as np
import pytest

from radiosity_baker.addon import cli, gltf
from radiosity_baker.core.lightmap import encodings, files

from scenes import grid, lit_ground
from test_gltf import FAST

LIGHTMAP = ["--method", "direct", "--samples", "4", "--target", "lightmap", "--texel-density", "6"]


@pytest.fixture
def ground_blend(empty_scene, tmp_path):
    """The lit ground with a material, saved as tmp/in.blend."""
    lit_ground(empty_scene)
    mat = bpy.data.materials.new("Grey")
    for ob in empty_scene.objects:
        if ob.type == "MESH":
            ob.data.materials.append(mat)
    blend = tmp_path / "in.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    return blend


@pytest.mark.parametrize("target", ["lightmap", "both"])
def test_frames_with_lightmaps_and_gltf_is_refused_before_baking(ground_blend, tmp_path, capfd,
                                                                 target):
    maps, glb = tmp_path / "maps", tmp_path / "out.glb"
    assert cli.main(["bake", str(ground_blend), *FAST[:-4], "--target", target, "--frames",
                     "1:2", "--output", str(maps), "--gltf", str(glb)]) == 2
    err = capfd.readouterr().err
    assert f"error: --gltf with --frames and --target {target}" in err and "image sequence" in err
    assert "baking on" not in err and not maps.exists() and not glb.exists()


def test_exporting_an_animation_s_lightmaps_is_an_error_naming_the_image_sequence(
        ground_blend, tmp_path, capfd):
    saved, glb = tmp_path / "anim.blend", tmp_path / "anim.glb"
    assert cli.main(["bake", str(ground_blend), *LIGHTMAP, "--frames", "1:2", "--output",
                     str(tmp_path / "maps"), "--save", str(saved)]) == 0
    capfd.readouterr()
    assert cli.main(["export", str(saved), str(glb)]) == 2
    err = capfd.readouterr().err
    assert f"error: cannot write {glb}: Radiosity Baker lightmaps: lightmap Lightmap is an " \
           f"image sequence" in err
    assert not glb.exists()


def test_a_failing_export_hook_fails_the_export(ground_blend, tmp_path, capfd, monkeypatch):
    saved, glb = tmp_path / "baked.blend", tmp_path / "out.glb"
    assert cli.main(["bake", str(ground_blend), *LIGHTMAP, "--output", str(tmp_path / "maps"),
                     "--save", str(saved)]) == 0

    def broken(rgb, encoding):
        raise RuntimeError("boom")

    monkeypatch.setattr(gltf, "encode", broken)
    capfd.readouterr()
    assert cli.main(["export", str(saved), str(glb)]) == 2
    captured = capfd.readouterr()
    assert f"error: cannot write {glb}: Radiosity Baker lightmaps: RuntimeError: boom" in \
        captured.err and "Traceback" in captured.err  # a bug: its traceback on the console
    assert not glb.exists()
    # File › Export (the operator): an error report, which bpy.ops raises
    bpy.ops.wm.open_mainfile(filepath=str(saved))
    with gltf.found_by_gltf(), pytest.raises(RuntimeError, match="RuntimeError: boom"):
        bpy.ops.export_scene.gltf(filepath=str(glb), export_format="GLB")


def test_a_hot_spot_clipped_by_an_8bit_lightmap_is_a_warning_giving_its_share(
        empty_scene, tmp_path, capfd):
    """A 4 m floor under a 1000 W lamp 5 mm above it (lighting 1e6 under the lamp, ~0.03 over
    most of the floor): with the brightest texel as the range, 98 % of the texels decoded to 0."""
    grid(empty_scene, "Floor", 4.0, 9)
    light = bpy.data.lights.new("Lamp", "POINT")
    light.energy, light.shadow_soft_size = 1000.0, 0.0
    lamp = bpy.data.objects.new("Lamp", light)
    lamp.location = (0.0, 0.0, 0.005)
    empty_scene.collection.objects.link(lamp)
    blend, maps, glb = tmp_path / "hot.blend", tmp_path / "maps", tmp_path / "hot.glb"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    assert cli.main(["bake", str(blend), *LIGHTMAP[:-1], "32", "--output", str(maps),
                     "--lightmap-format", "rgbm", "--gltf", str(glb)]) == 0
    out, err = capfd.readouterr()
    page = files.read_exr(maps / "Lightmap.exr")[..., :3]
    decoded, meta = encodings.read(maps / "Lightmap.rgbm.png")
    m = page.max(axis=2)
    share = f"{100 * np.mean(m > meta['range']):.2g} %"
    assert m.max() > 1e5 and meta["range"] < 1e3
    assert (decoded.max(axis=2)[m > 0] > 0).all()
    assert f"warning: lightmap Lightmap.rgbm.png: {share} of its lit texels" in err
    assert f"lightmap Lightmap: {share} of its lit texels" in out + err  # the export's log
    assert "--lightmap-format hdr" in err


@pytest.mark.parametrize("extra, words", [
    ([], ["in.blend holds nothing baked to export", "no mesh has a lightmap from a bake"]),
    (["--no-lightmaps"], ["holds nothing baked to export", "no mesh has a lightmap from a bake"]),
    (["--color-attribute", "Lighting"], ["--color-attribute Lighting: no mesh of in.blend has a "
                                         "color attribute of that name"])],
    ids=["never baked", "never baked, lightmaps left out", "missing attribute"])
def test_exporting_what_the_file_does_not_hold_is_an_error_and_writes_no_glb(ground_blend, tmp_path,
                                                                             capfd, extra, words):
    """Before: exit 0 and a GLB without lightmaps or colours, silently."""
    glb = tmp_path / "out.glb"
    assert cli.main(["export", str(ground_blend), str(glb), *extra]) == 2
    err = capfd.readouterr().err
    for word in words:
        assert word in err, err
    assert not glb.exists()
