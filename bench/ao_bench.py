"""Ambient occlusion over the disk tree: time against vertex count, next to the all-pairs sum;
hierarchy rebuild and refit of a deforming mesh; Bunnell indirect light against the reference.

Scene: a 10 m hilly terrain (a height field of k×k quads, hills 0.6 m high, 1.5 m apart) with
the default 10 m AO distance, so every receiver sees occluders at all scales. Times are wall
seconds of the AO gather (``ao.gather``, what ``ao.accessibility`` runs) at every vertex, the
hierarchy built beforehand and the kernels compiled by a warm-up run; the median of ``--repeat``
runs (other work on a shared machine shows as noise). The all-pairs sum (the same kernel
opening every node) runs while its predicted time stays under ``--pairs-limit`` seconds.

``--samples`` also compares Bunnell's one-bounce indirect light with the reference solver on the
sample scenes (needs the bpy module). Writes bench/results/ao-<hostname>.json.

    python bench/ao_bench.py [--sizes 10000 100000 1000000] [--device cpu|cuda] [--samples]
"""
from __future__ import annotations

import argparse
import platform
import socket
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from radiosity_baker.core import Settings, SceneData, gather, hierarchy
from radiosity_baker.core.problem import Problem
from radiosity_baker.core.scene import Lamps

sys.path.insert(0, str(Path(__file__).resolve().parent))
import results_file  # noqa: E402


def terrain(vertices: int, phase: float = 0.0) -> SceneData:
    """A 10 m square height field with about ``vertices`` vertices; ``phase`` (rad) shifts the
    hills, for deforming it."""
    k = max(2, int(round(np.sqrt(vertices))) - 1)
    s = np.linspace(-5.0, 5.0, k + 1)
    x, y = np.meshgrid(s, s, indexing="xy")
    z = 0.6 * np.sin(4.0 * x / np.pi + phase) * np.cos(4.0 * y / np.pi)
    dzdx = 0.6 * 4.0 / np.pi * np.cos(4.0 * x / np.pi + phase) * np.cos(4.0 * y / np.pi)
    dzdy = -0.6 * 4.0 / np.pi * np.sin(4.0 * x / np.pi + phase) * np.sin(4.0 * y / np.pi)
    pos = np.stack([x.ravel(), y.ravel(), z.ravel()], 1).astype(np.float32)
    nrm = np.stack([-dzdx.ravel(), -dzdy.ravel(), np.ones(x.size)], 1)
    nrm = (nrm / np.linalg.norm(nrm, axis=1, keepdims=True)).astype(np.float32)
    idx = np.arange((k + 1) ** 2).reshape(k + 1, k + 1)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, 1:].ravel(), idx[1:, :-1].ravel()
    tris = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)]).astype(np.int32)
    t = len(tris)
    return SceneData(positions=pos, corner_normals=nrm[tris], triangles=tris, tri_object=np.zeros(t, np.int32),
                     albedo=np.full((t, 3), 0.5, np.float32), emission=np.zeros((t, 3), np.float32),
                     lamps=Lamps.empty(), object_names=["Terrain"])


def _median_time(fn, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def scaling(sizes, settings: Settings, repeat: int, pairs_limit: float) -> list:
    rows = []
    pair_rate = None  # pairs per second of the all-pairs sum, from the last run
    for size in sizes:
        problem = Problem(terrain(size), settings)
        els, h = problem.elements, problem.tree
        n = els.count
        last = {}

        def run():
            last["gather"] = gather.gather(problem, els.position, els.normal, 10.0)

        tree = _median_time(run, repeat)
        row = {"vertices": n, "nodes": h.count, "levels": h.levels, "tree_seconds": round(tree, 4),
               "tree_receivers_per_second": round(n / tree),
               "visits_per_receiver": round(float(last["gather"].visits.mean()), 1)}
        if pair_rate is None or n * n / pair_rate <= pairs_limit:
            t0 = time.perf_counter()
            brute = gather.gather(problem, els.position, els.normal, 10.0, open_k=gather.ALL_PAIRS).accessibility
            pairs = time.perf_counter() - t0
            pair_rate = n * n / pairs
            access = last["gather"].accessibility
            row.update(all_pairs_seconds=round(pairs, 4),
                       tree_vs_all_pairs_mean_abs=round(float(np.abs(access - brute).mean()), 5),
                       tree_vs_all_pairs_max_abs=round(float(np.abs(access - brute).max()), 5))
        else:
            row["all_pairs_seconds_predicted"] = round(n * n / pair_rate, 1)
        rows.append(row)
        print(row, flush=True)
    for small, large in zip(rows, rows[1:]):
        large["time_ratio_to_previous"] = round(large["tree_seconds"] / small["tree_seconds"], 2)
        large["size_ratio_to_previous"] = round(large["vertices"] / small["vertices"], 2)
    return rows


def deforming(size: int, settings: Settings, frames: int) -> dict:
    """Build once, then per frame move the hills: the tree refitted (``Problem.move``: elements,
    device arrays and BVH updated, tree refitted) vs the tree rebuilt on the moved elements
    (seconds, median); the AO of the two trees compared on the last frame."""
    problem = Problem(terrain(size), settings)
    h = problem.tree
    refits, rebuilds, errors = [], [], []
    for f in range(1, frames + 1):
        moved = terrain(size, phase=0.2 * f)
        problem.__dict__.pop("tree")  # move without the tree: its refit is timed on its own
        problem.move(moved)
        t0 = time.perf_counter()
        hierarchy.refit(h, problem.surfels)
        refits.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        fresh = hierarchy.build(problem)
        rebuilds.append(time.perf_counter() - t0)
        problem.tree = h
        if f == frames:
            els = problem.elements
            a = gather.gather(problem, els.position, els.normal, 10.0).accessibility
            problem.tree = fresh
            b = gather.gather(problem, els.position, els.normal, 10.0).accessibility
            errors.append(float(np.abs(a - b).mean()))
    return {"vertices": problem.elements.count, "nodes": h.count, "frames": frames,
            "refit_seconds": round(statistics.median(refits), 5),
            "rebuild_seconds": round(statistics.median(rebuilds), 5),
            "refit_vs_rebuild_ao_mean_abs": round(errors[0], 5)}


def sample_scenes() -> dict:
    """Bunnell (one bounce) against the reference (default bounces, and one bounce) per sample."""
    import os
    import tempfile
    os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="rb-bench-"))
    import bpy

    from radiosity_baker.addon.extract import extract_scene
    from radiosity_baker.core import bake
    from harness import metrics

    root = Path(__file__).resolve().parents[1] / "sample_blends"
    out = {}
    for blend in ("cornell_box.blend", "lamp_scene.blend"):
        bpy.ops.wm.open_mainfile(filepath=str(root / blend))
        sc = extract_scene(bpy.context.evaluated_depsgraph_get()).scene
        results = {}
        for name, settings in (("bunnell", Settings(method="bunnell", device="cpu")),
                               ("reference", Settings(method="reference", device="cpu")),
                               ("reference_1_bounce", Settings(method="reference", bounces=1, device="cpu"))):
            t0 = time.perf_counter()
            results[name] = (bake(sc, settings), time.perf_counter() - t0)
        ours, seconds = results["bunnell"]
        row = {"elements": ours.counts["elements"], "bunnell_seconds": round(seconds, 3),
               "reference_seconds": round(results["reference"][1], 3)}
        for ref in ("reference", "reference_1_bounce"):
            r = results[ref][0]
            row[f"lighting_vs_{ref}"] = metrics.summary(ours.lighting, r.lighting)
            row[f"indirect_vs_{ref}"] = metrics.summary(ours.indirect, r.indirect)
        out[blend] = row
        print(blend, row, flush=True)
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[10_000, 100_000, 1_000_000])
    parser.add_argument("--device", choices=("cpu", "cuda"), default="cpu")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--pairs-limit", type=float, default=30.0,
                        help="skip the all-pairs sum when its predicted time exceeds this (s)")
    parser.add_argument("--deform-size", type=int, default=100_000)
    parser.add_argument("--frames", type=int, default=5)
    parser.add_argument("--samples", action="store_true",
                        help="also Bunnell vs the reference on the sample scenes (bpy)")
    args = parser.parse_args(argv)
    settings = Settings(device=args.device, content="ao", ao_distance=10.0)
    warm = Problem(terrain(2_000), settings)  # compile the kernels outside the timings
    gather.gather(warm, warm.elements.position, warm.elements.normal, 10.0)
    dev = warm.device
    report = {"host": socket.gethostname(), "device": dev.name, "threads": dev.threads,
              "platform": platform.platform(), "python": sys.version.split()[0],
              "scaling": scaling(args.sizes, settings, args.repeat, args.pairs_limit),
              "deforming": deforming(args.deform_size, settings, args.frames)}
    print("deforming", report["deforming"], flush=True)
    if args.samples:
        report["bunnell_vs_reference"] = sample_scenes()
    results_file.write("ao", report)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
