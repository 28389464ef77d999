"""Time extract_scene on a ~1 M-triangle scene built in bpy.

A hilly grid of ~125 k quads under a level-1 Subdivision modifier (~500 k quads, ~1 M triangles;
half of it flat-shaded, so shading vertices split), with a Principled material, plus three lamps.
The depsgraph (the modifier) is evaluated before timing; the first extract run still includes
Blender computing the evaluated mesh's triangles and corner normals on first access.
Prints the result and writes bench/results/extract-<hostname>.json.

    python bench/extract_bench.py [--side 354] [--repeat 3]
"""
import argparse
import json
import os
import platform
import socket
import sys
import tempfile
import time

os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="rb-bench-"))

import bpy  # noqa: E402
import numpy as np  # noqa: E402

from radiosity_baker.addon.extract import extract_scene  # noqa: E402


def build(side: int) -> None:
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=side, y_subdivisions=side, size=10)
    grid = bpy.context.object
    # Rolling hills, so flat-shaded faces carry different normals at shared vertices.
    co = np.empty(len(grid.data.vertices) * 3, np.float32)
    grid.data.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3)
    co[:, 2] = 0.3 * np.sin(co[:, 0] * 2) * np.cos(co[:, 1] * 3)
    grid.data.vertices.foreach_set("co", co.ravel())
    grid.modifiers.new("subdivide", "SUBSURF").levels = 1
    # Flat-shade half of the faces so the hard-edge split path is exercised too.
    flat = np.zeros(len(grid.data.polygons), bool)
    flat[: flat.size // 2] = True
    grid.data.polygons.foreach_set("use_smooth", ~flat)
    mat = bpy.data.materials.new("Grey")
    mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (0.5, 0.5, 0.5, 1)
    grid.data.materials.append(mat)
    for kind, loc in (("POINT", (0, 0, 3)), ("SUN", (0, 0, 5)), ("AREA", (2, 0, 3))):
        bpy.ops.object.light_add(type=kind, location=loc)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--side", type=int, default=354, help="grid subdivisions per side")
    parser.add_argument("--repeat", type=int, default=3, help="timed runs (best is reported)")
    args = parser.parse_args(argv)
    build(args.side)
    t0 = time.perf_counter()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    for inst in depsgraph.object_instances:  # evaluation is lazy: force the modifiers to run
        inst.object.data
    evaluate_s = time.perf_counter() - t0
    times = []
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        ex = extract_scene(depsgraph)
        times.append(time.perf_counter() - t0)
    result = {
        "benchmark": "extract_scene",
        "triangles": ex.scene.num_triangles,
        "shading_vertices": ex.scene.num_vertices,
        "mesh_vertices": ex.targets[0].num_vertices,
        "lamps": len(ex.scene.lamps),
        "depsgraph_evaluate_s": round(evaluate_s, 4),
        "extract_s_first": round(times[0], 4),  # includes Blender's lazy triangulation / normals
        "extract_s_best": round(min(times), 4),
        "extract_s_all": [round(t, 4) for t in times],
        "mtriangles_per_s": round(ex.scene.num_triangles / min(times) / 1e6, 3),
        "host": socket.gethostname(),
        "cpu_count": os.cpu_count(),
        "python": platform.python_version(),
        "blender": bpy.app.version_string,
        "numpy": np.__version__,
    }
    print(json.dumps(result, indent=2))
    out_dir = os.path.join(os.path.dirname(os.path.abspath(__file__)), "results")
    os.makedirs(out_dir, exist_ok=True)
    with open(os.path.join(out_dir, f"extract-{socket.gethostname()}.json"), "w") as f:
        json.dump(result, f, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
