"""The baked lightmaps in Blender's own glTF exporter (``io_scene_gltf2``), as ``MOZ_lightmap``.

This user extension adds to each material of a lightmapped object ``extensions.MOZ_lightmap =
{index, texCoord: 1, intensity, extras}``: ``index`` a texture holding the object's lightmap page
as an 8-bit PNG, ``intensity`` 1 (the texels hold lighting = irradiance/π, as Hubs' MOZ_lightmap
loader reads them), ``extras`` {"encoding", "range"} of that PNG (rgbm or rgbd; range: the largest
value it holds, also in the PNG's metadata). glTF's core allows only PNG and JPEG as a texture's
image (the Khronos validator's TEXTURE_INVALID_IMAGE_MIME_TYPE), so a float encoding (hdr:
Radiance RGBE, ``image/vnd.radiance``; half/float: OpenEXR, ``image/x-exr``) is no texture: its
file lies in a buffer view of the binary chunk named by ``extras.float_image`` = {"encoding",
"bufferView", "mimeType"}, and the texture holds the page in rgbm, what a loader reading only
``index`` finds. A directional bake's file is named by ``extras.directional`` the same way (a PNG
as a texture: {"layout", "texture"}; an EXR as {"layout", "bufferView", "mimeType"}). A
lightmapped object without a material gets, in the file only, a grey 0.8 diffuse one (what the
bake took it for) carrying its lightmap.

The exporter catches what a hook raises and only logs it, then writes the file without that
lightmap; so each hook here (:func:`_failing_the_export`) logs its failure as an error the
operator reports: File › Export shows it, and ``bpy.ops`` raises it (the command line's error).

Blender's exporter numbers UV maps in their order; engines (Unity, Godot, three.js) take the
second set as the lightmap's. So the export renumbers each mesh's sets: ``TEXCOORD_0`` the first
UV map other than ``Lightmap`` (``Lightmap`` again when it is the only one), ``TEXCOORD_1`` the
``Lightmap`` UV map, then the other UV maps in order; material textures follow their UV map
(a material's copy in the file where its numbers change). The .blend is not touched.

The exporter finds the class through the enabled add-on's top-level module (``glTF2ExportUserExtension``
there, see the package's ``__init__``); the command line's ``export`` enables it for the export
(:func:`found_by_gltf`). File › Export › glTF 2.0 shows a "Radiosity Baker lightmaps" panel:
on/off and the encoding (scene properties ``radiosity_baker_gltf``).
"""
from __future__ import annotations

import contextlib
import copy
import functools
import sys
import tempfile
import traceback
from pathlib import Path

import bpy
import numpy as np
from bpy.props import BoolProperty, EnumProperty, PointerProperty

from ..core.lightmap import encodings
from .lightmap import DIRECTIONAL_SUFFIX, UV_NAME
from .tags import DIRECTIONAL_TAG, IMAGE_TAG, NODE_IMAGE, NODE_UV, OBJECT_TAG

EXTENSION = "MOZ_lightmap"
ENCODINGS = ("rgbm", "rgbd", "hdr", "half", "float")
FALLBACK = "rgbm"  # the texture of a float encoding's lightmap, for loaders that read only index
MIME = {".png": "image/png", ".hdr": "image/vnd.radiance", ".exr": "image/x-exr"}


class LightmapExportError(ValueError):
    """A lightmap the export cannot carry; the message names it and says what to do."""


def _failing_the_export(hook):
    """Blender exporter hook ``hook`` (a method whose last argument is export_settings) whose
    failure fails the export: logged as an error for the operator to report, with the traceback
    on the console for anything but a LightmapExportError (a bug)."""
    @functools.wraps(hook)
    def run(self, *args):
        try:
            hook(self, *args)
        except Exception as exc:  # noqa: BLE001 - the exporter would swallow it
            log = args[-1]["log"]
            if not isinstance(exc, LightmapExportError):
                log.error(traceback.format_exc())
                exc = f"{type(exc).__name__}: {exc}"
            log.error(f"Radiosity Baker lightmaps: {exc}", popup=True)
    return run


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
    """One export: puts each mesh's ``Lightmap`` UV map at ``TEXCOORD_1`` and adds ``MOZ_lightmap``
    to the materials of lightmapped objects (one texture per lightmap page, shared by its
    materials; a default material for an object without one)."""

    def __init__(self):
        from io_scene_gltf2.io.com import gltf2_io
        from io_scene_gltf2.io.com.gltf2_io_extensions import Extension
        from io_scene_gltf2.io.exp.binary_data import BinaryData

        self._io, self._extension, self._binary = gltf2_io, Extension, BinaryData
        self.enabled, self.encoding = _options()
        self._textures: dict = {}  # image name -> (glTF texture, extras)
        self._renumbered: dict = {}  # (id(glTF material), renumbering) -> (material, its copy)
        self._defaults: dict = {}  # image name -> default glTF material carrying that lightmap

    @_failing_the_export
    def gather_material_hook(self, gltf2_material, blender_material, export_settings):
        if not self.enabled or gltf2_material is None:
            return
        found = _lightmaps_of(blender_material)
        if not found:
            return
        image, *others = found
        if any(o != image for o in others):
            export_settings["log"].warning(
                f"material {blender_material.name} is used by objects on different lightmaps: it "
                f"carries {image.name}; give the objects their own materials")
        self._add_lightmap(gltf2_material, image, export_settings)

    @_failing_the_export
    def gather_mesh_hook(self, gltf2_mesh, blender_mesh, blender_object, vertex_groups, modifiers,
                         materials, export_settings):
        """Renumber the TEXCOORD sets of a mesh with a ``Lightmap`` UV map (:func:`texcoord_order`)
        and the texCoord of its materials' textures with them."""
        if not self.enabled:
            return
        names = [layer.name for layer in blender_mesh.uv_layers]
        order = texcoord_order(names)
        if order is None or order == list(range(len(names))):
            return
        renumber = {b: order.index(b) for b in range(len(names))}  # Blender index -> glTF index
        for prim in gltf2_mesh.primitives:
            attributes = prim.attributes  # may be shared by primitives: replaced, not edited
            if not all(f"TEXCOORD_{b}" in attributes for b in range(len(names))):
                continue  # UVs not exported (or loose edges and points)
            kept = {k: v for k, v in attributes.items()
                    if not k.startswith("TEXCOORD_") or int(k[len("TEXCOORD_"):]) >= len(names)}
            prim.attributes = {**kept, **{f"TEXCOORD_{g}": attributes[f"TEXCOORD_{b}"]
                                          for g, b in enumerate(order)}}
            if prim.material is not None:
                prim.material = self._renumbered_material(prim.material, renumber)

    @_failing_the_export
    def gather_node_hook(self, gltf2_node, blender_object, export_settings):
        """Give the material-less primitives of a lightmapped object a default material with its
        lightmap."""
        if not self.enabled or gltf2_node.mesh is None or blender_object is None:
            return
        image = lightmap_image(blender_object)
        if image is None:
            return
        for prim in gltf2_node.mesh.primitives:
            if prim.material is None:
                prim.material = self._default_material(image, export_settings)
                export_settings["log"].info(
                    f"object {blender_object.name} has no material: exported with a grey 0.8 one "
                    f"carrying its lightmap")
            elif prim.material in self._defaults.values() and \
                    prim.material is not self._defaults.get(image.name):
                export_settings["log"].warning(
                    f"object {blender_object.name} shares its mesh with an object on another "
                    f"lightmap: give it its own mesh data")

    def _add_lightmap(self, gltf2_material, image, export_settings) -> None:
        """Add ``MOZ_lightmap`` with ``image`` (our lightmap page) to ``gltf2_material``."""
        log = export_settings["log"]
        if not export_settings["gltf_texcoords"]:
            log.warning(f"UVs are not exported: no lightmap on material {gltf2_material.name}")
            return
        if image.source == "TILED":
            log.warning(f"lightmap {image.name} is a UDIM tile set, which glTF cannot hold: "
                        f"bake with --atlas-pages one or --layout per_object to export it")
            return
        texture, extras = self._texture(image, log)
        extensions = gltf2_material.extensions or {}
        extensions[EXTENSION] = self._extension(
            EXTENSION, {"index": texture, "texCoord": 1, "intensity": 1.0, "extras": extras},
            required=False)
        gltf2_material.extensions = extensions

    def _default_material(self, image, export_settings):
        """The glTF material standing in for Blender's default on objects lit by ``image``:
        base colour 0.8 (the bake's albedo for them), not metallic, roughness 0.5."""
        if image.name not in self._defaults:
            pbr = self._io.MaterialPBRMetallicRoughness(
                base_color_factor=[0.8, 0.8, 0.8, 1.0], base_color_texture=None, extensions=None,
                extras=None, metallic_factor=0.0, metallic_roughness_texture=None,
                roughness_factor=0.5)
            material = self._io.Material(
                alpha_cutoff=None, alpha_mode=None, double_sided=None, emissive_factor=None,
                emissive_texture=None, extensions=None, extras=None,
                name=f"Radiosity Baker default ({image.name})", normal_texture=None,
                occlusion_texture=None, pbr_metallic_roughness=pbr)
            self._add_lightmap(material, image, export_settings)
            self._defaults[image.name] = material
        return self._defaults[image.name]

    def _renumbered_material(self, material, renumber: dict):
        """``material``, or its copy whose textures' texCoord b is ``renumber[b]`` (one copy per
        material and renumbering)."""
        key = (id(material), tuple(sorted(renumber.items())))
        if key not in self._renumbered:
            self._renumbered[key] = (material, _renumbered(material, renumber))
        return self._renumbered[key][1]

    def _texture(self, image, log):
        """(glTF texture, extras) of Blender ``image``, encoded once per export: the texture holds
        the page in the 8-bit encoding asked for, or in ``FALLBACK`` beside a float one (in
        ``extras.float_image``, see the module's docstring)."""
        if image.name not in self._textures:
            rgb = _pixels(image)
            eight_bit = self.encoding if self.encoding in encodings.EIGHT_BIT else FALLBACK
            data, extras = encode(rgb, eight_bit)
            if eight_bit == self.encoding:
                clipped = encodings.clip_warning(rgb, extras["range"], f"lightmap {image.name}")
                if clipped:
                    log.warning(clipped, popup=True)  # File › Export shows it too
            else:  # the stand-in may clip a hot spot: the float page keeps it
                exact, _ = encode(rgb, self.encoding)
                extras["float_image"] = {"encoding": self.encoding,
                                         **self._stored(exact, encodings.SUFFIX[self.encoding])}
            texture = self._embedded(data, image.name)
            self._textures[image.name] = (texture, {**extras, **self._directional(image)})
        return self._textures[image.name]

    def _embedded(self, png: bytes, name: str):
        """A glTF texture holding the PNG file ``png`` in the binary."""
        source = self._io.Image(buffer_view=self._binary(data=png), extensions=None, extras=None,
                                mime_type=MIME[".png"], name=name, uri=None)
        return self._io.Texture(extensions=None, extras=None, name=name, sampler=None, source=source)

    def _stored(self, data: bytes, suffix: str) -> dict:
        """{"bufferView", "mimeType"} of image file ``data`` (of type ``suffix``, one glTF's core
        does not allow: EXR, HDR) put in the binary as a buffer view of its own."""
        return {"bufferView": self._binary(data=data), "mimeType": MIME[suffix]}

    def _directional(self, image) -> dict:
        """{"directional": {"layout", "texture"}} (a PNG) or {"directional": {"layout",
        "bufferView", "mimeType"}} (an EXR) for a page baked with ``--directional``: the file beside
        it (``<page>.sh.exr``, ``.godot.exr`` or ``.dir.png``, manual: docs/directional-probes.md);
        else {}."""
        layout = image.get(DIRECTIONAL_TAG, "none")
        if layout not in DIRECTIONAL_SUFFIX:
            return {}
        page = Path(bpy.path.abspath(image.filepath))
        path = page.with_name(page.name.rsplit(".", 1)[0] + DIRECTIONAL_SUFFIX[layout])
        if not path.is_file():
            return {}
        if path.suffix == ".png":
            return {"directional": {"layout": layout,
                                    "texture": self._embedded(path.read_bytes(), path.name)}}
        return {"directional": {"layout": layout, **self._stored(path.read_bytes(), path.suffix)}}


def texcoord_order(uv_names: list[str]) -> list[int] | None:
    """The Blender UV map index each glTF ``TEXCOORD_<i>`` of a mesh takes, for a mesh whose UV
    maps are ``uv_names`` (Blender's order): the first UV map other than ``Lightmap`` (the
    ``Lightmap`` UV map again when it is the only one), then the ``Lightmap`` UV map, then the
    other UV maps in order. None without a ``Lightmap`` UV map. E.g. ["Lightmap"] -> [0, 0];
    ["A", "Lightmap"] -> [0, 1]; ["Lightmap", "A"] -> [1, 0];
    ["A", "B", "Lightmap"] -> [0, 2, 1]."""
    if UV_NAME not in uv_names:
        return None
    k = uv_names.index(UV_NAME)
    others = [b for b in range(len(uv_names)) if b != k]
    return [others[0], k, *others[1:]] if others else [k, k]


def _renumbered(node, renumber: dict):
    """``node`` (a glTF object of the exporter, dict or list), or a copy of it and of the objects on
    the way to each ``tex_coord`` / ``texCoord`` it holds (textures, ``KHR_texture_transform``)
    that ``renumber`` changes ({old index: new index}); our own ``MOZ_lightmap`` is left as is.
    What is not on such a way (textures, images) stays shared."""
    if isinstance(node, list):
        new = [_renumbered(v, renumber) for v in node]
        return new if any(a is not b for a, b in zip(new, node)) else node
    if isinstance(node, dict):
        fields = node
    elif hasattr(node, "__dict__") and not isinstance(node, (type, bpy.types.ID)):
        fields = vars(node)
    else:
        return node
    changes = {}
    for key, value in fields.items():
        if key == EXTENSION:
            continue
        if key in ("tex_coord", "texCoord") and isinstance(value, (int, type(None))):
            old = value or 0  # unset: set 0
            if renumber.get(old, old) != old:
                changes[key] = renumber[old]
        else:
            new = _renumbered(value, renumber)
            if new is not value:
                changes[key] = new
    if not changes:
        return node
    node = copy.copy(node)
    for key, value in changes.items():
        if isinstance(node, dict):
            node[key] = value
        else:
            setattr(node, key, value)
    return node


class glTF2ImportUserExtension:  # noqa: N801 - the name Blender's glTF importer looks for
    """One import: a material's ``MOZ_lightmap`` lightmap (the float page of
    ``extras.float_image`` where there is one, else the texture) becomes a Blender image (tagged as
    ours, with the extension's extras as custom properties, colour space Non-Color for an 8-bit
    encoding), shown by an unconnected ``RB Lightmap`` Image Texture node on the ``Lightmap`` UV
    map; the UV map at ``texCoord`` of each mesh using such a material is named ``Lightmap``."""

    def __init__(self):
        self._float_pages: dict = {}  # buffer view -> the Blender image made of it

    def gather_import_material_after_hook(self, pymaterial, vertex_color, blender_mat, gltf):
        ext = (pymaterial.extensions or {}).get(EXTENSION)
        if ext is None or blender_mat.node_tree is None:
            return
        from io_scene_gltf2.blender.imp.image import BlenderImage

        source = gltf.data.textures[ext["index"]].source
        extras = ext.get("extras") or {}
        page = extras.get("float_image")
        if page is not None:  # the float page rather than its 8-bit stand-in
            image = self._float_page(gltf, page["bufferView"], gltf.data.images[source].name)
            extras = {**{k: v for k, v in extras.items() if k not in ("range", "float_image")},
                      "encoding": page["encoding"]}
        else:
            BlenderImage.create(gltf, source)
            image = bpy.data.images[gltf.data.images[source].blender_image_name]
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

    def _float_page(self, gltf, buffer_view: int, name: str | None):
        """The Blender image ``name`` (packed) of the image file in ``buffer_view``, made once."""
        if buffer_view not in self._float_pages:
            from io_scene_gltf2.io.imp.gltf2_io_binary import BinaryData

            data = bytes(BinaryData.get_buffer_view(gltf, buffer_view))
            # the size is a stand-in: the packed file sets it
            image = bpy.data.images.new(name or "Lightmap", 8, 8, float_buffer=True)
            image.pack(data=data, data_len=len(data))
            image.source = "FILE"
            self._float_pages[buffer_view] = image
        return self._float_pages[buffer_view]

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
    """The lightmap images of the objects using ``material`` that a bake lightmapped (their
    ``OBJECT_TAG``) and that have a ``Lightmap`` UV map, in object order."""
    material = material.original
    found = []
    for ob in bpy.data.objects:
        if ob.type != "MESH" or not any(s.material is not None and s.material.original == material
                                        for s in ob.material_slots):
            continue
        image = lightmap_image(ob)
        if image is not None:
            found.append(image)
    return found


def lightmap_image(ob):
    """The lightmap image of mesh object ``ob`` (its ``OBJECT_TAG``), or None when a bake did not
    lightmap it, the image is gone, or the object has no ``Lightmap`` UV map."""
    page = ob.original.get(OBJECT_TAG)
    if page is None or ob.type != "MESH" or ob.data.uv_layers.find(UV_NAME) < 0:
        return None
    return next((im for im in bpy.data.images if im.get(IMAGE_TAG) == page), None)


def _pixels(image) -> np.ndarray:
    """float32[H,W,3] linear RGB of Blender float ``image``, row 0 at the bottom (as pages are).
    LightmapExportError for an image that holds no one page: an image sequence (an animation's
    lightmaps) or an image whose file cannot be read."""
    if image.source == "SEQUENCE":
        raise LightmapExportError(
            f"lightmap {image.name} is an image sequence (a bake with --frames), and glTF holds "
            f"one image per lightmap: bake a single frame (without --frames) to export it")
    w, h = image.size
    if not w or not h:
        raise LightmapExportError(f"lightmap {image.name} has no pixels: its file "
                                  f"{bpy.path.abspath(image.filepath)} cannot be read")
    px = np.empty(w * h * 4, np.float32)
    image.pixels.foreach_get(px)
    return px.reshape(h, w, 4)[..., :3]


def encode(rgb: np.ndarray, encoding: str) -> tuple[bytes, dict]:
    """(file bytes, extras) of float32[H,W,3] ``rgb`` (row 0 at the bottom) in ``encoding``, a
    file of suffix ``encodings.SUFFIX[encoding]`` (see ``core.lightmap.encodings``); extras:
    {"encoding"[, "range"]}."""
    with tempfile.TemporaryDirectory(prefix="rb-gltf-") as folder:
        path = Path(folder) / f"page{encodings.SUFFIX[encoding]}"
        extras = encodings.write(path, rgb, encoding)
        return path.read_bytes(), extras


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
