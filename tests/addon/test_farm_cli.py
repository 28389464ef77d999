"""Baking on a Dask farm from the command line: a lightmap's pages and an animation's frames as
tasks on a local cluster of two worker processes, equal to the same bake on this machine."""
import json

import bpy
import numpy as np
import pytest

from radiosity_baker.addon import cli
from radiosity_baker.core.lightmap import files

from scenes import GROUND, lit_ground, vertex_colors

pytest.importorskip("distributed", reason="the farm needs distributed: bash .ci/setup installs it")
FAST = ["--method", "direct", "--samples", "4"]
PAGES = ["--target", "lightmap", "--max-size", "32", "--texel-density", "5", "--layout", "per_object"]


@pytest.fixture
def lit_blend(empty_scene, tmp_path):
    lit_ground(empty_scene)
    lamp = bpy.data.objects["Lamp"]
    for frame, x in ((1, -1.0), (3, 1.0)):  # a lamp moving over the ground: frames differ
        lamp.location.x = x
        lamp.keyframe_insert("location", index=0, frame=frame)
    path = tmp_path / "in.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    return path


def test_a_lightmaps_pages_baked_on_a_local_cluster_equal_the_pages_baked_here(lit_blend, tmp_path):
    pages = {}
    for where, extra in (("here", []), ("farm", ["--scheduler", "local:2"])):
        report = tmp_path / f"{where}.json"
        assert cli.main(["bake", str(lit_blend), *FAST, *PAGES, "--output", str(tmp_path / where),
                         "--report", str(report), *extra]) == 0
        pages[where] = {p.name: files.read_exr(p) for p in sorted((tmp_path / where).glob("*.exr"))}
        counts = json.loads(report.read_text())["counts"]
    assert len(pages["here"]) >= 2 and pages["here"].keys() == pages["farm"].keys()
    for name, rgb in pages["here"].items():
        assert np.array_equal(rgb, pages["farm"][name]), name
    assert counts["farm"]["tasks"] == len(pages["farm"]) and counts["farm"]["retried"] == []


def test_an_animations_frames_baked_on_a_local_cluster_equal_the_frames_baked_here(lit_blend, tmp_path):
    values = {}
    for where, extra in (("here", []), ("farm", ["--scheduler", "local:2"])):
        out = tmp_path / f"{where}.blend"
        assert cli.main(["bake", str(lit_blend), *FAST, "--frames", "1:3", "--save", str(out),
                         *extra]) == 0
        bpy.ops.wm.open_mainfile(filepath=str(out))
        mesh = bpy.data.objects[GROUND].data
        values[where] = [vertex_colors(mesh, f"Lighting.{f:04d}") for f in (1, 2, 3)]
    assert not np.array_equal(values["here"][0], values["here"][2])  # the lamp moved
    for here, farm in zip(values["here"], values["farm"]):
        np.testing.assert_array_equal(here, farm)


def test_the_panels_bake_sends_the_pages_to_the_scheduler_it_names(lit_blend, tmp_path):
    bpy.ops.wm.open_mainfile(filepath=str(lit_blend))
    s = bpy.context.scene.radiosity_baker
    s.method, s.light_samples, s.target, s.layout = "direct", 4, "lightmap", "per_object"
    s.max_size, s.texel_density, s.output = 32, 5.0, str(tmp_path / "panel")
    s.scheduler = "local:2"
    assert bpy.ops.object.radiosity_bake(use_selected=False) == {"FINISHED"}
    baked = sorted(p.name for p in (tmp_path / "panel").glob("*.exr"))
    s.scheduler, s.output, s.reunwrap = "", str(tmp_path / "here"), True  # lay out afresh as the first did
    assert bpy.ops.object.radiosity_bake(use_selected=False) == {"FINISHED"}
    assert len(baked) == 2 and baked == sorted(p.name for p in (tmp_path / "here").glob("*.exr"))
    for name in baked:
        assert np.array_equal(files.read_exr(tmp_path / "panel" / name), files.read_exr(tmp_path / "here" / name))
