"""The reference solver on a room of about 8 k elements, through the command line, timed.

A room (six walls facing in, two blocks on the floor, an area lamp under the ceiling) is built with
bpy into a temporary .blend whose grids are subdivided to ``--elements`` shading vertices, then
baked with ``python -m radiosity_baker bake … --method reference --report``: the total wall time
and the stages from the report. ``--compare-with DIR`` bakes the same file with another checkout
of the package too (e.g. an earlier commit, ``git worktree add /tmp/old <rev>``), in the same run,
so the two times are comparable; ``--max-pairs`` passes a transport budget to both (the earlier
reference solver held the matrix only within its budget and otherwise traced every pair again on
every sweep). Writes bench/results/reference-<machine>.json.

    .venv/bin/python bench/reference_bench.py [--elements 8000] [--compare-with DIR] [--max-pairs N]
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))
import results_file  # noqa: E402


def build_room(path: Path, elements: int) -> None:
    """Write the room to ``path`` (a child process: bpy is imported once per process)."""
    script = f"""
import bpy, math
bpy.ops.wm.read_homefile(use_empty=True)
scene = bpy.context.scene
def grid(name, size, cuts, loc, rot):
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=cuts, y_subdivisions=cuts, size=size,
                                    location=loc, rotation=rot)
    ob = bpy.context.object
    ob.name = name
    return ob
# six walls, about {elements} vertices in all, each facing into the 4 m room
k = max(4, int(round(({elements} / 6.6) ** 0.5)))
for name, loc, rot in (("Floor", (0, 0, 0), (0, 0, 0)), ("Ceiling", (0, 0, 4), (math.pi, 0, 0)),
                       ("Back", (0, 2, 2), (math.pi / 2, 0, 0)), ("Front", (0, -2, 2), (-math.pi / 2, 0, 0)),
                       ("Left", (-2, 0, 2), (0, math.pi / 2, 0)), ("Right", (2, 0, 2), (0, -math.pi / 2, 0))):
    grid(name, 4.0, k, loc, rot)
for name, loc, size in (("BlockA", (-0.8, 0.5, 0.6), 1.2), ("BlockB", (0.9, -0.4, 0.4), 0.8)):
    bpy.ops.mesh.primitive_cube_add(size=size, location=loc)
    bpy.context.object.name = name
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.mesh.subdivide(number_cuts=max(1, k // 8))
    bpy.ops.object.mode_set(mode="OBJECT")
light = bpy.data.lights.new("Panel", "AREA")
light.energy, light.size = 600.0, 1.0
lamp = bpy.data.objects.new("Panel", light)
lamp.location = (0, 0, 3.9)
scene.collection.objects.link(lamp)
bpy.ops.wm.save_as_mainfile(filepath={str(path)!r})
"""
    subprocess.run([sys.executable, "-c", script], check=True, capture_output=True)


def bake(blend: Path, package_dir: Path | None, max_pairs: int | None, work: Path, label: str) -> dict:
    """Bake ``blend`` with the package at ``package_dir`` (None: this one); wall seconds and report."""
    env = dict(os.environ)
    if package_dir is not None:
        shim = work / f"shim-{label}"
        shim.mkdir(exist_ok=True)
        link = shim / "radiosity_baker"
        if not link.exists():
            link.symlink_to(package_dir.resolve())
        env["PYTHONPATH"] = os.pathsep.join([str(shim), env.get("PYTHONPATH", "")])
    report = work / f"report-{label}.json"
    cmd = [sys.executable, "-m", "radiosity_baker", "bake", str(blend), "--method", "reference",
           "--device", "cpu", "--report", str(report)]
    if max_pairs is not None:
        cmd += ["--max-pairs", str(max_pairs)]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True)
    seconds = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(f"{label}: bake failed: {proc.stderr.strip().splitlines()[-1:]}")
    data = json.loads(report.read_text())
    return {"label": label, "wall_seconds": round(seconds, 2),
            "bake_seconds": round(data["seconds"]["total"], 2),
            "stages": {k: round(v, 2) for k, v in data["seconds"].items()},
            "elements": data["counts"]["elements"], "counts": data["counts"],
            "peak_memory_mb": round(data["peak_memory_bytes"] / 2 ** 20, 1),
            "warnings": data["warnings"]}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--elements", type=int, default=8000)
    parser.add_argument("--compare-with", type=Path, help="another checkout of the package")
    parser.add_argument("--max-pairs", type=int, help="transport budget passed to both bakes")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="rb-reference-bench-") as tmp:
        work = Path(tmp)
        blend, small = work / "room.blend", work / "small.blend"
        build_room(blend, args.elements)
        build_room(small, 300)
        load = os.getloadavg()[0]
        runs = []
        for label, package in (("this", None), ("compared", args.compare_with)):
            if label == "compared" and package is None:
                continue
            bake(small, package, args.max_pairs, work, f"warm-{label}")  # kernels compiled, cached
            runs.append(bake(blend, package, args.max_pairs, work, label))
            print(runs[-1], flush=True)
    out = {"machine": platform.node(), "cpu_count": os.cpu_count(), "load_before": round(load, 2),
           "max_pairs": args.max_pairs, "compare_with": str(args.compare_with or ""), "runs": runs}
    results_file.write("reference", out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
