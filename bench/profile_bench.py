"""Where the default bake's time goes, per kernel: the sample scenes and code-built rooms.

    python bench/profile_bench.py [--scenes cornell_box lamp_scene room9k room20k room100k]
                                  [--baseline DIR] [--repeat 3] [--device cpu|cuda]

For each scene a default (hierarchical) bake runs inside ``core.device.profiling()``: every launch
through ``device.launch`` and every ``device.section`` (scans, sorts, copies back) is timed, wall
and process CPU seconds (CPU seconds, all threads, are the steadier measure on a shared machine).
The kernels are summed into the issue's categories (``CATEGORIES``); what a stage took beyond its
kernels is its Python and numpy work (``other``). Then, on the same problem:

- ``visibility``: the solver's links made again without visibility rays (same oracle, rays drawn
  but not traced): the oracle's seconds without rays; the difference to the bake's oracle is the
  rays' time (an estimate: without rays no link is split for partial visibility, so the two
  builds make slightly different links); rays/s from it; rays per link pair;
- ``create``: the geometric oracle without visibility or samples (``rays=0``, the counterpart of
  Meyer et al.'s link creation), best of ``--repeat``: links (both directions) per wall second
  and per CPU second.

Scenes: ``cornell_box`` and ``lamp_scene`` are the sample .blend files (extracted through bpy);
``room<N>k`` is ``bench/rooms.py``'s furnished room of about N thousand elements (point and area
lamp). With ``--baseline DIR`` (a folder holding another ``radiosity_baker`` package, e.g. an
export of an earlier commit) every scene is profiled by both, interleaved in subprocesses
(baseline, then this tree), so before and after share the machine's load; the load average is
recorded with each. Writes bench/results/profile-<host>.json.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import socket
import subprocess
import sys
import time
from pathlib import Path

BENCH = Path(__file__).resolve().parent
ROOT = BENCH.parent
sys.path.insert(0, str(BENCH))

# The categories: kernel or section names (``device.kernel_name``) or module prefixes
# ("module.") summed into each; what matches none is "other kernels".
CATEGORIES = {
    # on the CPU most links are made depth first, the oracle and the links' writes in one kernel
    "oracle (with rays)": ["links._oracle_kernel", "links._depth_first_kernel", "links._oracle_geometric_kernel",
                           "links._depth_first_geometric_kernel"],
    "scan/scatter": ["links.scan", "links._scatter_kernel", "links.concatenate", "links.grow"],
    "sort": ["links._directed_kernel", "links.sort", "links._csr_kernel", "links._count_kernel",
             "links._total_kernel", "links._cursor_kernel", "links._place_kernel"],
    "link setup": ["links._max_kernel", "links._first_leaf_kernel", "links._canonical_kernel"],
    # the cluster tree with its normal cones (before 2026-12-05 the cones were link setup)
    "tree": ["hierarchy._morton_kernel", "hierarchy._flag_kernel", "hierarchy._link_kernel",
             "hierarchy._place_kernel", "hierarchy._descend_kernel", "hierarchy._next_kernel",
             "hierarchy._leaf_kernel", "hierarchy._merge_kernel"],
    "sweeps": ["hierarchical._gather_kernel", "hierarchical._push_kernel", "hierarchy.", "base.",
               "hits._sweep_kernel"],
    "final gather": ["hierarchical._above_kernel", "hierarchical._leaf_gather_kernel"],
    "gather rays": ["hits._trace_kernel"],
    "direct light": ["direct."],
}
SCENES = ("cornell_box", "lamp_scene", "room9k", "room20k", "room100k")


def category(name: str) -> str:
    for cat, keys in CATEGORIES.items():
        if any(name == k or (k.endswith(".") and name.startswith(k)) for k in keys):
            return cat
    return "other kernels"


def load() -> list:
    return [round(x, 2) for x in os.getloadavg()]


def scene_data(name: str):
    """SceneData of a scene name (see the module docstring)."""
    if name.startswith("room"):
        from rooms import room
        return room(int(name[4:].rstrip("k")) * 1000)
    import bpy
    from radiosity_baker.addon.extract import extract_scene
    bpy.ops.wm.open_mainfile(filepath=str(ROOT / "sample_blends" / f"{name}.blend"))
    return extract_scene(bpy.context.evaluated_depsgraph_get()).scene


def profile_scene(name: str, device: str, repeat: int) -> dict:
    """One scene's profile (this process's ``radiosity_baker``)."""
    from dataclasses import replace

    from radiosity_baker.core import Settings, bake, links
    from radiosity_baker.core import device as device_mod
    from radiosity_baker.core.problem import Problem
    from radiosity_baker.core.solvers import hierarchical
    from rooms import room

    settings = Settings(method="hierarchical", device=device)
    bake(room(1500), settings)  # kernels loaded and first launches made outside the timings
    scene = scene_data(name)
    row = {"scene": name, "load_before": load()}
    t0, c0 = time.perf_counter(), time.process_time()
    with device_mod.profiling() as table:
        result = bake(scene, settings)
    row["bake"] = {"seconds": round(time.perf_counter() - t0, 3), "cpu_seconds": round(time.process_time() - c0, 3)}
    c = result.counts
    row["counts"] = {k: c.get(k) for k in ("elements", "links", "link_threshold", "rays", "iterations",
                                           "leaf_evaluations", "gather_rays", "gather_sweeps")}
    row["stages"] = {k: round(v, 3) for k, v in result.timings.items()}
    row["kernels"] = table.as_dict()
    cats: dict = {}
    for kname, k in table.rows.items():
        cat = cats.setdefault(category(kname), {"seconds": 0.0, "cpu_seconds": 0.0})
        cat["seconds"] += k["seconds"]
        cat["cpu_seconds"] += k["cpu_seconds"]
    row["categories"] = {k: {x: round(y, 4) for x, y in v.items()} for k, v in cats.items()}

    problem = Problem(scene, settings)
    oracle = hierarchical.oracle(settings)
    radiance = hierarchical.first_radiance(problem)
    builds = {}
    for label, o in (("with_rays", oracle), ("without_rays", replace(oracle, visibility=False))):
        with device_mod.profiling() as t:
            made = links.build(problem, o, radiance)
        oracle_rows = [v for name, v in t.rows.items() if name in CATEGORIES["oracle (with rays)"]]
        builds[label] = {"seconds": round(made.seconds, 3),
                         "oracle_seconds": round(sum(k["seconds"] for k in oracle_rows), 4),
                         "oracle_cpu_seconds": round(sum(k["cpu_seconds"] for k in oracle_rows), 4),
                         "links": made.count, "rays": made.rays_traced}
    w, wo = builds["with_rays"], builds["without_rays"]
    ray_seconds = max(w["oracle_seconds"] - wo["oracle_seconds"], 1e-9)
    ray_cpu = max(w["oracle_cpu_seconds"] - wo["oracle_cpu_seconds"], 1e-9)
    row["visibility"] = {**builds, "rays_per_link_pair": round(w["rays"] / max(w["links"] // 2, 1), 2),
                         "ray_seconds": round(ray_seconds, 3), "rays_per_second": round(w["rays"] / ray_seconds),
                         "rays_per_cpu_second": round(w["rays"] / ray_cpu)}
    geometric = links.Oracle(threshold=settings.link_threshold, rays=0, visibility=False,
                             budget=settings.link_memory << 20)
    best = None
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        made = links.build(problem, geometric)
        took = (time.perf_counter() - t0, time.process_time() - c0)
        best = took if best is None or took[0] < best[0] else best
    row["create"] = {"links": made.count, "rounds": made.rounds, "seconds": round(best[0], 4),
                     "cpu_seconds": round(best[1], 4), "links_per_second": round(made.count / best[0]),
                     "links_per_cpu_second": round(made.count / best[1])}
    row["load_after"] = load()
    return row


def run_worker(package_dir: Path | None, name: str, device: str, repeat: int) -> dict:
    """``profile_scene`` in a subprocess importing ``radiosity_baker`` from ``package_dir``
    (None: this process's path)."""
    env = dict(os.environ)
    if package_dir is not None:
        env["PYTHONPATH"] = os.pathsep.join([str(package_dir), env.get("PYTHONPATH", "")])
    out = subprocess.run([sys.executable, __file__, "--worker", name, "--device", device, "--repeat", str(repeat)],
                         env=env, check=True, capture_output=True, text=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def summary(row: dict) -> str:
    v, cr = row["visibility"], row["create"]
    cats = ", ".join(f"{k} {x['seconds']:.2f}" for k, x in row["categories"].items())
    return (f"{row['scene']}: bake {row['bake']['seconds']:.2f} s ({cats}); links {row['counts']['links']}, "
            f"{v['rays_per_link_pair']} rays/pair, {v['rays_per_second'] / 1e6:.2f} M rays/s; create "
            f"{cr['links_per_second'] / 1e6:.2f} M links/s ({cr['links_per_cpu_second'] / 1e6:.2f} M per CPU s); "
            f"load {row['load_before'][0]}")


def markdown(report: dict) -> str:
    """The table the manual quotes: per scene and version, CPU seconds per category, the bake's wall
    and CPU seconds, rays per link pair and link creation per CPU second."""
    cats = list(CATEGORIES) + ["other kernels"]
    lines = [f"| scene | version | {' | '.join(cats)} | bake wall (CPU) s | rays/pair | rays/CPU s | create links/CPU s |",
             "| --- | --- |" + " ---: |" * (len(cats) + 4)]
    for name, entry in report["scenes"].items():
        for version, row in entry.items():
            c = row["categories"]
            cells = " | ".join(f"{c[k]['cpu_seconds']:.2f}" if k in c else "" for k in cats)
            v, cr = row["visibility"], row["create"]
            lines.append(f"| {name} ({row['counts']['elements']}) | {version} | {cells} | {row['bake']['seconds']:.1f} "
                         f"({row['bake']['cpu_seconds']:.1f}) | {v['rays_per_link_pair']:.2f} | "
                         f"{v['rays_per_cpu_second'] / 1e6:.2f} M | {cr['links_per_cpu_second'] / 1e6:.2f} M |")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", nargs="+", default=list(SCENES))
    parser.add_argument("--baseline", type=Path, help="a folder holding another radiosity_baker package")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--device", choices=("cpu", "cuda"), default="cpu")
    parser.add_argument("--worker", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.worker:
        print(json.dumps(profile_scene(args.worker, args.device, args.repeat)), flush=True)
        return 0
    report = {"host": socket.gethostname(), "platform": platform.platform(), "cpus": os.cpu_count(),
              "python": sys.version.split()[0], "device": args.device, "load_before": load(),
              "baseline": str(args.baseline) if args.baseline else None, "scenes": {}}
    for name in args.scenes:
        entry = {}
        if args.baseline:
            entry["before"] = run_worker(args.baseline.resolve(), name, args.device, args.repeat)
            print("before", summary(entry["before"]), flush=True)
        entry["after"] = run_worker(None, name, args.device, args.repeat)
        print("after " if args.baseline else "", summary(entry["after"]), flush=True)
        report["scenes"][name] = entry
    report["load_after"] = load()
    import results_file
    results_file.write("profile", report)
    print(markdown(report))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
