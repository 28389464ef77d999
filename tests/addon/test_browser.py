"""The three.js example (examples/threejs) shows the Cornell box's exported GLB as Blender shows
the same bake: headless Chromium's screenshot against a Cycles render of albedo × the baked
lightmap through the same camera, mean colour per object; the page without MOZ_lightmap must fail.

Chromium is driven by its own command line (examples/threejs/headless.py: the page draws once,
after the GLB has loaded, on a magenta page, so a page that did not finish fails the comparison);
needs Debian's ``chromium`` and ``npm ci`` in examples/threejs (README's
set-up does both where it runs as root). Without them the test skips, or fails where
RB_REQUIRE_BROWSER=1 (CI).
"""
import os
from pathlib import Path

import bpy
import headless  # examples/threejs (tests/conftest.py puts it on the path)
import numpy as np
import pytest

from radiosity_baker.addon import cli
from radiosity_baker.core.lightmap import files

CORNELL = Path(__file__).resolve().parents[2] / "sample_blends" / "cornell_box.blend"
SIZE = 192
# Largest difference of an object's mean sRGB colour (0–1) between the page and Blender.
TOLERANCE = 0.03


def _require_browser() -> None:
    missing = headless.missing()
    if missing:
        message = "the browser test needs " + " and ".join(missing)
        if os.environ.get("RB_REQUIRE_BROWSER") == "1":
            pytest.fail(message)
        pytest.skip(message)


def screenshot(site: Path, tmp_path: Path, query: str) -> np.ndarray:
    """float32[SIZE,SIZE,3] sRGB (0–1) of the page served from ``site``."""
    shot = headless.screenshot(site, tmp_path / "shot.png", SIZE, query)
    return files.read_exr(shot)[::-1][:SIZE, :SIZE, :3]  # top row first, canvas at the top left


def blender_view(saved: Path, tmp_path: Path) -> tuple[np.ndarray, np.ndarray, list]:
    """(float32[SIZE,SIZE,3] sRGB of a Cycles render of emission + albedo × baked lightmap
    through the file's camera, int[SIZE,SIZE] object index per pixel (-1: none), object names)."""
    bpy.ops.wm.open_mainfile(filepath=str(saved))
    scene = bpy.context.scene
    image = next(im for im in bpy.data.images if im.get("radiosity_baker_lightmap"))
    names = sorted(ob.name for ob in scene.objects if ob.type == "MESH")
    for mat in bpy.data.materials:
        nodes, links = mat.node_tree.nodes, mat.node_tree.links
        bsdf = next(n for n in nodes if n.type == "BSDF_PRINCIPLED")
        base = bsdf.inputs["Base Color"].default_value[:]
        glow = [c * bsdf.inputs["Emission Strength"].default_value
                for c in bsdf.inputs["Emission Color"].default_value[:3]]
        nodes.clear()
        uv, tex = nodes.new("ShaderNodeUVMap"), nodes.new("ShaderNodeTexImage")
        uv.uv_map, tex.image, tex.interpolation = "Lightmap", image, "Linear"
        mix = nodes.new("ShaderNodeMix")
        mix.data_type, mix.blend_type = "RGBA", "MULTIPLY"
        mix.inputs["Factor"].default_value = 1.0
        mix.inputs[6].default_value = base
        add = nodes.new("ShaderNodeVectorMath")
        add.operation, add.inputs[1].default_value = "ADD", glow
        emit, out = nodes.new("ShaderNodeEmission"), nodes.new("ShaderNodeOutputMaterial")
        links.new(uv.outputs["UV"], tex.inputs["Vector"])
        links.new(tex.outputs["Color"], mix.inputs[7])
        links.new(mix.outputs[2], add.inputs[0])
        links.new(add.outputs[0], emit.inputs["Color"])
        links.new(emit.outputs[0], out.inputs["Surface"])
    scene.render.engine = "CYCLES"
    scene.cycles.samples, scene.cycles.use_denoising, scene.cycles.max_bounces = 16, False, 0
    scene.render.resolution_x = scene.render.resolution_y = SIZE
    scene.render.resolution_percentage = 100
    scene.view_settings.view_transform, scene.view_settings.look = "Standard", "None"
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.filepath = str(tmp_path / "blender.exr")
    bpy.ops.render.render(write_still=True)
    linear = files.read_exr(tmp_path / "blender.exr")[::-1][..., :3]
    srgb = np.where(linear <= 0.0031308, 12.92 * linear,
                    1.055 * np.power(np.clip(linear, 0, None), 1 / 2.4) - 0.055)
    # object index: each object drawn in its own flat emission (red = (i + 1)/64), one sample
    for i, name in enumerate(names):
        mat = bpy.data.materials.new(f"index {i}")
        bsdf = mat.node_tree.nodes["Principled BSDF"]
        bsdf.inputs["Base Color"].default_value = (0, 0, 0, 1)
        bsdf.inputs["Emission Color"].default_value = ((i + 1) / 64, 0, 0, 1)
        bsdf.inputs["Emission Strength"].default_value = 1.0
        ob = scene.objects[name]
        for slot in ob.material_slots:
            slot.link, slot.material = "OBJECT", mat
    scene.cycles.samples, scene.cycles.filter_width = 1, 0.01
    scene.render.filepath = str(tmp_path / "index.exr")
    bpy.ops.render.render(write_still=True)
    index = np.rint(files.read_exr(tmp_path / "index.exr")[::-1][..., 0] * 64).astype(int)
    return np.clip(srgb, 0, 1), index - 1, names


def object_means(rgb: np.ndarray, index: np.ndarray, names: list) -> dict:
    """{object: mean colour} over each object's pixels, two pixels in from its outline."""
    means = {}
    for i, name in enumerate(names):
        mask = index == i
        for _ in range(2):  # erode: edges are where the two renderers' rasterisation differs
            mask = mask & np.roll(mask, 1, 0) & np.roll(mask, -1, 0) & np.roll(mask, 1, 1) & np.roll(mask, -1, 1)
        if mask.sum() >= 20:
            means[name] = rgb[mask].mean(axis=0)
    return means


@pytest.mark.parametrize("encoding", ["rgbm", "hdr", "half"])  # a PNG texture; float pages in
def test_threejs_page_shows_the_cornell_lightmap_as_blender_does(empty_scene, tmp_path, encoding):
    _require_browser()  # buffer views (extras.float_image): HDRLoader, EXRLoader
    site = headless.make_site(tmp_path / "site")
    saved, glb = tmp_path / "box.blend", site / "cornell_box.glb"
    assert cli.main(["bake", str(CORNELL), "--method", "bunnell", "--samples", "4", "--target",
                     "lightmap", "--texel-density", "8", "--output", str(tmp_path / "maps"),
                     "--lightmap-format", encoding, "--gltf", str(glb), "--save", str(saved)]) == 0
    page = screenshot(site, tmp_path, "")
    stripped = screenshot(site, tmp_path, "&strip=1")
    reference, index, names = blender_view(saved, tmp_path)
    want = object_means(reference, index, names)
    got, control = object_means(page, index, names), object_means(stripped, index, names)
    diffs = {n: float(np.abs(got[n] - want[n]).max()) for n in want}
    print(f"\npage vs Blender, largest channel difference of each object's mean sRGB: "
          f"{ {n: round(d, 4) for n, d in diffs.items()} }")
    assert len(want) >= 5 and max(diffs.values()) <= TOLERANCE
    assert max(float(np.abs(control[n] - want[n]).max()) for n in want) > 5 * TOLERANCE
