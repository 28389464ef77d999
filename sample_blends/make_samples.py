"""Make the sample scenes: ``cornell_box.blend``, ``lamp_scene.blend`` and ``animated_room.blend``
next to this script.

Run with the bpy module:  .venv/bin/python sample_blends/make_samples.py

Cornell box: Cornell University's published geometry (millimetres, y up) converted to metres and
Blender's z-up by the rotation (x, y, z) -> (x, -z, y): the open front faces +Y, the camera looks
down −Y into it, the red wall is on the camera's left, the green wall on its right. Surfaces are
subdivided grids (real vertices, no modifiers) so per-vertex bakes have something to resolve.
Lamp scene: a floor, three objects and one lamp of each type (point, spot, sun, area).
Animated room: a floor and two walls, a column bent by a two-bone armature over frames 1–48 (a
"character" deforming), a door panel swinging open and a point lamp sliding along the room, for
frame-range bakes (``--frames 1:48``).
"""
from __future__ import annotations

import math
from pathlib import Path

import bpy  # first: it makes bmesh importable
import bmesh
import numpy as np

HERE = Path(__file__).resolve().parent
CORNELL_PATH = HERE / "cornell_box.blend"
LAMP_SCENE_PATH = HERE / "lamp_scene.blend"
ANIMATED_PATH = HERE / "animated_room.blend"

WHITE = (0.73, 0.73, 0.73)
RED = (0.65, 0.05, 0.05)
GREEN = (0.12, 0.45, 0.15)
# Emitted radiance of the ceiling light (W m⁻² sr⁻¹): lights the floor below it to ≈ 0.3
# (irradiance/π) directly, about as bright again with the interreflections.
CORNELL_LIGHT_STRENGTH = 16.0
# Target edge length of the grid cells (m): ≈ 2800 vertices in the whole box.
CORNELL_CELL = 0.03
# Lamp scene: floor cell (m) and subdivision cuts of the primitives.
LAMP_FLOOR_CELL = 0.15
SUBDIVIDE_CUTS = {"Cube": 5}
# A pillar of gridded quads (a subdivided cylinder's n-gon caps bake badly in Cycles' vertex bake).
PILLAR_TOP = np.array([(-0.3, -1.6, 1.2), (0.3, -1.6, 1.2), (0.3, -1.0, 1.2), (-0.3, -1.0, 1.2)])
PILLAR_CELL = 0.1
# How far the light quad hangs below the ceiling (m), so the two never overlap.
CORNELL_LIGHT_DROP = 0.001

# Cornell data (mm, y up). Quads list their corners in order around the quad.
_FLOOR = [(552.8, 0, 0), (0, 0, 0), (0, 0, 559.2), (549.6, 0, 559.2)]
_CEILING = [(556, 548.8, 0), (556, 548.8, 559.2), (0, 548.8, 559.2), (0, 548.8, 0)]
_BACK = [(549.6, 0, 559.2), (0, 0, 559.2), (0, 548.8, 559.2), (556, 548.8, 559.2)]
_GREEN_WALL = [(0, 0, 559.2), (0, 0, 0), (0, 548.8, 0), (0, 548.8, 559.2)]
_RED_WALL = [(552.8, 0, 0), (549.6, 0, 559.2), (556, 548.8, 559.2), (556, 548.8, 0)]
_LIGHT = [(343, 548.8, 227), (343, 548.8, 332), (213, 548.8, 332), (213, 548.8, 227)]
_SHORT_TOP = [(130, 165, 65), (82, 165, 225), (240, 165, 272), (290, 165, 114)]
_TALL_TOP = [(423, 330, 247), (265, 330, 296), (314, 330, 456), (472, 330, 406)]

# What the samples hold; tests/addon/test_samples.py checks the saved files against this.
CORNELL_OBJECTS = {  # name: material
    "Floor": "White", "Ceiling": "White", "BackWall": "White", "RedWall": "Red",
    "GreenWall": "Green", "ShortBlock": "White", "TallBlock": "White", "Light": "Light",
}
CORNELL_VERTEX_RANGE = (2000, 4000)
LAMP_SCENE_LAMPS = {"Point": "POINT", "Spot": "SPOT", "Sun": "SUN", "Area": "AREA"}
LAMP_SCENE_MESHES = ("Floor", "Cube", "Sphere", "Pillar")
LAMP_SCENE_VERTEX_RANGE = (1500, 3000)
ANIMATED_FRAMES = (1, 48)
ANIMATED_MESHES = ("Floor", "BackWall", "SideWall", "Column", "Door")


def cornell_to_blender(points_mm) -> np.ndarray:
    """float64[N,3] metres, z up, from Cornell millimetres, y up."""
    p = np.asarray(points_mm, np.float64) / 1000.0
    return np.stack([p[:, 0], -p[:, 2], p[:, 1]], axis=1)


def grid(corners: np.ndarray, cell: float) -> tuple[np.ndarray, np.ndarray]:
    """Bilinear grid over the quad ``corners`` (float[4,3], in order around it).

    Cells are at most about ``cell`` metres on a side. Returns (float64[V,3] vertices,
    int[F,4] quads) wound like ``corners``.
    """
    nu = max(1, round(max(np.linalg.norm(corners[1] - corners[0]),
                          np.linalg.norm(corners[2] - corners[3])) / cell))
    nv = max(1, round(max(np.linalg.norm(corners[3] - corners[0]),
                          np.linalg.norm(corners[2] - corners[1])) / cell))
    u = np.linspace(0.0, 1.0, nu + 1)[None, :, None]
    v = np.linspace(0.0, 1.0, nv + 1)[:, None, None]
    c0, c1, c2, c3 = corners
    verts = ((1 - u) * (1 - v) * c0 + u * (1 - v) * c1 + u * v * c2 + (1 - u) * v * c3).reshape(-1, 3)
    i = np.arange(nv)[:, None] * (nu + 1) + np.arange(nu)[None, :]
    quads = np.stack([i, i + 1, i + nu + 2, i + nu + 1], axis=-1).reshape(-1, 4)
    return verts, quads


def facing(corners: np.ndarray, towards: np.ndarray) -> np.ndarray:
    """``corners`` reordered if needed so the quad's normal points towards the point ``towards``."""
    normal = np.cross(corners[1] - corners[0], corners[3] - corners[0])
    return corners if normal @ (towards - corners.mean(axis=0)) > 0 else corners[::-1].copy()


def box_sides(top: np.ndarray) -> list[np.ndarray]:
    """The four side quads of a block standing on z = 0 under the quad ``top``."""
    bottom = top * np.array([1.0, 1.0, 0.0])
    return [np.array([bottom[k], bottom[(k + 1) % 4], top[(k + 1) % 4], top[k]]) for k in range(4)]


def principled(name: str, color, emission=None, strength: float = 0.0) -> bpy.types.Material:
    """A matte Principled material: Base Color ``color``, no specular, roughness 1."""
    mat = bpy.data.materials.new(name)
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (*color, 1.0)
    bsdf.inputs["Specular IOR Level"].default_value = 0.0
    bsdf.inputs["Roughness"].default_value = 1.0
    if emission is not None:
        bsdf.inputs["Emission Color"].default_value = (*emission, 1.0)
        bsdf.inputs["Emission Strength"].default_value = strength
    mat.diffuse_color = (*color, 1.0)
    return mat


def mesh_object(name: str, quads: list[np.ndarray], cell: float, material) -> bpy.types.Object:
    """An object made of gridded ``quads`` (each float[4,3]), coincident vertices merged, flat shaded."""
    verts, faces, offset = [], [], 0
    for corners in quads:
        v, f = grid(corners, cell)
        verts.append(v)
        faces.append(f + offset)
        offset += len(v)
    return flat_object(name, np.concatenate(verts), np.concatenate(faces), material)


def flat_object(name: str, verts, faces, material, flip: bool = False) -> bpy.types.Object:
    """A flat-shaded mesh object of ``verts`` (float[V,3]) and ``faces`` (corner lists), coincident
    vertices merged, its faces reversed if ``flip``, linked to the scene."""
    me = bpy.data.meshes.new(name)
    me.from_pydata(np.asarray(verts, float).tolist(), [], [[int(i) for i in f] for f in faces])
    bm = bmesh.new()
    bm.from_mesh(me)
    bmesh.ops.remove_doubles(bm, verts=bm.verts, dist=1e-6)
    if flip:
        bmesh.ops.reverse_faces(bm, faces=bm.faces)
    bm.to_mesh(me)
    bm.free()
    me.shade_flat()
    me.materials.append(material)
    ob = bpy.data.objects.new(name, me)
    bpy.context.scene.collection.objects.link(ob)
    return ob


def black_world(scene: bpy.types.Scene) -> None:
    world = bpy.data.worlds.new("Black")
    world.color = (0.0, 0.0, 0.0)
    background = world.node_tree.nodes["Background"]
    background.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
    background.inputs["Strength"].default_value = 0.0
    scene.world = world


def add_camera(scene, location, rotation_deg, lens=35.0, sensor=36.0) -> None:
    cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    cam.data.lens = lens
    cam.data.sensor_width = sensor
    cam.location = location
    cam.rotation_euler = [math.radians(a) for a in rotation_deg]
    scene.collection.objects.link(cam)
    scene.camera = cam


def empty_file() -> bpy.types.Scene:
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = bpy.context.scene
    scene.render.resolution_x = scene.render.resolution_y = 512
    black_world(scene)
    return scene


def make_cornell_box() -> None:
    scene = empty_file()
    white, red, green = principled("White", WHITE), principled("Red", RED), principled("Green", GREEN)
    # A black emitter: it sits 1 mm below the ceiling, and a reflective one would trap light in the
    # gap (both of its faces reflect in Cycles, only the front of an element reflects here).
    light = principled("Light", (0.0, 0.0, 0.0), emission=(1.0, 1.0, 1.0),
                       strength=CORNELL_LIGHT_STRENGTH)
    inside = cornell_to_blender([(278, 274.4, 279.6)])[0]
    for name, quad, mat in (("Floor", _FLOOR, white), ("Ceiling", _CEILING, white),
                            ("BackWall", _BACK, white), ("RedWall", _RED_WALL, red),
                            ("GreenWall", _GREEN_WALL, green)):
        mesh_object(name, [facing(cornell_to_blender(quad), inside)], CORNELL_CELL, mat)
    for name, top_mm in (("ShortBlock", _SHORT_TOP), ("TallBlock", _TALL_TOP)):
        top = cornell_to_blender(top_mm)
        centre = top.mean(axis=0) * np.array([1.0, 1.0, 0.5])
        quads = [facing(q, 2 * q.mean(axis=0) - centre) for q in [top, *box_sides(top)]]
        mesh_object(name, quads, CORNELL_CELL, white)
    lamp = cornell_to_blender(_LIGHT) - np.array([0.0, 0.0, CORNELL_LIGHT_DROP])
    mesh_object("Light", [facing(lamp, lamp.mean(axis=0) - np.array([0.0, 0.0, 1.0]))], 0.05, light)
    # Cornell's camera: at (278, 273, -800) mm, 35 mm lens on a 25 mm film, looking into the box.
    add_camera(scene, cornell_to_blender([(278, 273, -800)])[0], (90.0, 0.0, 180.0), lens=35.0,
               sensor=25.0)
    bpy.ops.wm.save_as_mainfile(filepath=str(CORNELL_PATH), compress=True)


def make_lamp_scene() -> None:
    scene = empty_file()
    grey, orange, blue = (principled("Grey", (0.6, 0.6, 0.6)), principled("Orange", (0.8, 0.35, 0.1)),
                          principled("Blue", (0.1, 0.25, 0.7)))
    floor = np.array([(-3.0, -3.0, 0.0), (3.0, -3.0, 0.0), (3.0, 3.0, 0.0), (-3.0, 3.0, 0.0)])
    mesh_object("Floor", [floor], LAMP_FLOOR_CELL, grey)
    for name, op, kwargs, location, mat in (
            ("Cube", bpy.ops.mesh.primitive_cube_add, {"size": 1.0}, (-1.0, 0.5, 0.5), orange),
            ("Sphere", bpy.ops.mesh.primitive_uv_sphere_add,
             {"radius": 0.6, "segments": 32, "ring_count": 16}, (1.0, 0.0, 0.6), blue),
            ):
        op(location=location, **kwargs)
        ob = bpy.context.object
        ob.name = ob.data.name = name
        ob.data.materials.append(mat)
        if name in SUBDIVIDE_CUTS:
            # per-vertex bakes need vertices where light changes: a cylinder's sides are one
            # quad tall otherwise
            bpy.ops.object.mode_set(mode="EDIT")
            bpy.ops.mesh.subdivide(number_cuts=SUBDIVIDE_CUTS[name])
            bpy.ops.object.mode_set(mode="OBJECT")
        if name == "Sphere":
            ob.data.shade_smooth()
    centre = PILLAR_TOP.mean(axis=0) * np.array([1.0, 1.0, 0.5])
    mesh_object("Pillar", [facing(q, 2 * q.mean(axis=0) - centre) for q in [PILLAR_TOP, *box_sides(PILLAR_TOP)]],
                PILLAR_CELL, grey)
    for name, kind, location, rotation_deg, settings in (
            ("Point", "POINT", (2.0, 2.0, 2.5), (0, 0, 0), {"energy": 300.0, "shadow_soft_size": 0.1}),
            ("Spot", "SPOT", (-2.0, -1.5, 3.0), (35.0, 0.0, -50.0),
             {"energy": 800.0, "shadow_soft_size": 0.05, "spot_size": math.radians(50.0),
              "spot_blend": 0.3}),
            ("Sun", "SUN", (0.0, 0.0, 5.0), (40.0, 10.0, 30.0), {"energy": 1.5, "angle": math.radians(3.0)}),
            ("Area", "AREA", (0.0, 2.5, 2.0), (-50.0, 0.0, 0.0),
             {"energy": 200.0, "shape": "RECTANGLE", "size": 1.0, "size_y": 0.5})):
        data = bpy.data.lights.new(name, kind)
        for key, value in settings.items():
            setattr(data, key, value)
        ob = bpy.data.objects.new(name, data)
        ob.location = location
        ob.rotation_euler = [math.radians(a) for a in rotation_deg]
        scene.collection.objects.link(ob)
    add_camera(scene, (6.5, -6.0, 4.5), (63.0, 0.0, 47.0), lens=50.0)
    bpy.ops.wm.save_as_mainfile(filepath=str(LAMP_SCENE_PATH), compress=True)


def animated_room(scene, cell: float = 0.1, frames: tuple = ANIMATED_FRAMES) -> None:
    """Build the animated room into ``scene``: grids of ``cell`` metres, animated over ``frames``
    (first, last): the column bends 60° at its middle, the door swings 80° open, the lamp slides
    2 m along x."""
    first, last = frames
    white, red = principled("White", (0.7, 0.7, 0.7)), principled("Red", (0.7, 0.15, 0.1))
    inside = np.array([0.0, 0.0, 1.25])
    for name, quad, mat in (
            ("Floor", [(-2.5, -2.0, 0.0), (2.5, -2.0, 0.0), (2.5, 2.0, 0.0), (-2.5, 2.0, 0.0)], white),
            ("BackWall", [(-2.5, 2.0, 0.0), (2.5, 2.0, 0.0), (2.5, 2.0, 2.5), (-2.5, 2.0, 2.5)], white),
            ("SideWall", [(-2.5, -2.0, 0.0), (-2.5, 2.0, 0.0), (-2.5, 2.0, 2.5), (-2.5, -2.0, 2.5)], red)):
        mesh_object(name, [facing(np.array(quad), inside)], cell, mat)
    top = np.array([(-0.2, -0.2, 1.8), (0.2, -0.2, 1.8), (0.2, 0.2, 1.8), (-0.2, 0.2, 1.8)])
    centre = top.mean(axis=0) * np.array([1.0, 1.0, 0.5])
    column = mesh_object("Column", [facing(q, 2 * q.mean(axis=0) - centre) for q in [top, *box_sides(top)]],
                         cell / 2, red)
    # smooth within each side, sharp at the box's edges, as a character is: bending then moves the
    # shading normals without splitting vertices apart, so every frame keeps the same elements
    column.data.shade_smooth()
    column.data.set_sharp_from_angle(angle=math.radians(30.0))
    door_top = np.array([(1.2, 1.0, 1.6), (2.0, 1.0, 1.6), (2.0, 1.06, 1.6), (1.2, 1.06, 1.6)])
    centre = door_top.mean(axis=0) * np.array([1.0, 1.0, 0.5])
    door = mesh_object("Door", [facing(q, 2 * q.mean(axis=0) - centre) for q in [door_top, *box_sides(door_top)]],
                       cell, white)
    # the door swings about its edge at x = 1.2
    door.data.transform(np.array([[1, 0, 0, -1.2], [0, 1, 0, -1.0], [0, 0, 1, 0], [0, 0, 0, 1]]))
    door.location = (1.2, 1.0, 0.0)
    door.rotation_euler = (0.0, 0.0, 0.0)
    door.keyframe_insert("rotation_euler", frame=first)
    door.rotation_euler = (0.0, 0.0, math.radians(-80.0))
    door.keyframe_insert("rotation_euler", frame=last)

    arm = bpy.data.armatures.new("Rig")
    rig = bpy.data.objects.new("Rig", arm)
    scene.collection.objects.link(rig)
    bpy.context.view_layer.objects.active = rig
    bpy.ops.object.mode_set(mode="EDIT")
    lower, upper = arm.edit_bones.new("Lower"), arm.edit_bones.new("Upper")
    lower.head, lower.tail = (0.0, 0.0, 0.0), (0.0, 0.0, 0.9)
    upper.head, upper.tail = (0.0, 0.0, 0.9), (0.0, 0.0, 1.8)
    upper.parent, upper.use_connect = lower, True
    bpy.ops.object.mode_set(mode="OBJECT")
    heights = np.array([v.co.z for v in column.data.vertices])
    w_upper = np.clip((heights - 0.7) / 0.4, 0.0, 1.0)  # blended over 0.7–1.1 m
    for name, weights in (("Lower", 1.0 - w_upper), ("Upper", w_upper)):
        group = column.vertex_groups.new(name=name)
        for index, weight in enumerate(weights):
            if weight > 0.0:
                group.add([index], float(weight), "REPLACE")
    column.modifiers.new("Armature", "ARMATURE").object = rig
    bone = rig.pose.bones["Upper"]
    bone.rotation_mode = "XYZ"
    bone.rotation_euler = (0.0, 0.0, 0.0)
    bone.keyframe_insert("rotation_euler", frame=first)
    bone.rotation_euler = (math.radians(60.0), 0.0, 0.0)
    bone.keyframe_insert("rotation_euler", frame=last)

    light = bpy.data.lights.new("Lamp", "POINT")
    light.energy, light.shadow_soft_size = 400.0, 0.1
    lamp = bpy.data.objects.new("Lamp", light)
    scene.collection.objects.link(lamp)
    lamp.location = (-1.0, -0.5, 2.2)
    lamp.keyframe_insert("location", frame=first)
    lamp.location = (1.0, -0.5, 2.2)
    lamp.keyframe_insert("location", frame=last)
    scene.frame_start, scene.frame_end = first, last
    scene.frame_set(first)


def make_animated_room() -> None:
    scene = empty_file()
    animated_room(scene)
    add_camera(scene, (0.0, -6.5, 2.0), (80.0, 0.0, 0.0), lens=30.0)
    bpy.ops.wm.save_as_mainfile(filepath=str(ANIMATED_PATH), compress=True)


def main() -> None:
    make_cornell_box()
    make_lamp_scene()
    make_animated_room()
    for path in (CORNELL_PATH, LAMP_SCENE_PATH, ANIMATED_PATH):
        print(f"wrote {path} ({path.stat().st_size / 1024:.0f} KiB)")


if __name__ == "__main__":
    main()
