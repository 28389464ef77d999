"""The three.js example (examples/threejs) shows the Cornell box's exported GLB as Blender shows
the same bake: headless Chromium's screenshot against a Cycles render of albedo × the baked
lightmap through the same camera, mean colour per object; the page without MOZ_lightmap must fail.

Chromium is driven by its own command line (``--screenshot`` after ``--virtual-time-budget``:
the page draws once, after the GLB has loaded, on a magenta page, so a page that did not finish
fails the comparison); needs Debian's ``chromium`` and ``npm ci`` in examples/threejs (README's
set-up does both where it runs as root). Without them the test skips, or fails where
RB_REQUIRE_BROWSER=1 (CI).
"""
import functools
import http.server
import os
import shutil
import subprocess
import threading
from pathlib import Path

import bpy
import numpy as np
import pytest

from radiosity_baker.addon import cli
from radiosity_baker.core.lightmap import files

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "examples" / "threejs"
CORNELL = ROOT / "sample_blends" / "cornell_box.blend"
SIZE = 192
# Largest difference of an object's mean sRGB colour (0–1) between the page and Blender.
TOLERANCE = 0.03


def _browser() -> str:
    missing = []
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        missing.append("Debian's chromium (apt-get install chromium)")
    if not (EXAMPLE / "node_modules" / "three").is_dir():
        missing.append("three.js (cd examples/threejs && npm ci)")
    if missing:
        message = "the browser test needs " + " and ".join(missing)
        if os.environ.get("RB_REQUIRE_BROWSER") == "1":
            pytest.fail(message)
        pytest.skip(message)
    return chromium


def screenshot(chromium: str, site: Path, tmp_path: Path, query: str) -> np.ndarray:
    """float32[SIZE,SIZE,3] sRGB (0–1) of the page served from ``site`` on 127.0.0.1."""
    handler = functools.partial(http.server.SimpleHTTPRequestHandler, directory=str(site))
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    shot = tmp_path / "shot.png"
    try:
        subprocess.run([chromium, "--headless=new", "--no-sandbox", "--use-angle=swiftshader",
                        "--enable-unsafe-swiftshader", f"--screenshot={shot}",
                        f"--window-size={SIZE + 64},{SIZE + 64}", "--virtual-time-budget=20000",
                        f"http://127.0.0.1:{server.server_address[1]}/index.html?size={SIZE}{query}"],
                       check=True, timeout=60, capture_output=True, cwd=tmp_path)
    finally:
        server.shutdown()
        server.server_close()
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


def test_threejs_page_shows_the_cornell_lightmap_as_blender_does(empty_scene, tmp_path):
    chromium = _browser()
    saved, glb = tmp_path / "box.blend", tmp_path / "site" / "cornell_box.glb"
    site = glb.parent
    site.mkdir()
    for name in ("index.html", "main.js", "moz_lightmap.js", "node_modules"):
        (site / name).symlink_to(EXAMPLE / name)
    assert cli.main(["bake", str(CORNELL), "--method", "bunnell", "--samples", "4", "--target",
                     "lightmap", "--texel-density", "8", "--output", str(tmp_path / "maps"),
                     "--lightmap-format", "rgbm", "--gltf", str(glb), "--save", str(saved)]) == 0
    page = screenshot(chromium, site, tmp_path, "")
    stripped = screenshot(chromium, site, tmp_path, "&strip=1")
    reference, index, names = blender_view(saved, tmp_path)
    want = object_means(reference, index, names)
    got, control = object_means(page, index, names), object_means(stripped, index, names)
    diffs = {n: float(np.abs(got[n] - want[n]).max()) for n in want}
    print(f"\npage vs Blender, largest channel difference of each object's mean sRGB: "
          f"{ {n: round(d, 4) for n, d in diffs.items()} }")
    assert len(want) >= 5 and max(diffs.values()) <= TOLERANCE
    assert max(float(np.abs(control[n] - want[n]).max()) for n in want) > 5 * TOLERANCE
