"""The command line, in-process (``main``) and as ``python -m radiosity_baker``, end to end."""
import json
import os
import subprocess
import sys
from pathlib import Path

import bpy
import numpy as np
import pytest

from radiosity_baker.addon import cli
from radiosity_baker.addon.preview import render_preview
from radiosity_baker.core.lightmap import files

from scenes import GROUND, LIT, SHADOW, lit_ground, snapshot, value_at, vertex_colors

FAST = ["--method", "direct", "--samples", "4"]
LAMP_SCENE = Path(__file__).resolve().parents[2] / "sample_blends" / "lamp_scene.blend"


@pytest.fixture
def lit_blend(empty_scene, tmp_path) -> Path:
    """The lit ground scene saved as tmp/in.blend."""
    lit_ground(empty_scene)
    path = tmp_path / "in.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    return path


def one_error_line(capsys) -> str:
    err = [line for line in capsys.readouterr().err.splitlines()
           if line.startswith("radiosity_baker: error:")]
    assert len(err) == 1, err
    return err[0]


def test_bake_saves_attribute_and_report_and_leaves_input_alone(lit_blend, tmp_path, capsys):
    original = lit_blend.read_bytes()
    out, rep = tmp_path / "out.blend", tmp_path / "report.json"
    assert cli.main(["bake", str(lit_blend), *FAST, "--attribute", "GI", "--save", str(out),
                     "--report", str(rep)]) == 0
    assert "radiosity_baker: direct" in capsys.readouterr().out  # progress lines
    assert lit_blend.read_bytes() == original

    report = json.loads(rep.read_text())
    for key in ("blender_version", "radiosity_baker_version", "python_version", "numpy_version",
                "warp_version", "device", "settings", "seconds", "counts", "peak_memory_bytes",
                "warnings", "outputs"):
        assert key in report, key
    assert report["settings"]["method"] == "direct" and report["settings"]["attribute"] == "GI"
    assert {"extract", "direct", "write", "total"} <= report["seconds"].keys()
    assert report["counts"]["elements"] > 0 and report["peak_memory_bytes"] > 0
    assert report["outputs"]["save"] == str(out.resolve())

    bpy.ops.wm.open_mainfile(filepath=str(out))
    mesh = bpy.data.objects[GROUND].data
    assert (mesh.attributes["GI"].domain, mesh.attributes["GI"].data_type) == ('POINT', 'FLOAT_COLOR')
    assert value_at(mesh, "GI", SHADOW).mean() < 0.05 * value_at(mesh, "GI", LIT).mean()


def test_objects_option_writes_only_named_objects(lit_blend, tmp_path):
    out = tmp_path / "out.blend"
    assert cli.main(["bake", str(lit_blend), *FAST, "--objects", "Occluder", "--save", str(out)]) == 0
    bpy.ops.wm.open_mainfile(filepath=str(out))
    assert "Lighting" in bpy.data.objects["Occluder"].data.attributes
    assert "Lighting" not in bpy.data.objects[GROUND].data.attributes


def test_unknown_object_is_a_one_line_error(lit_blend, capsys):
    assert cli.main(["bake", str(lit_blend), *FAST, "--objects", "Nope"]) == 1
    assert "Nope" in one_error_line(capsys)


def test_without_save_nothing_is_written(lit_blend):
    before = sorted(p.name for p in lit_blend.parent.iterdir())
    original = lit_blend.read_bytes()
    assert cli.main(["bake", str(lit_blend), *FAST]) == 0
    assert sorted(p.name for p in lit_blend.parent.iterdir()) == before
    assert lit_blend.read_bytes() == original


def test_save_may_name_the_input_explicitly(lit_blend):
    assert cli.main(["bake", str(lit_blend), *FAST, "--save", str(lit_blend)]) == 0
    bpy.ops.wm.open_mainfile(filepath=str(lit_blend))
    assert "Lighting" in bpy.data.objects[GROUND].data.attributes


def test_missing_blend_is_a_one_line_error(tmp_path, capsys):
    assert cli.main(["bake", str(tmp_path / "missing.blend")]) == 2
    assert "missing.blend" in one_error_line(capsys)


def test_unreadable_blend_is_a_one_line_error(tmp_path, capsys):
    path = tmp_path / "text.blend"
    path.write_text("not a blend file")
    assert cli.main(["bake", str(path)]) == 2
    assert "cannot open" in one_error_line(capsys)


@pytest.mark.parametrize("where", ["/proc/radiosity_baker/out.blend", "in.blend/out.blend"])
def test_unwritable_save_path_fails_before_baking(lit_blend, where, capsys):
    target = lit_blend.parent / where  # an absolute `where` replaces the folder
    stat = lit_blend.stat()
    assert cli.main(["bake", str(lit_blend), *FAST, "--save", str(target)]) == 2
    assert str(target) in one_error_line(capsys)
    assert "radiosity_baker: direct" not in capsys.readouterr().out  # no bake started
    assert lit_blend.stat().st_mtime_ns == stat.st_mtime_ns and not target.exists()


def test_empty_scene_is_a_clear_error(empty_scene, tmp_path, capsys):
    path = tmp_path / "empty.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    assert cli.main(["bake", str(path)]) == 1
    assert "nothing to bake" in one_error_line(capsys)


@pytest.mark.parametrize("argv", [["bake"], ["bake", "x.blend", "--method", "magic"],
                                  ["bake", "x.blend", "--bounces", "0"], ["frobnicate"]])
def test_bad_arguments_are_one_line_errors(argv, capsys):
    assert cli.main(argv) == 2
    one_error_line(capsys)


def test_missing_output_folders_are_created(lit_blend, tmp_path):
    out = tmp_path / "new" / "folder"
    assert cli.main(["bake", str(lit_blend), "--method", "direct", "--save", str(out / "baked.blend"),
                     "--report", str(out / "report.json")]) == 0
    assert (out / "baked.blend").is_file() and (out / "report.json").is_file()


def test_build_extension_subcommand_reaches_the_builder(capsys):
    assert cli.main(["build-extension", "--help"]) == 0
    assert "--fetch-wheels" in capsys.readouterr().out


def test_python_dash_m_runs_the_same_command(tmp_path):
    env = {k: v for k, v in os.environ.items() if k != "BLENDER_USER_RESOURCES"}
    proc = subprocess.run([sys.executable, "-m", "radiosity_baker", "bake",
                           str(tmp_path / "missing.blend")], capture_output=True, text=True,
                          env=env, timeout=120)
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines()[-1].startswith("radiosity_baker: error: no such")


def test_bake_names_its_device_once_without_warps_driver_warning(lit_blend):
    env = {k: v for k, v in os.environ.items() if k != "BLENDER_USER_RESOURCES"}
    proc = subprocess.run([sys.executable, "-m", "radiosity_baker", "bake", str(lit_blend), *FAST],
                          capture_output=True, text=True, env=env, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "Could not find or load the NVIDIA CUDA driver" not in proc.stdout + proc.stderr
    said = [line for line in proc.stdout.splitlines() if line.startswith("radiosity_baker: baking on ")]
    assert len(said) == 1, proc.stdout
    assert said[0].startswith(("radiosity_baker: baking on the CPU (", "radiosity_baker: baking on the GPU "))


def test_preview_renders_attribute_and_restores_scene(lit_blend, tmp_path):
    assert cli.main(["bake", str(lit_blend), *FAST]) == 0
    scene = bpy.context.scene
    before = snapshot()
    engine, transform = scene.render.engine, scene.view_settings.view_transform
    png = tmp_path / "preview.png"
    render_preview(scene, "Lighting", png, size=48, samples=2)
    assert snapshot() == before and scene.camera is None
    assert (scene.render.engine, scene.view_settings.view_transform) == (engine, transform)
    image = bpy.data.images.load(str(png))
    try:
        assert tuple(image.size) == (48, 48)
        px = np.empty(48 * 48 * 4, np.float32)
        image.pixels.foreach_get(px)
        rgb = px.reshape(48, 48, 4)[..., :3]
        assert rgb.max() > 0.9 and rgb.min() < 0.1  # clipped under the lamp, black shadow/sky
    finally:
        bpy.data.images.remove(image)


def test_preview_option_writes_png_and_keeps_it_out_of_saved_file(lit_blend, tmp_path):
    out, png = tmp_path / "out.blend", tmp_path / "preview.png"
    assert cli.main(["bake", str(lit_blend), *FAST, "--save", str(out), "--preview", str(png)]) == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    bpy.ops.wm.open_mainfile(filepath=str(out))
    assert not bpy.data.materials and not bpy.data.cameras


def _baked(out: Path, maps: Path, attribute: str):
    """Every mesh's baked attribute (float32[ΣV,3]) in the saved ``out`` and the lightmap EXR's
    covered texels (float32[N,3])."""
    bpy.ops.wm.open_mainfile(filepath=str(out))
    meshes = sorted({ob.data for ob in bpy.data.objects if ob.type == "MESH"}, key=lambda m: m.name)
    per_vertex = np.concatenate([vertex_colors(m, attribute)[:, :3] for m in meshes])
    exr = files.read_exr(maps / "Lightmap.exr")
    return per_vertex, exr[exr[..., 3] > 0][:, :3]


@pytest.mark.parametrize("method, content", [("hierarchical", "lighting"), ("bunnell", "lighting"),
                                             ("implicit", "lighting"), ("antiradiance", "lighting"),
                                             ("direct", "ao")])
def test_light_methods_and_ao_bake_into_color_attributes_and_lightmaps(tmp_path, method, content):
    """On the lamp scene: hierarchical radiosity's, Bunnell's, implicit visibility's and
    antiradiance's indirect light adds to the same direct light (same seed) in both targets; AO
    lies in [0, 1], with occlusion where objects stand on the floor."""
    def run(name, m):
        out, maps = tmp_path / f"{name}.blend", tmp_path / name
        assert cli.main(["bake", str(LAMP_SCENE), "--method", m, "--content", content, "--samples", "4",
                         "--target", "both", "--output", str(maps), "--texel-density", "8",
                         "--save", str(out)]) == 0
        return _baked(out, maps, "Lighting")

    vertices, texels = run("ours", method)
    assert np.isfinite(vertices).all() and np.isfinite(texels).all() and len(texels) > 1000
    if content == "ao":
        for values in (vertices, texels):
            assert values.min() >= 0.0 and values.max() <= 1.0
            assert np.allclose(values[:, 0], values[:, 2])
            assert values.min() < 0.5 < values.mean()  # open floor, occluded contact
        return
    direct_vertices, direct_texels = run("direct", "direct")
    for ours, direct in ((vertices, direct_vertices), (texels, direct_texels)):
        assert (ours >= direct - 1e-4).all()
        assert ours.sum() > 1.02 * direct.sum()
