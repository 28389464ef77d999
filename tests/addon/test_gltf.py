"""The bake in Blender's glTF exporter: MOZ_lightmap on the materials of lightmapped objects, the
Lightmap UV map as a TEXCOORD, from ``bake --gltf`` and ``export``; and back through the importer."""
import hashlib
import json
import struct
from pathlib import Path

import bpy
import numpy as np
import pytest

from radiosity_baker.addon import cli, gltf
from radiosity_baker.core.lightmap import encodings, files

from scenes import lit_ground

FAST = ["--method", "direct", "--samples", "4", "--target", "both", "--texel-density", "6"]


def read_glb(path: Path) -> tuple[dict, bytes]:
    """(JSON, binary chunk) of a GLB file."""
    data = path.read_bytes()
    n = struct.unpack("<I", data[12:16])[0]
    return json.loads(data[20:20 + n]), data[20 + n + 8:]


def image_bytes(doc: dict, binary: bytes, index: int) -> bytes:
    view = doc["bufferViews"][doc["images"][index]["bufferView"]]
    return binary[view.get("byteOffset", 0):view.get("byteOffset", 0) + view["byteLength"]]


@pytest.fixture
def baked(empty_scene, tmp_path):
    """The lit ground with a material and a UV map of the user's on each grid, baked (lightmap
    and color attribute) with ``bake --gltf``: (input .blend, saved .blend, GLB, lightmap folder)."""
    lit_ground(empty_scene)
    mat = bpy.data.materials.new("Grey")
    for ob in empty_scene.objects:
        if ob.type == "MESH":
            ob.data.uv_layers.new(name="UVMap")
            ob.data.materials.append(mat)
    blend = tmp_path / "in.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    glb, saved, maps = tmp_path / "out.glb", tmp_path / "out.blend", tmp_path / "maps"
    before = hashlib.sha256(blend.read_bytes()).hexdigest()
    assert cli.main(["bake", str(blend), *FAST, "--output", str(maps), "--lightmap-format", "rgbm",
                     "--gltf", str(glb), "--save", str(saved)]) == 0
    assert hashlib.sha256(blend.read_bytes()).hexdigest() == before
    return blend, saved, glb, maps


def test_bake_gltf_writes_moz_lightmap_on_texcoord_1_and_color_0(baked):
    _, _, glb, maps = baked
    doc, binary = read_glb(glb)
    assert "MOZ_lightmap" in doc["extensionsUsed"] and "MOZ_lightmap" not in doc.get(
        "extensionsRequired", [])
    (material,) = doc["materials"]
    ext = material["extensions"]["MOZ_lightmap"]
    assert ext["texCoord"] == 1 and ext["intensity"] == 1.0 and ext["extras"]["encoding"] == "rgbm"
    for mesh in doc["meshes"]:
        for prim in mesh["primitives"]:
            assert {"TEXCOORD_0", "TEXCOORD_1", "COLOR_0"} <= set(prim["attributes"])
    image = doc["images"][doc["textures"][ext["index"]]["source"]]
    assert image["mimeType"] == "image/png"
    # the PNG in the GLB decodes to the baked page within RGBM's step
    png = maps.parent / "from_glb.png"
    png.write_bytes(image_bytes(doc, binary, doc["textures"][ext["index"]]["source"]))
    decoded, meta = encodings.read(png)
    assert meta["range"] == pytest.approx(ext["extras"]["range"])
    exr = files.read_exr(maps / "Lightmap.exr")[..., :3]
    m = exr.max(axis=2, keepdims=True)
    err = np.abs(decoded - exr)
    assert (err <= (0.5 / 255) * (m + meta["range"] / 255) + 1e-3 * m + 1e-6).all()  # + half's


def test_export_command_encodes_as_asked_and_can_leave_lightmaps_out(baked, tmp_path):
    _, saved, _, _ = baked
    before = hashlib.sha256(saved.read_bytes()).hexdigest()
    hdr, bare = tmp_path / "hdr.glb", tmp_path / "bare.glb"
    assert cli.main(["export", str(saved), str(hdr), "--lightmap-format", "hdr"]) == 0
    assert cli.main(["export", str(saved), str(bare), "--no-lightmaps"]) == 0
    assert hashlib.sha256(saved.read_bytes()).hexdigest() == before
    doc, _ = read_glb(hdr)
    ext = doc["materials"][0]["extensions"]["MOZ_lightmap"]
    assert ext["extras"] == {"encoding": "hdr"}
    assert doc["images"][doc["textures"][ext["index"]]["source"]]["mimeType"] == "image/vnd.radiance"
    doc, _ = read_glb(bare)
    assert "MOZ_lightmap" not in json.dumps(doc) and "COLOR_0" not in json.dumps(doc)
    assert "TEXCOORD_1" in json.dumps(doc)
    assert "radiosity_baker" not in bpy.context.preferences.addons  # only during the export


def test_gltf_output_must_be_a_glb(baked, tmp_path, capsys):
    _, saved, _, _ = baked
    assert cli.main(["export", str(saved), str(tmp_path / "x.gltf")]) == 2
    assert "must be a .glb" in capsys.readouterr().err and not (tmp_path / "x.gltf").exists()


def test_reimported_glb_keeps_both_uv_maps_and_the_lightmap_image(baked):
    _, _, glb, maps = baked
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    with gltf.found_by_gltf():
        bpy.ops.import_scene.gltf(filepath=str(glb))
    meshes = [ob.data for ob in bpy.data.objects if ob.type == "MESH"]
    assert meshes and all([l.name for l in me.uv_layers] == ["UVMap", "Lightmap"] for me in meshes)
    (image,) = [im for im in bpy.data.images if im.get("radiosity_baker_lightmap")]
    assert image["radiosity_baker_encoding"] == "rgbm"
    w, h = image.size
    px = np.empty(w * h * 4, np.float32)
    image.pixels.foreach_get(px)
    rgba = np.rint(px.reshape(h, w, 4) * 255).astype(np.uint8)
    decoded = encodings.decode(rgba, "rgbm", image["radiosity_baker_range"])
    exr = files.read_exr(maps / "Lightmap.exr")[..., :3]
    m = exr.max(axis=2, keepdims=True)
    assert (np.abs(decoded - exr) <= (0.5 / 255) * (m + image["radiosity_baker_range"] / 255)
            + 1e-3 * m + 1e-6).all()
    mat = bpy.data.materials["Grey"]
    assert mat.node_tree.nodes["RB Lightmap"].image == image
