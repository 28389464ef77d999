"""Render ``docs/img/directional_wall.png``: a normal-mapped wall lit through the plain lightmap (left) and
through the directional one (right), side by side.

A 2 m wall (bumped by a noise height field through a Bump node) between a warm lamp grazing
from the left and a cool one from the right is baked with ``--directional sh`` (default method: hierarchical radiosity). For
the picture, each copy of the wall shows albedo × lighting as emission, Cycles renders with no
bounces: left ``lighting = L0``; right ``lighting = L0 + L1 · (n' − n)`` per channel (manual,
docs/directional-probes.md), n' the bumped normal, n the wall's. Nothing is saved.

    .venv/bin/python sample_blends/render_directional.py
"""
import os
import tempfile
from pathlib import Path

os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="rb-render-"))

import bpy  # noqa: E402

from radiosity_baker.addon.job import BakeJob  # noqa: E402
from radiosity_baker.core import Settings  # noqa: E402
from radiosity_baker.core.lightmap import files  # noqa: E402

HERE = Path(__file__).resolve().parent
ALBEDO = (0.8, 0.8, 0.8, 1.0)


def wall():
    """The wall: a 2 m square in the xz plane facing −y (the camera), 16 cuts."""
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=16, y_subdivisions=16, size=2.0,
                                    location=(0.0, 0.0, 1.0), rotation=(1.5707963, 0.0, 0.0))
    ob = bpy.context.object
    ob.name = "Wall"
    return ob


def lamp(name, location, colour, power):
    light = bpy.data.lights.new(name, 'POINT')
    light.energy, light.color, light.shadow_soft_size = power, colour, 0.0
    ob = bpy.data.objects.new(name, light)
    ob.location = location
    bpy.context.scene.collection.objects.link(ob)


def image(path: Path):
    im = bpy.data.images.load(str(path))
    im.colorspace_settings.name = "Non-Color"
    return im


def shown(ob, layers: dict, directional: bool):
    """A material showing albedo × the lightmap as emission (with ``directional``, L0 + L1 · (n' − n)
    with n' the bumped normal); layers: {"L0", "L1x", "L1y", "L1z": image}."""
    mat = bpy.data.materials.new("Directional" if directional else "Plain")
    tree = mat.node_tree
    nodes, link = tree.nodes, tree.links.new
    nodes.clear()
    uv = nodes.new("ShaderNodeUVMap")
    uv.uv_map = "Lightmap"

    def texture(name):
        tex = nodes.new("ShaderNodeTexImage")
        tex.image = layers[name]
        link(uv.outputs["UV"], tex.inputs["Vector"])
        return tex.outputs["Color"]

    def vmath(op, a, b):
        node = nodes.new("ShaderNodeVectorMath")
        node.operation = op
        link(a, node.inputs[0])
        if isinstance(b, float):
            node.inputs["Scale"].default_value = b
        else:
            link(b, node.inputs[1])
        return node.outputs["Vector"]

    lighting = texture("L0")
    if directional:
        height = nodes.new("ShaderNodeTexNoise")
        height.inputs["Scale"].default_value = 4.0
        height.inputs["Detail"].default_value = 1.0
        bump = nodes.new("ShaderNodeBump")
        bump.inputs["Strength"].default_value = 1.0
        bump.inputs["Distance"].default_value = 0.05
        link(height.outputs["Fac"], bump.inputs["Height"])
        geometry = nodes.new("ShaderNodeNewGeometry")
        tilt = nodes.new("ShaderNodeSeparateXYZ")
        link(vmath("SUBTRACT", bump.outputs["Normal"], geometry.outputs["Normal"]), tilt.inputs[0])
        for axis, name in enumerate(("L1x", "L1y", "L1z")):
            scaled = nodes.new("ShaderNodeVectorMath")
            scaled.operation = "SCALE"
            link(texture(name), scaled.inputs[0])
            link(tilt.outputs[axis], scaled.inputs["Scale"])
            lighting = vmath("ADD", lighting, scaled.outputs["Vector"])
    albedo = nodes.new("ShaderNodeRGB")
    albedo.outputs[0].default_value = ALBEDO
    emission = nodes.new("ShaderNodeEmission")
    link(vmath("MULTIPLY", lighting, albedo.outputs[0]), emission.inputs["Color"])
    output = nodes.new("ShaderNodeOutputMaterial")
    link(emission.outputs["Emission"], output.inputs["Surface"])
    ob.data.materials.clear()
    ob.data.materials.append(mat)


def main() -> None:
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = bpy.context.scene
    plain = wall()
    lamp("Warm", (-2.2, -0.3, 1.4), (1.0, 0.55, 0.25), 250.0)
    lamp("Cool", (2.2, -0.3, 0.7), (0.25, 0.5, 1.0), 250.0)
    out = Path(tempfile.mkdtemp(prefix="rb-directional-"))
    settings = Settings(target="lightmap", output=str(out), texel_density=96.0, directional="sh")
    for w in BakeJob(settings).run_sync(bpy.context):
        print("warning:", w)
    sh = files.read_exr(out / "Lightmap.sh.exr")
    layers = {}
    for k, name in enumerate(("L0", "L1x", "L1y", "L1z")):
        files.write_exr(out / f"{name}.exr", sh[..., 3 * k:3 * k + 3], "float")
        layers[name] = image(out / f"{name}.exr")
    # the two copies side by side: the plain one on the left
    directional = plain.copy()
    directional.data = plain.data.copy()
    scene.collection.objects.link(directional)
    plain.location.x, directional.location.x = -1.05, 1.05
    shown(plain, layers, directional=False)
    shown(directional, layers, directional=True)
    for ob in [o for o in scene.objects if o.type == 'LIGHT']:
        ob.hide_render = True  # the picture shows the lightmaps alone
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    camera.location, camera.rotation_euler = (0.0, -7.0, 1.0), (1.5707963, 0.0, 0.0)
    camera.data.type, camera.data.ortho_scale = "ORTHO", 4.3
    scene.collection.objects.link(camera)
    scene.camera = camera
    scene.render.engine = "CYCLES"
    scene.cycles.device, scene.cycles.samples, scene.cycles.max_bounces = "CPU", 8, 0
    scene.cycles.use_denoising = False
    scene.view_settings.view_transform = "Standard"
    scene.render.resolution_x, scene.render.resolution_y = 640, 310
    scene.render.resolution_percentage = 100
    scene.render.image_settings.file_format = "PNG"
    scene.render.filepath = str(HERE.parent / "docs" / "img" / "directional_wall.png")
    bpy.ops.render.render(write_still=True)
    print("written", scene.render.filepath)


if __name__ == "__main__":
    main()
