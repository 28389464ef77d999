"""Accuracy and speed of every method against Cycles, in one run (issues #3 and #5).

    .venv/bin/python bench/accuracy.py [--scenes cornell_box lamp_scene flat_furnace emissive_room
                                                  furnished_room open_scene level]
                                       [--methods direct reference bunnell]
                                       [--variants contact_levels=2,link_threshold=0.03 ...]
                                       [--samples 16 64 256 1024] [--reference-samples 4096]
                                       [--no-ao] [--device auto|cpu|cuda]
                                       [--passes all|direct [--light-samples 64 128 256]
                                        [--light-selections tree exact]]

For each scene — the sample scenes, and built in code (``bench/emissive_scenes.py``) a closed
flat-shaded emissive furnace and a room lit by a 2 304-triangle emissive sign, and
(``bench/real_scenes.py``) a furnished room of 8 940 vertices, an open scene lit by the sun and
the benchmark level at 116 k elements —
two quantities, each against Cycles bakes of the same vertices at each
sample count and at a high sample count taken as the truth:

- lighting (DIFFUSE, Direct + Indirect, no Color) for each method of ours, and for each of
  ``--variants`` (the default method with those settings changed, labelled by them): relative
  RMSE, mean bias, 95th-percentile error (core.metrics.summary); the speedup is measured on
  relative RMSE;
- with ``--passes direct`` (issue 20), direct light alone: Cycles' DIFFUSE Direct pass against our
  ``direct`` method at each of ``--light-samples`` shadow rays per receiver and each of
  ``--light-selections`` (no AO);
- ambient occlusion (Cycles' AO bake, the world's AO distance) for ``--content ao``: mean absolute
  error, mean bias, 95th-percentile absolute error (core.metrics.scalar_summary); the speedup is
  measured on the mean absolute error.

With ``--lightmap`` (issue #13) it compares lightmaps instead: see :func:`run_lightmap`. With
``--lightmap-cost 256 1024 4096`` (issue 40) it times our page of each ``--lightmap-scene`` alone at
each size, no Cycles bake: seconds and microseconds per covered texel, by stage
(:func:`run_lightmap_cost`; accuracy-lightmap-cost-<scene>-<machine>-<date>.*).

Every bake is timed (wall clock, extraction included for ours, scene sync included for Cycles),
after one untimed bake of ours that loads Warp's kernels (the add-on loads them when Blender
starts).
The equal-error speedup is the time Cycles needs to reach our error — interpolated on its log
error / log time curve, or extrapolated along its last segment when our error lies outside the
measured range (marked) — divided by our time. Writes bench/results/accuracy-<machine>-<date>.json
(accuracy-direct-… with ``--passes direct``),
a PNG plot and the markdown tables the manual quotes (.md) beside it, and prints the tables.
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

from harness.compare import bake_vertex_values, stack
from harness.cycles import cycles_bake_image, cycles_bake_vertex_colors
from radiosity_baker.core import Settings
from harness import metrics
from radiosity_baker.core import settings as core_settings
from radiosity_baker.core.errors import SettingsError
from radiosity_baker.core.solvers import SOLVERS

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "addon"))
from test_reference_vs_cycles import receivers  # noqa: E402  (the same receiver choice as the test)
from test_lightmap_vs_cycles import _next_to_a_jump  # noqa: E402  (the same texels left out)
sys.path.insert(0, str(ROOT / "bench"))
import emissive_scenes  # noqa: E402  (scenes built in code: the flat-shaded furnace, the emissive room)
import real_scenes  # noqa: E402  (scenes built in code: the furnished room, the open scene)

SCENES = {**emissive_scenes.SCENES, **real_scenes.SCENES}  # the scenes built in code, by name


# What each quantity is baked as in Cycles, how errors are summarised, and which summary entry the
# equal-error speedup is measured on.
QUANTITIES = {
    "lighting": {"bake_type": "DIFFUSE", "summary": metrics.summary, "error": "relative_rmse"},
    "ao": {"bake_type": "AO", "summary": metrics.scalar_summary, "error": "mean_abs_error"},
}


# Cycles' DIFFUSE passes of each ``--passes`` choice.
PASSES = {"all": ("DIRECT", "INDIRECT"), "direct": ("DIRECT",)}


def cycles_series(names, samples, reference_samples, bake_type, passes=PASSES["all"]):
    """({samples: (values, seconds)}, truth values) of Cycles ``bake_type`` bakes of ``names``
    (DIFFUSE with ``passes``)."""
    series = {}
    for s in samples:
        t0 = time.perf_counter()
        values = cycles_bake_vertex_colors(names, bake_type=bake_type, passes=passes, samples=s, seed=s)
        series[s] = (stack(values, names), time.perf_counter() - t0)
        print(f"  cycles {bake_type} {s:5d} samples: {series[s][1]:7.2f} s", flush=True)
    t0 = time.perf_counter()
    truth = stack(cycles_bake_vertex_colors(names, bake_type=bake_type, passes=passes,
                                            samples=reference_samples, seed=7), names)
    print(f"  cycles {bake_type} {reference_samples:5d} samples (truth): {time.perf_counter() - t0:7.2f} s",
          flush=True)
    return series, truth


def equal_error_seconds(errors, seconds, target):
    """Cycles seconds at error ``target`` on the log–log curve through (seconds, errors); and
    whether that needed extrapolation. A curve of one point is extended at Monte Carlo's rate,
    error ∝ time^(−1/2)."""
    le, lt = np.log(np.asarray(errors)), np.log(np.asarray(seconds))
    order = np.argsort(le)  # increasing error
    le, lt = le[order], lt[order]
    x = np.log(target)
    if le[0] <= x <= le[-1]:
        return float(np.exp(np.interp(x, le, lt))), False
    if len(le) == 1:
        return float(np.exp(lt[0] - 2.0 * (x - le[0]))), True
    i = (0, 1) if x < le[0] else (-2, -1)
    slope = (lt[i[1]] - lt[i[0]]) / (le[i[1]] - le[i[0]])
    return float(np.exp(lt[i[0]] + slope * (x - le[i[0]]))), True


def run_quantity(names, quantity, runs, samples, reference_samples, passes=PASSES["all"]):
    """Cycles' error/time curve for ``quantity`` (lighting: of the DIFFUSE ``passes``) and each of
    our ``runs`` ({label: Settings}) placed on it: {"cycles": [rows], "ours": [rows]}."""
    q = QUANTITIES[quantity]
    series, truth = cycles_series(names, samples, reference_samples, q["bake_type"], passes)
    cycles = [{"samples": s, "seconds": round(t, 3), **q["summary"](v, truth)} for s, (v, t) in series.items()]
    ours = []
    if runs:  # untimed: Warp loads its kernels at the first bake (the add-on does at start-up)
        bake_vertex_values(names, next(iter(runs.values())))
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


def variant(label: str, device: str) -> Settings:
    """The Settings of ``label`` (``name=value,…``: settings fields changed from their defaults,
    each value read as its default's type)."""
    defaults = Settings()
    changed = {}
    for item in label.split(","):
        name, _, value = item.partition("=")
        kind = type(getattr(defaults, name.strip()))
        changed[name.strip()] = kind(value) if kind is not bool else value.lower() in ("1", "true", "on")
    return Settings(device=device, **changed).validate()


def direct_runs(light_samples, selections, device) -> dict:
    """{label: Settings} of the ``direct`` method at each light sample count and selection."""
    return {f"direct {sel} {n}": Settings(method="direct", light_selection=sel, light_samples=n, device=device)
            for sel in selections for n in light_samples}


def _open(scene_name):
    """Open a sample scene (``sample_blends``) or build one in code (``SCENES``); the scene."""
    if scene_name in SCENES:
        SCENES[scene_name]()
    else:
        bpy.ops.wm.open_mainfile(filepath=str(ROOT / "sample_blends" / f"{scene_name}.blend"))
    return bpy.context.scene


def run_scene(scene_name, methods, samples, reference_samples, device, with_ao, passes="all",
              light_samples=(64,), selections=("auto",), variants=()):
    """One sample scene (``sample_blends``) or scene built in code (``SCENES``);
    ``passes`` direct compares direct light alone (``direct_runs``, no AO); ``variants``: labels
    ``name=value,…`` of settings runs of the default method (``variant``)."""
    scene = _open(scene_name)
    names = receivers(scene)
    print(f"{scene_name}: {', '.join(names)}", flush=True)
    out = {"receivers": names, "vertices": int(sum(len(scene.objects[n].data.vertices) for n in names)),
           "reference_samples": reference_samples, "passes": passes}
    runs = (direct_runs(light_samples, selections, device) if passes == "direct"
            else {**{m: Settings(method=m, device=device) for m in methods},
                  **{v: variant(v, device) for v in variants}})
    out["lighting"] = run_quantity(names, "lighting", runs, samples, reference_samples, PASSES[passes])
    if with_ao and passes == "all":
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


def _oidn():
    """The pyoidn module, or None where it is not installed."""
    try:
        import pyoidn
    except ImportError:
        return None
    return pyoidn


def _denoised(pyoidn, image: np.ndarray) -> tuple:
    """(float32[H,W,3] RGB, seconds) of a Cycles image bake (float32[H,W,4], alpha = baked)
    denoised by OIDN's lightmap filter after its charts were dilated into the gutter (a bake
    margin of DENOISE_MARGIN texels), as lightmappers that bake with Cycles do."""
    from radiosity_baker.core.lightmap.pages import dilate

    t0 = time.perf_counter()
    rgb = dilate(image[..., :3], image[..., 3] > 0.5, DENOISE_MARGIN)
    out = pyoidn.denoise(np.ascontiguousarray(rgb, np.float32), filter_type="RTLightmap")
    return out, time.perf_counter() - t0


DENOISE_MARGIN = 16


def _lightmap_mask(page, reference: np.ndarray) -> np.ndarray:
    """The texels compared, as tests/addon/test_lightmap_vs_cycles.py chooses them: baked by both,
    not next to the light's outline (a jump of the lighting inside a texel), not hidden (0 in
    Cycles)."""
    baked = page.covered & (reference[..., 3] > 0.5)
    return baked & ~_next_to_a_jump(page.rgb, page.covered) & (reference[..., :3].max(axis=2) > 0.0)


def _rel(squared: float, mean: float) -> float:
    """Relative RMSE from a mean squared RGB error (clamped at 0) and the truth's mean norm."""
    return float(np.sqrt(max(squared, 0.0)) / mean)


def _ms(a: np.ndarray, b: np.ndarray, mask: np.ndarray) -> float:
    return float(((a[mask] - b[mask]) ** 2).sum(axis=1).mean())


def _our_lightmap(names, size: int, output: Path, method: dict):
    """Our lightmap of ``names`` on one page of ``size`` (the default settings but ``method``:
    Settings fields, which override them), baked through the add-on so the ``Lightmap`` UVs Cycles
    bakes through are written: (page, wall seconds from extraction to written files, timings)."""
    from radiosity_baker.addon.job import BakeJob

    settings = Settings(**{"target": "lightmap", "max_size": size, "texel_density": 1e4, "padding": 2,
                           "atlas_pages": "one", "reunwrap": True, "output": str(output),
                           **method})
    t0 = time.perf_counter()
    job = BakeJob(settings, names)
    job.run_sync(bpy.context)
    return job.result["lightmap"].pages[0], time.perf_counter() - t0, job.timings


def _lightmapped(scene_name) -> list:
    """Open ``scene_name``; the names of the meshes its lightmap bakes: in the sample scenes every
    mesh but the Cornell light, in the scenes built in code their reflectors."""
    scene = _open(scene_name)
    return (receivers(scene) if scene_name in SCENES
            else sorted(o.name for o in scene.objects if o.type == "MESH" and o.name != "Light"))


def run_lightmap(scene_name, truth_size, samples, reference_samples, pair_sizes, pair_samples,
                 extrapolated_sizes, output: Path, passes="all", method=None) -> dict:
    """Lightmaps of ``scene_name`` against Cycles' image bake through the same UVs: its DIFFUSE
    ``passes`` against ours with ``method`` (Settings fields; None: the defaults).

    At ``truth_size``: our page, Cycles at each of ``samples`` and a ``reference_samples`` truth;
    each Cycles bake also denoised (OIDN ``RTLightmap``, where pyoidn is installed). At each of
    ``pair_sizes`` (too many texels for a truth): two Cycles bakes of different seeds at each of
    ``pair_samples``; their difference measures Cycles' own noise σ² (half its mean square), so
    errors against the truth follow from errors against a noisy bake: Cycles' is its noise, ours
    is mean|ours − mean of the pair|² − σ²/2, a denoised bake's mean|D(first) − second|² − σ² of
    the second (the highest sample count). At ``extrapolated_sizes``: our page timed and one Cycles
    bake at the lowest of ``pair_samples`` timed; errors per sample count taken from the largest
    pair size (noise per texel does not depend on the page size), Cycles' and OIDN's times scaled
    from there by texels × samples and texels (marked extrapolated). Equal-error speedups as for
    vertices, against raw Cycles and against Cycles + OIDN.
    """
    pyoidn = _oidn()
    method = dict(method or {})
    names = _lightmapped(scene_name)
    out = {"objects": names, "method": method.get("method", Settings().method), "settings": method,
           "passes": list(PASSES[passes]),
           "denoiser": "OIDN RTLightmap (pyoidn)" if pyoidn else None,
           "denoiser_note": None if pyoidn else "pyoidn is not installed: no denoised curve", "sizes": {}}
    for size in [truth_size, *pair_sizes, *extrapolated_sizes]:
        page, seconds, timings = _our_lightmap(names, size, output / f"ours-{size}", method)
        w, h = page.size
        row = {"size": [w, h], "texels": int(page.covered.sum()), "ours_seconds": round(seconds, 3),
               "ours_stages": {k: round(v, 3) for k, v in timings.items()}}
        print(f"  lightmap {size}: ours {w}x{h} in {seconds:.1f} s", flush=True)
        bake = {}

        def cycles(s, seed):
            t0 = time.perf_counter()
            image = cycles_bake_image(names, "Lightmap", w, h, samples=s, seed=seed, passes=PASSES[passes])
            bake[(s, seed)] = (image, time.perf_counter() - t0)
            print(f"  lightmap {size}: cycles {s} spp seed {seed}: {bake[(s, seed)][1]:.1f} s", flush=True)
            return bake[(s, seed)]

        if size == truth_size:
            truth, _ = cycles(reference_samples, 7)
            mask = _lightmap_mask(page, truth)
            mean = float(np.linalg.norm(truth[..., :3][mask], axis=1).mean())
            curve = []
            for s in samples:
                image, t = cycles(s, s)
                entry = {"samples": s, "seconds": round(t, 3),
                         "relative_rmse": round(_rel(_ms(image[..., :3], truth[..., :3], mask), mean), 5)}
                if pyoidn:
                    d, td = _denoised(pyoidn, image)
                    entry.update(denoise_seconds=round(td, 3),
                                 denoised_relative_rmse=round(_rel(_ms(d, truth[..., :3], mask), mean), 5))
                curve.append(entry)
            ours = _rel(_ms(page.rgb, truth[..., :3], mask), mean)
            row.update(truth_samples=reference_samples, texels_compared=int(mask.sum()))
        elif size in pair_sizes:
            top = max(pair_samples)
            (a_top, _), (b_top, _) = cycles(top, 1), cycles(top, 2)
            mask = _lightmap_mask(page, a_top) & (b_top[..., 3] > 0.5)
            mean = float(np.linalg.norm(0.5 * (a_top + b_top)[..., :3][mask], axis=1).mean())
            sigma_top = 0.5 * _ms(a_top[..., :3], b_top[..., :3], mask)
            curve = []
            for s in sorted(pair_samples):
                (a, ta), (b, _) = (bake[(s, 1)], bake[(s, 2)]) if s == top else (cycles(s, 1), cycles(s, 2))
                entry = {"samples": s, "seconds": round(ta, 3),
                         "relative_rmse": round(_rel(0.5 * _ms(a[..., :3], b[..., :3], mask), mean), 5)}
                if pyoidn:
                    d, td = _denoised(pyoidn, a)
                    entry.update(denoise_seconds=round(td, 3), denoised_relative_rmse=round(
                        _rel(_ms(d, b_top[..., :3], mask) - sigma_top, mean), 5))
                curve.append(entry)
            ours = _rel(_ms(page.rgb, 0.5 * (a_top + b_top)[..., :3], mask) - 0.5 * sigma_top, mean)
            row.update(pair_samples=sorted(pair_samples), texels_compared=int(mask.sum()),
                       cycles_noise_measured_from="pairs of bakes")
        else:  # extrapolated from the largest pair size
            base = out["sizes"][str(max(pair_sizes))]
            low = min(pair_samples)
            _, t_low = cycles(low, 1)
            scale = t_low / next(c["seconds"] for c in base["cycles"] if c["samples"] == low)
            texel_scale = row["texels"] / base["texels"]
            curve = [{"samples": c["samples"], "seconds": round(c["seconds"] * scale, 3),
                      "relative_rmse": c["relative_rmse"],
                      **({"denoise_seconds": round(c["denoise_seconds"] * texel_scale, 3),
                          "denoised_relative_rmse": c["denoised_relative_rmse"]} if pyoidn else {})}
                     for c in base["cycles"]]
            ours = base["ours_relative_rmse"]
            row.update(extrapolated=True, cycles_seconds_measured={low: round(t_low, 3)},
                       note=f"Cycles measured at {low} spp only; errors from the {max(pair_sizes)} page")
        row["cycles"] = curve
        row["ours_relative_rmse"] = round(ours, 5)
        for label, key, extra in (("cycles", "relative_rmse", None), ("cycles_oidn", "denoised_relative_rmse",
                                                                       "denoise_seconds")):
            if key not in curve[0]:
                continue
            t, extrapolated = equal_error_seconds([c[key] for c in curve],
                                                  [c["seconds"] + (c[extra] if extra else 0.0) for c in curve],
                                                  max(ours, 1e-6))
            row[f"{label}_seconds_at_equal_error"] = round(t, 3)
            row[f"speedup_vs_{label}"] = float(f"{t / seconds:.3g}")  # 3 figures: a small ratio must not read 0
            row[f"{label}_extrapolated"] = extrapolated
        speedups = {k: v for k, v in row.items() if "speedup" in k}
        print(f"  lightmap {size}: ours RMSE {ours:.4f}; {json.dumps(speedups)}", flush=True)
        out["sizes"][str(size)] = row
    return out


def run_lightmap_cost(scene_name, sizes, output: Path, method=None) -> dict:
    """Our lightmap of ``scene_name`` (receivers as :func:`run_lightmap` takes them) on one page of
    each of ``sizes``, after one untimed bake at the smallest that loads the kernels: per size the
    page, the covered texels, the wall seconds from extraction to written files, microseconds per
    covered texel and the stages' seconds; a size the bake refuses (``SettingsError``) gets its
    message instead."""
    method = dict(method or {})
    names = _lightmapped(scene_name)
    try:
        _our_lightmap(names, min(sizes), output / "warm", method)
    except SettingsError:
        pass  # the loop below says why
    rows = []
    for size in sizes:
        try:
            page, seconds, timings = _our_lightmap(names, size, output / f"ours-{size}", method)
        except SettingsError as error:  # e.g. over the memory a bake may use: said, and the rest kept
            rows.append({"max_size": size, "refused": str(error)})
            print(f"  lightmap cost {size}: refused: {error}", flush=True)
            continue
        texels = int(page.covered.sum())
        rows.append({"max_size": size, "size": list(page.size), "texels": texels, "seconds": round(seconds, 3),
                     "microseconds_per_texel": round(1e6 * seconds / max(texels, 1), 2),
                     "stages": {k: round(v, 3) for k, v in timings.items()}})
        print(f"  lightmap cost {size}: {page.size[0]}x{page.size[1]}, {texels} texels in {seconds:.1f} s "
              f"({rows[-1]['microseconds_per_texel']} µs a texel)", flush=True)
    return {"objects": names, "method": method.get("method", Settings().method), "settings": method, "sizes": rows}


def cost_markdown(results) -> str:
    """One row per page size: texels, seconds, µs per texel and the three largest stages."""
    lines = ["| page | covered texels | seconds | µs per texel | largest stages (s) |",
             "| --- | ---: | ---: | ---: | --- |"]
    for r in results["cost"]["sizes"]:
        if "refused" in r:
            lines.append(f"| {r['max_size']} (max) | | | | refused: {r['refused']} |")
            continue
        top = sorted(r["stages"].items(), key=lambda kv: -kv[1])[:3]
        lines.append(f"| {r['size'][0]}×{r['size'][1]} | {r['texels']} | {r['seconds']:.1f} | "
                     f"{r['microseconds_per_texel']:.1f} | {', '.join(f'{k} {v:.1f}' for k, v in top)} |")
    return "\n".join(lines)


def cost_plot(results, path: Path) -> None:
    """Seconds and microseconds per texel against covered texels, log-log."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    rows = [r for r in results["cost"]["sizes"] if "refused" not in r]
    texels = [r["texels"] for r in rows]
    fig, (left, right) = plt.subplots(1, 2, figsize=(12, 4.5))
    left.plot(texels, [r["seconds"] for r in rows], "r-s")
    left.set_ylabel("wall time, extraction to written files (s)")
    right.plot(texels, [r["microseconds_per_texel"] for r in rows], "r-s")
    right.set_ylabel("µs per covered texel")
    for ax in (left, right):
        for r in rows:
            ax.annotate(f"{r['size'][0]}²", (r["texels"], r["seconds"] if ax is left else r["microseconds_per_texel"]),
                        textcoords="offset points", xytext=(4, 4), fontsize=8)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("covered texels")
        ax.set_title(f"{results['cost']['scene']}: our lightmap by page size")
        ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def lightmap_markdown(results) -> str:
    """One table: per page size, Cycles' rows (raw and denoised) and ours with both speedups."""
    lines = ["| page | bake | time (s) | rel. RMSE | denoised time (s) | denoised rel. RMSE |",
             "| --- | --- | ---: | ---: | ---: | ---: |"]
    for size, r in results["lightmap"]["sizes"].items():
        mark = "*" if r.get("extrapolated") else ""
        w, h = r["size"]
        for c in r["cycles"]:
            den = (f"{c['seconds'] + c['denoise_seconds']:.1f}{mark} | {c['denoised_relative_rmse']:.4f}"
                   if "denoised_relative_rmse" in c else " | ")
            lines.append(f"| {w}×{h} | Cycles {c['samples']} spp | {c['seconds']:.1f}{mark} | "
                         f"{c['relative_rmse']:.4f} | {den} |")
        speed = "; ".join(f"{r[f'speedup_vs_{k}']:.1f}×{'*' if r[f'{k}_extrapolated'] else ''} vs {label}"
                          for k, label in (("cycles", "Cycles"), ("cycles_oidn", "Cycles + OIDN"))
                          if f"speedup_vs_{k}" in r)
        settings = results["lightmap"].get("settings", {})
        label = " ".join(str(settings[k]) for k in ("light_selection", "light_samples") if k in settings)
        lines.append(f"| {w}×{h} | **ours** ({results['lightmap']['method']}{' ' + label if label else ''}, "
                     f"{r['texels']} texels) | "
                     f"{r['ours_seconds']:.1f} | "
                     f"{r['ours_relative_rmse']:.4f} | {speed} | |")
    return "\n".join(lines)


def lightmap_plot(results, path: Path) -> None:
    """Error against time per page size: Cycles raw and denoised as lines, ours as a mark."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    sizes = results["lightmap"]["sizes"]
    fig, axes = plt.subplots(1, len(sizes), figsize=(6 * len(sizes), 4.5), squeeze=False)
    for ax, (size, r) in zip(axes[0], sizes.items()):
        c = r["cycles"]
        ax.plot([x["seconds"] for x in c], [x["relative_rmse"] for x in c], "k-o", label="Cycles")
        if "denoised_relative_rmse" in c[0]:
            ax.plot([x["seconds"] + x["denoise_seconds"] for x in c], [x["denoised_relative_rmse"] for x in c],
                    "b-o", label="Cycles + OIDN")
        for x in c:
            ax.annotate(str(x["samples"]), (x["seconds"], x["relative_rmse"]), textcoords="offset points",
                        xytext=(4, 4), fontsize=8)
        ax.plot([r["ours_seconds"]], [max(r["ours_relative_rmse"], 1e-4)], "rs", markersize=9, label="ours")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("wall time (s)")
        ax.set_ylabel("relative RMSE")
        ax.set_title(f"{results['lightmap']['scene']} lightmap {r['size'][0]}×{r['size'][1]}"
                     + (" (Cycles extrapolated)" if r.get("extrapolated") else ""))
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def _lightmap_method(args) -> dict:
    """Settings fields of our lightmap bake: with ``--passes direct`` the direct method at the
    first of ``--light-samples`` and ``--light-selections``, one sample per texel (the default:
    Cycles' image bake lights each texel at its centre — on the emissive room's 128 page
    supersample 2 read 2.06 % from a 4096-sample Cycles bake, 1 read 1.84 %); else the defaults
    but the device and ``--supersample`` (2 unless told: in ``bench/lightmap_errors.py`` it is
    closer than 1 to Cycles' point bake on the furnished room, the emissive room and the open scene,
    as well as to the texel-footprint mean it aims at)."""
    if args.passes != "direct":
        return {"device": args.device, "supersample": args.supersample}
    return {"method": "direct", "light_samples": args.light_samples[0], "supersample": 1,
            "light_selection": args.light_selections[0], "device": args.device}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenes", nargs="+", default=["cornell_box", "lamp_scene"])
    light = [name for name, info in SOLVERS.items() if info.light]
    parser.add_argument("--methods", nargs="+", default=light, choices=light)
    parser.add_argument("--samples", nargs="+", type=int, default=[16, 64, 256, 1024])
    parser.add_argument("--reference-samples", type=int, default=4096)
    parser.add_argument("--variants", nargs="*", default=[],
                        help="runs of the default method with settings changed: name=value,name=value")
    parser.add_argument("--no-ao", dest="ao", action="store_false", help="leave out AO against Cycles' AO bake")
    parser.add_argument("--device", default="auto", choices=core_settings.DEVICES)
    parser.add_argument("--passes", default="all", choices=sorted(PASSES),
                        help="direct: Cycles' Direct pass against our direct light alone (no AO)")
    parser.add_argument("--light-samples", nargs="+", type=int, default=[64],
                        help="with --passes direct: shadow rays per receiver of each run")
    parser.add_argument("--light-selections", nargs="+", default=["auto"], choices=core_settings.LIGHT_SELECTIONS,
                        help="with --passes direct: emitter selection of each run")
    parser.add_argument("--output", type=Path, default=ROOT / "bench" / "results")
    parser.add_argument("--lightmap", action="store_true",
                        help="compare lightmaps with Cycles' image bake instead")
    parser.add_argument("--lightmap-scene", nargs="+", default=["cornell_box"],
                        help=f"sample scenes or ones built in code ({', '.join(SCENES)}), one file each")
    parser.add_argument("--truth-size", type=int, default=256, help="page with a high-sample Cycles truth")
    parser.add_argument("--pair-sizes", type=int, nargs="*", default=[1024],
                        help="pages whose Cycles noise is measured from pairs of bakes")
    parser.add_argument("--pair-samples", type=int, nargs="+", default=[16, 64])
    parser.add_argument("--extrapolated-sizes", type=int, nargs="*", default=[2048])
    parser.add_argument("--lightmap-cost", type=int, nargs="+", metavar="SIZE",
                        help="time our lightmap of each --lightmap-scene at these page sizes, no Cycles")
    parser.add_argument("--supersample", type=int, default=2,
                        help="our lightmap's samples per texel along each axis (not with --passes direct)")
    args = parser.parse_args(argv)
    machine = platform.node() or "machine"
    stamp = datetime.date.today().isoformat()
    if args.lightmap_cost:
        import os
        import tempfile
        for scene in args.lightmap_scene:
            results = {"machine": machine, "date": stamp, "platform": platform.platform(),
                       "cpu_count": os.cpu_count(), "blender": bpy.app.version_string,
                       "load_at_start": round(os.getloadavg()[0], 2),
                       "cost": {"scene": scene, **run_lightmap_cost(scene, args.lightmap_cost,
                                                                    Path(tempfile.mkdtemp(prefix="rb-cost-")),
                                                                    _lightmap_method(args))},
                       "load_at_end": round(os.getloadavg()[0], 2)}
            _write(args.output / f"accuracy-lightmap-cost-{scene}-{machine}-{stamp}", results, cost_markdown,
                   cost_plot)
        return 0
    if args.lightmap:
        import os
        import tempfile
        kind = "-direct" if args.passes == "direct" else ""
        for scene in args.lightmap_scene:
            load = os.getloadavg()[0]
            results = {"machine": machine, "date": stamp, "platform": platform.platform(),
                       "cpu_count": os.cpu_count(), "blender": bpy.app.version_string, "load_at_start": round(load, 2),
                       "lightmap": {"scene": scene,
                                    **run_lightmap(scene, args.truth_size, args.samples, args.reference_samples,
                                                   args.pair_sizes, args.pair_samples, args.extrapolated_sizes,
                                                   Path(tempfile.mkdtemp(prefix="rb-acc-")), args.passes,
                                                   _lightmap_method(args))},
                       "load_at_end": round(os.getloadavg()[0], 2)}
            _write(args.output / f"accuracy-lightmap{kind}-{scene}-{machine}-{stamp}", results, lightmap_markdown,
                   lightmap_plot)
        return 0
    results = {"machine": machine, "date": stamp, "platform": platform.platform(),
               "cpu_count": __import__("os").cpu_count(), "blender": bpy.app.version_string,
               "load_at_start": round(__import__("os").getloadavg()[0], 2),
               "scenes": {s: run_scene(s, args.methods, args.samples, args.reference_samples, args.device, args.ao,
                                       args.passes, args.light_samples, args.light_selections, args.variants)
                          for s in args.scenes}}
    results["load_at_end"] = round(__import__("os").getloadavg()[0], 2)
    kind = "direct-" if args.passes == "direct" else ""
    return _write(args.output / f"accuracy-{kind}{machine}-{stamp}", results, markdown, plot)


def _write(base: Path, results: dict, tables, plotter) -> int:
    """``base``.json, .md (the tables) and .png (the plot) of ``results``; prints the tables."""
    base.parent.mkdir(parents=True, exist_ok=True)
    base.with_suffix(".json").write_text(json.dumps(results, indent=2) + "\n")
    table = tables(results)
    base.with_suffix(".md").write_text(table + "\n")
    plotter(results, base.with_suffix(".png"))
    print(table)
    print(f"wrote {base}.json, .md, .png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
