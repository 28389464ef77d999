"""Lightmaps in Blender: reading ``Lightmap`` UV maps before a bake, and in the job's final step
writing the EXR files, the UV maps, the images and (on request) the material nodes; ``clear``
removes exactly what a bake added (the ``object.radiosity_bake_clear`` operator).

What a bake adds is tagged so that clearing never touches the user's data: UV maps it created carry
the mesh custom property ``radiosity_baker_uv``, images it loaded ``radiosity_baker_lightmap``, and
material nodes it added are named ``RB Lightmap…``.

Shared data: a mesh used by several objects has one UV map (laid out once, for the first object);
in the shared atlas only that object is lightmapped, the per-object layout gives each its own image.
A material used by objects on different lightmap images can show only one: it shows the first one
and a warning says so.
"""
from __future__ import annotations

import contextlib
import sys
from dataclasses import dataclass
from pathlib import Path

import bpy
import numpy as np

from ..core import directional
from ..core.lightmap import ATLAS_NAME, LightmapObject, LightmapRequest, budget, encodings, files
from .extract import ExtractionError
from .outputs import OutputError, Staging, check_folder, same_file
from .tags import DIRECTIONAL_TAG, IMAGE_TAG, NODE_IMAGE, NODE_MULTIPLY, NODE_PREFIX, NODE_UV, OBJECT_TAG, UV_TAG
from .write import name_clash

UV_NAME = "Lightmap"
# The object property holding an object's own texel density (0 or absent: the scene's).
DENSITY_PROP = "radiosity_baker_texel_density"
MAX_UV_LAYERS = 8
COLORSPACE = "Linear Rec.709"


def python_executable() -> str:
    """A Python interpreter for the xatlas worker: ``sys.executable`` when it is one (the bpy
    module, Blender ≥ 2.91), else the interpreter bundled under Blender's ``sys.prefix``."""
    if Path(sys.executable).name.lower().startswith("python"):
        return sys.executable
    for folder in (Path(sys.prefix) / "bin", Path(sys.prefix)):
        for name in (f"python{sys.version_info.major}.{sys.version_info.minor}", "python3", "python",
                     "python.exe"):
            if (folder / name).is_file():
                return str(folder / name)
    raise ExtractionError(f"no Python interpreter found for the UV unwrapper (looked next to "
                          f"{sys.executable} and in {sys.prefix})")


def _cache_dir():
    package = __package__.rpartition(".")[0]
    if package.startswith("bl_ext."):
        return Path(bpy.utils.extension_path_user(package, path="unwrap_cache", create=True))
    return None  # core's default: the user's cache folder (core.lightmap.cache)


def output_folder(settings) -> Path:
    """The absolute lightmap folder of ``settings.output`` (``//`` = the .blend's folder).

    Raises OutputError when it is relative to an unsaved file or files cannot be created in it
    (tried by creating one; folders made for the try are removed again).
    """
    text = settings.output.strip()
    if text.startswith("//") and not bpy.data.filepath:
        raise OutputError(f"lightmap output {text!r} is relative to the .blend file, which is not "
                          f"saved: save it or choose an absolute folder")
    folder = Path(bpy.path.abspath(text)).resolve()
    check_folder(folder, f"lightmaps to {folder}")
    return folder


def object_density(ob):
    """The object's own texel density (its ``DENSITY_PROP``), None where it has none (0): read
    where the add-on keeps it, also when the add-on is not registered (the bpy-module command line)."""
    value = getattr(ob, DENSITY_PROP, None)
    if value is None:
        stored = ob.bl_system_properties_get()  # None when the object holds no such property
        value = stored.get(DENSITY_PROP) if stored is not None else None
    return float(value) if value else None


def _check_uv_name(ob, me) -> None:
    """Raise OutputError when something other than a UV map holds the name ``Lightmap`` on ``me``
    (Blender would call our UV map ``Lightmap.001``, and every rebake add another)."""
    clash = name_clash(ob, me, UV_NAME, "uv")
    if clash is not None:
        raise OutputError(f"{ob.name}: mesh {me.name} already has {clash} named '{UV_NAME}', the name "
                          f"of the lightmap's UV map: rename it")


def _check_uv_room(ob, me) -> None:
    """Raise ExtractionError when ``me`` has no ``Lightmap`` UV map and no room for one."""
    if me.uv_layers.get(UV_NAME) is None and len(me.uv_layers) >= MAX_UV_LAYERS:
        raise ExtractionError(f"mesh {me.name} ({ob.name}) already has {MAX_UV_LAYERS} UV maps, "
                              f"Blender's limit: remove one or add a '{UV_NAME}' UV map to reuse")


def request(extraction, settings) -> tuple[LightmapRequest, list[str]]:
    """What to lightmap (main thread, before the bake), and warnings.

    Objects whose modifiers change the topology are skipped with the message color attributes get;
    a mesh without a ``Lightmap`` UV map that already holds 8 is an error naming it, and so is one
    where another kind of layer is called ``Lightmap`` (OutputError), or a color attribute of that
    name baked alongside.
    """
    if "vertices" in settings.targets and settings.attribute == UV_NAME:
        raise OutputError(f"the color attribute cannot be called '{UV_NAME}' when lightmaps are baked "
                          f"too: their UV map has that name")
    warnings, targets = [], []
    for t in extraction.targets:
        ob = bpy.data.objects.get(t.object_name)
        me = ob.data
        if t.topology_changed or len(me.loops) != t.corner_vert.shape[0]:
            warnings.append(f"{ob.name}: its modifiers change the vertex count ({t.num_vertices} "
                            f"evaluated vs {len(me.vertices)} original); apply the modifiers to "
                            f"lightmap it")
            continue
        if me.library is not None:
            warnings.append(f"{ob.name}: mesh {me.name} is linked from a library: not lightmapped")
            continue
        _check_uv_name(ob, me)
        _check_uv_room(ob, me)
        layer = me.uv_layers.get(UV_NAME)
        corner_uv = None
        if layer is not None and not settings.reunwrap:
            corner_uv = np.empty(len(me.loops) * 2, np.float32)
            layer.uv.foreach_get("vector", corner_uv)
            corner_uv = corner_uv.reshape(-1, 2)
        targets.append(LightmapObject(
            object_name=ob.name, mesh_name=me.name, corner_vert=t.corner_vert,
            corner_triangles=t.corner_triangles,
            triangle_offset=t.triangle_offset, corner_uv=corner_uv,
            density=object_density(ob)))
    if not targets:
        raise ExtractionError("no object can be lightmapped" + (f": {warnings[-1]}" if warnings else ""))
    budget.check(targets, extraction.scene, settings)  # pages too large for memory: stop now
    return LightmapRequest(targets, python=python_executable(), cache_dir=_cache_dir()), warnings


def write_files(result, settings, staging=None, frame=None, folder=None) -> tuple[dict, list]:
    """Write each page as ``<folder>/<page>.exr`` (a tile of a UDIM set as ``<image>.<tile>.exr``;
    ``<page>.<frame>.exr`` for a frame of an animation, four digits: a Blender image sequence)
    plus a ``.png`` preview; returns ({page stem: path of the file Blender loads}, warnings).
    ``.hdr`` instead of ``.exr`` for the ``hdr`` format; an 8-bit format (rgbm, rgbd) adds
    ``<page>.<format>.png``, with a warning where a hot spot's texels are clipped to its range
    (``encodings.page_range``).

    All files are written under temporary names, read back, then moved into place together: on
    any failure (OutputError) the folder is as it was. ``staging``: an ``outputs.Staging`` the
    caller commits (an animation's frames go into place together); ``folder``: the output folder
    when known (it is resolved through Blender, on the main thread).
    """
    folder = folder if folder is not None else output_folder(settings)
    suffix = "" if frame is None else f".{frame:04d}"
    names, _ = _file_names(result.pages)  # prepare() warned of the names it changed
    paths, warnings = {}, []
    with contextlib.ExitStack() as stack:
        own = staging is None
        if own:
            staging = stack.enter_context(Staging())
        for page in result.pages:
            if frame is not None and page.tile is not None:
                # Blender plays no sequence of UDIM tile sets: stop before anything is written.
                raise OutputError(f"the lightmap {page.name} of an animation needs several pages "
                                  f"(a UDIM tile set), which Blender cannot play as an image "
                                  f"sequence: bake with --atlas-pages one or --layout per_object")
            stem = names[page.name] + ("" if page.tile is None else f".{page.tile}") + suffix
            fmt = settings.lightmap_format
            paths[page.stem] = folder / f"{stem}{encodings.SUFFIX[fmt]}"
            if fmt in encodings.EIGHT_BIT:  # Blender shows the float page: a half EXR beside
                paths[page.stem] = folder / f"{stem}.exr"
                with staging.writing(folder / f"{stem}.{fmt}.png") as temp:
                    extras = encodings.write(temp, page.rgb, fmt)
                    files.verify(temp, page.size)
                clipped = encodings.clip_warning(page.rgb, extras["range"],
                                                 f"lightmap {stem}.{fmt}.png")
                warnings += [clipped] if clipped else []
            warnings += _replacing(paths[page.stem], page.objects)
            with staging.writing(paths[page.stem]) as temp:
                encodings.write(temp, page.rgb, "half" if fmt in encodings.EIGHT_BIT else fmt,
                                page.objects)
                files.verify(temp, page.size)
            if page.l1 is not None:  # a directional bake: its layout beside the page
                layout = settings.directional
                with staging.writing(folder / f"{stem}{DIRECTIONAL_SUFFIX[layout]}") as temp:
                    _write_directional(temp, page, layout, settings.lightmap_format)
                    files.verify(temp, (page.size[0], page.size[1] * (4 if layout == "godot" else 1)))
            with staging.writing(folder / f"{stem}.png") as temp:
                files.write_preview(temp, page.rgb)
                files.verify(temp, page.size)
        if own:
            staging.commit()
    return paths, warnings


# The file beside a page that holds its directional layout (``--directional``; manual,
# docs/directional-probes.md).
DIRECTIONAL_SUFFIX = {"sh": ".sh.exr", "godot": ".godot.exr", "unity": ".dir.png"}


def _write_directional(path, page, layout: str, fmt: str) -> None:
    """The directional file of ``page`` (L0 ``rgb``, L1 ``l1``) in ``layout``: sh its L0 and L1
    channels; godot Godot's four layers; unity Unity's direction map (the page is its colour)."""
    precision = fmt if fmt in ("half", "float") else "half"
    if layout == "sh":
        files.write_directional_exr(path, page.rgb, page.l1, precision)
    elif layout == "godot":
        files.write_layers_exr(path, directional.godot_layers(page.rgb, page.l1), precision)
    else:
        files.write_png8(path, directional.unity_direction(page.rgb, page.l1))


@dataclass
class LightmapWrites:
    """The Blender side of a finished lightmap bake, checked: ``uv`` [(mesh, float32[C,2])] to write
    as ``Lightmap`` UV maps, ``hookups`` [(material, page name)] and the warnings found so far."""

    uv: list
    hookups: list
    warnings: list

    def apply(self, result, paths: dict, settings, frames=None) -> list[str]:
        """UV maps, images (loaded from ``paths``, {page stem: exr path}) and material nodes;
        returns all warnings. frames: (first, count) of an animation's image sequences, whose first
        files ``paths`` names."""
        for me, uv in self.uv:
            _write_uv(me, uv)
        warnings = list(self.warnings)
        pack = settings.pack_images and frames is None
        if settings.pack_images and frames is not None:
            warnings.append("lightmap image sequences are not packed (Blender packs single images): "
                            "keep the output folder with the .blend")
        images = {}
        for page in result.pages:  # the tiles of a UDIM set make one image, loaded through any
            if page.name not in images:
                images[page.name] = _load_image(page.name, paths[page.stem], pack, page.tile is not None,
                                                frames is not None)
        for image in images.values():  # the directional file beside it (the glTF export reads it)
            image[DIRECTIONAL_TAG] = settings.directional
        for mat, page in self.hookups:
            warnings += _hook_up(mat, images[page], settings.hookup == "multiply", frames)
        for page in result.pages:  # which image each object is on (what the glTF export reads)
            for name in page.objects:
                _object(name)[OBJECT_TAG] = page.name
        return warnings


def _object(name: str):
    """The mesh object called ``name``; OutputError when it vanished (renamed, deleted, converted)."""
    ob = bpy.data.objects.get(name)
    if ob is None or ob.type != "MESH":
        raise OutputError(f"object {name} no longer exists as a mesh: nothing written")
    return ob


def prepare(result, request: LightmapRequest, settings) -> LightmapWrites:
    """Check, before any file or Blender data is written, that a finished bake can be written:
    objects resolved by name (a mesh renamed meanwhile is found through its object), meshes with
    the corner count they were baked with, room and the name for the UV map. Raises OutputError
    (or ExtractionError for a mesh that now holds 8 UV maps)."""
    owner = {}  # mesh name at extraction -> the object it was read through
    for t in request.targets:
        owner.setdefault(t.mesh_name, t.object_name)
    uv = []
    for mesh_name, corner_uv in result.uv.items():
        ob = _object(owner[mesh_name])
        me = ob.data
        if len(me.loops) != corner_uv.shape[0]:
            raise OutputError(f"{ob.name} changed during the bake ({len(me.loops)} face corners, "
                              f"{corner_uv.shape[0]} baked): nothing written")
        _check_uv_name(ob, me)
        _check_uv_room(ob, me)
        uv.append((me, corner_uv))
    _, warnings = _file_names(result.pages)
    for page in result.pages:
        if files.exr_precision(page.rgb, settings.lightmap_format) != settings.lightmap_format:
            warnings.append(f"lightmap {page.stem} holds values up to {float(page.rgb.max()):.4g}, "
                            f"beyond half float's {files.HALF_MAX:g}: written with 32-bit float "
                            f"channels")
    hookups = []
    shown: dict[str, str] = {}  # material name -> page it shows
    for page in result.pages:
        for name in page.objects:
            ob = _object(name)
            if settings.hookup == "none":
                continue
            for slot in ob.material_slots:
                mat = slot.material
                if mat is None or mat.library is not None or mat.node_tree is None:
                    warnings.append(f"{name}: a material slot has no editable material: "
                                    f"lightmap not hooked up there")
                    continue
                if shown.setdefault(mat.name, page.name) != page.name:
                    warnings.append(f"material {mat.name} is used by objects on lightmaps "
                                    f"{shown[mat.name]} and {page.name}: it shows "
                                    f"{shown[mat.name]}; give the objects their own materials")
                    continue
                hookups.append((mat, page.name))
    return LightmapWrites(uv, hookups, warnings)


def _write_uv(me, uv: np.ndarray) -> None:
    """Create (tagged) or overwrite the ``Lightmap`` UV map; the active and render UV maps stay."""
    layers = me.uv_layers
    active = layers.active.name if layers.active is not None else None
    render = next((l.name for l in layers if l.active_render), None)
    layer = layers.get(UV_NAME)
    if layer is None:
        layer = layers.new(name=UV_NAME, do_init=False)
        me[UV_TAG] = True
    layer.uv.foreach_set("vector", np.nan_to_num(uv).astype(np.float32).ravel())
    if active is not None:
        layers.active = layers[active]
    if render is not None:
        layers[render].active_render = True
    me.update()


def may_replace(folder: Path, path: Path) -> bool:
    """Whether a lightmap bake into ``folder`` may replace the file ``path``: its folder is
    ``folder`` and its name one that lightmap files take (``Lightmap….exr`` / ``.png``: pages,
    tiles and frames alike), compared without case (for case-insensitive file systems)."""
    name = path.name.lower()
    return (name.startswith(ATLAS_NAME.lower()) and path.suffix.lower() in (".exr", ".png")
            and same_file(path.parent, folder))


def _replacing(path: Path, objects: list) -> list:
    """A warning when ``path`` holds the lightmap of other objects, which an earlier bake into the
    folder wrote (e.g. another ``--objects`` bake): a .blend saved by it shows this page now."""
    before = files.objects_of(path) if path.is_file() else None
    if before is None or sorted(before) == sorted(objects):
        return []
    return [f"{path.name} in {path.parent} held the lightmap of {', '.join(before)} (an earlier "
            f"bake into this folder) and now holds {', '.join(objects)}'s: a .blend saved by that "
            "bake shows this lightmap now; bake those objects together, or give each --objects "
            "bake its own --output"]


def _file_names(pages) -> tuple[dict, list]:
    """{page name: its files' name without tile, frame or extension}, safe on every file system and
    unique among ``pages`` without case (names that clean to one, ``a/b`` and ``a_b``, or differ
    only in case get ``_2``, ``_3`` …), and a warning for each name changed so."""
    names, first, warnings = {}, {}, []
    for page in pages:
        if page.name in names:  # the tiles of a UDIM set share one name
            continue
        clean = name = bpy.path.clean_name(page.name)
        k = 1
        while name.lower() in first:
            k += 1
            name = f"{clean}_{k}"
        first[name.lower()] = page.name
        names[page.name] = name
        if name != clean:
            warnings.append(f"lightmaps {first[clean.lower()]} and {page.name} would share the file "
                            f"name {clean}: {page.name} is written as {name}")
    return names, warnings


def _load_image(name: str, path: Path, pack: bool, tiled: bool = False, sequence: bool = False):
    """Our image ``name`` reloaded from ``path`` (with ``tiled``, one tile file of its UDIM set:
    Blender finds the others; with ``sequence``, the first file of an image sequence), or a new
    one loaded from it (a user's image of that name is left alone: Blender gives ours a numbered
    name)."""
    image = next((im for im in bpy.data.images if im.get(IMAGE_TAG) == name), None)
    if image is None:
        image = bpy.data.images.load(str(path), check_existing=False)
        image.name = name
        image[IMAGE_TAG] = name
        image.use_fake_user = True  # kept in the saved file even before a material uses it
    else:  # ours from an earlier bake: point it at the new files
        if image.packed_file is not None or len(image.packed_files):
            image.unpack(method="REMOVE")
        image.source = "FILE"
        image.filepath = str(path)
    # from the file name's tile number Blender finds the whole set, from its frame number the rest
    image.source = "TILED" if tiled else "SEQUENCE" if sequence else "FILE"
    image.reload()
    image.colorspace_settings.name = COLORSPACE
    if pack:
        image.pack()
    return image


def _hook_up(mat, image, multiply: bool, frames=None) -> list[str]:
    """Add (or update) the UV Map + Image Texture pair showing ``image``; with ``multiply`` also a
    Mix (Multiply) node between the Principled BSDF's Base Color and what fed it. frames: (first,
    count) of an image sequence, played with the scene's frames."""
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    uv_node = nodes.get(NODE_UV) or nodes.new("ShaderNodeUVMap")
    uv_node.name, uv_node.label, uv_node.uv_map = NODE_UV, "Lightmap UV", UV_NAME
    tex = nodes.get(NODE_IMAGE) or nodes.new("ShaderNodeTexImage")
    tex.name, tex.label, tex.image, tex.interpolation = NODE_IMAGE, "Lightmap", image, "Linear"
    if not tex.inputs["Vector"].is_linked:
        links.new(uv_node.outputs["UV"], tex.inputs["Vector"])
    if frames is not None:  # file number = scene frame (frame_start − 1 + offset + 1)
        first, count = frames
        user = tex.image_user
        user.frame_start, user.frame_duration, user.frame_offset = first, count, first - 1
        user.use_auto_refresh = True
    left = min((n.location.x for n in nodes if not n.name.startswith(NODE_PREFIX)), default=0.0)
    tex.location = (left - 320.0, -400.0)
    uv_node.location = (left - 520.0, -400.0)
    if not multiply or nodes.get(NODE_MULTIPLY) is not None:
        return []
    bsdf = next((n for n in nodes if n.type == "BSDF_PRINCIPLED"), None)
    if bsdf is None:
        return [f"material {mat.name} has no Principled BSDF: lightmap added but not multiplied"]
    base = bsdf.inputs["Base Color"]
    mix = nodes.new("ShaderNodeMix")
    mix.name, mix.label = NODE_MULTIPLY, "Lightmap Multiply"
    mix.data_type, mix.blend_type = "RGBA", "MULTIPLY"
    _socket(mix.inputs, "Factor_Float").default_value = 1.0
    mix.location = (bsdf.location.x - 220.0, bsdf.location.y - 300.0)
    _socket(mix.inputs, "A_Color").default_value = base.default_value
    if base.is_linked:
        links.new(base.links[0].from_socket, _socket(mix.inputs, "A_Color"))
    links.new(tex.outputs["Color"], _socket(mix.inputs, "B_Color"))
    links.new(_socket(mix.outputs, "Result_Color"), base)
    return []


def _socket(sockets, identifier: str):
    """The socket with this identifier (a Mix node has several sockets of each name)."""
    return next(s for s in sockets if s.identifier == identifier)


def clear(objects) -> int:
    """Remove what bakes added to ``objects``: tagged UV maps, ``RB Lightmap…`` nodes (restoring the
    Base Color link a multiply node took over) and tagged images no longer used. Returns how many
    items were removed. The EXR files on disk stay."""
    removed = 0
    materials = {slot.material for ob in objects for slot in ob.material_slots
                 if slot.material is not None and slot.material.node_tree is not None}
    for mat in materials:
        nodes, links = mat.node_tree.nodes, mat.node_tree.links
        mix = nodes.get(NODE_MULTIPLY)
        if mix is not None:
            a = _socket(mix.inputs, "A_Color")
            source = a.links[0].from_socket if a.is_linked else None
            for link in list(_socket(mix.outputs, "Result_Color").links):
                target = link.to_socket
                links.remove(link)
                if source is not None:
                    links.new(source, target)
        for node in [n for n in nodes if n.name.startswith(NODE_PREFIX)]:
            nodes.remove(node)
            removed += 1
    for ob in objects:
        if ob.get(OBJECT_TAG) is not None:
            del ob[OBJECT_TAG]
    for me in {ob.data for ob in objects if ob.type == "MESH"}:
        if me.get(UV_TAG) and UV_NAME in me.uv_layers:
            me.uv_layers.remove(me.uv_layers[UV_NAME])
            del me[UV_TAG]
            removed += 1
    for image in [im for im in bpy.data.images
                  if im.get(IMAGE_TAG) is not None and im.users == int(im.use_fake_user)]:
        bpy.data.images.remove(image)
        removed += 1
    return removed
