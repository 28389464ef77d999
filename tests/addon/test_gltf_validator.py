"""Every GLB the export writes passes the Khronos glTF validator (npm ``gltf-validator``, run by
``tests/gltf_validator/validate.mjs``): each lightmap encoding and each directional layout, with no
error and no warning. Float pages (hdr, half, float) and directional EXRs are no texture — glTF's
core allows only PNG and JPEG as a texture's image (TEXTURE_INVALID_IMAGE_MIME_TYPE) — but buffer
views named in ``MOZ_lightmap.extras``; they read back as the page, through Blender's importer too.

Needs node and ``npm ci`` in tests/gltf_validator (.ci/setup does it); without them the tests skip,
or fail where RB_REQUIRE_BROWSER=1 (CI), as the browser test does.
"""
import json
import os
import shutil
import subprocess
from pathlib import Path

import bpy
import numpy as np
import pytest

from radiosity_baker.addon import cli, gltf
from radiosity_baker.core.lightmap import files

from scenes import lit_ground
from test_gltf import FAST, read_glb

VALIDATOR = Path(__file__).resolve().parents[1] / "gltf_validator"
FORMATS = ("rgbm", "rgbd", "hdr", "half", "float")
LAYOUTS = ("sh", "godot", "unity")


def _require_validator() -> None:
    missing = []
    if shutil.which("node") is None:
        missing.append("node (apt-get install nodejs npm)")
    if not (VALIDATOR / "node_modules" / "gltf-validator").is_dir():
        missing.append("the validator (cd tests/gltf_validator && npm ci)")
    if missing:
        message = "the glTF validator test needs " + " and ".join(missing)
        if os.environ.get("RB_REQUIRE_BROWSER") == "1":
            pytest.fail(message)
        pytest.skip(message)


def validate(paths: list) -> dict:
    """{path: the validator's report} of GLB files, in one run of the validator."""
    run = subprocess.run(["node", str(VALIDATOR / "validate.mjs"), *map(str, paths)],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    return dict(zip(paths, map(json.loads, run.stdout.splitlines())))


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    """The lit ground (a material on each grid) baked into lightmaps, exported in each encoding,
    and baked with each directional layout with ``--gltf`` (half, the default format):
    ({name: GLB}, the lightmap folder of the plain bake)."""
    out = tmp_path_factory.mktemp("validator")
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    lit_ground(bpy.context.scene)
    mat = bpy.data.materials.new("Grey")
    for ob in bpy.context.scene.objects:
        if ob.type == "MESH":
            ob.data.materials.append(mat)
    blend, saved = out / "in.blend", out / "baked.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    glbs = {}
    assert cli.main(["bake", str(blend), *FAST, "--output", str(out / "maps"),
                     "--save", str(saved)]) == 0
    for fmt in FORMATS:
        glbs[fmt] = out / f"{fmt}.glb"
        assert cli.main(["export", str(saved), str(glbs[fmt]), "--lightmap-format", fmt]) == 0
    for layout in LAYOUTS:
        glbs[layout] = out / f"{layout}.glb"
        assert cli.main(["bake", str(blend), *FAST, "--directional", layout, "--output",
                         str(out / f"maps_{layout}"), "--gltf", str(glbs[layout])]) == 0
    return glbs, out / "maps"


def test_every_format_and_directional_layout_passes_the_khronos_validator(exported):
    _require_validator()
    glbs, _ = exported
    reports = validate(list(glbs.values()))
    for name, path in glbs.items():
        issues = reports[path]["issues"]
        codes = sorted({m["code"] for m in issues["messages"]})
        print(f"\n{name}: {issues['numErrors']} errors, {issues['numWarnings']} warnings, "
              f"{issues['numInfos']} infos {codes}")
        bad = [m for m in issues["messages"] if m["severity"] <= 1]  # 0 error, 1 warning
        assert not bad, f"{name}: {bad}"
        # what is left: MOZ_lightmap unknown to the validator, and what only it uses
        assert set(codes) <= {"UNSUPPORTED_EXTENSION", "UNUSED_OBJECT", "IMAGE_NPOT_DIMENSIONS"}


@pytest.mark.parametrize("fmt", ["hdr", "half", "float"])
def test_a_float_page_is_a_buffer_view_beside_an_rgbm_texture(exported, fmt):
    glbs, maps = exported
    doc, binary = read_glb(glbs[fmt])
    assert {im["mimeType"] for im in doc["images"]} == {"image/png"}
    page = files.read_exr(maps / "Lightmap.exr")[..., :3]
    for material in doc["materials"]:
        ext = material["extensions"]["MOZ_lightmap"]
        stored = ext["extras"]["float_image"]
        assert ext["extras"]["encoding"] == gltf.FALLBACK and ext["extras"]["range"] > 0
        assert stored["encoding"] == fmt
        assert stored["mimeType"] == ("image/vnd.radiance" if fmt == "hdr" else "image/x-exr")
        view = doc["bufferViews"][stored["bufferView"]]
        data = binary[view.get("byteOffset", 0):view.get("byteOffset", 0) + view["byteLength"]]
        path = glbs[fmt].with_name(f"from_{fmt}{'.hdr' if fmt == 'hdr' else '.exr'}")
        path.write_bytes(data)
        read = files.read_exr(path)[..., :3]
        if fmt == "hdr":  # RGBE: within m/128 of the page (its largest channel m)
            assert np.all(np.abs(read - page) <= page.max(axis=2, keepdims=True) / 128 + 1e-6)
        else:  # the half page exactly, in half or float channels
            np.testing.assert_array_equal(read, page)


@pytest.mark.parametrize("layout", ["sh", "godot"])
def test_a_directional_exr_is_a_buffer_view_named_in_the_extras(exported, layout):
    glbs, _ = exported
    doc, binary = read_glb(glbs[layout])
    folder = glbs[layout].parent / f"maps_{layout}"
    for material in doc["materials"]:
        directional = material["extensions"]["MOZ_lightmap"]["extras"]["directional"]
        assert directional["layout"] == layout and directional["mimeType"] == "image/x-exr"
        view = doc["bufferViews"][directional["bufferView"]]
        start = view.get("byteOffset", 0)
        assert binary[start:start + view["byteLength"]] == \
            (folder / f"Lightmap.{layout}.exr").read_bytes()


def test_a_reimported_float_glb_gives_the_float_page(exported):
    glbs, maps = exported
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    with gltf.found_by_gltf():
        bpy.ops.import_scene.gltf(filepath=str(glbs["half"]))
    (image,) = [im for im in bpy.data.images if im.get("radiosity_baker_lightmap")]
    assert image["radiosity_baker_encoding"] == "half" and "radiosity_baker_range" not in image
    assert image.is_float and image.packed_file is not None
    w, h = image.size
    px = np.empty(w * h * 4, np.float32)
    image.pixels.foreach_get(px)
    np.testing.assert_array_equal(px.reshape(h, w, 4)[..., :3],
                                  files.read_exr(maps / "Lightmap.exr")[..., :3])
    assert bpy.data.materials["Grey"].node_tree.nodes["RB Lightmap"].image == image
