"""The bake in Blender's glTF exporter: MOZ_lightmap on the materials of lightmapped objects, the
Lightmap UV map as TEXCOORD_1, from ``bake --gltf``, ``export`` and File › Export with the add-on
enabled; and back through the importer."""
import hashlib
import json
import struct
from pathlib import Path

import addon_utils
import bpy
import numpy as np
import pytest

from radiosity_baker.addon import cli, gltf
from radiosity_baker.core.lightmap import encodings, files

import radiosity_baker
from scenes import lit_ground

FAST = ["--method", "direct", "--samples", "4", "--target", "both", "--texel-density", "6"]
SAMPLES = Path(__file__).resolve().parents[2] / "sample_blends"



def _bake_with_gltf(tmp_path):
    """Save the open file as tmp/in.blend, bake it into lightmaps with ``--gltf``; (the saved
    .blend, the GLB)."""
    blend, saved, glb = tmp_path / "in.blend", tmp_path / "out.blend", tmp_path / "out.glb"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    assert cli.main(["bake", str(blend), *FAST, "--output", str(tmp_path / "maps"),
                     "--gltf", str(glb), "--save", str(saved)]) == 0
    return saved, glb


def read_glb(path: Path) -> tuple[dict, bytes]:
    """(JSON, binary chunk) of a GLB file."""
    data = path.read_bytes()
    n = struct.unpack("<I", data[12:16])[0]
    return json.loads(data[20:20 + n]), data[20 + n + 8:]


def sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def accessor(doc: dict, binary: bytes, index: int) -> np.ndarray:
    """float32[count, 2] of a VEC2 float accessor (tightly packed, as Blender writes them)."""
    acc = doc["accessors"][index]
    assert acc["type"] == "VEC2" and acc["componentType"] == 5126
    view = doc["bufferViews"][acc["bufferView"]]
    start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
    return np.frombuffer(binary, np.float32, acc["count"] * 2, start).reshape(-1, 2)


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
    before = sha256(blend)
    assert cli.main(["bake", str(blend), *FAST, "--output", str(maps), "--lightmap-format", "rgbm",
                     "--gltf", str(glb), "--save", str(saved)]) == 0
    assert sha256(blend) == before
    return blend, saved, glb, maps


@pytest.fixture(scope="module")
def samples(tmp_path_factory):
    """The sample scenes baked into lightmaps with ``bake --gltf``: {name: (saved .blend, GLB)};
    the sample files are checked unchanged."""
    out, baked = tmp_path_factory.mktemp("samples"), {}
    for name in ("cornell_box", "lamp_scene"):
        blend = SAMPLES / f"{name}.blend"
        before = sha256(blend)
        saved, glb = out / f"{name}.blend", out / f"{name}.glb"
        assert cli.main(["bake", str(blend), "--method", "direct", "--samples", "4", "--target",
                         "lightmap", "--texel-density", "6", "--output", str(out / f"{name}_maps"),
                         "--gltf", str(glb), "--save", str(saved)]) == 0
        assert sha256(blend) == before
        baked[name] = saved, glb
    return baked


@pytest.fixture
def addon_enabled():
    """The package enabled by Blender's add-on manager (``addon_utils``, an entry in
    ``preferences.addons``) as File › Export finds it in Blender, in place of conftest's
    register."""
    radiosity_baker.unregister()
    try:
        addon_utils.enable("radiosity_baker", default_set=True, handle_error=_raise)
        assert "radiosity_baker" in bpy.context.preferences.addons
        yield
    finally:
        addon_utils.disable("radiosity_baker", default_set=True, handle_error=_raise)
        radiosity_baker.register()


def _raise(exc):
    raise exc


def lightmapped_uv_maps() -> dict:
    """{mesh object: its UV map names} of the objects a bake lightmapped, in the open file."""
    return {ob.name: [uv.name for uv in ob.data.uv_layers]
            for ob in bpy.data.objects if ob.get("radiosity_baker_page")}


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
    assert ext["extras"]["float_image"]["encoding"] == "hdr"  # beside an RGBM texture
    assert ext["extras"]["float_image"]["mimeType"] == "image/vnd.radiance"
    assert doc["images"][doc["textures"][ext["index"]]["source"]]["mimeType"] == "image/png"
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


def test_texcoord_order_puts_the_lightmap_uv_map_second():
    assert gltf.texcoord_order(["Lightmap"]) == [0, 0]
    assert gltf.texcoord_order(["UVMap", "Lightmap"]) == [0, 1]
    assert gltf.texcoord_order(["Lightmap", "UVMap"]) == [1, 0]
    assert gltf.texcoord_order(["A", "B", "Lightmap", "C"]) == [0, 2, 1, 3]
    assert gltf.texcoord_order(["UVMap"]) is None


def test_cornell_box_lightmap_is_texcoord_1_with_a_copy_as_texcoord_0(samples):
    saved, glb = samples["cornell_box"]
    doc, binary = read_glb(glb)
    for mesh in doc["meshes"]:  # every object of the box is baked; 'Lightmap' is its only UV map
        for prim in mesh["primitives"]:
            attrs = prim["attributes"]
            assert attrs["TEXCOORD_0"] == attrs["TEXCOORD_1"] and "TEXCOORD_2" not in attrs
            assert doc["materials"][prim["material"]]["extensions"]["MOZ_lightmap"]["texCoord"] == 1
    assert accessor(doc, binary, attrs["TEXCOORD_1"]).ptp(axis=0).min() > 0.01  # UVs, not zeros
    bpy.ops.wm.open_mainfile(filepath=str(saved))
    assert set(map(tuple, lightmapped_uv_maps().values())) == {("Lightmap",)}


def test_textures_follow_their_uv_maps_when_the_lightmap_moves_to_texcoord_1(empty_scene, tmp_path):
    """Meshes with UV maps [A, B, Lightmap]: glTF sets [A, Lightmap, B]; a texture on B gets
    texCoord 2; the file's UV maps stay as they were."""
    lit_ground(empty_scene)
    mat = bpy.data.materials.new("Textured")
    tex = mat.node_tree.nodes.new("ShaderNodeTexImage")
    tex.image = bpy.data.images.new("Checker", 4, 4)
    uv = mat.node_tree.nodes.new("ShaderNodeUVMap")
    uv.uv_map = "B"
    mat.node_tree.links.new(uv.outputs["UV"], tex.inputs["Vector"])
    mat.node_tree.links.new(tex.outputs["Color"],
                            mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"])
    for ob in empty_scene.objects:
        if ob.type == "MESH":
            for name, value in (("A", 0.25), ("B", 0.75)):
                ob.data.uv_layers.new(name=name).uv.foreach_set(
                    "vector", [value] * (2 * len(ob.data.loops)))
            ob.data.materials.append(mat)
    tex.image.pack()
    saved, glb = _bake_with_gltf(tmp_path)
    doc, binary = read_glb(glb)
    (material,) = doc["materials"]
    assert material["pbrMetallicRoughness"]["baseColorTexture"]["texCoord"] == 2
    assert material["extensions"]["MOZ_lightmap"]["texCoord"] == 1
    for mesh in doc["meshes"]:
        (prim,) = mesh["primitives"]
        attrs = prim["attributes"]
        assert np.allclose(accessor(doc, binary, attrs["TEXCOORD_0"]), [0.25, 0.75])  # v flipped
        assert np.allclose(accessor(doc, binary, attrs["TEXCOORD_2"]), [0.75, 0.25])
        assert accessor(doc, binary, attrs["TEXCOORD_1"]).ptp(axis=0).min() > 0.01
    bpy.ops.wm.open_mainfile(filepath=str(saved))
    assert set(map(tuple, lightmapped_uv_maps().values())) == {("A", "B", "Lightmap")}


@pytest.mark.parametrize("name", ["cornell_box", "lamp_scene"])
def test_file_export_with_the_addon_enabled_uses_the_panel_settings(samples, addon_enabled, name,
                                                                    tmp_path):
    """bpy.ops.export_scene.gltf as File › Export › glTF 2.0 runs it: the exporter finds the
    user extension through preferences.addons; the panel's encoding and on/off switch apply."""
    import io_scene_gltf2

    assert "Radiosity Baker lightmaps" in io_scene_gltf2.exporter_extension_layout_draw
    saved, _ = samples[name]
    bpy.ops.wm.open_mainfile(filepath=str(saved))
    uv_maps = lightmapped_uv_maps()
    materials = {ob.name: [s.material.name for s in ob.material_slots]
                 for ob in bpy.data.objects if ob.name in uv_maps}
    assert uv_maps and all(materials.values())
    panel = bpy.context.scene.radiosity_baker_gltf
    panel.encoding = "hdr"
    hdr, bare = tmp_path / "hdr.glb", tmp_path / "bare.glb"
    bpy.ops.export_scene.gltf(filepath=str(hdr), export_format="GLB")
    panel.enabled = False
    bpy.ops.export_scene.gltf(filepath=str(bare), export_format="GLB")

    doc, _ = read_glb(hdr)
    nodes = {node["name"]: node for node in doc["nodes"]}
    for ob_name in uv_maps:
        for prim in doc["meshes"][nodes[ob_name]["mesh"]]["primitives"]:
            assert "TEXCOORD_1" in prim["attributes"]
            ext = doc["materials"][prim["material"]]["extensions"]["MOZ_lightmap"]
            assert ext["texCoord"] == 1 and ext["extras"]["float_image"]["encoding"] == "hdr"
            assert ext["extras"]["float_image"]["mimeType"] == "image/vnd.radiance"
    doc, _ = read_glb(bare)  # left out: no lightmap, and Blender's own UV numbering
    assert "MOZ_lightmap" not in json.dumps(doc)
    for ob_name, names in uv_maps.items():
        for prim in doc["meshes"][nodes[ob_name]["mesh"]]["primitives"]:
            assert sorted(k for k in prim["attributes"] if k.startswith("TEXCOORD_")) == \
                [f"TEXCOORD_{i}" for i in range(len(names))]
    assert lightmapped_uv_maps() == uv_maps  # the file's UV maps and materials as they were
    assert {ob: [s.material.name for s in bpy.data.objects[ob].material_slots]
            for ob in materials} == materials


def test_objects_without_a_material_get_a_grey_one_with_their_lightmap_in_the_file_only(
        empty_scene, tmp_path):
    lit_ground(empty_scene)  # no materials: the bake took them for grey 0.8
    saved, glb = _bake_with_gltf(tmp_path)
    doc, _ = read_glb(glb)
    (material,) = doc["materials"]
    assert material["pbrMetallicRoughness"] == {"baseColorFactor": [0.8, 0.8, 0.8, 1.0],
                                                "metallicFactor": 0.0, "roughnessFactor": 0.5}
    assert material["extensions"]["MOZ_lightmap"]["texCoord"] == 1
    assert len(doc["meshes"]) == 2 and all(
        prim["material"] == 0 for mesh in doc["meshes"] for prim in mesh["primitives"])
    bpy.ops.wm.open_mainfile(filepath=str(saved))
    assert not bpy.data.materials and all(
        not ob.material_slots for ob in bpy.data.objects if ob.type == "MESH")


def test_a_udim_lightmap_is_left_out_with_a_warning_naming_it(empty_scene, tmp_path, capfd):
    lit_ground(empty_scene)
    mat = bpy.data.materials.new("Grey")
    for ob in empty_scene.objects:
        if ob.type == "MESH":
            ob.data.materials.append(mat)
    blend, glb = tmp_path / "in.blend", tmp_path / "out.glb"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    capfd.readouterr()
    assert cli.main(["bake", str(blend), "--method", "direct", "--samples", "4", "--target",
                     "lightmap", "--texel-density", "20", "--max-size", "128", "--atlas-pages",
                     "many", "--output", str(tmp_path / "maps"), "--gltf", str(glb)]) == 0
    assert sorted(p.name for p in (tmp_path / "maps").glob("*.exr")) == [
        "Lightmap.1001.exr", "Lightmap.1002.exr"]  # the ground fills the first tile
    out = "".join(capfd.readouterr())
    assert "lightmap Lightmap is a UDIM tile set" in out and "--atlas-pages one" in out
    doc, _ = read_glb(glb)
    assert "MOZ_lightmap" not in json.dumps(doc)
