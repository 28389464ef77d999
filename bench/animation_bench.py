"""Frames per second of an animation's re-solve, per method, and Cycles' time per frame at equal
error (issue 12).

Scene: ``sample_blends/make_samples.py``'s animated room (a column bent by an armature, a door
swinging, a lamp sliding) built at grid cells that give about ``--sizes`` elements. For each size
and method, ``--frames`` frames are baked one after another with ``core.pipeline.Sequence`` (the
problem moved while the topology stays, the last solution the starting point), extraction
(bpy, main thread) and solve timed apart; the re-solve rate is 1 / the median solve time, what
the live preview and a frame-range bake wait for per frame. For the smallest size, the first frame
is also baked by Cycles (DIFFUSE Direct + Indirect vertex bake) at ``--cycles-samples`` and at
``--truth-samples`` as the truth, and the last (warm) frame at ``--truth-samples`` for its own
error; each of our methods is placed on Cycles' error/time curve as in
``bench/accuracy.py``. Writes bench/results/animation-<machine>.json.

    .venv/bin/python bench/animation_bench.py [--sizes 20000 100000] [--frames 6]
        [--methods direct bunnell ao hierarchical] [--cycles-samples 16 64 256] [--truth-samples 1024]
"""
from __future__ import annotations

import argparse
import importlib.util
import os
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="rb-bench-"))
import bpy  # noqa: E402
import numpy as np  # noqa: E402

from harness.cycles import cycles_bake_vertex_colors  # noqa: E402
from radiosity_baker.addon.extract import extract_scene  # noqa: E402
from radiosity_baker.addon.write import _per_vertex  # noqa: E402
from radiosity_baker.core import Settings  # noqa: E402
from harness import metrics  # noqa: E402
from radiosity_baker.core.pipeline import Sequence  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))
from accuracy import equal_error_seconds  # noqa: E402
import results_file  # noqa: E402


def _make_samples():
    spec = importlib.util.spec_from_file_location("make_samples", ROOT / "sample_blends" / "make_samples.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def room(elements: int):
    """The animated room with about ``elements`` shading vertices (frames 1–48); its mesh names."""
    make = _make_samples()
    bpy.ops.wm.read_homefile(use_empty=True, use_factory_startup=True)
    scene = bpy.context.scene
    # the room holds ~41 m² of walls and floor at 1/cell² vertices each, the column twice as fine
    cell = float(np.sqrt(45.0 / max(elements, 1)))
    make.animated_room(scene, cell=cell)
    return scene, sorted(ob.name for ob in scene.objects if ob.type == "MESH")


def frames(scene, names, settings, count):
    """Bake ``count`` frames spread over the animation; per-frame timings and the first frame's
    per-vertex output by mesh."""
    seq = Sequence(settings)
    rows, first, last = [], None, None
    for k, frame in enumerate(np.linspace(1, 48, count).round().astype(int)):
        t0 = time.perf_counter()
        scene.frame_set(int(frame))
        extraction = extract_scene(bpy.context.evaluated_depsgraph_get())
        t1 = time.perf_counter()
        result = seq.bake(extraction.scene)
        t2 = time.perf_counter()
        last = {t.object_name: _per_vertex(t, result.output) for t in extraction.targets}
        first = last if first is None else first
        rows.append({"frame": int(frame), "extract_seconds": round(t1 - t0, 4), "solve_seconds": round(t2 - t1, 4),
                     "moved": "move" in result.timings, "iterations": result.counts.get("iterations"),
                     "elements": result.counts["elements"],
                     "gather_rays_kept": result.counts.get("gather_rays_kept"),
                     "gather_rays": result.counts.get("gather_rays"),
                     # inclusive: "solve" holds "gather rays", "links" …; "lit backs" holds "direct"
                     "stages": {k: round(v, 4) for k, v in sorted(result.timings.items(), key=lambda kv: -kv[1])
                                if v >= 0.005}})
    return rows, first, last, int(frame)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[20_000, 100_000])
    parser.add_argument("--frames", type=int, default=6)
    parser.add_argument("--methods", nargs="+", default=["direct", "bunnell", "ao", "hierarchical"])
    parser.add_argument("--cycles-samples", type=int, nargs="+", default=[16, 64, 256])
    parser.add_argument("--truth-samples", type=int, default=1024)
    parser.add_argument("--no-cycles", dest="cycles", action="store_false")
    parser.add_argument("--device", default="cpu")
    args = parser.parse_args(argv)
    out = {"machine": platform.node(), "cpu_count": os.cpu_count(), "load_before": round(os.getloadavg()[0], 2),
           "frames_per_size": args.frames, "sizes": []}
    for size in args.sizes:
        scene, names = room(size)
        entry = {"asked_elements": size, "methods": {}}
        firsts, lasts = {}, {}
        for method in args.methods:
            settings = Settings(method=method, device=args.device, content="ao" if method == "ao" else "lighting")
            frames(scene, names, settings, 2)  # kernels compiled, caches warm
            rows, firsts[method], lasts[method], last_frame = frames(scene, names, settings, args.frames)
            moved = [r["solve_seconds"] for r in rows[1:] if r["moved"]] or [r["solve_seconds"] for r in rows]
            median = statistics.median(moved)
            entry["elements"] = rows[0]["elements"]
            entry["methods"][method] = {"frames": rows, "median_solve_seconds": round(median, 4),
                                        "solves_per_second": round(1.0 / median, 2),
                                        "median_extract_seconds": round(statistics.median(r["extract_seconds"] for r in rows), 4)}
            print(size, method, entry["methods"][method]["solves_per_second"], "solves/s", flush=True)
        if args.cycles and size == min(args.sizes):
            scene.frame_set(1)
            lit = [n for n in names]
            truth_t0 = time.perf_counter()
            truth = cycles_bake_vertex_colors(lit, samples=args.truth_samples, seed=7)
            truth_seconds = time.perf_counter() - truth_t0
            stack = (lambda values: np.concatenate([values[n] for n in lit]))
            curve = []
            for s in args.cycles_samples:
                t0 = time.perf_counter()
                values = cycles_bake_vertex_colors(lit, samples=s, seed=s)
                curve.append({"samples": s, "seconds": round(time.perf_counter() - t0, 3),
                              **metrics.summary(stack(values), stack(truth))})
                print("cycles", s, curve[-1], flush=True)
            entry["cycles"] = {"truth_samples": args.truth_samples, "truth_seconds": round(truth_seconds, 2),
                               "curve": curve}
            # the last frame, warm (moved from the frame before it): its own Cycles truth
            scene.frame_set(last_frame)
            truth_last = cycles_bake_vertex_colors(lit, samples=args.truth_samples, seed=7)
            for method, first in firsts.items():
                if method == "ao":
                    continue  # the AO bake is another quantity
                entry["methods"][method]["last_frame_vs_cycles"] = metrics.summary(stack(lasts[method]),
                                                                                    stack(truth_last))
                errors = metrics.summary(stack(first), stack(truth))
                seconds, extrapolated = equal_error_seconds([c["relative_rmse"] for c in curve],
                                                            [c["seconds"] for c in curve],
                                                            max(errors["relative_rmse"], 1e-6))
                m = entry["methods"][method]
                per_frame = m["median_solve_seconds"] + m["median_extract_seconds"]
                m.update(vs_cycles=errors, cycles_seconds_per_frame_at_equal_error=round(seconds, 2),
                         speedup_per_frame=round(seconds / per_frame, 1), extrapolated=extrapolated)
                print(method, m["vs_cycles"], m["speedup_per_frame"], flush=True)
        out["sizes"].append(entry)
    results_file.write("animation", out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
