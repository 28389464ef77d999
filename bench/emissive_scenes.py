"""Scenes built in code for ``bench/accuracy.py`` (issue 20): light from emissive surfaces.

- ``flat_furnace``: a closed flat-shaded icosphere (Blender's subdivisions 3: 320 triangles) seen from
  inside, every face emitting radiance 1 with albedo 0.5: lighting 2 at every vertex
  (B = E/(1−ρ)), direct light 1.
- ``emissive_room``: a closed 4 × 3 × 2.6 m room (albedo 0.7, 0.2 m cells) with a block on the
  floor, lit by a neon sign — a wavy tube of 2 304 emissive triangles 8 cm in front of the back
  wall —, a glowing tube lying on the floor and two point lamps.

Each builder empties the open file (Blender's bpy module) and adds its objects; the materials are
matte Principled BSDFs (Specular IOR Level 0), emitters black with Emission Strength × Color.
"""
from __future__ import annotations

import importlib.util
from pathlib import Path

import bmesh
import bpy
import numpy as np

# sample_blends/make_samples.py (not a package): its mesh builder
_spec = importlib.util.spec_from_file_location(
    "make_samples", Path(__file__).resolve().parents[1] / "sample_blends" / "make_samples.py")
make_samples = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(make_samples)


def _empty():
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = bpy.context.scene
    world = bpy.data.worlds.new("Black")
    world.color = (0.0, 0.0, 0.0)
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 0.0
    scene.world = world
    return scene


def _material(name, color, emission=0.0):
    mat = bpy.data.materials.new(name)
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (*color, 1.0)
    bsdf.inputs["Specular IOR Level"].default_value = 0.0
    bsdf.inputs["Roughness"].default_value = 1.0
    if emission > 0.0:
        bsdf.inputs["Emission Color"].default_value = (1.0, 1.0, 1.0, 1.0)
        bsdf.inputs["Emission Strength"].default_value = emission
    return mat


def _box(centre, size, cell):
    """(verts, quads) of an axis-aligned box's six faces, gridded at about ``cell``, outward."""
    c, h = np.asarray(centre, float), np.asarray(size, float) / 2
    verts, faces = [], []
    for axis in range(3):
        u, v = [a for a in range(3) if a != axis]
        nu, nv = max(1, round(2 * h[u] / cell)), max(1, round(2 * h[v] / cell))
        su, sv = np.meshgrid(np.linspace(-h[u], h[u], nu + 1), np.linspace(-h[v], h[v], nv + 1), indexing="ij")
        idx = np.arange(su.size).reshape(nu + 1, nv + 1)
        quads = np.stack([idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]], -1).reshape(-1, 4)
        for side in (1.0, -1.0):
            p = np.zeros((su.size, 3))
            p[:, u], p[:, v], p[:, axis] = su.ravel(), sv.ravel(), side * h[axis]
            q = quads if np.cross(np.eye(3)[u], np.eye(3)[v])[axis] * side > 0 else quads[:, ::-1]
            faces.append(q + sum(len(x) for x in verts))
            verts.append(p + c)
    return np.concatenate(verts), np.concatenate(faces)


def _tube(path, radius, sides):
    """(verts, quads) of a closed tube (end caps as fans) of ``radius`` along ``path`` (float[N,3])."""
    path = np.asarray(path, float)
    tangent = np.gradient(path, axis=0)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    normal = np.cross(tangent, (0.0, 0.0, 1.0) if abs(tangent[0, 2]) < 0.9 else (1.0, 0.0, 0.0))
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    binormal = np.cross(tangent, normal)
    a = np.arange(sides) * 2 * np.pi / sides
    ring = path[:, None] + radius * (np.cos(a)[None, :, None] * normal[:, None] + np.sin(a)[None, :, None] * binormal[:, None])
    n = len(path)
    idx = np.arange(n * sides).reshape(n, sides)
    quads = np.stack([idx[:-1], idx[:-1, np.r_[1:sides, 0]], idx[1:, np.r_[1:sides, 0]], idx[1:]], -1).reshape(-1, 4)
    verts = np.concatenate([ring.reshape(-1, 3), path[[0, -1]]])
    caps = [np.stack([np.full(sides, n * sides), idx[0, np.r_[1:sides, 0]], idx[0], idx[0]], 1),
            np.stack([np.full(sides, n * sides + 1), idx[-1], idx[-1, np.r_[1:sides, 0]], idx[-1]], 1)]
    tris = [c[:, :3] for c in caps]
    return verts, [*quads.tolist(), *(t.tolist() for c in tris for t in c)]


def flat_furnace():
    _empty()
    bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=3, radius=1.0)
    ob = bpy.context.object
    ob.name = "Furnace"
    bm = bmesh.new()
    bm.from_mesh(ob.data)
    bmesh.ops.reverse_faces(bm, faces=bm.faces)  # seen from inside
    bm.to_mesh(ob.data)
    bm.free()
    ob.data.shade_flat()
    ob.data.materials.append(_material("Furnace", (0.5,) * 3, emission=1.0))


def emissive_room():
    _empty()
    verts, faces = _box((0.0, 0.0, 1.3), (4.0, 3.0, 2.6), 0.2)
    make_samples.flat_object("Room", verts, faces, _material("Wall", (0.7,) * 3), flip=True)
    verts, faces = _box((0.6, 0.3, 0.3), (0.6, 0.6, 0.6), 0.1)
    make_samples.flat_object("Block", verts, faces, _material("Block", (0.6, 0.5, 0.4)))
    s = np.linspace(0.0, 1.0, 97)
    sign = np.stack([-1.2 + 2.4 * s, np.full_like(s, 1.42), 1.7 + 0.25 * np.sin(6 * np.pi * s)], 1)
    verts, faces = _tube(sign, 0.02, 12)
    make_samples.flat_object("Sign", verts, faces, _material("Neon", (0.0,) * 3, emission=20.0))
    s = np.linspace(0.0, 1.0, 25)
    floor_tube = np.stack([-1.0 + 1.0 * s, -0.6 + 0.3 * np.sin(2 * np.pi * s), np.full_like(s, 0.03)], 1)
    verts, faces = _tube(floor_tube, 0.03, 12)
    make_samples.flat_object("Tube", verts, faces, _material("Glow", (0.0,) * 3, emission=10.0))
    for k, location in enumerate(((-1.2, -0.8, 2.3), (1.3, 0.6, 2.2))):
        data = bpy.data.lights.new(f"Lamp{k}", "POINT")
        data.energy = 60.0
        data.shadow_soft_size = 0.05
        lamp = bpy.data.objects.new(f"Lamp{k}", data)
        lamp.location = location
        bpy.context.scene.collection.objects.link(lamp)


SCENES = {"flat_furnace": flat_furnace, "emissive_room": emissive_room}
