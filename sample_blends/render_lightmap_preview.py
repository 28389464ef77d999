"""Render ``docs/img/cornell_lightmap.png``: the Cornell box shown through its baked lightmap alone.

Bakes the ``combined`` content (emission + albedo × lighting) of every mesh into one atlas with the
default method (hierarchical radiosity) and hooks it up (``--hookup``); then, for the picture only, each material shows
the lightmap as emission and Cycles renders with no bounces, so every pixel is the lightmap's value.
The .blend file is not changed.

    .venv/bin/python sample_blends/render_lightmap_preview.py
"""
import os
import tempfile
from pathlib import Path

os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="rb-render-"))

import bpy  # noqa: E402

from radiosity_baker.addon.job import BakeJob  # noqa: E402
from radiosity_baker.core import Settings  # noqa: E402

HERE = Path(__file__).resolve().parent


def main() -> None:
    bpy.ops.wm.open_mainfile(filepath=str(HERE / "cornell_box.blend"))
    out = Path(tempfile.mkdtemp(prefix="rb-lightmaps-"))
    settings = Settings(target="lightmap", content="combined", output=str(out),
                        texel_density=256.0, max_size=512, hookup="node")
    warnings = BakeJob(settings).run_sync(bpy.context)
    for w in warnings:
        print("warning:", w)
    for mat in bpy.data.materials:
        tree = mat.node_tree
        tex = tree.nodes.get("RB Lightmap") if tree else None
        if tex is None:
            continue
        emit = tree.nodes.new("ShaderNodeEmission")
        tree.links.new(tex.outputs["Color"], emit.inputs["Color"])
        tree.links.new(emit.outputs["Emission"], tree.get_output_node("ALL").inputs["Surface"])
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = 16
    scene.cycles.max_bounces = 0
    scene.cycles.use_denoising = False
    scene.view_settings.view_transform = "Standard"
    scene.render.resolution_x = scene.render.resolution_y = 512
    scene.render.resolution_percentage = 100
    scene.render.image_settings.file_format = "PNG"
    scene.render.filepath = str(HERE.parent / "docs" / "img" / "cornell_lightmap.png")
    bpy.ops.render.render(write_still=True)
    print("written", scene.render.filepath)


if __name__ == "__main__":
    main()
