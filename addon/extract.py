"""Blender scene -> :class:`~radiosity_baker.core.scene.SceneData`.

Everything the render would show is read as the depsgraph evaluates it: modifiers, shape keys,
armatures, curves / text / surfaces / metaballs (the depsgraph hands them out converted, as mesh
instances of themselves), collection and geometry-nodes instances (each with its own world
matrix). The Python depsgraph is the viewport one, so render visibility (``hide_render`` of
objects, collections and instancers) is applied here.

All per-vertex, per-corner and per-triangle work is vectorised with ``foreach_get`` and numpy;
Python only loops over objects, instances and materials.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import bpy
import numpy as np

from ..core.elements import shading_vertices
from ..core.scene import (LAMP_AREA, LAMP_POINT, LAMP_SPOT, LAMP_SUN, SHAPE_ELLIPSE,
                          SHAPE_RECTANGLE, Lamps, SceneData, detail_centre)
from .tags import NODE_MULTIPLY

# Object types whose evaluated geometry is a surface (others: empties, cameras, hair, volumes…).
# The depsgraph hands the non-mesh ones out already converted, as a mesh instance of themselves.
_SURFACE_TYPES = {"MESH", "CURVE", "SURFACE", "FONT", "META"}
_GREY = (0.8, 0.8, 0.8)
# A coordinate (m) beyond this is taken for infinite: Blender stores an infinite one as FLT_MAX
# (3.4e38), and squared distances overflow float32 from about 1.8e19 m.
_LARGEST_COORDINATE = 1e18
# Custom property on an object made by realize_copy: the name of the object it was made from.
COPY_SOURCE_PROPERTY = "radiosity_baker_source"
# Barycentric points averaged when an image texture is sampled over a triangle: the centroid and
# the centres of the three sub-triangles towards each corner.
_TEXTURE_BARY = np.array([[1 / 3, 1 / 3, 1 / 3], [2 / 3, 1 / 6, 1 / 6], [1 / 6, 2 / 3, 1 / 6],
                          [1 / 6, 1 / 6, 2 / 3]], np.float32)


class ExtractionError(Exception):
    """The scene cannot be extracted; the message names the object."""


@dataclass
class TargetMesh:
    """One receiver object whose per-vertex results can be written back.

    object_name: name of the original object.
    mesh_name: ``ob.data.name`` of the original object.
    corner_shading: int32[C], for each face corner (loop) of the evaluated mesh, the global
        shading-vertex index (``core.elements.shading_vertices`` of the extracted scene: where the
        bake's per-shading-vertex results are).
    corner_vert: int32[C], evaluated mesh corner -> vertex index.
    num_vertices: vertex count of the evaluated mesh.
    topology_changed: the evaluated vertex count differs from the original ``ob.data`` one
        (modifiers added or removed vertices), so results do not map onto the original mesh.
    corner_triangles: int32[T,3], the face corners of each of the object's triangles, in the order
        of its triangles in ``SceneData`` (which start at ``triangle_offset``) and of their corners.
    """

    object_name: str
    mesh_name: str
    corner_shading: np.ndarray
    corner_vert: np.ndarray
    num_vertices: int
    topology_changed: bool
    corner_triangles: np.ndarray = None
    triangle_offset: int = 0


@dataclass
class Extraction:
    """The extracted scene, its shading vertices (``core.elements.ShadingVertices``: where the
    bake's per-vertex results are), the objects results can be written to, and what the user
    should know."""

    scene: SceneData
    shading: object = None
    targets: list = field(default_factory=list)
    warnings: list = field(default_factory=list)

    def adopt(self, shading) -> None:
        """Map the targets' face corners to ``shading`` (``core.elements.ShadingVertices`` of these
        triangles: where a bake's per-vertex results are)."""
        self.shading = shading
        for t in self.targets:
            t.corner_shading = np.empty(t.corner_vert.shape[0], np.int32)
            span = slice(t.triangle_offset, t.triangle_offset + t.corner_triangles.shape[0])
            t.corner_shading[t.corner_triangles] = shading.corner[span]


# ----------------------------------------------------------------------------------------------
# materials


@dataclass
class _Texture:
    """An image texture feeding a colour socket: linear RGB pixels float32[H,W,3], row 0 bottom."""

    pixels: np.ndarray
    uv_map: str  # "" = the mesh's active render UV map
    repeat: bool


@dataclass
class _Shading:
    """What a material contributes: colours are an RGB tuple or a _Texture."""

    albedo: object
    emission: object
    emission_strength: float


class _Materials:
    """Converts materials once each (keyed by pointer) and paints them onto triangles."""

    def __init__(self, warnings: list):
        self._warnings = warnings
        self._shading: dict[int, _Shading] = {}
        self._images: dict[int, np.ndarray] = {}
        self._warned: set = set()

    def _warn(self, message: str) -> None:
        if message not in self._warned:
            self._warned.add(message)
            self._warnings.append(message)

    def shading(self, mat) -> _Shading:
        key = mat.as_pointer()
        if key not in self._shading:
            self._shading[key] = self._convert(mat)
        return self._shading[key]

    def _convert(self, mat) -> _Shading:
        fallback = _Shading(tuple(mat.diffuse_color[:3]), (0.0, 0.0, 0.0), 0.0)
        tree = mat.node_tree
        output = None
        if tree is not None:
            for target in ("ALL", "CYCLES", "EEVEE"):
                output = tree.get_output_node(target)
                if output is not None:
                    break
        surface = output.inputs.get("Surface") if output is not None else None
        shader = _linked_node(surface)
        if shader is None:
            self._warn(f"material {mat.name} has no surface shader: its viewport colour is used")
            return fallback
        black = (0.0, 0.0, 0.0)
        if shader.type == "BSDF_PRINCIPLED":
            strength = float(shader.inputs["Emission Strength"].default_value)
            emission = self._colour(mat, shader.inputs["Emission Color"]) if strength else black
            return _Shading(self._colour(mat, shader.inputs["Base Color"]), emission, strength)
        if shader.type == "BSDF_DIFFUSE":
            return _Shading(self._colour(mat, shader.inputs["Color"]), black, 0.0)
        if shader.type == "EMISSION":
            return _Shading(black, self._colour(mat, shader.inputs["Color"]),
                            float(shader.inputs["Strength"].default_value))
        self._warn(f"material {mat.name} uses a {shader.bl_label} shader, which the baker does not "
                   f"read: its viewport colour is used")
        return fallback

    def _colour(self, mat, socket):
        """RGB tuple of an unlinked socket, a _Texture for a linked Image Texture (read through
        the Multiply node of a lightmap hook-up: the material's own colour)."""
        socket = _before_lightmap_multiply(socket)
        node = _linked_node(socket)
        constant = tuple(socket.default_value[:3])
        if node is None:
            return constant
        if node.type == "TEX_IMAGE" and node.image is not None:
            pixels = self._pixels(node.image)
            if pixels is not None:
                uv_node = _linked_node(node.inputs["Vector"])
                uv_map = uv_node.uv_map if uv_node is not None and uv_node.type == "UVMAP" else ""
                return _Texture(pixels, uv_map, node.extension == "REPEAT")
            self._warn(f"material {mat.name}: image {node.image.name} has no pixels: "
                       f"{socket.name} {_fmt(constant)} used")
            return constant
        self._warn(f"material {mat.name}: {socket.name} comes from a {node.bl_label} node, which "
                   f"the baker does not read: {_fmt(constant)} used")
        return constant

    def _pixels(self, image):
        """Linear RGB float32[H,W,3] of ``image`` (row 0 at the bottom), None without pixels."""
        key = image.as_pointer()
        if key not in self._images:
            width, height = image.size  # asking for the size loads a file image
            px = np.empty(width * height * image.channels, np.float32)
            try:
                image.pixels.foreach_get(px)
            except RuntimeError:
                px = px[:0]
            if px.size == 0:
                self._images[key] = None
            else:
                px = px.reshape(height, width, image.channels)
                rgb = px[..., :3] if image.channels >= 3 else np.repeat(px[..., :1], 3, axis=2)
                # Byte images hand out their stored (display-encoded) values; float ones are linear.
                if not image.is_float and image.colorspace_settings.name == "sRGB":
                    rgb = _srgb_to_linear(rgb)
                self._images[key] = np.ascontiguousarray(rgb, np.float32)
        return self._images[key]

    def paint(self, me, materials: list, loops: np.ndarray, tri_material: np.ndarray,
              object_name: str):
        """(per-triangle albedo and emission, float32[T,3] each; whether some triangle has no
        material: grey 0.8).

        materials: the object's material per slot (None for an empty slot); loops: int32[T,3]
        corners of each triangle; tri_material: int32[T] slot index of each triangle.
        """
        t = tri_material.shape[0]
        albedo = np.empty((t, 3), np.float32)
        emission = np.zeros((t, 3), np.float32)
        materials = materials or [None]
        # Blender clamps a material index past the last slot to the last slot.
        slot = np.clip(tri_material, 0, len(materials) - 1)
        uv_cache: dict[str, np.ndarray] = {}
        bare = False
        for s in np.unique(slot):
            mat = materials[s]
            mask = slot == s
            if mat is None:
                albedo[mask] = _GREY
                bare = True
                continue
            shading = self.shading(mat)
            albedo[mask] = self._evaluate(shading.albedo, me, loops, mask, uv_cache, object_name)
            if shading.emission_strength != 0.0:
                emission[mask] = shading.emission_strength * self._evaluate(
                    shading.emission, me, loops, mask, uv_cache, object_name)
        return albedo, emission, bare

    def _evaluate(self, colour, me, loops, mask, uv_cache, object_name):
        if not isinstance(colour, _Texture):
            return np.asarray(colour, np.float32)
        name = colour.uv_map or _render_uv_name(me)
        if name is None or name not in me.uv_layers:
            missing = f"UV map {colour.uv_map}" if colour.uv_map else "UV map"
            self._warn(f"object {object_name} has no {missing}: the image's mean colour is used")
            return colour.pixels.reshape(-1, 3).mean(axis=0)
        if name not in uv_cache:
            uv = np.empty(len(me.loops) * 2, np.float32)
            me.uv_layers[name].uv.foreach_get("vector", uv)
            uv_cache[name] = uv.reshape(-1, 2)
        tri_uv = uv_cache[name][loops[mask]]                       # [t,3,2]
        points = np.einsum("sk,tkc->tsc", _TEXTURE_BARY, tri_uv)   # [t,samples,2]
        return _sample(colour, points).mean(axis=1)


def _linked_node(socket):
    """The node feeding ``socket`` (through reroutes), or None when unlinked."""
    while socket is not None and socket.is_linked:
        link = socket.links[0]
        if not link.is_valid or link.is_muted:
            return None
        node = link.from_node
        if node.type != "REROUTE":
            return node
        socket = node.inputs[0]
    return None


def _before_lightmap_multiply(socket):
    """The socket that held ``socket``'s value before ``--hookup multiply`` put its Multiply node in
    between (its A input, which took over the link or the value); ``socket`` itself otherwise."""
    node = _linked_node(socket)
    while node is not None and node.name == NODE_MULTIPLY:
        socket = next(s for s in node.inputs if s.identifier == "A_Color")
        node = _linked_node(socket)
    return socket


def _within_range(values: np.ndarray) -> bool:
    """Whether every coordinate of ``values`` is a number within ±_LARGEST_COORDINATE (m): NaN,
    infinite and FLT_MAX ones are not (compared without numpy warnings)."""
    return bool((np.abs(values) <= _LARGEST_COORDINATE).all())


def _render_uv_name(me):
    for layer in me.uv_layers:
        if layer.active_render:
            return layer.name
    return me.uv_layers[0].name if len(me.uv_layers) else None


def _sample(texture: _Texture, uv: np.ndarray) -> np.ndarray:
    """Nearest-texel lookup of float32[...,2] UVs -> float32[...,3]."""
    h, w = texture.pixels.shape[:2]
    x = np.floor(uv[..., 0] * w).astype(np.int64)
    y = np.floor(uv[..., 1] * h).astype(np.int64)
    if texture.repeat:
        x, y = np.mod(x, w), np.mod(y, h)
    else:
        x, y = np.clip(x, 0, w - 1), np.clip(y, 0, h - 1)
    return texture.pixels[y, x]


def _srgb_to_linear(c: np.ndarray) -> np.ndarray:
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _fmt(rgb) -> str:
    return "(" + ", ".join(f"{x:.3g}" for x in rgb) + ")"


# ----------------------------------------------------------------------------------------------
# geometry


@dataclass
class _Geometry:
    """One evaluated mesh in its local space, read once and shared by all its instances.

    positions: float32[V,3] vertices; corner_normals: float32[C,3] shading normal per face corner;
    triangles: int32[T,3] vertex indices; albedo, emission: float32[T,3]; corner_vert: int32[C];
    loops: int32[T,3] face corners of each triangle; num_vertices: mesh vertex count; bare:
    some triangle has no material (grey 0.8).
    """

    positions: np.ndarray
    corner_normals: np.ndarray
    triangles: np.ndarray
    albedo: np.ndarray
    emission: np.ndarray
    corner_vert: np.ndarray
    num_vertices: int
    loops: np.ndarray
    bare: bool = False


def _read_attribute(me, name, domain_size, width, dtype, fallback):
    """foreach_get of a generic attribute (fast path), else of a legacy collection property."""
    out = np.empty(domain_size * width, dtype)
    attr = me.attributes.get(name)
    if attr is not None:
        attr.data.foreach_get("vector" if width == 3 else "value", out)
    else:
        collection, prop = fallback
        getattr(me, collection).foreach_get(prop, out)
    return out.reshape(-1, width) if width > 1 else out


def _read_mesh(me, materials: list, palette: _Materials, object_name: str):
    """Vertices, corner normals, triangles and colours of an evaluated mesh; None when it has no
    faces."""
    nv, nc, nt = len(me.vertices), len(me.loops), len(me.loop_triangles)
    if nt == 0:
        return None
    positions = _read_attribute(me, "position", nv, 3, np.float32, ("vertices", "co"))
    if not _within_range(positions):
        raise ExtractionError(f"object {object_name} has NaN or infinite vertex positions")
    corner_vert = _read_attribute(me, ".corner_vert", nc, 1, np.int32, ("loops", "vertex_index"))
    loops = np.empty(nt * 3, np.int32)
    me.loop_triangles.foreach_get("loops", loops)
    loops = loops.reshape(nt, 3)
    tri_poly = np.empty(nt, np.int32)
    me.loop_triangle_polygons.foreach_get("value", tri_poly)
    corner_normals = np.empty(nc * 3, np.float32)
    me.corner_normals.foreach_get("vector", corner_normals)
    corner_normals = np.nan_to_num(corner_normals.reshape(nc, 3))
    if "material_index" in me.attributes:
        poly_material = _read_attribute(me, "material_index", len(me.polygons), 1, np.int32, None)
    else:
        poly_material = np.zeros(len(me.polygons), np.int32)
    albedo, emission, bare = palette.paint(me, materials, loops, poly_material[tri_poly], object_name)
    return _Geometry(positions=positions, corner_normals=corner_normals,
                     triangles=corner_vert[loops], albedo=albedo, emission=emission,
                     corner_vert=corner_vert, num_vertices=nv, loops=loops, bare=bare)


def _object_materials(ob, me) -> list:
    """Material per slot as the evaluated object sees it (object-linked slots included)."""
    if len(ob.material_slots):
        return [slot.material for slot in ob.material_slots]
    return list(me.materials)


def _transform(geom: _Geometry, matrix: np.ndarray, name: str):
    """World positions (float64[V,3]), per-triangle-corner normals (float32[T,3,3]), CCW triangles
    (int32[T,3]) and their face corners (int32[T,3], in the same corner order) of ``geom`` under
    ``matrix``."""
    linear, offset = matrix[:3, :3], matrix[:3, 3]
    invalid = f"object {name} has NaN or infinite vertex positions in world space"
    if not _within_range(matrix):  # first: inf × 0 would make NaN, with a numpy warning
        raise ExtractionError(invalid)
    positions = geom.positions.astype(np.float64) @ linear.T + offset
    if not _within_range(positions):
        raise ExtractionError(invalid)
    normal_matrix = np.linalg.pinv(linear).T  # pinv: a zero-scaled axis must not raise
    normals = geom.corner_normals.astype(np.float64) @ normal_matrix.T
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    normals = np.where(length > 0, normals / np.where(length > 0, length, 1.0), (0.0, 0.0, 1.0))
    loops = geom.loops
    if np.linalg.det(linear) < 0:  # a mirror reverses the winding seen from the normal side
        loops = loops[:, [0, 2, 1]]
    return positions, normals.astype(np.float32)[loops], geom.corner_vert[loops], loops


# ----------------------------------------------------------------------------------------------
# visibility


def _render_collections(view_layer) -> set:
    """Pointers of the collections of ``view_layer`` that render (not excluded, not hide_render,
    nor any ancestor)."""
    visible = set()
    stack = [view_layer.layer_collection]
    while stack:
        lc = stack.pop()
        if lc.exclude or lc.collection.hide_render:
            continue
        visible.add(lc.collection.as_pointer())
        stack.extend(lc.children)
    return visible


def _renders(ob, collections: set) -> bool:
    """Whether an original object in the view layer shows in a render."""
    return not ob.hide_render and any(c.as_pointer() in collections for c in ob.users_collection)


# ----------------------------------------------------------------------------------------------
# lamps


def _lamp(light, matrix: np.ndarray, name: str):
    """One lamp's fields (see core.scene.Lamps) from bpy Light data and its world matrix."""
    axes = matrix[:3, :3]
    scale = np.linalg.norm(axes, axis=0)
    unit = axes / np.where(scale > 0, scale, 1.0)
    size = (light.shadow_soft_size, 0.0)
    shape = SHAPE_RECTANGLE
    kind = {"POINT": LAMP_POINT, "SPOT": LAMP_SPOT, "SUN": LAMP_SUN, "AREA": LAMP_AREA}[light.type]
    if kind == LAMP_SUN:
        size = (light.angle, 0.0)
    elif kind == LAMP_AREA:
        sy = light.size_y if light.shape in {"RECTANGLE", "ELLIPSE"} else light.size
        size = (light.size * scale[0], sy * scale[1])
        shape = SHAPE_ELLIPSE if light.shape in {"DISK", "ELLIPSE"} else SHAPE_RECTANGLE
    spot = (light.spot_size, light.spot_blend) if kind == LAMP_SPOT else (0.0, 0.0)
    return dict(kind=kind, position=matrix[:3, 3], direction=-unit[:, 2], axis_u=unit[:, 0],
                axis_v=unit[:, 1], size=size, shape=shape,
                power=np.asarray(light.color[:3]) * light.energy, spot_size=spot[0],
                spot_blend=spot[1], name=name)


def _lamps(items: list) -> Lamps:
    if not items:
        return Lamps.empty()

    def col(key, dtype):
        return np.asarray([x[key] for x in items], dtype)

    return Lamps(kind=col("kind", np.int32), position=col("position", np.float64),
                 direction=col("direction", np.float32), axis_u=col("axis_u", np.float32),
                 axis_v=col("axis_v", np.float32), size=col("size", np.float32),
                 shape=col("shape", np.int32), power=col("power", np.float32),
                 spot_size=col("spot_size", np.float32), spot_blend=col("spot_blend", np.float32),
                 names=[x["name"] for x in items])


# ----------------------------------------------------------------------------------------------
# the scene


def extract_scene(depsgraph, receivers=None) -> Extraction:
    """Extract everything ``depsgraph`` shows in a render as SceneData (world space, metres).

    receivers: original bpy objects whose results will be written (None: every visible mesh
    object); a target is made for each one that is a visible mesh with faces, the others get a
    warning. The whole visible scene is always extracted, since it casts light and shadow, except
    copies made by :func:`realize_copy` while their source renders (they would double it).
    Raises ExtractionError for NaN / infinite geometry (naming the object) or when nothing has faces.
    """
    warnings: list[str] = []
    palette = _Materials(warnings)
    collections = _render_collections(depsgraph.view_layer)
    receiver_names = None if receivers is None else {ob.name: ob for ob in receivers}
    geometries: dict = {}      # (data pointer, materials) -> _Geometry or None
    parts = []                 # (positions, corner normals, triangles, albedo, emission, object)
    names: list[str] = []
    targets: list[TargetMesh] = []
    lamp_items: list = []
    seen: set = set()
    no_faces: list[str] = []
    instancers: set = set()
    converted: list[str] = []  # curves, text …: in the scene's light, not written
    bare: list[str] = []       # objects with faces of no material
    offset = 0
    triangle_offset = 0

    for inst in depsgraph.object_instances:
        ob = inst.object
        if inst.is_instance:
            parent = inst.parent.original
            instancers.add(parent.name)
            if not _renders(parent, collections) or ob.original.hide_render:
                continue
            # Curves, text, surfaces and metaballs arrive as a mesh instance of themselves.
            name = parent.name if ob.original == parent else f"{parent.name}/{ob.name}"
            if ob.original == parent and parent.type != "MESH" and ob.type == "MESH":
                converted.append(name)
        else:
            original = ob.original
            seen.add(original.name)
            if not _renders(original, collections):
                continue
            # The viewport decides show_self; a render shows an instancer as its own flag says.
            if original.is_instancer and not original.show_instancer_for_render:
                continue
            if _is_copy_of_rendered(original, collections, receiver_names):
                continue
            name = original.name
            _warn_viewport_modifiers(original, warnings)
        # Instances are only valid inside this loop: copy the matrix now.
        matrix = np.array(inst.matrix_world, np.float64)

        if ob.type == "LIGHT":
            lamp_items.append(_lamp(ob.data, matrix, name))
            continue
        if ob.type != "MESH":
            # Other types' surfaces come as the mesh instance above (converted by the depsgraph).
            continue
        materials = _object_materials(ob, ob.data)
        key = (ob.data.as_pointer(), tuple(m.as_pointer() if m else 0 for m in materials))
        if key not in geometries:
            geometries[key] = _read_mesh(ob.data, materials, palette, name)
        geom = geometries[key]
        if geom is None:
            no_faces.append(name)
            continue

        if geom.bare:
            bare.append(name)
        positions, normals, triangles, loops = _transform(geom, matrix, name)
        parts.append((positions, normals, triangles + offset, geom.albedo, geom.emission,
                      len(names)))
        names.append(name)
        if not inst.is_instance and (receiver_names is None or name in receiver_names):
            original = ob.original
            targets.append(TargetMesh(
                object_name=name, mesh_name=original.data.name, corner_shading=None,
                corner_vert=geom.corner_vert, num_vertices=geom.num_vertices,
                topology_changed=geom.num_vertices != len(original.data.vertices),
                corner_triangles=loops, triangle_offset=triangle_offset))
        offset += positions.shape[0]
        triangle_offset += triangles.shape[0]

    # An object whose geometry nodes output only instances has no faces of its own: not news.
    warnings += _fold([n for n in dict.fromkeys(no_faces) if n not in instancers],
                      "{name} has no faces: skipped", "{count} objects have no faces: skipped ({names})")
    warnings += _fold(list(dict.fromkeys(bare)), "object {name} has no material: grey 0.8 used",
                      "{count} objects have no material: grey 0.8 used ({names})")
    if receiver_names is None:
        warnings += _fold(list(dict.fromkeys(converted)),
                          "{name} casts light and shadow but takes no results (only meshes do): "
                          "convert it to a mesh (Object › Convert › Mesh) to bake it",
                          "{count} curve, text, surface or metaball objects cast light and shadow but "
                          "take no results (only meshes do): {names}; convert them to meshes "
                          "(Object › Convert › Mesh) to bake them")
    _warn_unseen(depsgraph, collections, seen, warnings)
    if receiver_names is not None:
        made = {t.object_name for t in targets}
        for rname, rob in receiver_names.items():
            if rname in made or (rname in no_faces and rname not in instancers):
                continue
            if rob.type != "MESH":
                warnings.append(f"{rname} is not a mesh: its results cannot be written")
            elif rname in instancers:
                warnings.append(f"{rname} has no faces of its own, only instances: not baked")
            else:
                warnings.append(f"{rname} is not visible in renders: not baked")
    if not parts:
        raise ExtractionError("nothing to bake: no visible object with faces")

    def cat(i):
        return np.concatenate([p[i] for p in parts])

    tri_object = np.concatenate([np.full(p[2].shape[0], p[5], np.int32) for p in parts])
    # Positions are kept relative to a point amid the scene's detail, computed in double
    # precision, so a scene far from the world origin keeps float32 precision (core.scene).
    world = cat(0)
    triangles = cat(2).astype(np.int32)
    centre = detail_centre(world, triangles, tri_object, len(names))
    lamps = _lamps(lamp_items)
    lamps.position = (lamps.position.astype(np.float64) - centre).astype(np.float32)
    scene = SceneData(positions=(world - centre).astype(np.float32), corner_normals=cat(1),
                      triangles=triangles, tri_object=tri_object, albedo=cat(3),
                      emission=cat(4), lamps=lamps, object_names=names,
                      ao_distance=_ao_distance(depsgraph.scene), origin=centre)
    # Results come per shading vertex (split by core where a vertex's normals differ).
    extraction = Extraction(scene=scene, targets=targets, warnings=warnings)
    extraction.adopt(shading_vertices(scene))
    return extraction


def _ao_distance(scene) -> float:
    """The world's AO distance (m); Blender's default, 10 m, for a scene without a world."""
    world = scene.world
    return float(world.light_settings.distance) if world is not None else 10.0


def _warn_viewport_modifiers(ob, warnings: list) -> None:
    """The depsgraph evaluates modifiers with their viewport settings: say where a render differs."""
    for mod in ob.modifiers:
        if mod.show_viewport != mod.show_render:
            state = "on" if mod.show_viewport else "off"
            warnings.append(f"{ob.name}: modifier {mod.name} is {state} in the viewport but not in "
                            f"renders: baked as the viewport shows it")
        elif mod.show_viewport and getattr(mod, "levels", None) != getattr(mod, "render_levels", None):
            warnings.append(f"{ob.name}: modifier {mod.name} has {mod.levels} viewport levels and "
                            f"{mod.render_levels} render levels: baked with the viewport's")


def _is_copy_of_rendered(ob, collections: set, receiver_names) -> bool:
    """Whether ``ob`` is a copy made by :func:`realize_copy` whose source object also renders (and
    the copy is not an explicit receiver): both in the scene would put the geometry there twice."""
    source = bpy.data.objects.get(ob.get(COPY_SOURCE_PROPERTY, ""))
    if source is None or receiver_names is not None and ob.name in receiver_names:
        return False
    return _renders(source, collections)


# Objects a folded warning names before saying how many more.
FOLD = 5


def _fold(names: list, one: str, many: str) -> list[str]:
    """One warning for the objects ``names`` (in order, each once), none for none: ``one`` with
    {name} for one object, else ``many`` with {count} and {names} (the first FOLD names, then how
    many more), so ten thousand objects make one line, not ten thousand."""
    if len(names) <= 1:
        return [one.format(name=n) for n in names]
    shown = ", ".join(names[:FOLD]) + (f" and {len(names) - FOLD:,} more" if len(names) > FOLD else "")
    return [many.format(count=f"{len(names):,}", names=shown)]


def _warn_unseen(depsgraph, collections: set, seen: set, warnings: list) -> None:
    """Warn about objects a render shows but the viewport depsgraph left out (hidden in the
    viewport): the Python API offers no render depsgraph, so they cannot be baked as they are."""
    view_layer = depsgraph.view_layer
    for ob in view_layer.objects:
        if (ob.name not in seen and (ob.type in _SURFACE_TYPES or ob.type == "LIGHT")
                and _renders(ob, collections) and not ob.visible_get(view_layer=view_layer)):
            warnings.append(f"{ob.name} renders but is hidden in the viewport: not included "
                            f"(unhide it to bake it)")


def realize_copy(context, obj):
    """A new object ``<obj.name>_baked`` holding ``obj``'s evaluated mesh (modifiers applied), in
    the same collections, with the same world matrix and materials; ``obj`` is not modified.

    The copy's vertices are the evaluated mesh's, in the same order, so per-vertex results of the
    evaluated mesh map onto it one-to-one. An existing copy of ``obj`` of that name (a previous
    bake into a copy) is reused: its mesh is replaced. The copy records its source in the custom
    property ``radiosity_baker_source``; extract_scene leaves such a copy out while its source
    renders, so a rebake does not see the geometry twice.
    """
    depsgraph = context.evaluated_depsgraph_get()
    ob_eval = obj.evaluated_get(depsgraph)
    name = f"{obj.name}_baked"
    mesh = bpy.data.meshes.new_from_object(ob_eval, preserve_all_data_layers=True,
                                           depsgraph=depsgraph)
    mesh.name = name
    copy = bpy.data.objects.get(name)
    if copy is not None and copy.get(COPY_SOURCE_PROPERTY) == obj.name and copy.library is None:
        old = copy.data
        copy.data = mesh
        if old.users == 0:
            bpy.data.meshes.remove(old)
    else:
        copy = bpy.data.objects.new(name, mesh)
        copy[COPY_SOURCE_PROPERTY] = obj.name
        for collection in obj.users_collection:
            collection.objects.link(copy)
    copy.matrix_world = obj.matrix_world.copy()
    for src, dst in zip(obj.material_slots, copy.material_slots):
        if src.link == "OBJECT":
            dst.link = "OBJECT"
            dst.material = src.material
    return copy
