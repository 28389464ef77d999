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
"""
from __future__ import annotations

import argparse
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
from test_hierarchical import box_room  # noqa: E402

from radiosity_baker.core import Settings, bake, metrics  # noqa: E402
from radiosity_baker.core import device as device_mod  # noqa: E402
from radiosity_baker.core.scene import LAMP_POINT  # noqa: E402
from radiosity_baker.core.solvers import antiradiance  # noqa: E402

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

    from radiosity_baker.addon.compare import bake_vertex_values, stack

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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bins", nargs="+", default=["64", "256", "1024"])
    parser.add_argument("--scenes", nargs="+", default=list(SCENES))
    parser.add_argument("--half", action="store_true")
    parser.add_argument("--blends", nargs="*", help="sample scenes (sample_blends/NAME.blend) through bpy")
    args = parser.parse_args()
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
