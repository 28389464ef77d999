"""Accuracy and speed of every method against Cycles, in one run (issue #3).

    .venv/bin/python bench/accuracy.py [--scenes cornell_box lamp_scene] [--methods direct reference]
                                       [--samples 16 64 256 1024] [--reference-samples 4096]
                                       [--device auto|cpu|cuda]

For each sample scene: Cycles vertex-colour bakes (DIFFUSE, Direct + Indirect, no Color) at each
sample count and at a high sample count taken as the truth; then each method of ours. Every bake is
timed (wall clock, extraction included for ours, scene sync included for Cycles) and compared with
the truth: relative RMSE, mean bias, 95th-percentile error (core.metrics). The equal-error speedup
is the time Cycles needs to reach our error — interpolated on its log error / log time curve, or
extrapolated along its last segment when our error lies outside the measured range (marked) —
divided by our time. Writes bench/results/<machine>-<date>.json, a PNG plot beside it, and prints
the markdown table README quotes.
"""
from __future__ import annotations

import argparse
import datetime
import json
import platform
import sys
import time
from pathlib import Path

import bpy
import numpy as np

from radiosity_baker.addon.compare import bake_vertex_values, stack
from radiosity_baker.addon.cycles_ref import cycles_bake_vertex_colors
from radiosity_baker.core import Settings, metrics
from radiosity_baker.core import settings as core_settings

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "addon"))
from test_reference_vs_cycles import receivers  # noqa: E402  (the same receiver choice as the test)


def cycles_series(names, samples, reference_samples):
    """({samples: (values, seconds)}, truth values) of Cycles bakes of ``names``."""
    series = {}
    for s in samples:
        t0 = time.perf_counter()
        values = cycles_bake_vertex_colors(names, samples=s, seed=s)
        series[s] = (stack(values, names), time.perf_counter() - t0)
        print(f"  cycles {s:5d} samples: {series[s][1]:7.2f} s", flush=True)
    t0 = time.perf_counter()
    truth = stack(cycles_bake_vertex_colors(names, samples=reference_samples, seed=7), names)
    print(f"  cycles {reference_samples:5d} samples (truth): {time.perf_counter() - t0:7.2f} s", flush=True)
    return series, truth


def equal_error_seconds(errors, seconds, target):
    """Cycles seconds at error ``target`` on the log–log curve through (seconds, errors); and
    whether that needed extrapolation."""
    le, lt = np.log(np.asarray(errors)), np.log(np.asarray(seconds))
    order = np.argsort(le)  # increasing error
    le, lt = le[order], lt[order]
    x = np.log(target)
    if le[0] <= x <= le[-1]:
        return float(np.exp(np.interp(x, le, lt))), False
    i = (0, 1) if x < le[0] else (-2, -1)
    slope = (lt[i[1]] - lt[i[0]]) / (le[i[1]] - le[i[0]])
    return float(np.exp(lt[i[0]] + slope * (x - le[i[0]]))), True


def run_scene(scene_name, methods, samples, reference_samples, device):
    bpy.ops.wm.open_mainfile(filepath=str(ROOT / "sample_blends" / f"{scene_name}.blend"))
    names = receivers(bpy.context.scene)
    print(f"{scene_name}: {', '.join(names)}", flush=True)
    series, truth = cycles_series(names, samples, reference_samples)
    cycles = [{"samples": s, "seconds": round(t, 3), **metrics.summary(v, truth)}
              for s, (v, t) in series.items()]
    ours = []
    for method in methods:
        values, result, seconds = bake_vertex_values(names, Settings(method=method, device=device))
        row = {"method": method, "seconds": round(seconds, 3), "device": result.device,
               "stages": {k: round(v, 3) for k, v in result.timings.items()},
               "peak_memory_mb": round(result.peak_memory_bytes / 2 ** 20, 1),
               "elements": result.counts["elements"], **metrics.summary(stack(values, names), truth)}
        cyc_seconds, extrapolated = equal_error_seconds([c["relative_rmse"] for c in cycles],
                                                        [c["seconds"] for c in cycles],
                                                        max(row["relative_rmse"], 1e-6))
        row.update(cycles_seconds_at_equal_error=round(cyc_seconds, 3),
                   speedup_at_equal_error=round(cyc_seconds / seconds, 2), extrapolated=extrapolated)
        print(f"  {method}: {seconds:.2f} s, rmse {row['relative_rmse']:.4f}, "
              f"speedup {row['speedup_at_equal_error']}{' (extrapolated)' if extrapolated else ''}", flush=True)
        ours.append(row)
    return {"receivers": names, "vertices": int(truth.shape[0]), "reference_samples": reference_samples,
            "cycles": cycles, "ours": ours}


def markdown(results) -> str:
    lines = ["| scene | method | time (s) | rel. RMSE | bias | p95 | Cycles time at equal error (s) | speedup |",
             "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: |"]
    for scene, r in results["scenes"].items():
        for c in r["cycles"]:
            lines.append(f"| {scene} | Cycles {c['samples']} spp | {c['seconds']:.2f} | {c['relative_rmse']:.4f} | "
                         f"{c['mean_bias']:+.4f} | {c['p95']:.4f} | | |")
        for o in r["ours"]:
            mark = "*" if o["extrapolated"] else ""
            lines.append(f"| {scene} | {o['method']} ({o['device']}) | {o['seconds']:.2f} | {o['relative_rmse']:.4f} | "
                         f"{o['mean_bias']:+.4f} | {o['p95']:.4f} | {o['cycles_seconds_at_equal_error']:.2f}{mark} | "
                         f"{o['speedup_at_equal_error']:.1f}×{mark} |")
    return "\n".join(lines)


def plot(results, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    scenes = results["scenes"]
    fig, axes = plt.subplots(1, len(scenes), figsize=(6 * len(scenes), 4.5), squeeze=False)
    for ax, (scene, r) in zip(axes[0], scenes.items()):
        ax.plot([c["seconds"] for c in r["cycles"]], [c["relative_rmse"] for c in r["cycles"]], "k-o",
                label="Cycles (16…1024 spp)")
        for c in r["cycles"]:
            ax.annotate(str(c["samples"]), (c["seconds"], c["relative_rmse"]), textcoords="offset points",
                        xytext=(4, 4), fontsize=8)
        for o in r["ours"]:
            ax.plot([o["seconds"]], [o["relative_rmse"]], "s", markersize=9, label=f"{o['method']} ({o['device']})")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("wall time (s)")
        ax.set_ylabel(f"relative RMSE vs Cycles {r['reference_samples']} spp")
        ax.set_title(scene)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenes", nargs="+", default=["cornell_box", "lamp_scene"])
    parser.add_argument("--methods", nargs="+", default=list(core_settings.METHODS),
                        choices=core_settings.METHODS)
    parser.add_argument("--samples", nargs="+", type=int, default=[16, 64, 256, 1024])
    parser.add_argument("--reference-samples", type=int, default=4096)
    parser.add_argument("--device", default="auto", choices=core_settings.DEVICES)
    parser.add_argument("--output", type=Path, default=ROOT / "bench" / "results")
    args = parser.parse_args(argv)
    machine = platform.node() or "machine"
    stamp = datetime.date.today().isoformat()
    results = {"machine": machine, "date": stamp, "platform": platform.platform(),
               "cpu_count": __import__("os").cpu_count(), "blender": bpy.app.version_string,
               "scenes": {s: run_scene(s, args.methods, args.samples, args.reference_samples, args.device)
                          for s in args.scenes}}
    args.output.mkdir(parents=True, exist_ok=True)
    base = args.output / f"accuracy-{machine}-{stamp}"
    base.with_suffix(".json").write_text(json.dumps(results, indent=2) + "\n")
    table = markdown(results)
    base.with_suffix(".md").write_text(table + "\n")
    plot(results, base.with_suffix(".png"))
    print(table)
    print(f"wrote {base}.json, .md, .png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
