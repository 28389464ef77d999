"""Make the benchmark level: a courtyard lit by the sun, street lamps, area lamps and neon signs.

    .venv/bin/python sample_blends/make_level.py OUT.blend [--detail 1.0]

At ``--detail 1`` it holds 164 objects and about 230 k triangles: a 48 m plaza ringed by 16 building
blocks, an arcade of 32 columns under 8 roof slabs (an area lamp under each of 4 of them), 12 trees,
a fountain, benches, barrels and crates, 8 street lamps (a point lamp in each emissive globe) and 4
wavy neon signs (2 048 emissive triangles each) on boards; a sun and a black, sky-less world.
``--detail`` scales the tessellation (not the object count): 0.05 makes a small copy for tests. The
file is not kept in the repository (``bench/lightmap_bench.py`` makes it under ``out/``).
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import bpy  # first: it makes bmesh importable
import bmesh
import numpy as np

PLAZA = 48.0  # m, side of the courtyard's ground
SUN_STRENGTH = 3.0  # W/m²
NEON = {"Red": (1.0, 0.1, 0.15), "Blue": (0.1, 0.3, 1.0), "Green": (0.2, 1.0, 0.3), "Amber": (1.0, 0.6, 0.1)}
NEON_STRENGTH = 8.0
GLOBE_STRENGTH = 4.0


def _n(base: int, detail: float, low: int = 2) -> int:
    """A tessellation count: ``base`` at detail 1, scaled by √detail (counts are per side)."""
    return max(low, int(round(base * math.sqrt(detail))))


def _material(name: str, color=(0.6, 0.6, 0.6), emission=None, strength=0.0):
    mat = bpy.data.materials.new(name)
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (*color, 1.0)
    bsdf.inputs["Specular IOR Level"].default_value = 0.0
    if emission is not None:
        bsdf.inputs["Emission Color"].default_value = (*emission, 1.0)
        bsdf.inputs["Emission Strength"].default_value = strength
    return mat


def _object(name: str, verts: np.ndarray, faces: np.ndarray, material, location=(0.0, 0.0, 0.0),
            rotation=(0.0, 0.0, 0.0)):
    """A mesh object from float[N,3] vertices and faces (int[F,3|4], or a list of corner lists),
    linked to the scene."""
    me = bpy.data.meshes.new(name)
    faces = faces.tolist() if isinstance(faces, np.ndarray) else faces  # quads and triangles
    me.from_pydata(np.asarray(verts, np.float64).tolist(), [], faces)
    me.materials.append(material)
    me.update()
    ob = bpy.data.objects.new(name, me)
    ob.location = location
    ob.rotation_euler = rotation
    bpy.context.scene.collection.objects.link(ob)
    return ob


def _grid(nx: int, ny: int, sx: float, sy: float):
    """An nx × ny-quad grid of sx × sy m centred at the origin in z = 0, facing +Z."""
    x, y = np.meshgrid(np.linspace(-sx / 2, sx / 2, nx + 1), np.linspace(-sy / 2, sy / 2, ny + 1))
    verts = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)
    i = np.arange((nx + 1) * (ny + 1)).reshape(ny + 1, nx + 1)
    faces = np.stack([i[:-1, :-1], i[:-1, 1:], i[1:, 1:], i[1:, :-1]], axis=-1).reshape(-1, 4)
    return verts, faces


def _box(sx: float, sy: float, sz: float, cuts: int):
    """A closed box of sx × sy × sz m standing on z = 0, each face a cuts × cuts grid (outward)."""
    parts, faces, base = [], [], 0
    for axis, sign in ((0, 1), (0, -1), (1, 1), (1, -1), (2, 1), (2, -1)):
        size = np.array([sx, sy, sz])
        u, v = [a for a in range(3) if a != axis]
        g, f = _grid(cuts, cuts, size[u], size[v])
        p = np.zeros_like(g)
        p[:, u], p[:, v], p[:, axis] = g[:, 0], g[:, 1], sign * size[axis] / 2
        # (u, v, axis) right-handed for sign +1 when axis follows v cyclically; flip otherwise
        if (sign > 0) != ((u, v, axis) in ((0, 1, 2), (1, 2, 0), (2, 0, 1))):
            f = f[:, ::-1]
        parts.append(p + (0, 0, sz / 2))
        faces.append(f + base)
        base += len(g)
    return np.concatenate(parts), np.concatenate(faces)


def _cylinder(radius: float, height: float, segments: int, rings: int):
    """An open cylinder of ``rings`` × ``segments`` quads on z = 0 (outward) with a fan cap on top."""
    a = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    z = np.linspace(0, height, rings + 1)
    verts = np.stack([np.tile(radius * np.cos(a), rings + 1), np.tile(radius * np.sin(a), rings + 1),
                      np.repeat(z, segments)], axis=1)
    i = np.arange((rings + 1) * segments).reshape(rings + 1, segments)
    j = np.roll(i, -1, axis=1)
    faces = np.stack([i[:-1], j[:-1], j[1:], i[1:]], axis=-1).reshape(-1, 4)
    top = len(verts)
    verts = np.concatenate([verts, [(0.0, 0.0, height)]])
    cap = np.stack([i[-1], j[-1], np.full(segments, top), np.full(segments, top)], axis=1)[:, :3]
    return verts, [*faces.tolist(), *cap.tolist()]


def _torus(major: float, minor: float, segments: int, sides: int):
    u, v = np.meshgrid(np.linspace(0, 2 * np.pi, segments, endpoint=False),
                       np.linspace(0, 2 * np.pi, sides, endpoint=False), indexing="ij")
    verts = np.stack([(major + minor * np.cos(v)) * np.cos(u), (major + minor * np.cos(v)) * np.sin(u),
                      minor * np.sin(v)], axis=-1).reshape(-1, 3)
    i = np.arange(segments * sides).reshape(segments, sides)
    j, k = np.roll(i, -1, axis=0), np.roll(i, -1, axis=1)
    faces = np.stack([i, j, np.roll(j, -1, axis=1), k], axis=-1).reshape(-1, 4)
    return verts, faces


def _sphere(radius: float, subdivisions: int):
    bm = bmesh.new()
    bmesh.ops.create_icosphere(bm, subdivisions=subdivisions, radius=radius)
    verts = np.array([v.co[:] for v in bm.verts])
    faces = np.array([[v.index for v in f.verts] for f in bm.faces])
    bm.free()
    return verts, faces


def _lamp(name: str, kind: str, location, rotation=(0.0, 0.0, 0.0), **settings):
    data = bpy.data.lights.new(name, kind)
    for key, value in settings.items():
        setattr(data, key, value)
    ob = bpy.data.objects.new(name, data)
    ob.location = location
    ob.rotation_euler = rotation
    bpy.context.scene.collection.objects.link(ob)
    return ob


def build(detail: float = 1.0) -> dict:
    """Fill the current (empty) scene with the courtyard; returns its counts."""
    rng = np.random.default_rng(7)
    stone = _material("Stone", (0.55, 0.52, 0.48))
    plaster = _material("Plaster", (0.75, 0.7, 0.62))
    wood = _material("Wood", (0.45, 0.3, 0.18))
    leaves = _material("Leaves", (0.2, 0.4, 0.15))
    metal = _material("Metal", (0.3, 0.3, 0.32))
    water = _material("Water", (0.2, 0.3, 0.35))
    globe = _material("Globe", (0.0, 0.0, 0.0), (1.0, 0.8, 0.55), GLOBE_STRENGTH)
    neon = {k: _material(f"Neon{k}", (0.0, 0.0, 0.0), c, NEON_STRENGTH) for k, c in NEON.items()}

    v, f = _grid(_n(120, detail), _n(120, detail), PLAZA, PLAZA)
    _object("Ground", v, f, stone)
    half = PLAZA / 2
    for side in range(4):  # 16 building blocks around the plaza
        for k in range(4):
            v, f = _box(11.0, 6.0, 7.0 + 3.0 * ((side + k) % 3), _n(12, detail))
            x = -half + 6.0 + 12.0 * k
            angle = side * math.pi / 2
            c, s = math.cos(angle), math.sin(angle)
            pos = (c * x - s * (half + 3.0), s * x + c * (half + 3.0), 0.0)
            _object(f"Building{side}{k}", v, f, plaster, pos, (0.0, 0.0, angle))
    for k in range(32):  # the arcade: two rows of columns along two sides
        row, i = divmod(k, 16)
        v, f = _cylinder(0.3, 4.0, _n(48, detail, 6), _n(40, detail))
        x = -half + 3.0 + 2.8 * i
        pos = (x, half - 4.0, 0.0) if row == 0 else (-(half - 4.0), x, 0.0)
        _object(f"Column{k:02d}", v, f, stone, pos)
    for k in range(8):  # roof slabs over the arcade, an area lamp under four of them
        row, i = divmod(k, 4)
        x = -half + 7.0 + 11.0 * i
        pos = (x, half - 2.5, 4.0) if row == 0 else (-(half - 2.5), x, 4.0)
        v, f = _box(11.0, 3.5, 0.3, _n(8, detail)) if row == 0 else _box(3.5, 11.0, 0.3, _n(8, detail))
        _object(f"Roof{k}", v, f, plaster, pos)
        if k % 2 == 0:
            _lamp(f"ArcadeLight{k}", "AREA", (pos[0], pos[1], 3.95), energy=400.0, shape="RECTANGLE",
                  size=2.0, size_y=0.6, color=(1.0, 0.85, 0.7))
    for k in range(12):  # trees: a trunk and a canopy each
        a = 2 * math.pi * k / 12
        pos = (12.0 * math.cos(a), 12.0 * math.sin(a), 0.0)
        v, f = _cylinder(0.25, 3.0, _n(16, detail, 6), _n(8, detail))
        _object(f"Trunk{k:02d}", v, f, wood, pos)
        v, f = _sphere(1.8, 3 if detail > 0.2 else 1)
        _object(f"Canopy{k:02d}", v * (1.0, 1.0, 0.8), f, leaves, (pos[0], pos[1], 4.2))
    v, f = _cylinder(3.0, 0.6, _n(64, detail, 8), _n(4, detail, 1))
    _object("FountainBasin", v, f, stone)
    v, f = _torus(2.6, 0.35, _n(48, detail, 8), _n(24, detail, 6))
    _object("FountainRim", v, f, stone, (0.0, 0.0, 0.6))
    v, f = _grid(_n(24, detail), _n(24, detail), 4.6, 4.6)
    _object("FountainWater", v, f, water, (0.0, 0.0, 0.5))
    for k in range(16):  # benches
        a = 2 * math.pi * (k + 0.5) / 16
        v, f = _box(1.8, 0.5, 0.45, _n(3, detail))
        _object(f"Bench{k:02d}", v, f, wood, (7.0 * math.cos(a), 7.0 * math.sin(a), 0.0), (0, 0, a + math.pi / 2))
    for k in range(20):  # barrels and crates near the buildings
        pos = (rng.uniform(-half + 3, half - 8), rng.uniform(-half + 3, -half + 8), 0.0)
        v, f = _cylinder(0.35, 0.9, _n(24, detail, 6), _n(6, detail))
        _object(f"Barrel{k:02d}", v, f, wood, pos)
        v, f = _box(0.8, 0.8, 0.8, _n(4, detail))
        _object(f"Crate{k:02d}", v, f, wood, (pos[0] + 1.2, pos[1] + 0.4, 0.0), (0, 0, rng.uniform(0, 1)))
    for k, (name, mat) in enumerate(neon.items()):  # neon signs on boards above the doors
        x = -12.0 + 8.0 * k
        v, f = _box(3.0, 0.2, 1.6, _n(4, detail))
        _object(f"SignBoard{k}", v, f, metal, (x, -half + 0.2, 3.0))
        v, f = _grid(_n(32, detail), _n(32, detail), 2.6, 1.2)
        v[:, 2] = 0.05 * np.sin(v[:, 0] * 12.0) * np.cos(v[:, 1] * 9.0)
        _object(f"Neon{name}", v, f, mat, (x, -half + 0.45, 3.8), (math.pi / 2, 0.0, 0.0))
    for k in range(8):  # street lamps: a post, an emissive globe, a point lamp in it
        a = 2 * math.pi * k / 8 + 0.2
        pos = (18.0 * math.cos(a), 18.0 * math.sin(a), 0.0)
        v, f = _cylinder(0.08, 3.5, _n(12, detail, 6), _n(6, detail))
        _object(f"LampPost{k}", v, f, metal, pos)
        v, f = _sphere(0.3, 2 if detail > 0.2 else 1)
        _object(f"LampGlobe{k}", v, f, globe, (pos[0], pos[1], 3.8))
        _lamp(f"StreetLight{k}", "POINT", (pos[0], pos[1], 3.8), energy=150.0, shadow_soft_size=0.12,
              color=(1.0, 0.8, 0.55))
    _lamp("Sun", "SUN", (0.0, 0.0, 30.0), (math.radians(50.0), 0.0, math.radians(35.0)),
          energy=SUN_STRENGTH, angle=math.radians(1.0))
    world = bpy.data.worlds.new("Night") if bpy.context.scene.world is None else bpy.context.scene.world
    bpy.context.scene.world = world
    world.color = (0.0, 0.0, 0.0)
    if world.node_tree is not None:
        world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    bpy.context.view_layer.update()
    meshes = [ob for ob in bpy.context.scene.objects if ob.type == "MESH"]
    triangles = sum(sum(len(p.vertices) - 2 for p in ob.data.polygons) for ob in meshes)
    return {"objects": len(meshes), "triangles": triangles,
            "lamps": sum(ob.type == "LIGHT" for ob in bpy.context.scene.objects),
            "emissive_objects": sum(ob.data.materials[0].name.startswith(("Neon", "Globe")) for ob in meshes)}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("output", type=Path)
    parser.add_argument("--detail", type=float, default=1.0, help="tessellation scale (1: ~230 k triangles)")
    args = parser.parse_args(argv)
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    counts = build(args.detail)
    args.output.parent.mkdir(parents=True, exist_ok=True)
    bpy.ops.wm.save_as_mainfile(filepath=str(args.output.resolve()))
    print(f"{args.output}: {counts}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
