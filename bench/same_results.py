"""Does a change keep the results? The sample scenes baked with every method into the shading
vertices and a lightmap page, by this checkout and by another one (a checkout of an older
commit), each in its own process; prints the largest difference per scene and method, relative to
the brightest value, and the bake times side by side.

    .venv/bin/python bench/same_results.py --baseline DIR [--scenes cornell_box lamp_scene]
                                           [--methods direct reference …] [--json OUT]

DIR holds the older ``radiosity_baker`` package (a folder with a ``radiosity_baker`` link to the
older checkout). For refactors that must change nothing (issue #22): 0, or float noise where a
kernel's arithmetic was reordered. Writes nothing unless ``--json`` names a file.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
METHODS = ("direct", "reference", "hierarchical", "implicit", "antiradiance", "bunnell", "ao")


def _bake(scene: str, methods: list, out: str) -> None:
    """Child process: bake ``scene`` with each method into vertices and a lightmap (one page at
    8 texels/m); save per method its output per shading vertex and the page as ``out`` (.npz),
    and print the seconds per method as JSON."""
    os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="rb-same-"))
    import time

    import bpy
    import numpy as np

    from radiosity_baker.addon.extract import extract_scene
    from radiosity_baker.addon.lightmap import request
    from radiosity_baker.core import Settings, bake

    bpy.ops.wm.open_mainfile(filepath=str(ROOT / "sample_blends" / f"{scene}.blend"))
    extraction = extract_scene(bpy.context.evaluated_depsgraph_get())
    arrays, seconds = {}, {}
    for method in methods:
        settings = Settings(method=method, target="both", texel_density=8.0, atlas_pages="one",
                            device="cpu", output=tempfile.mkdtemp())
        lm_request, _ = request(extraction, settings)
        lm_request.cache_dir = Path(tempfile.mkdtemp())
        t0 = time.perf_counter()
        try:  # this checkout: targets; checkouts before the target contract: lightmap=
            from radiosity_baker.core import targets
            result = bake(extraction.scene, settings,
                          targets=[targets.make("vertices"), targets.make("lightmap", lm_request)])
            page = result["lightmap"].pages[0]
        except ImportError:
            result = bake(extraction.scene, settings, lightmap=lm_request)
            page = result.lightmap.pages[0]
        seconds[method] = round(time.perf_counter() - t0, 3)
        arrays[f"{method}.vertices"] = result.output
        arrays[f"{method}.page"] = page.rgb
    np.savez(out, **arrays)
    print(json.dumps(seconds))


def _run(scene: str, methods: list, pythonpath) -> tuple:
    env = dict(os.environ)
    if pythonpath:
        env["PYTHONPATH"] = str(pythonpath)
    out = tempfile.mktemp(suffix=".npz")
    proc = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--child", scene, out,
                           *methods], env=env, capture_output=True, text=True, cwd=tempfile.gettempdir())
    if proc.returncode != 0:
        raise SystemExit(f"bake of {scene} failed:\n{proc.stderr[-3000:]}")
    import numpy as np

    with np.load(out) as data:
        arrays = dict(data)
    os.unlink(out)
    return arrays, json.loads(proc.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--baseline", type=Path, required=True)
    parser.add_argument("--scenes", nargs="+", default=["cornell_box", "lamp_scene"])
    parser.add_argument("--methods", nargs="+", default=list(METHODS), choices=METHODS)
    parser.add_argument("--json", type=Path)
    args = parser.parse_args(argv)
    import numpy as np

    rows = []
    for scene in args.scenes:
        new, new_s = _run(scene, args.methods, None)
        old, old_s = _run(scene, args.methods, args.baseline)
        for method in args.methods:
            row = {"scene": scene, "method": method, "seconds": old_s[method], "seconds_new": new_s[method]}
            for part in ("vertices", "page"):
                a, b = old[f"{method}.{part}"], new[f"{method}.{part}"]
                row[part] = (float(np.abs(a - b).max() / max(float(np.abs(a).max()), 1e-30))
                             if a.shape == b.shape else f"shapes differ: {a.shape} vs {b.shape}")
            rows.append(row)
            print(f"{scene:12} {method:13} vertices {row['vertices']:<10.3} page {row['page']:<10.3} "
                  f"{row['seconds']:7.2f} s → {row['seconds_new']:7.2f} s", flush=True)
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    if sys.argv[1:2] == ["--child"]:
        _bake(sys.argv[2], sys.argv[4:], sys.argv[3])
    else:
        sys.exit(main())
