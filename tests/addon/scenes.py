"""Small scenes built in code for the add-on tests (bpy): a lit ground with a shadow."""
import hashlib
import importlib.util
import math
from pathlib import Path

import bpy
import numpy as np

ROOT = Path(__file__).resolve().parents[2]
LAMP_POWER = 1000.0  # W
LAMP_HEIGHT = 3.0  # m above the ground
GROUND = "Ground"
OCCLUDER = "Occluder"
# Ground points (x, y) in m: under the lamp, lit at 2 m from it, and in the occluder's shadow at
# the mirror point (same distance to the lamp).
UNDER_LAMP, LIT, SHADOW = (0.0, 0.0), (-2.0, 0.0), (2.0, 0.0)


def script(path: str):
    """The module of the repository's script at ``path`` (``sample_blends/make_samples.py``),
    loaded from its file (those folders are not packages)."""
    spec = importlib.util.spec_from_file_location(Path(path).stem, ROOT / path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def expected_point_lighting(x: float, y: float) -> float:
    """Lighting (irradiance/π) of an unshadowed ground point from the lamp (DESIGN.md units)."""
    d2 = x * x + y * y + LAMP_HEIGHT ** 2
    return LAMP_POWER / (4 * math.pi ** 2 * d2) * (LAMP_HEIGHT / math.sqrt(d2))


def grid(scene, name: str, size: float, n: int, center=(0.0, 0.0, 0.0)):
    """An n×n-vertex square grid of ``size`` m facing +Z, linked to ``scene``; returns the object."""
    xs = np.linspace(-size / 2, size / 2, n)
    verts = [(center[0] + x, center[1] + y, center[2]) for y in xs for x in xs]
    faces = [(j * n + i, j * n + i + 1, (j + 1) * n + i + 1, (j + 1) * n + i)
             for j in range(n - 1) for i in range(n - 1)]
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(verts, [], faces)
    ob = bpy.data.objects.new(name, mesh)
    scene.collection.objects.link(ob)
    return ob


def lit_ground(scene):
    """A 6 m ground (25×25 vertices, 0.25 m apart) under a point lamp 3 m up, and a 0.6 m square
    occluder halfway between the lamp and the ground point SHADOW, whose shadow (1.2 m wide)
    covers it. No materials (grey 0.8)."""
    grid(scene, GROUND, 6.0, 25)
    grid(scene, OCCLUDER, 0.6, 3, center=(SHADOW[0] / 2, SHADOW[1] / 2, LAMP_HEIGHT / 2))
    light = bpy.data.lights.new("Lamp", 'POINT')
    light.energy = LAMP_POWER
    light.shadow_soft_size = 0.0
    lamp = bpy.data.objects.new("Lamp", light)
    lamp.location = (0.0, 0.0, LAMP_HEIGHT)
    scene.collection.objects.link(lamp)
    bpy.context.view_layer.update()


def fast_settings(scene, **overrides) -> None:
    """Settings that keep a test bake short: direct light, few samples."""
    s = scene.radiosity_baker
    s.method = "direct"
    s.light_samples = 4
    for name, value in overrides.items():
        setattr(s, name, value)


def vertex_colors(mesh, name: str) -> np.ndarray:
    """float32[N,4] of the POINT colour attribute ``name``."""
    attr = mesh.attributes[name]
    out = np.empty(len(mesh.vertices) * 4, np.float32)
    attr.data.foreach_get("color", out)
    return out.reshape(-1, 4)


def value_at(mesh, name: str, xy) -> np.ndarray:
    """RGB of attribute ``name`` at the vertex of ``mesh`` nearest to the ground point ``xy``."""
    co = np.empty(len(mesh.vertices) * 3, np.float32)
    mesh.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3)
    i = int(np.argmin(np.linalg.norm(co[:, :2] - np.asarray(xy, np.float32), axis=1)))
    return vertex_colors(mesh, name)[i, :3]


def snapshot() -> dict:
    """What a bake may change: objects, meshes with their attribute names and vertex positions."""
    out = {"objects": sorted(bpy.data.objects.keys()), "materials": sorted(bpy.data.materials.keys())}
    for mesh in bpy.data.meshes:
        co = np.empty(len(mesh.vertices) * 3, np.float32)
        mesh.vertices.foreach_get("co", co)
        out[mesh.name] = (sorted(mesh.attributes.keys()), co.tobytes())
    return out


# Attribute data type -> (foreach property, values per element, dtype) for reading any attribute.
_ATTRIBUTE_READ = {"FLOAT_COLOR": ("color", 4, np.float32), "BYTE_COLOR": ("color", 4, np.float32),
                   "FLOAT2": ("vector", 2, np.float32), "FLOAT_VECTOR": ("vector", 3, np.float32),
                   "INT32_2D": ("value", 2, np.int32), "INT": ("value", 1, np.int32),
                   "INT8": ("value", 1, np.int32), "FLOAT": ("value", 1, np.float32),
                   "BOOLEAN": ("value", 1, bool), "QUATERNION": ("value", 4, np.float32)}


def mesh_data(mesh, skip=()) -> dict:
    """Every attribute of ``mesh`` but those named in ``skip`` — (domain, type, bytes of its data)
    — plus the UV maps' names and active / render flags and the active / render colour attribute."""
    out = {}
    for attr in mesh.attributes:
        if attr.name in skip:
            continue
        prop, width, dtype = _ATTRIBUTE_READ[attr.data_type]
        data = np.empty(len(attr.data) * width, dtype)
        attr.data.foreach_get(prop, data)
        out[attr.name] = (attr.domain, attr.data_type, data.tobytes())
    out["uv"] = [(uv.name, uv.active, uv.active_render) for uv in mesh.uv_layers if uv.name not in skip]
    out["colors"] = (mesh.color_attributes.active_color_name, mesh.color_attributes.default_color_name)
    out["materials"] = [m.name if m else None for m in mesh.materials]
    return out


def user_data(skip=()) -> dict:
    """What a bake must leave byte-identical in the open file: every mesh's data (``mesh_data``,
    layers named in ``skip`` left out), vertex groups, images (the baker's own lightmaps left out)
    and materials (nodes, their inputs' values, links)."""
    out = {"objects": sorted((ob.name, ob.type, ob.data.name if ob.data else None, tuple(ob.matrix_world.col[3]),
                              tuple(g.name for g in ob.vertex_groups)) for ob in bpy.data.objects)}
    for mesh in bpy.data.meshes:
        out[f"mesh {mesh.name}"] = mesh_data(mesh, skip)
    for image in bpy.data.images:
        if image.get("radiosity_baker_lightmap") is None:
            packed = image.packed_file.data if image.packed_file else b""
            out[f"image {image.name}"] = (tuple(image.size), image.source, image.filepath,
                                          hashlib.sha256(packed).hexdigest())
    for mat in bpy.data.materials:
        tree = mat.node_tree
        nodes = [] if tree is None else sorted(
            (n.name, n.bl_idname, tuple((s.identifier, _value(s)) for s in n.inputs)) for n in tree.nodes)
        links = [] if tree is None else sorted(
            (l.from_node.name, l.from_socket.identifier, l.to_node.name, l.to_socket.identifier)
            for l in tree.links)
        out[f"material {mat.name}"] = (tuple(mat.diffuse_color), nodes, links)
    return out


def _value(socket):
    value = getattr(socket, "default_value", None)
    return tuple(value) if hasattr(value, "__len__") and not isinstance(value, str) else value
