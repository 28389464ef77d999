"""Implicit visibility and antiradiance against the reference solver, per directional bin count
(issue #11), on scenes built in code (no bpy):

    .venv/bin/python bench/antiradiance_bench.py [--bins 64 256 1024] [--half] [--blends cornell_box lamp_scene]

Scenes: the Cornell box (``tests/core/shapes.cornell_box``: Cornell's geometry with the sample's
light, a black emitter 1 mm under the ceiling), the same box lit by a point lamp in the middle
instead (no light hidden behind the emitter), and a closed room with a cube
(``tests/core/test_hierarchical.box_room``). Per method and bin count: relative RMSE and mean bias
of the lighting (direct + indirect) at the vertices against the reference, iterations, links,
table memory, the bake's wall time and the time per iteration (the solver's own count). ``--half`` also runs antiradiance with its tables
rounded to half precision after every pass that writes them (what storing them as float16 would
give). ``--blends`` runs the sample scenes instead, opened through the bpy module (the vertices
of the meshes that reflect, as ``tests/addon/test_reference_vs_cycles.py`` compares them; the
errors only, per method and bin count). Writes bench/results/antiradiance-<machine>.json (or
antiradiance-samples-<machine>.json) and prints a markdown table.

``--anchor`` measures our time at the sizes of the published anchor instead (Meyer et al. 2009,
antiradiance on a GTX 260: 21 k patches, 1.1 M links, 256 bins; link creation 24.2 ms, three
iterations 53.1 ms, 11 fps for the whole frame):

    .venv/bin/python bench/antiradiance_bench.py --anchor [--elements 21000] [--links 1100000]
                                                 [--bins 256] [--device cpu|cuda]

The furnished room of ``bench/rooms.py`` sized to about ``--elements`` elements; the link
threshold found by a few link builds of the antiradiance oracle (``implicit.oracle``: no
visibility, both faces; secant steps on log links against log threshold) so that there are about
``--links`` links (directed, as ``counts["links"]`` counts them; within 5 %, else the closest
within 10 %); then per bin count one bake each with ``method="antiradiance"`` and
``"implicit"`` at that threshold, ``bounces=3`` and the smallest tolerance (exactly three
iterations), after a warm-up bake of a small room (kernels loaded, first launches made). Per
bake, seconds: ``links`` and ``direction masks`` (the stages of ``result.timings``: antiradiance's
bin masks and path transfers, implicit's per-element path weights) and their sum, link creation;
per iteration (the solver's own count) and three of them; frames per second, 1 / (link creation
+ three iterations); the solve stage and the bake's wall time; table MB (nodes × bins × 28
bytes), the process's peak memory; each against the anchor's (ours / anchor). On CUDA a stage's
last launches may finish in the next one: the sum of link creation and iterations holds, its
split may not. Writes bench/results/antiradiance-anchor-<machine>.json and prints a markdown
table.
"""
from __future__ import annotations

import argparse
import math
import os
import platform
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "core"))
sys.path.insert(0, str(ROOT / "bench"))

import shapes  # noqa: E402
import results_file  # noqa: E402
from rooms import room  # noqa: E402
from test_hierarchical import box_room  # noqa: E402

from radiosity_baker.core import Settings, bake, links  # noqa: E402
from harness import metrics  # noqa: E402
from radiosity_baker.core import device as device_mod  # noqa: E402
from radiosity_baker.core.problem import Problem  # noqa: E402
from radiosity_baker.core.scene import LAMP_POINT  # noqa: E402
from radiosity_baker.core.settings import option  # noqa: E402
from radiosity_baker.core.solvers import antiradiance, implicit  # noqa: E402

# Meyer et al. 2009 (data-parallel hierarchical link creation), antiradiance on a GTX 260; times
# in seconds. The 11 fps are the whole frame's, more than link creation and the iterations.
ANCHOR = {"what": "Meyer et al. 2009, GTX 260: antiradiance, 21 k patches, 1.1 M links, 256 bins",
          "elements": 21_000, "links": 1_100_000, "bins": 256, "link_creation_seconds": 0.0242,
          "iterations": 3, "iterations_seconds": 0.0531, "fps": 11.0}
# d log(links) / d log(threshold) of the room's antiradiance links (3.8 k elements, thresholds
# 0.05 … 0.4: −0.72 … −0.77): the threshold search's first step, before it has two builds.
LINK_SLOPE = -0.75
# The search stops within LINK_TOLERANCE of the asked links (a closer one costs another build:
# seconds at 21 k elements); the closest of at most LINK_TRIALS builds must be within LINK_LIMIT.
LINK_TOLERANCE, LINK_LIMIT, LINK_TRIALS = 0.05, 0.10, 6

def cornell_point():
    """The Cornell box lit by a 20 W point lamp in its middle, the emitter switched off."""
    sc = shapes.cornell_box()
    return replace(sc, emission=np.zeros_like(sc.emission),
                   lamps=shapes.lamp(LAMP_POINT, (0.278, 0.28, 0.4), power=(20,) * 3))


SCENES = {"cornell_box": shapes.cornell_box, "cornell_point_lamp": cornell_point, "box_room": box_room}


def halved(fn):
    """Run ``fn`` with antiradiance's tables rounded to float16 after each pass that writes them."""
    launch = device_mod.launch
    writes = {antiradiance._pull_kernel: -1, antiradiance._transport_kernel: (-2, -1),
              antiradiance._through_kernel: -1}

    def rounding(kernel, n, inputs, device, *args, **kwargs):
        launch(kernel, n, inputs, device, *args, **kwargs)
        if kernel in writes:
            where = writes[kernel]
            for k in (where if isinstance(where, tuple) else (where,)):
                a = inputs[k]
                a.assign(a.numpy().astype(np.float16).astype(np.float32))

    device_mod.launch = rounding
    try:
        return fn()
    finally:
        device_mod.launch = launch


def run(scene, method: str, bins: str, reference, half: bool = False) -> dict:
    settings = Settings(method=method, device="cpu", directional_bins=bins)
    t0 = time.perf_counter()
    ours = halved(lambda: bake(scene, settings)) if half else bake(scene, settings)
    seconds = time.perf_counter() - t0
    iterations = int(ours.counts["iterations"])
    row = {"method": method + (" (half)" if half else ""), "bins": int(bins), "iterations": iterations,
           "links": int(ours.counts["links"]), "seconds": round(seconds, 2),
           "seconds_per_iteration": round(ours.counts["seconds_per_iteration"], 4),
           "link_seconds": round(ours.timings.get("links", 0.0) + ours.timings.get("direction masks", 0.0), 2),
           **metrics.summary(ours.lighting, reference.lighting)}
    if "table_bytes" in ours.counts:
        row["table_mb"] = round(ours.counts["table_bytes"] / 2**20, 1)
    return row


def samples(blends, bins) -> dict:
    """Errors against the reference on the sample scenes (bpy), per method and bin count."""
    import bpy

    from harness.compare import bake_vertex_values, stack

    sys.path.insert(0, str(ROOT / "tests" / "addon"))
    from test_reference_vs_cycles import receivers

    out = {}
    for blend in blends:
        bpy.ops.wm.open_mainfile(filepath=str(ROOT / "sample_blends" / f"{blend}.blend"))
        names = receivers(bpy.context.scene)
        reference, result, _ = bake_vertex_values(names, Settings(method="reference"))
        rows = []
        for method in ("implicit", "antiradiance"):
            for b in bins:
                ours, res, seconds = bake_vertex_values(names, Settings(method=method, directional_bins=b))
                rows.append({"method": method, "bins": int(b), "seconds": round(seconds, 1),
                             "iterations": int(res.counts["iterations"]), "links": int(res.counts["links"]),
                             **metrics.summary(stack(ours, names), stack(reference, names))})
                print(blend, rows[-1], flush=True)
        out[blend] = {"elements": int(result.counts["elements"]), "rows": rows}
    return out


def anchor_room(elements: int):
    """The room of ``bench/rooms.py`` with about ``elements`` elements: its grids' edge vertices
    add 5–25 % to the count asked for, so it is asked once more, scaled by the excess."""
    first = room(elements).num_vertices
    return room(round(elements * elements / first))


def find_threshold(problem, settings: Settings, target: int) -> tuple[dict, list]:
    """The link threshold whose antiradiance links (``implicit.oracle`` of ``settings`` at that
    threshold) number about ``target`` (directed links): from the settings' threshold, secant
    steps on log links against log threshold (links grow as it falls), the first with
    LINK_SLOPE, until within LINK_TOLERANCE or LINK_TRIALS builds. Returns the closest build and
    every build: {threshold, links, seconds}."""
    low, high = option("link_threshold").low, option("link_threshold").high
    slope, threshold, trials = LINK_SLOPE, settings.link_threshold, []
    while len(trials) < LINK_TRIALS:
        t0 = time.perf_counter()
        made = links.build(problem, implicit.oracle(replace(settings, link_threshold=threshold)))
        # the build's own threshold: over the link budget it makes coarser links
        trials.append({"threshold": made.threshold, "links": made.count,
                       "seconds": round(time.perf_counter() - t0, 3)})
        print("threshold trial", trials[-1], flush=True)
        del made
        if abs(trials[-1]["links"] / target - 1) <= LINK_TOLERANCE:
            break
        if len(trials) > 1:
            a, b = trials[-2], trials[-1]
            if a["links"] != b["links"] and a["threshold"] != b["threshold"]:
                slope = math.log(b["links"] / a["links"]) / math.log(b["threshold"] / a["threshold"])
        step = trials[-1]["threshold"] * (target / trials[-1]["links"]) ** (1 / slope)
        threshold = min(max(step, low), high)
        if threshold == trials[-1]["threshold"]:  # held at a bound of the setting
            break
    best = min(trials, key=lambda r: abs(math.log(r["links"] / target)))
    if abs(best["links"] / target - 1) > LINK_LIMIT:
        raise SystemExit(f"no link threshold in [{low:g}, {high:g}] gives {target} links ±"
                         f"{100 * LINK_LIMIT:.0f} % in {len(trials)} builds: {trials}")
    return best, trials


def anchor_bake(scene, settings: Settings) -> dict:
    """One bake at the anchor's sizes: the link creation stages, iterations and their cost against
    the anchor's (seconds, MB; see the module docstring)."""
    t0 = time.perf_counter()
    result = bake(scene, settings)
    wall = time.perf_counter() - t0
    t, c = result.timings, result.counts
    creation = t["links"] + t.get("direction masks", 0.0)
    three = ANCHOR["iterations"] * c["seconds_per_iteration"]
    row = {"method": settings.method, "bins": int(settings.directional_bins), "links": int(c["links"]),
           "threshold": c["link_threshold"], "iterations": int(c["iterations"]),
           "links_seconds": round(t["links"], 4), "direction_masks_seconds": round(t.get("direction masks", 0.0), 4),
           "link_creation_seconds": round(creation, 4), "seconds_per_iteration": round(c["seconds_per_iteration"], 4),
           "three_iterations_seconds": round(three, 4), "fps": float(f"{1 / (creation + three):.3g}"),
           "solve_seconds": round(t["solve"], 3), "bake_seconds": round(wall, 2),
           "peak_memory_mb": round(result.peak_memory_bytes / 2**20), "stages": {k: round(v, 4) for k, v in t.items()},
           "warnings": result.warnings,
           "ours_over_anchor": {"link_creation": round(creation / ANCHOR["link_creation_seconds"], 1),
                                "three_iterations": round(three / ANCHOR["iterations_seconds"], 1),
                                "total": round((creation + three) / (ANCHOR["link_creation_seconds"]
                                                                      + ANCHOR["iterations_seconds"]), 1),
                                "fps": float(f"{1 / (creation + three) / ANCHOR['fps']:.3g}")}}
    if "table_bytes" in c:
        row["table_mb"] = round(c["table_bytes"] / 2**20, 1)
    if "path_links" in c:  # implicit: what its per-element weights cost grows with
        row["path_links"] = int(c["path_links"])
    if row["iterations"] != ANCHOR["iterations"]:
        print(f"warning: {settings.method} stopped after {row['iterations']} iterations", flush=True)
    print(row, flush=True)
    return row


def anchor(elements: int, target: int, bins: list[str], device: str) -> None:
    """The ``--anchor`` mode (module docstring): threshold search, bakes, JSON and a table."""
    dev = device_mod.select(device)
    load_before = [round(x, 2) for x in os.getloadavg()]
    scene = anchor_room(elements)
    base = Settings(method="antiradiance", device=device, bounces=ANCHOR["iterations"],
                    tolerance=option("tolerance").low)  # the smallest allowed: no early stop
    problem = Problem(scene, base)
    nodes = problem.tree.count
    count = problem.elements.count
    best, trials = find_threshold(problem, base, target)
    del problem
    print(f"{count} elements, {nodes} nodes: threshold {best['threshold']:.4g} gives {best['links']} links; "
          f"tables up to {', '.join(f'{antiradiance.table_bytes(nodes, int(b)) / 2**20:.0f} MB at {b} bins' for b in bins)}",
          flush=True)
    small = anchor_room(1_000)
    for b in bins:  # kernels loaded and first launches made outside the timings
        for method in ("antiradiance", "implicit"):
            bake(small, replace(base, method=method, directional_bins=b))
    rows = [anchor_bake(scene, replace(base, method=method, directional_bins=b, link_threshold=best["threshold"]))
            for b in bins for method in ("antiradiance", "implicit")]
    results_file.write("antiradiance-anchor", {
        "machine": f"{platform.node()}: {dev.name}, {dev.threads} threads", "device": dev.name,
        "elements": count, "nodes": nodes, "links": best["links"], "threshold": best["threshold"],
        "threshold_trials": trials, "bins": [int(b) for b in bins], "anchor": ANCHOR, "rows": rows,
        "load_before": load_before, "load_after": [round(x, 2) for x in os.getloadavg()]})
    print(f"\n{count} elements, {nodes} nodes, {best['links']} links (threshold {best['threshold']:.4g}), {dev.name}\n")
    print("| method | bins | links s | masks s | link creation s | s/iteration | 3 iterations s | fps | "
          "tables MB | solve s | ours/anchor (creation, iterations, total) |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    print(f"| anchor (GTX 260, 2009) | {ANCHOR['bins']} | | | {ANCHOR['link_creation_seconds']} | "
          f"{ANCHOR['iterations_seconds'] / ANCHOR['iterations']:.4f} | {ANCHOR['iterations_seconds']} | "
          f"{ANCHOR['fps']:g} (frame) | | | |")
    for r in rows:
        q = r["ours_over_anchor"]
        print(f"| {r['method']} | {r['bins']} | {r['links_seconds']} | {r['direction_masks_seconds']} | "
              f"{r['link_creation_seconds']} | {r['seconds_per_iteration']} | {r['three_iterations_seconds']} | "
              f"{r['fps']} | {r.get('table_mb', '–')} | {r['solve_seconds']} | "
              f"{q['link_creation']} × / {q['three_iterations']} × / {q['total']} × |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bins", nargs="+", help="directional bins (default 64 256 1024; --anchor: 256)")
    parser.add_argument("--scenes", nargs="+", default=list(SCENES))
    parser.add_argument("--half", action="store_true")
    parser.add_argument("--blends", nargs="*", help="sample scenes (sample_blends/NAME.blend) through bpy")
    parser.add_argument("--anchor", action="store_true", help="our time at the sizes of Meyer et al. 2009")
    parser.add_argument("--elements", type=int, default=ANCHOR["elements"], help="--anchor: about this many elements")
    parser.add_argument("--links", type=int, default=ANCHOR["links"], help="--anchor: about this many links")
    parser.add_argument("--device", choices=("cpu", "cuda"), default="cpu", help="--anchor: where it runs")
    args = parser.parse_args()
    if args.anchor:
        anchor(args.elements, args.links, args.bins or [str(ANCHOR["bins"])], args.device)
        return
    args.bins = args.bins or ["64", "256", "1024"]
    if args.blends:
        results_file.write("antiradiance-samples", {"machine": f"{platform.node()}: cpu",
                                                    "scenes": samples(args.blends, args.bins)})
        return
    out = {"machine": f"{platform.node()}: {device_mod.select('cpu').name}, {device_mod.select('cpu').threads} threads",
           "scenes": {}}
    for name in args.scenes:
        scene = SCENES[name]()
        reference = bake(scene, Settings(method="reference", device="cpu"))
        hier = bake(scene, Settings(method="hierarchical", device="cpu"))
        rows = [{"method": "hierarchical", "bins": 0, **metrics.summary(hier.lighting, reference.lighting)}]
        for method in ("implicit", "antiradiance"):
            rows += [run(scene, method, b, reference) for b in args.bins]
        if args.half:
            rows += [run(scene, "antiradiance", b, reference, half=True) for b in args.bins]
        out["scenes"][name] = {"elements": int(reference.counts["elements"]), "rows": rows}
        print(f"\n{name} ({reference.counts['elements']} elements)\n")
        print("| method | bins | rel. RMSE | bias | iterations | s/iteration | links | table MB |")
        print("| --- | --- | --- | --- | --- | --- | --- | --- |")
        for r in rows:
            print(f"| {r['method']} | {r['bins'] or '–'} | {100 * r['relative_rmse']:.1f} % | "
                  f"{100 * r['mean_bias']:+.1f} % | {r.get('iterations', '–')} | "
                  f"{r.get('seconds_per_iteration', '–')} | {r.get('links', '–')} | {r.get('table_mb', '–')} |")
    results_file.write("antiradiance", out)


if __name__ == "__main__":
    main()
