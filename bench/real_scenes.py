"""Scenes built in code for ``bench/accuracy.py`` (issue 21): a furnished room, an open scene, a level.

- ``furnished_room``: the closed 8 × 6 × 3 m room of ``bench/rooms.py`` (ROOM, inward) holding its
  furniture (FURNITURE: a table with four legs, two shelves, a sofa, a cabinet and boxes), every
  face flat and gridded in 0.185 m cells; Blender's Suzanne 0.53 m wide (subdivided once, smooth)
  on the table and a smooth UV sphere of radius 0.3 m on the floor; lit by a 300 W point lamp of
  radius 5 cm 0.4 m under the ceiling and an 800 W 1.5 × 1.0 m rectangular area lamp 5 cm in front
  of a wall, facing into the room (rooms.py's window). 8 940 vertices.
- ``open_scene``: a 6 × 6 m floor (a grid of 63 × 63 squares: 4 096 vertices, flat) and nothing
  around it; a smooth capsule of radius 0.25 m and height 2 m (a cylinder with hemispherical
  ends, 1 926 vertices) standing on it, bent 45° by a live Simple Deform modifier (the bake reads
  the evaluated mesh); lit by a sun of strength 3 W/m² and angle 2°, 50° from the zenith.

- ``level``: the benchmark courtyard of ``sample_blends/make_level.py`` at half its tessellation
  (LEVEL_DETAIL): 164 objects, 116 k elements, a sun, 8 street lamps in emissive globes, 4 area
  lamps under the arcade and 4 neon signs of 1 058 emissive triangles each (4 872 with the globes).

Each builder empties the open file (Blender's bpy module, world black) and adds its objects; the
materials are matte Principled BSDFs (Specular IOR Level 0, Roughness 1).
"""
from __future__ import annotations

import importlib.util
import math
from pathlib import Path

import bpy
import numpy as np

from emissive_scenes import _box, _empty, _material, make_samples
from rooms import FURNITURE, ROOM

# sample_blends/make_level.py (a script, not a package): its lamp builder
_spec = importlib.util.spec_from_file_location(
    "make_level", Path(__file__).resolve().parents[1] / "sample_blends" / "make_level.py")
make_level = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(make_level)
_lamp = make_level._lamp


def _capsule(radius, height, segments):
    """(verts, faces) of a capsule standing on z = 0 around the z axis: ``segments`` around, rings
    about as far apart as the segments are wide; poles joined by triangle fans."""
    step = 2 * math.pi * radius / segments
    n_cap = max(1, round(math.pi / 2 * radius / step))
    n_side = max(1, round((height - 2 * radius) / step))
    polar = np.linspace(-math.pi / 2, 0.0, n_cap + 1)[1:]  # bottom cap up to its equator
    rho = np.concatenate([np.cos(polar), np.ones(n_side - 1), np.cos(polar[::-1])]) * radius
    z = np.concatenate([radius + radius * np.sin(polar),
                        np.linspace(radius, height - radius, n_side + 1)[1:-1],
                        height - radius - radius * np.sin(polar[::-1])])
    a = np.arange(segments) * 2 * math.pi / segments
    ring = np.stack([rho[:, None] * np.cos(a), rho[:, None] * np.sin(a), np.broadcast_to(z[:, None], (len(z), segments))], -1)
    idx = np.arange(ring.shape[0] * segments).reshape(-1, segments)
    nxt = np.r_[1:segments, 0]
    quads = np.stack([idx[:-1], idx[:-1, nxt], idx[1:, nxt], idx[1:]], -1).reshape(-1, 4)
    bottom, top = idx.size, idx.size + 1
    fans = [[bottom, idx[0, nxt[k]], idx[0, k]] for k in range(segments)]
    fans += [[top, idx[-1, k], idx[-1, nxt[k]]] for k in range(segments)]
    verts = np.concatenate([ring.reshape(-1, 3), [(0.0, 0.0, 0.0), (0.0, 0.0, height)]])
    return verts, [*quads.tolist(), *fans]


def _in_fixed_order(ob):
    """Rebuild ``ob``'s mesh with its vertices sorted by position and its polygons by their
    vertices: Blender 5.0.1's ``primitive_uv_sphere_add`` orders its polygons differently in each
    process (measured), and xatlas' charts follow that order, so without this the Sphere's
    lightmap layout, and a Cycles truth cached for it, change between runs."""
    me = ob.data
    co = np.empty(3 * len(me.vertices), np.float32)
    me.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3)
    order = np.lexsort(np.round(co, 5).T[::-1])
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    polygons = []
    for polygon in me.polygons:
        corners = [int(rank[v]) for v in polygon.vertices]
        first = corners.index(min(corners))  # the same winding, started at its lowest vertex
        polygons.append(tuple(corners[first:] + corners[:first]))
    fixed = bpy.data.meshes.new(me.name)
    fixed.from_pydata(co[order].tolist(), [], sorted(polygons))
    fixed.update()
    ob.data = fixed
    bpy.data.meshes.remove(me)


def furnished_room():
    _empty()
    # one cell everywhere, as rooms.py grids them: 6 446 vertices for the boxes, 2 494 for the rest
    cell = 0.185
    centre, size, albedo = ROOM
    verts, faces = _box(centre, size, cell)
    make_samples.flat_object("Room", verts, faces, _material("Wall", albedo), flip=True)
    materials = {}
    for k, (centre, size, albedo) in enumerate(FURNITURE):
        verts, faces = _box(centre, size, cell)
        mat = materials.setdefault(albedo, _material(f"Furniture{len(materials)}", albedo))
        make_samples.flat_object(f"Furniture{k:02d}", verts, faces, mat)
    bpy.ops.mesh.primitive_monkey_add(size=0.4, location=(-0.35, 0.0, 0.0))
    monkey = bpy.context.object
    monkey.name = "Suzanne"
    subsurf = monkey.modifiers.new("Subdivision", "SUBSURF")
    subsurf.levels = 1
    # applied: Cycles' vertex bake writes to the original mesh, which must be the one we bake
    bpy.ops.object.modifier_apply(modifier=subsurf.name)
    table_top = FURNITURE[0][0][2] + FURNITURE[0][1][2] / 2
    monkey.location.z = table_top - min(v.co.z for v in monkey.data.vertices)
    monkey.data.shade_smooth()
    monkey.data.materials.append(_material("Suzanne", (0.8, 0.6, 0.3)))
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.3, location=(-1.6, -0.6, 0.3))
    sphere = bpy.context.object
    sphere.name = "Sphere"
    _in_fixed_order(sphere)
    sphere.data.shade_smooth()
    sphere.data.materials.append(_material("Sphere", (0.3, 0.5, 0.7)))
    _lamp("Lamp", "POINT", (0.5, -0.5, 2.6), energy=300.0, shadow_soft_size=0.05)
    # the window: its light (local −z) turned to +y, its 1.5 m side along x, 1.0 m along z
    wall = ROOM[0][1] - ROOM[1][1] / 2
    _lamp("Window", "AREA", (0.0, wall + 0.05, 1.6), (math.pi / 2, 0.0, 0.0), energy=800.0,
          shape="RECTANGLE", size=1.5, size_y=1.0)


def open_scene():
    scene = _empty()
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=63, y_subdivisions=63, size=6.0)
    floor = bpy.context.object
    floor.name = "Floor"
    floor.data.materials.append(_material("Floor", (0.6, 0.6, 0.6)))
    me = bpy.data.meshes.new("Capsule")
    verts, faces = _capsule(0.25, 2.0, 37)
    me.from_pydata(verts.tolist(), [], [[int(i) for i in f] for f in faces])
    me.shade_smooth()
    me.materials.append(_material("Capsule", (0.7, 0.45, 0.3)))
    capsule = bpy.data.objects.new("Capsule", me)
    scene.collection.objects.link(capsule)
    # bent about the x axis around its origin, the bottom pole: it stays on the floor
    bend = capsule.modifiers.new("Bend", "SIMPLE_DEFORM")
    bend.deform_method = "BEND"
    bend.deform_axis = "X"
    bend.angle = math.radians(45.0)
    _lamp("Sun", "SUN", (0.0, 0.0, 5.0), (math.radians(50.0), 0.0, math.radians(30.0)), energy=3.0,
          angle=math.radians(2.0))


# The level's tessellation (``make_level.py --detail``): 111 683 triangles, 60 927 vertices,
# 116 326 elements — issue 21 asks for a level of at least 100 k.
LEVEL_DETAIL = 0.5


def level():
    _empty()
    make_level.build(LEVEL_DETAIL)


SCENES = {"furnished_room": furnished_room, "open_scene": open_scene, "level": level}
