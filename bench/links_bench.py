"""Link creation and hierarchical radiosity: links per second, link counts, time per iteration and
end-to-end bake time against the element count; links rebuilt per frame on a deforming mesh; the
hierarchical solver against the reference at about 20 k elements.

    python bench/links_bench.py [--sizes 20000 200000 1000000] [--device cpu|cuda] [--repeat 3]
                                [--deform-size 100000] [--frames 5] [--reference-size 20000]
                                [--create-only]

Scenes (``bench/rooms.py``): a closed furnished room (walls, table, shelves, sofa, cabinet,
boxes) lit by a ceiling lamp and a window, tessellated to about the asked-for number of elements.
For each size:

- ``create``: the links of the geometric oracle without visibility (the counterpart of Meyer et
  al.'s antiradiance link creation, 50 M links/s on a GTX 260): seconds, links (directed: each
  link of a pair of nodes counts once per direction, as the gather reads them) and links/s, the
  best of ``--repeat`` runs;
- ``bake``: ``pipeline.bake`` end to end (elements, direct light, tree, links, solve) — wall
  seconds, peak memory, seconds per stage; within it ``links``, the links the solver builds
  (brightness-weighted oracle, 4 visibility samples per link: seconds, links, rays of the whole
  bake in ``rays``) and ``iteration``, seconds per gather + push over them (median) and of the
  final gather at the elements.

The deforming mesh is the hilly terrain of ``bench/ao_bench.py`` (hills moving each frame) under a
sun: per frame ``Problem.move`` (BVH and tree refitted) and the links made again from scratch.
Writes bench/results/links-<hostname>.json with the machine's load before and after;
``--create-only`` measures only ``create`` per size (minutes at a million elements instead of
an hour) into bench/results/links-create-<hostname>.json.
"""
from __future__ import annotations

import argparse
import os
import platform
import socket
import statistics
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from ao_bench import terrain  # noqa: E402  (the same deforming mesh as the AO benchmark)
from rooms import room, sun  # noqa: E402
import results_file  # noqa: E402

from radiosity_baker.core import Settings, bake, links  # noqa: E402
from harness import metrics  # noqa: E402
from radiosity_baker.core.problem import Problem  # noqa: E402
from radiosity_baker.core.solvers import hierarchical  # noqa: E402

ANCHOR = {"links_per_second": 50e6, "what": "Meyer et al. 2009, GTX 260: link creation for antiradiance "
          "(21 k patches, 1.1 M links in 24.2 ms)"}


def load() -> list:
    return [round(x, 2) for x in os.getloadavg()]


def best(fn, repeat):
    times, out = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return min(times), out


def size_row(size: int, settings: Settings, repeat: int, with_bake: bool = True) -> dict:
    scene = room(size)
    problem = Problem(scene, settings)
    problem.tree  # noqa: B018  (made before the timings)
    geometric = links.Oracle(threshold=settings.link_threshold, rays=0, visibility=False,
                             budget=settings.link_memory << 20)
    seconds, made = best(lambda p=problem: links.build(p, geometric), repeat)
    row = {"elements": problem.elements.count, "triangles": scene.num_triangles, "nodes": problem.tree.count,
           "create": {"seconds": round(seconds, 3), "links": made.count, "rounds": made.rounds,
                      "links_per_second": round(made.count / seconds)}}
    del made, problem
    if not with_bake:
        print(row, flush=True)
        return row
    marks = {}

    def progress(stage, fraction):
        marks.setdefault(stage, []).append(time.perf_counter())

    t0 = time.perf_counter()
    result = bake(scene, settings, progress=progress)
    row["bake"] = {"seconds": round(time.perf_counter() - t0, 2),
                   "peak_memory_mb": round(result.peak_memory_bytes / 2**20),
                   "stages": {k: round(v, 2) for k, v in result.timings.items()}, "warnings": result.warnings}
    c = result.counts
    row["links"] = {"seconds": round(result.timings["links"], 3), "links": c["links"],
                    "links_per_element": round(c["links"] / c["elements"], 1), "threshold": c["link_threshold"]}
    # iterations: from the links' end to each "bounces" report; the final gather from the last one
    # to the solve's end
    steps = np.diff([marks["links"][-1], *marks["bounces"]])
    row["iteration"] = {"seconds": round(float(np.median(steps)), 4), "iterations": len(steps),
                        "final_gather_seconds": round(marks["solve"][-1] - marks["bounces"][-1], 3),
                        "leaf_evaluations": c["leaf_evaluations"]}
    row["rays"] = c["rays"]
    print(row, flush=True)
    return row


def ratios(rows: list) -> list:
    """Each larger size against the previous: size ratio and time ratios."""
    out = []
    for small, large in zip(rows, rows[1:]):
        out.append({"elements": [small["elements"], large["elements"]],
                    "size_ratio": round(large["elements"] / small["elements"], 2),
                    **{f"{k}_time_ratio": round(large[k]["seconds"] / small[k]["seconds"], 2)
                       for k in ("create", "links", "iteration", "bake") if k in large}})
    return out


def deforming(size: int, settings: Settings, frames: int) -> dict:
    """Per frame: move the hills (Problem.move refits the BVH and the tree), then make the links
    again from scratch and solve; median seconds of each."""
    def lit(phase):
        return replace(terrain(size, phase), lamps=sun((0.3, 0.2, -0.93), 3.0))

    problem = Problem(lit(0.0), settings)
    hierarchical.solve(problem)
    moves, rebuilds, solves = [], [], []
    for f in range(1, frames + 1):
        moved = lit(0.2 * f)
        t0 = time.perf_counter()
        problem.move(moved)
        moves.append(time.perf_counter() - t0)
        problem.direct  # noqa: B018  (traced again; not part of the link rebuild)
        t0 = time.perf_counter()
        made = hierarchical.links_of(problem)
        rebuilds.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        hierarchical.solve(problem)
        solves.append(time.perf_counter() - t0)
    return {"vertices": int(moved.num_vertices), "elements": problem.elements.count, "links": made.count,
            "frames": frames, "move_refit_seconds": round(statistics.median(moves), 3),
            "links_rebuild_seconds": round(statistics.median(rebuilds), 3),
            "solve_seconds": round(statistics.median(solves), 3)}


def against_reference(size: int, settings: Settings) -> dict:
    """The hierarchical bake and the reference (its pair visibility held: --max-pairs raised so
    n² bytes fit) on the room of about ``size`` elements."""
    scene = room(size)
    t0 = time.perf_counter()
    ours = bake(scene, settings)
    ours_seconds = time.perf_counter() - t0
    n = ours.counts["elements"]
    ref_settings = Settings(**{**settings.as_dict(), "method": "reference", "max_pairs": n * n // 4 + 1})
    t0 = time.perf_counter()
    reference = bake(scene, ref_settings)
    ref_seconds = time.perf_counter() - t0
    return {"elements": n, "hierarchical_seconds": round(ours_seconds, 2), "reference_seconds": round(ref_seconds, 2),
            "reference_transport": reference.counts.get("transport"), "speedup": round(ref_seconds / ours_seconds, 1),
            "hierarchical_vs_reference": metrics.summary(ours.lighting, reference.lighting),
            "indirect_vs_reference": metrics.summary(ours.indirect, reference.indirect)}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[20_000, 200_000, 1_000_000])
    parser.add_argument("--device", choices=("cpu", "cuda"), default="cpu")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--deform-size", type=int, default=100_000)
    parser.add_argument("--frames", type=int, default=5)
    parser.add_argument("--reference-size", type=int, default=20_000, help="0 leaves the reference out")
    parser.add_argument("--create-only", action="store_true",
                        help="only link creation per size (no bakes, deforming mesh or reference); "
                             "writes links-create-<host>.json")
    args = parser.parse_args(argv)
    settings = Settings(method="hierarchical", device=args.device)
    warm = Problem(room(2_000), settings)  # compile the kernels outside the timings
    hierarchical.solve(warm)
    report = {"host": socket.gethostname(), "device": warm.device.name, "threads": warm.device.threads,
              "platform": platform.platform(), "python": sys.version.split()[0], "load_before": load(),
              "anchor": ANCHOR, "settings": {"link_threshold": settings.link_threshold,
                                             "visibility_rays": settings.visibility_rays}}
    report["sizes"] = [size_row(s, settings, args.repeat, not args.create_only) for s in args.sizes]
    report["ratios"] = ratios(report["sizes"])
    if args.create_only:
        report["load_after"] = load()
        results_file.write("links-create", report)
        return 0
    if args.deform_size:
        report["deforming"] = deforming(args.deform_size, settings, args.frames)
        print("deforming", report["deforming"], flush=True)
    if args.reference_size:
        report["reference"] = against_reference(args.reference_size, settings)
        print("reference", report["reference"], flush=True)
    report["load_after"] = load()
    results_file.write("links", report)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
