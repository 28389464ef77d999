"""Accuracy and speed of every method against Cycles, in one run (issues #3 and #5).

    .venv/bin/python bench/accuracy.py [--scenes cornell_box lamp_scene] [--methods direct reference bunnell]
                                       [--samples 16 64 256 1024] [--reference-samples 4096]
                                       [--no-ao] [--device auto|cpu|cuda]

For each sample scene, two quantities, each against Cycles bakes of the same vertices at each
sample count and at a high sample count taken as the truth:

- lighting (DIFFUSE, Direct + Indirect, no Color) for each method of ours: relative RMSE, mean
  bias, 95th-percentile error (core.metrics.summary); the speedup is measured on relative RMSE;
- ambient occlusion (Cycles' AO bake, the world's AO distance) for ``--content ao``: mean absolute
  error, mean bias, 95th-percentile absolute error (core.metrics.scalar_summary); the speedup is
  measured on the mean absolute error.

Every bake is timed (wall clock, extraction included for ours, scene sync included for Cycles).
The equal-error speedup is the time Cycles needs to reach our error — interpolated on its log
error / log time curve, or extrapolated along its last segment when our error lies outside the
measured range (marked) — divided by our time. Writes bench/results/accuracy-<machine>-<date>.json,
a PNG plot and the markdown tables README quotes (.md) beside it, and prints the tables.
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
from radiosity_baker.core.solvers import SOLVERS

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "addon"))
from test_reference_vs_cycles import receivers  # noqa: E402  (the same receiver choice as the test)


# What each quantity is baked as in Cycles, how errors are summarised, and which summary entry the
# equal-error speedup is measured on.
QUANTITIES = {
    "lighting": {"bake_type": "DIFFUSE", "summary": metrics.summary, "error": "relative_rmse"},
    "ao": {"bake_type": "AO", "summary": metrics.scalar_summary, "error": "mean_abs_error"},
}


def cycles_series(names, samples, reference_samples, bake_type):
    """({samples: (values, seconds)}, truth values) of Cycles ``bake_type`` bakes of ``names``."""
    series = {}
    for s in samples:
        t0 = time.perf_counter()
        values = cycles_bake_vertex_colors(names, bake_type=bake_type, samples=s, seed=s)
        series[s] = (stack(values, names), time.perf_counter() - t0)
        print(f"  cycles {bake_type} {s:5d} samples: {series[s][1]:7.2f} s", flush=True)
    t0 = time.perf_counter()
    truth = stack(cycles_bake_vertex_colors(names, bake_type=bake_type, samples=reference_samples, seed=7),
                  names)
    print(f"  cycles {bake_type} {reference_samples:5d} samples (truth): {time.perf_counter() - t0:7.2f} s",
          flush=True)
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


def run_quantity(names, quantity, runs, samples, reference_samples):
    """Cycles' error/time curve for ``quantity`` and each of our ``runs`` ({label: Settings})
    placed on it: {"cycles": [rows], "ours": [rows]}."""
    q = QUANTITIES[quantity]
    series, truth = cycles_series(names, samples, reference_samples, q["bake_type"])
    cycles = [{"samples": s, "seconds": round(t, 3), **q["summary"](v, truth)} for s, (v, t) in series.items()]
    ours = []
    for label, settings in runs.items():
        values, result, seconds = bake_vertex_values(names, settings)
        row = {"method": label, "seconds": round(seconds, 3), "device": result.device,
               "stages": {k: round(v, 3) for k, v in result.timings.items()},
               "peak_memory_mb": round(result.peak_memory_bytes / 2 ** 20, 1),
               "elements": result.counts["elements"], **q["summary"](stack(values, names), truth)}
        cyc_seconds, extrapolated = equal_error_seconds([c[q["error"]] for c in cycles],
                                                        [c["seconds"] for c in cycles],
                                                        max(row[q["error"]], 1e-6))
        row.update(cycles_seconds_at_equal_error=round(cyc_seconds, 3),
                   speedup_at_equal_error=round(cyc_seconds / seconds, 2), extrapolated=extrapolated)
        print(f"  {quantity} {label}: {seconds:.2f} s, {q['error']} {row[q['error']]:.4f}, "
              f"speedup {row['speedup_at_equal_error']}{' (extrapolated)' if extrapolated else ''}", flush=True)
        ours.append(row)
    return {"error": q["error"], "truth_mean": round(float(truth.mean()), 5),
            "cycles": cycles, "ours": ours}


def run_scene(scene_name, methods, samples, reference_samples, device, with_ao):
    bpy.ops.wm.open_mainfile(filepath=str(ROOT / "sample_blends" / f"{scene_name}.blend"))
    scene = bpy.context.scene
    names = receivers(scene)
    print(f"{scene_name}: {', '.join(names)}", flush=True)
    out = {"receivers": names, "vertices": int(sum(len(scene.objects[n].data.vertices) for n in names)),
           "reference_samples": reference_samples,
           "lighting": run_quantity(names, "lighting", {m: Settings(method=m, device=device) for m in methods},
                                    samples, reference_samples)}
    if with_ao:
        out["ao_distance"] = float(scene.world.light_settings.distance)
        out["ao"] = run_quantity(names, "ao", {"ao": Settings(content="ao", device=device)}, samples,
                                 reference_samples)
    return out


def markdown(results) -> str:
    """One table per quantity: Cycles' rows, then ours with the equal-error speedup (* extrapolated)."""
    tables = []
    for quantity, heads in (("lighting", ("rel. RMSE", "bias", "p95")),
                            ("ao", ("mean abs error", "mean bias", "p95 abs error"))):
        scenes = {k: r[quantity] for k, r in results["scenes"].items() if quantity in r}
        if not scenes:
            continue
        keys = list(scenes.values())[0]["cycles"][0]
        keys = [k for k in keys if k not in ("samples", "seconds")]
        lines = [f"| scene | {quantity} | time (s) | {' | '.join(heads)} | Cycles time at equal error (s) | speedup |",
                 "| --- | --- | ---: | ---: | ---: | ---: | ---: | ---: |"]
        def errors(row):
            return " | ".join(f"{row[k]:+.4f}" if "bias" in k else f"{row[k]:.4f}" for k in keys)

        for scene, r in scenes.items():
            for c in r["cycles"]:
                lines.append(f"| {scene} | Cycles {c['samples']} spp | {c['seconds']:.2f} | {errors(c)} | | |")
            for o in r["ours"]:
                mark = "*" if o["extrapolated"] else ""
                lines.append(f"| {scene} | **{o['method']}** ({o['device']}) | {o['seconds']:.2f} | {errors(o)} | "
                             f"{o['cycles_seconds_at_equal_error']:.2f}{mark} | {o['speedup_at_equal_error']:.1f}×{mark} |")
        tables.append("\n".join(lines))
    return "\n\n".join(tables)


def plot(results, path: Path) -> None:
    """Error against wall time, one panel per scene and quantity: Cycles as a line, ours as marks."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    quantities = [q for q in QUANTITIES if any(q in r for r in results["scenes"].values())]
    scenes = results["scenes"]
    fig, axes = plt.subplots(len(quantities), len(scenes), figsize=(6 * len(scenes), 4.5 * len(quantities)),
                             squeeze=False)
    for row, quantity in zip(axes, quantities):
        for ax, (scene, r) in zip(row, scenes.items()):
            if quantity in r:
                _panel(ax, scene, quantity, r[quantity], r["reference_samples"])
            else:
                ax.set_visible(False)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def _panel(ax, scene, quantity, r, reference_samples) -> None:
    err = r["error"]
    ax.plot([c["seconds"] for c in r["cycles"]], [c[err] for c in r["cycles"]], "k-o",
            label=f"Cycles ({r['cycles'][0]['samples']}…{r['cycles'][-1]['samples']} spp)")
    for c in r["cycles"]:
        ax.annotate(str(c["samples"]), (c["seconds"], c[err]), textcoords="offset points",
                    xytext=(4, 4), fontsize=8)
    for o in r["ours"]:
        ax.plot([o["seconds"]], [o[err]], "s", markersize=9, label=f"{o['method']} ({o['device']})")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("wall time (s)")
    ax.set_ylabel(f"{err.replace('_', ' ')} vs Cycles {reference_samples} spp")
    ax.set_title(f"{scene}: {quantity}")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenes", nargs="+", default=["cornell_box", "lamp_scene"])
    light = [name for name, info in SOLVERS.items() if info.light]
    parser.add_argument("--methods", nargs="+", default=light, choices=light)
    parser.add_argument("--samples", nargs="+", type=int, default=[16, 64, 256, 1024])
    parser.add_argument("--reference-samples", type=int, default=4096)
    parser.add_argument("--no-ao", dest="ao", action="store_false", help="leave out AO against Cycles' AO bake")
    parser.add_argument("--device", default="auto", choices=core_settings.DEVICES)
    parser.add_argument("--output", type=Path, default=ROOT / "bench" / "results")
    args = parser.parse_args(argv)
    machine = platform.node() or "machine"
    stamp = datetime.date.today().isoformat()
    results = {"machine": machine, "date": stamp, "platform": platform.platform(),
               "cpu_count": __import__("os").cpu_count(), "blender": bpy.app.version_string,
               "scenes": {s: run_scene(s, args.methods, args.samples, args.reference_samples, args.device, args.ao)
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
