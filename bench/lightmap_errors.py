"""Where a lightmap's error sits (issue 40 item 1), texel by texel, against Cycles' image bake.

    .venv/bin/python bench/lightmap_errors.py [--scenes furnished_room emissive_room open_scene]
                                              [--size 128] [--samples 1024]

For each scene (built in code: ``bench/real_scenes.py``, ``bench/emissive_scenes.py``) our
lightmap of its reflectors on one page of at most ``--size`` texels a side is baked through the
add-on (defaults: supersample 1; and supersample 2, as ``bench/accuracy.py --lightmap`` bakes it),
and Cycles bakes the same ``Lightmap`` UVs (DIFFUSE, Direct + Indirect, no Color):

- the **point truth**: the page itself, one point per texel as Cycles bakes it, a pair of bakes
  of ``--samples`` each (their difference gives Cycles' own noise, which is taken out of every
  figure: error² = mean|ours − mean of the pair|² − σ²/2);
- the **footprint truth**: the page at twice the size, each texel the mean of its 2×2 sub-texels
  (texels whose four sub-texels Cycles baked), a pair of ``--samples``/4 each — what supersample 2
  aims at;
- the direct and indirect parts apart (Cycles' DIRECT and INDIRECT passes against our ``direct``
  method and ``content indirect``), at the point truth.

Texels compared are those both bake, lit in Cycles and not next to the light's outline (as
``bench/accuracy.py --lightmap`` chooses them). Each is put in classes: the truth's contrast
around it (the spread of the 3×3 texels around it relative to its own value: smooth < 10 %,
gradual < 30 %, edge < 100 %, discontinuity beyond), on a chart border (next to a texel no chart
covers) or inside, and per object; each class gets its texel count, its relative RMSE (over the
whole page's mean, so classes' squares add up) and its share of the squared error. How much of
the error the worst 1 % of the texels hold, and the RMSE without them, say whether the error is
everywhere or in a few texels. Beside it, the vertex bake of the same scene at the defaults
against a pair of Cycles vertex bakes of ``--samples``.

Writes bench/results/lightmap-errors-<machine>-<date>.json and .md, and per scene a picture of the
truth, our page and the error map (…-<scene>.png).
"""
from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

import bpy
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))
import accuracy  # noqa: E402  (scenes, receivers, our page and the texels compared)
from harness.compare import bake_vertex_values, stack  # noqa: E402
from harness.cycles import cycles_bake_image, cycles_bake_vertex_colors  # noqa: E402
from radiosity_baker.core import Settings  # noqa: E402
from radiosity_baker.core import device as device_mod  # noqa: E402
from radiosity_baker.core.lightmap import raster  # noqa: E402

CONTRAST = {"smooth": (0.0, 0.1), "gradual": (0.1, 0.3), "edge": (0.3, 1.0), "discontinuity": (1.0, np.inf)}
WORST = 0.01  # the worst fraction of texels whose share of the error is reported


def _error(ours: np.ndarray, pair: tuple, mask: np.ndarray, mean: float, own_noise=None) -> dict:
    """Relative RMSE of ``ours`` (float32[H,W,3]) against the mean of a pair of noisy truths over
    ``mask``, Cycles' noise taken out, normalised by ``mean``; the squared error per texel.
    own_noise: float[H,W] the noise variance of ``ours`` itself where it is a Cycles bake too."""
    a, b = pair
    truth = 0.5 * (a + b)
    sigma2 = 0.5 * ((a - b) ** 2).sum(axis=2)  # per texel: one bake's noise variance, estimated
    # the pair's mean has noise σ²/2: taken out per texel, unclamped, so that sums over classes are
    # unbiased (each class's total is clamped at 0 instead, in _rmse)
    squared = ((ours - truth) ** 2).sum(axis=2) - 0.5 * sigma2 - (0.0 if own_noise is None else own_noise)
    n = int(mask.sum())
    return {"texels": n, "relative_rmse": _rmse(squared[mask], mean) if n else None,
            "cycles_noise": round(float(np.sqrt(sigma2[mask].mean()) / mean), 5) if n else None}, squared


def _rmse(squared: np.ndarray, mean: float) -> float:
    """Relative RMSE of noise-corrected squared errors (float[N]), over ``mean``."""
    return round(float(np.sqrt(max(float(squared.mean()), 0.0)) / mean), 5)


def _around(a: np.ndarray, fill) -> np.ndarray:
    """[9,H,W]: each texel's 3×3 neighbourhood of ``a`` [H,W] (``fill`` beyond the page)."""
    h, w = a.shape
    pad = np.pad(a, 1, constant_values=fill)
    return np.stack([pad[1 + dy:1 + dy + h, 1 + dx:1 + dx + w] for dy in (-1, 0, 1) for dx in (-1, 0, 1)])


def _contrast(truth: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """float[H,W]: spread (max − min) of the truth's brightest channel over the 3×3 texels around
    each (those in ``mask``), relative to the texel's own."""
    lum = truth.max(axis=2)
    around = _around(np.where(mask, lum, np.nan), np.nan)
    with np.errstate(invalid="ignore", divide="ignore"):
        spread = np.nanmax(around, axis=0) - np.nanmin(around, axis=0)  # all-NaN only outside mask
        return np.where(mask, spread / np.maximum(lum, 1e-9), 0.0)


def _border(covered: np.ndarray) -> np.ndarray:
    """bool[H,W]: covered texels next to (8-neighbourhood) a texel no chart covers."""
    return covered & ~_around(covered, False).all(axis=0)


def _objects(names, size: tuple) -> np.ndarray:
    """int[H,W]: the index in ``names`` of the object whose ``Lightmap`` UV triangle holds each
    texel's centre (as Cycles picks the surface it bakes), −1 where none does."""
    w, h = size
    owner = np.full(h * w, -1, np.int64)
    dev = device_mod.select("cpu")
    for k, name in enumerate(names):
        me = bpy.data.objects[name].data
        me.calc_loop_triangles()
        uv = np.empty(len(me.loops) * 2, np.float32)
        me.uv_layers["Lightmap"].data.foreach_get("uv", uv)
        loops = np.empty(len(me.loop_triangles) * 3, np.int32)
        me.loop_triangles.foreach_get("loops", loops)
        tri_uv = uv.reshape(-1, 2)[loops].reshape(-1, 3, 2)
        texels = raster.rasterize(tri_uv, w, h, dev)
        corners = tri_uv[texels.triangle] * (w, h)
        point = np.einsum("nk,nkc->nc", texels.bary, corners)
        centre = np.stack([texels.index % w, texels.index // w], axis=1) + 0.5
        owner[texels.index[np.linalg.norm(point - centre, axis=1) < 1e-4]] = k
    return owner.reshape(h, w)


def _classes(squared: np.ndarray, mask: np.ndarray, classes: dict, mean: float) -> dict:
    """Per class (bool[H,W] each): texels, relative RMSE over the page's ``mean`` and share of the
    squared error over ``mask``."""
    total = float(squared[mask].sum())
    out = {}
    for label, sel in classes.items():
        sel = sel & mask
        n = int(sel.sum())
        out[label] = {"texels": n,
                      "relative_rmse": _rmse(squared[sel], mean) if n else None,
                      "share_of_squared_error": round(float(squared[sel].sum()) / total, 4) if total else 0.0}
    return out


def _worst(squared: np.ndarray, mask: np.ndarray, mean: float) -> dict:
    """The share of the squared error in the worst WORST of the texels and the RMSE without them."""
    values = np.sort(squared[mask])[::-1]
    k = max(1, int(round(WORST * values.size)))
    return {"worst_fraction": WORST, "worst_texels": k,
            "share_of_squared_error": round(float(values[:k].sum() / values.sum()), 4),
            "relative_rmse_without_them": _rmse(values[k:], mean)}


def _footprint(image: np.ndarray) -> tuple:
    """(float32[H,W,3] mean of each 2×2 block of a page baked at twice the size, bool[H,W] blocks
    whose four sub-texels were baked)."""
    h, w = image.shape[0] // 2, image.shape[1] // 2
    baked = image[..., 3] > 0.5
    rgb = np.where(baked[..., None], image[..., :3], 0.0).reshape(h, 2, w, 2, 3).sum(axis=(1, 3))
    count = baked.reshape(h, 2, w, 2).sum(axis=(1, 3))
    return rgb / np.maximum(count, 1)[..., None], count == 4


def _vertex_error(names, samples: int) -> dict:
    """Our vertex bake (defaults) against a pair of Cycles vertex bakes, Cycles' noise taken out."""
    ours, _, seconds = bake_vertex_values(names, Settings())
    ours = stack(ours, names)
    t0 = time.perf_counter()
    a, b = (stack(cycles_bake_vertex_colors(names, samples=samples, seed=s), names) for s in (1, 2))
    cycles_seconds = (time.perf_counter() - t0) / 2
    mean = float(np.linalg.norm(0.5 * (a + b), axis=1).mean())
    pair = (a[:, None, :], b[:, None, :])
    figures, squared = _error(ours[:, None, :], pair, np.ones((len(ours), 1), bool), mean)
    return {"vertices": len(ours), **figures, "seconds": round(seconds, 3),
            "cycles_seconds_per_bake": round(cycles_seconds, 3),
            "worst": _worst(squared, np.ones_like(squared, bool), mean)}


def _picture(path: Path, truth: np.ndarray, ours: np.ndarray, squared: np.ndarray, mask: np.ndarray,
             mean: float, title: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(15, 5.4))
    top = np.percentile(truth.max(axis=2)[mask], 99)
    for ax, image, label in ((axes[0], truth, "Cycles (point truth)"), (axes[1], ours, "ours, defaults (charts only)")):
        ax.imshow(np.clip(image / top, 0, 1) ** (1 / 2.2), origin="lower", interpolation="nearest")
        ax.set_title(label)
    error = np.where(mask, np.sqrt(np.maximum(squared, 0.0)) / mean, np.nan)
    shown = axes[2].imshow(error, origin="lower", interpolation="nearest", cmap="magma", vmin=0, vmax=0.5)
    axes[2].set_title("|ours − Cycles| / page mean (grey: not compared)")
    axes[2].set_facecolor("0.6")
    fig.colorbar(shown, ax=axes[2], fraction=0.046)
    for ax in axes:
        ax.set_xticks([])
        ax.set_yticks([])
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def run_scene(name: str, size: int, samples: int, output: Path, pictures: Path) -> dict:
    scene = accuracy._open(name)
    names = accuracy.receivers(scene)
    print(f"{name}: {', '.join(names)}", flush=True)
    pages, seconds = {}, {}
    runs = {"defaults": {"supersample": 1}, "supersample 2": {"supersample": 2},
            "direct": {"supersample": 1, "method": "direct"}, "indirect": {"supersample": 1, "content": "indirect"}}
    for label, method in runs.items():
        page, seconds[label], _ = accuracy._our_lightmap(names, size, output / label.replace(" ", "-"), method)
        pages[label] = page
        print(f"  ours {label}: {page.size[0]}x{page.size[1]} in {seconds[label]:.1f} s", flush=True)
    w, h = pages["defaults"].size

    def cycles(passes, scale, spp):
        t0 = time.perf_counter()
        pair = tuple(cycles_bake_image(names, "Lightmap", w * scale, h * scale, samples=spp, seed=s, passes=passes)
                     for s in (1, 2))
        print(f"  cycles {'+'.join(passes)} at {w * scale}x{h * scale}, {spp} spp: "
              f"{(time.perf_counter() - t0) / 2:.1f} s a bake", flush=True)
        return pair

    point = cycles(("DIRECT", "INDIRECT"), 1, samples)
    mask = accuracy._lightmap_mask(pages["defaults"], point[0]) & (point[1][..., 3] > 0.5)
    truth = tuple(p[..., :3] for p in point)
    mean = float(np.linalg.norm(0.5 * (truth[0] + truth[1])[mask], axis=1).mean())
    contrast = _contrast(0.5 * (truth[0] + truth[1]), mask)
    border = _border(pages["defaults"].covered)
    owner = _objects(names, (w, h))
    classes = {**{f"{label} ({lo:g}–{hi:g})" if np.isfinite(hi) else f"{label} (> {lo:g})":
                  (contrast >= lo) & (contrast < hi) for label, (lo, hi) in CONTRAST.items()},
               "chart border": border, "inside a chart": ~border}
    by_object = {n: owner == k for k, n in enumerate(names)}
    out = {"objects": names, "page": [w, h], "texels_compared": int(mask.sum()),
           "cycles_samples": samples, "ours_seconds": {k: round(v, 3) for k, v in seconds.items()}, "point_truth": {}}
    for label in ("defaults", "supersample 2"):
        figures, squared = _error(pages[label].rgb, truth, mask, mean)
        out["point_truth"][label] = {**figures, "classes": _classes(squared, mask, classes, mean),
                                     "objects": _classes(squared, mask, by_object, mean),
                                     "worst": _worst(squared, mask, mean)}
        if label == "defaults":
            _picture(pictures.with_name(f"{pictures.name}-{name}.png"), 0.5 * (truth[0] + truth[1]),
                     pages[label].rgb * pages[label].covered[..., None], squared, mask, mean,
                     f"{name}: lightmap {w}×{h} against Cycles' image bake ({samples} spp pair), texel by texel")
    for part, passes in (("direct", ("DIRECT",)), ("indirect", ("INDIRECT",))):
        pair = tuple(p[..., :3] for p in cycles(passes, 1, samples))
        figures, squared = _error(pages[part].rgb, pair, mask, mean)
        out["point_truth"][f"{part} part"] = {**figures, "classes": _classes(squared, mask, classes, mean),
                                              "objects": _classes(squared, mask, by_object, mean),
                                              "worst": _worst(squared, mask, mean)}
    fine = cycles(("DIRECT", "INDIRECT"), 2, max(1, samples // 4))
    (fa, whole_a), (fb, whole_b) = _footprint(fine[0]), _footprint(fine[1])
    full = mask & whole_a & whole_b
    point_noise = 0.25 * ((truth[0] - truth[1]) ** 2).sum(axis=2)  # σ²/2 of the point pair's mean
    out["footprint_truth"] = {"texels": int(full.sum()), "point_truth_against_it": _error(
        0.5 * (truth[0] + truth[1]), (fa, fb), full, mean, point_noise)[0]}
    for label in ("defaults", "supersample 2"):
        figures, squared = _error(pages[label].rgb, (fa, fb), full, mean)
        out["footprint_truth"][label] = {**figures, "worst": _worst(squared, full, mean),
                                         "point_truth_same_texels": _error(pages[label].rgb, truth, full, mean)[0]}
    out["vertex_bake"] = _vertex_error(names, samples)
    print(f"  defaults: {json.dumps(out['point_truth']['defaults']['worst'])}", flush=True)
    return out


def markdown(results: dict) -> str:
    lines = []
    for name, r in results["scenes"].items():
        pt, fp, vx = r["point_truth"], r["footprint_truth"], r["vertex_bake"]
        lines += [f"### {name} ({r['page'][0]}×{r['page'][1]} page, {r['texels_compared']} texels compared; "
                  f"vertex bake {vx['relative_rmse']:.2%} over {vx['vertices']} vertices, its worst 1 % "
                  f"{vx['worst']['share_of_squared_error']:.0%} of its squared error)", "",
                  "| ours | against | rel. RMSE | worst 1 % of texels: share of the error | RMSE without them |",
                  "| --- | --- | --- | --- | --- |"]
        for label in ("defaults", "supersample 2", "direct part", "indirect part"):
            e = pt[label]
            lines.append(f"| {label} | point truth | {e['relative_rmse']:.2%} | {e['worst']['share_of_squared_error']:.0%}"
                         f" | {e['worst']['relative_rmse_without_them']:.2%} |")
        for label in ("defaults", "supersample 2"):
            e = fp[label]
            lines.append(f"| {label} | footprint truth ({fp['texels']} texels) | {e['relative_rmse']:.2%} "
                         f"(point truth there {e['point_truth_same_texels']['relative_rmse']:.2%}) | "
                         f"{e['worst']['share_of_squared_error']:.0%} | {e['worst']['relative_rmse_without_them']:.2%} |")
        lines.append(f"| Cycles' point bake (the pair's mean) | footprint truth | "
                     f"{fp['point_truth_against_it']['relative_rmse']:.2%} | | |")
        lines += ["", "| class (defaults, point truth) | texels | rel. RMSE | share of the squared error |",
                  "| --- | --- | --- | --- |"]
        for label, c in {**pt["defaults"]["classes"], **pt["defaults"]["objects"]}.items():
            if c["texels"]:
                lines.append(f"| {label} | {c['texels']} | {c['relative_rmse']:.2%} | {c['share_of_squared_error']:.0%} |")
        lines.append("")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenes", nargs="+", default=["furnished_room", "emissive_room", "open_scene"],
                        choices=sorted(accuracy.SCENES))
    parser.add_argument("--size", type=int, default=128, help="the page's largest side (texels)")
    parser.add_argument("--samples", type=int, default=1024, help="Cycles samples of each point-truth bake")
    parser.add_argument("--output", type=Path, default=ROOT / "bench" / "results")
    args = parser.parse_args(argv)
    machine = platform.node() or "machine"
    base = args.output / f"lightmap-errors-{machine}-{datetime.date.today().isoformat()}"
    base.parent.mkdir(parents=True, exist_ok=True)
    results = {"machine": machine, "platform": platform.platform(), "cpu_count": os.cpu_count(),
               "blender": bpy.app.version_string, "load_at_start": round(os.getloadavg()[0], 2),
               "scenes": {s: run_scene(s, args.size, args.samples, Path(tempfile.mkdtemp(prefix="rb-lme-")), base)
                          for s in args.scenes}}
    results["load_at_end"] = round(os.getloadavg()[0], 2)
    base.with_suffix(".json").write_text(json.dumps(results, indent=2) + "\n")
    table = markdown(results)
    base.with_suffix(".md").write_text(table + "\n")
    print(table)
    print(f"wrote {base}.json, .md and a picture per scene")
    return 0


if __name__ == "__main__":
    sys.exit(main())
