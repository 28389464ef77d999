"""The baked lightmaps in Blender's own glTF exporter (``io_scene_gltf2``), as ``MOZ_lightmap``.

Blender's exporter writes every UV map, so an object's ``Lightmap`` UV map becomes
``TEXCOORD_<its index>`` (``TEXCOORD_1`` beside one UV map of the user's). This user extension adds
to each material of a lightmapped object ``extensions.MOZ_lightmap = {index, texCoord, intensity,
extras}``: ``index`` a texture holding the object's lightmap page encoded as ``encoding`` says
(rgbm/rgbd: 8-bit PNG; hdr: Radiance RGBE, ``image/vnd.radiance``; half/float: OpenEXR,
``image/x-exr``), ``texCoord`` the UV map's index, ``intensity`` 1 (the texels hold lighting =
irradiance/π, as Hubs' MOZ_lightmap loader reads them), ``extras`` {"encoding", "range"} (range:
the largest value an 8-bit page holds, also in the PNG's metadata).

The exporter finds the class through the enabled add-on's top-level module (``glTF2ExportUserExtension``
there, see the package's ``__init__``); the command line's ``export`` enables it for the export
(:func:`found_by_gltf`). File › Export › glTF 2.0 shows a "Radiosity Baker lightmaps" panel:
on/off and the encoding (scene properties ``radiosity_baker_gltf``).
"""
from __future__ import annotations

import contextlib
import sys
import tempfile
from pathlib import Path

import bpy
import numpy as np
from bpy.props import BoolProperty, EnumProperty, PointerProperty

from ..core.lightmap import encodings
from .lightmap import DIRECTIONAL_SUFFIX, UV_NAME
from .tags import DIRECTIONAL_TAG, IMAGE_TAG, NODE_IMAGE, NODE_UV, OBJECT_TAG

EXTENSION = "MOZ_lightmap"
ENCODINGS = ("rgbm", "rgbd", "hdr", "half", "float")
MIME = {".png": "image/png", ".hdr": "image/vnd.radiance", ".exr": "image/x-exr"}


class RadiosityBakerGltfSettings(bpy.types.PropertyGroup):
    enabled: BoolProperty(name="Lightmaps (MOZ_lightmap)", default=True,
                          description="Export each baked object's lightmap as a MOZ_lightmap "
                                      "texture on its materials")
    encoding: EnumProperty(
        name="Encoding", default="rgbm",
        items=[("rgbm", "RGBM PNG", "8-bit PNG, value = rgb·a·range (any engine, web)"),
               ("rgbd", "RGBD PNG", "8-bit PNG, value = rgb·(range/255)/a (finer dim values)"),
               ("hdr", "Radiance HDR", "RGBE float texture"),
               ("half", "OpenEXR half", "16-bit float EXR"),
               ("float", "OpenEXR float", "32-bit float EXR")],
        description="How the lightmap texture is stored in the glTF file")


_override = None  # (enabled, encoding) while a script's export runs (found_by_gltf)


def _options() -> tuple[bool, str]:
    """(enabled, encoding) of the export running: a script's (:func:`found_by_gltf`), else
    the scene's panel settings, else the defaults."""
    if _override is not None:
        return _override
    props = getattr(bpy.context.scene, "radiosity_baker_gltf", None)
    if props is None:
        return True, "rgbm"
    return props.enabled, props.encoding


class glTF2ExportUserExtension:  # noqa: N801 - the name Blender's glTF exporter looks for
    """One export: adds ``MOZ_lightmap`` to the materials of lightmapped objects (one texture per
    lightmap page, shared by its materials)."""

    def __init__(self):
        from io_scene_gltf2.io.com import gltf2_io
        from io_scene_gltf2.io.com.gltf2_io_extensions import Extension
        from io_scene_gltf2.io.exp.binary_data import BinaryData

        self._io, self._extension, self._binary = gltf2_io, Extension, BinaryData
        self.enabled, self.encoding = _options()
        self._textures: dict = {}  # image name -> (glTF texture, extras)

    def gather_material_hook(self, gltf2_material, blender_material, export_settings):
        if not self.enabled or gltf2_material is None:
            return
        log = export_settings["log"]
        found = _lightmaps_of(blender_material)
        if not found:
            return
        (image, tex_coord), *others = found
        if any(o != (image, tex_coord) for o in others):
            log.warning(f"material {blender_material.name} is used by objects on different "
                        f"lightmaps or Lightmap UV indices: it carries {image.name}; give the "
                        f"objects their own materials")
        if image.source == "TILED":
            log.warning(f"lightmap {image.name} is a UDIM tile set, which glTF cannot hold: "
                        f"bake with --atlas-pages one or --layout per_object to export it")
            return
        texture, extras = self._texture(image)
        extensions = gltf2_material.extensions or {}
        extensions[EXTENSION] = self._extension(
            EXTENSION, {"index": texture, "texCoord": tex_coord, "intensity": 1.0,
                        "extras": extras}, required=False)
        gltf2_material.extensions = extensions

    def _texture(self, image):
        """(glTF texture, extras) of Blender ``image``, encoded once per export."""
        if image.name not in self._textures:
            data, suffix, extras = encode_image(image, self.encoding)
            texture = self._embedded(data, suffix, image.name)
            self._textures[image.name] = (texture, {**extras, **self._directional(image)})
        return self._textures[image.name]

    def _embedded(self, data: bytes, suffix: str, name: str):
        """A glTF texture holding the image file ``data`` (of type ``suffix``) in the binary."""
        source = self._io.Image(buffer_view=self._binary(data=data), extensions=None, extras=None,
                                mime_type=MIME[suffix], name=name, uri=None)
        return self._io.Texture(extensions=None, extras=None, name=name, sampler=None, source=source)

    def _directional(self, image) -> dict:
        """{"directional": {"layout", "texture"}} for a page baked with ``--directional``: the file
        beside it (``<page>.sh.exr``, ``.godot.exr`` or ``.dir.png``, README "Directional
        lightmaps") as one more texture, whose index the export writes there; else {}."""
        layout = image.get(DIRECTIONAL_TAG, "none")
        if layout not in DIRECTIONAL_SUFFIX:
            return {}
        page = Path(bpy.path.abspath(image.filepath))
        path = page.with_name(page.name.rsplit(".", 1)[0] + DIRECTIONAL_SUFFIX[layout])
        if not path.is_file():
            return {}
        texture = self._embedded(path.read_bytes(), path.suffix, path.name)
        return {"directional": {"layout": layout, "texture": texture}}


class glTF2ImportUserExtension:  # noqa: N801 - the name Blender's glTF importer looks for
    """One import: a material's ``MOZ_lightmap`` texture becomes a Blender image (tagged as ours,
    with the extension's extras as custom properties, colour space Non-Color for an 8-bit
    encoding), shown by an unconnected ``RB Lightmap`` Image Texture node on the ``Lightmap`` UV
    map; the UV map at ``texCoord`` of each mesh using such a material is named ``Lightmap``."""

    def gather_import_material_after_hook(self, pymaterial, vertex_color, blender_mat, gltf):
        ext = (pymaterial.extensions or {}).get(EXTENSION)
        if ext is None or blender_mat.node_tree is None:
            return
        from io_scene_gltf2.blender.imp.image import BlenderImage

        source = gltf.data.textures[ext["index"]].source
        BlenderImage.create(gltf, source)
        image = bpy.data.images[gltf.data.images[source].blender_image_name]
        extras = ext.get("extras") or {}
        image[IMAGE_TAG] = image.name
        for key, value in extras.items():
            image[f"radiosity_baker_{key}"] = value
        if extras.get("encoding") in encodings.EIGHT_BIT:
            image.colorspace_settings.name = "Non-Color"
        nodes = blender_mat.node_tree.nodes
        uv_node = nodes.get(NODE_UV) or nodes.new("ShaderNodeUVMap")
        uv_node.name, uv_node.uv_map = NODE_UV, UV_NAME
        tex = nodes.get(NODE_IMAGE) or nodes.new("ShaderNodeTexImage")
        tex.name, tex.label, tex.image = NODE_IMAGE, "Lightmap", image
        blender_mat.node_tree.links.new(uv_node.outputs["UV"], tex.inputs["Vector"])

    def gather_import_mesh_after_hook(self, pymesh, mesh, gltf):
        for prim in pymesh.primitives:
            if prim.material is None:
                continue
            ext = (gltf.data.materials[prim.material].extensions or {}).get(EXTENSION)
            if ext is not None and mesh.uv_layers.get(UV_NAME) is None:
                index = ext.get("texCoord", 0)
                if index < len(mesh.uv_layers):
                    mesh.uv_layers[index].name = UV_NAME


def _lightmaps_of(material) -> list:
    """[(lightmap image, Lightmap UV index)] of the objects using ``material`` that a bake
    lightmapped (their ``OBJECT_TAG``), in object order."""
    material = material.original
    found = []
    for ob in bpy.data.objects:
        page = ob.get(OBJECT_TAG)
        if page is None or ob.type != "MESH" or not any(
                s.material is not None and s.material.original == material for s in ob.material_slots):
            continue
        image = next((im for im in bpy.data.images if im.get(IMAGE_TAG) == page), None)
        index = ob.data.uv_layers.find(UV_NAME)
        if image is not None and index >= 0:
            found.append((image, index))
    return found


def encode_image(image, encoding: str) -> tuple[bytes, str, dict]:
    """(file bytes, suffix, extras) of Blender float ``image`` in ``encoding`` (see
    ``core.lightmap.encodings``); extras: {"encoding"[, "range"]}."""
    w, h = image.size
    px = np.empty(w * h * 4, np.float32)
    image.pixels.foreach_get(px)  # linear float, row 0 at the bottom (as pages are)
    rgb = px.reshape(h, w, 4)[..., :3]
    suffix = encodings.SUFFIX[encoding]
    with tempfile.TemporaryDirectory(prefix="rb-gltf-") as folder:
        path = Path(folder) / f"page{suffix}"
        extras = encodings.write(path, rgb, encoding)
        return path.read_bytes(), suffix, extras


def _draw(context, layout) -> None:
    """The exporter's panel of this extension (File › Export › glTF 2.0)."""
    props = context.scene.radiosity_baker_gltf
    header, body = layout.panel("RADIOSITY_BAKER_gltf_lightmaps", default_closed=False)
    header.use_property_split = False
    header.prop(props, "enabled")
    if body is not None:
        body.active = props.enabled
        body.prop(props, "encoding")


@contextlib.contextmanager
def found_by_gltf(encoding: str = "rgbm", enabled: bool = True):
    """Let the glTF exporter and importer find these extensions during a script's export or import
    (the bpy-module command line, where the add-on is imported but not enabled); an export uses
    ``encoding`` (the scene's panel
    settings aside): the package stands in ``preferences.addons`` under its own module name for
    the duration."""
    package = __package__.rpartition(".")[0]
    addons = bpy.context.preferences.addons
    entry = None
    if package not in addons.keys():
        entry = addons.new()
        entry.module = package
    global _override
    _override = (enabled, encoding)
    try:
        yield
    finally:
        _override = None
        if entry is not None:
            addons.remove(entry)


def register() -> None:
    bpy.utils.register_class(RadiosityBakerGltfSettings)
    bpy.types.Scene.radiosity_baker_gltf = PointerProperty(type=RadiosityBakerGltfSettings)
    exporter = sys.modules.get("io_scene_gltf2")
    if exporter is not None:
        exporter.exporter_extension_layout_draw["Radiosity Baker lightmaps"] = _draw


def unregister() -> None:
    exporter = sys.modules.get("io_scene_gltf2")
    if exporter is not None:
        exporter.exporter_extension_layout_draw.pop("Radiosity Baker lightmaps", None)
    del bpy.types.Scene.radiosity_baker_gltf
    bpy.utils.unregister_class(RadiosityBakerGltfSettings)
