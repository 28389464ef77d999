"""Lightmap speed: texels per second, adaptive shadows at equal error, many lights, the level.

    .venv/bin/python bench/lightmap_bench.py [--sizes 256 1024] [--shadow-size 512]
        [--budgets 32 64 128 256] [--reference-samples 2048] [--baseline DIR]
        [--emitters 1 100 10000] [--level-detail 1.0] [--skip cornell shadows lights level]

Parts, each written to bench/results/lightmap-<host>.json as it finishes (with the machine's load
average before it, ``uptime``):

- ``cornell``: one page of the Cornell box per size (reference solver, ``--atlas-pages one``, a
  density that fills the page): unwrap (uncached), raster, texel direct light (adaptive shadows at
  the default budget), final gather, dilation; texels per second of direct light and of the gather;
  with ``--baseline`` the older code's page of each size right after ours.
- ``shadows``: direct light alone on one ``--shadow-size`` page of the Cornell box: fixed 16
  samples per texel and adaptive shadows at each ``--budgets``, their texels per second and
  relative RMSE against fixed ``--reference-samples`` per texel on the same page. ``--baseline
  DIR`` (a checkout of an older commit, holding ``radiosity_baker``) bakes the same page with that
  code's defaults in a subprocess, for the speed and error of what the older code did.
- ``lights``: a 10 m floor under N small emissive triangles (the same total power) on one 512-texel
  page, direct light alone: time per texel with 16 light samples per texel chosen through the light
  tree, weighing every emitter exactly (on a 128-texel page), and with adaptive shadows (which
  trace more rays where the light of many emitters is noisier).
- ``level``: ``sample_blends/make_level.py`` makes the courtyard under out/level/, baked through the
  command line (bunnell, lightmap at the default density and max size, several pages) with a
  report: seconds per stage, end to end.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CORNELL = ROOT / "sample_blends" / "cornell_box.blend"


def _load() -> float:
    return os.getloadavg()[0]


def page(settings: dict, cache: str, save: str | None = None) -> dict:
    """Bake one lightmap of the Cornell box with ``settings`` (core Settings fields) in this
    process; its timings and counts (and its page as .npy at ``save``)."""
    os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="rb-bench-"))
    import bpy
    import numpy as np

    from radiosity_baker.addon.extract import extract_scene
    from radiosity_baker.addon.lightmap import request
    from radiosity_baker.core import Settings, bake, targets

    bpy.ops.wm.open_mainfile(filepath=str(CORNELL))
    extraction = extract_scene(bpy.context.evaluated_depsgraph_get())
    s = Settings(**settings)
    lm_request, _ = request(extraction, s)
    lm_request.cache_dir = Path(cache)
    t0 = time.perf_counter()
    result = bake(extraction.scene, s, targets=[targets.make("lightmap", lm_request)])
    total = time.perf_counter() - t0
    p = result["lightmap"].pages[0]
    if save:
        np.save(save, p.rgb)
    return {"size": list(p.size), "pages": len(result["lightmap"].pages), "texels": int(result.counts["texels"]),
            "density": round(p.density, 1), "seconds_total": round(total, 3),
            "seconds": {k: round(v, 4) for k, v in result.timings.items()}, "rays": int(result.counts["rays"]),
            "elements": int(result.counts["elements"]), "device": result.device}


def _page_subprocess(settings: dict, cache: str, save: str | None, pythonpath: str | None = None) -> dict:
    """``page`` in a fresh process (each bake on a fresh Warp; ``pythonpath`` for older code)."""
    env = dict(os.environ)
    if pythonpath:
        env["PYTHONPATH"] = pythonpath
    cmd = [sys.executable, str(Path(__file__).resolve()), "page", json.dumps(settings), cache]
    if save:
        cmd.append(save)
    out = subprocess.run(cmd, env=env, capture_output=True, text=True, check=True, cwd=tempfile.gettempdir())
    return json.loads(out.stdout.strip().splitlines()[-1])


def _rmse(a, b) -> float:
    import numpy as np
    cov = (a.max(axis=2) > 0) | (b.max(axis=2) > 0)
    d = a[cov] - b[cov]
    return float(np.sqrt((d ** 2).sum(axis=1).mean()) / np.linalg.norm(b[cov], axis=1).mean())


def cornell(sizes, baseline) -> list:
    """Per size our page, and with ``baseline`` the older code's right after it (its defaults: one
    page, 16 light samples per emitter): the same machine load for both."""
    rows = []
    for size in sizes:
        settings = dict(method="reference", target="lightmap", max_size=size, texel_density=1e4, padding=4)
        for label, extra, path in (("ours", {"atlas_pages": "one"}, None), ("baseline", {}, baseline)):
            if label == "baseline" and not baseline:
                continue
            load = _load()
            r = _page_subprocess({**settings, **extra}, tempfile.mkdtemp(prefix="rb-unwrap-"), None, path)
            t = r["seconds"]
            r.update(code=label, load=round(load, 2),
                     texels_per_second_direct=round(r["texels"] / t["texel direct"]),
                     texels_per_second_gather=round(r["texels"] / t["texel gather"]))
            print(f"cornell {size} {label}: {json.dumps(r)}", flush=True)
            rows.append(r)
    return rows


def shadows(size, budgets, reference_samples, baseline) -> dict:
    import numpy as np
    cache = tempfile.mkdtemp(prefix="rb-unwrap-")
    tmp = Path(tempfile.mkdtemp(prefix="rb-shadows-"))
    common = dict(method="direct", target="lightmap", max_size=size, texel_density=1e4, padding=4,
                  atlas_pages="one")
    _page_subprocess(common, cache, None)  # unwrap once (cached for the timed bakes)
    load = _load()
    ref = _page_subprocess({**common, "texel_shadows": "fixed", "light_samples": reference_samples}, cache,
                           str(tmp / "ref.npy"))
    truth = np.load(tmp / "ref.npy")
    runs = {"fixed 16": {**common, "texel_shadows": "fixed", "light_samples": 16}}
    runs.update({f"adaptive {b}": {**common, "shadow_budget": b} for b in budgets})
    rows = []
    for label, settings in runs.items():
        r = _page_subprocess(settings, cache, str(tmp / "page.npy"))
        r.update(run=label, relative_rmse=round(_rmse(np.load(tmp / "page.npy"), truth), 5),
                 texels_per_second_direct=round(r["texels"] / r["seconds"]["texel direct"]))
        print(f"shadows {label}: {r['texels_per_second_direct']} texels/s, RMSE {r['relative_rmse']}", flush=True)
        rows.append(r)
    out = {"size": ref["size"], "reference_samples": reference_samples, "load": round(load, 2),
           "reference_seconds": ref["seconds"]["texel direct"], "runs": rows}
    if baseline:
        base = {k: v for k, v in common.items() if k != "atlas_pages"}  # older code: one page only
        b_ref = _page_subprocess({**base, "light_samples": 256}, tempfile.mkdtemp(prefix="rb-unwrap-"),
                                 str(tmp / "bref.npy"), baseline)
        b16 = _page_subprocess(base, tempfile.mkdtemp(prefix="rb-unwrap-"), str(tmp / "b16.npy"), baseline)
        out["baseline"] = {"code": baseline, "size": b16["size"], "texels": b16["texels"],
                           "light_samples": 16, "reference_light_samples": 256,
                           "texels_per_second_direct": round(b16["texels"] / b16["seconds"]["texel direct"]),
                           "relative_rmse": round(_rmse(np.load(tmp / "b16.npy"), np.load(tmp / "bref.npy")), 5),
                           "reference_seconds": b_ref["seconds"]["texel direct"]}
        print(f"baseline: {out['baseline']}", flush=True)
    return out


def lights(counts) -> list:
    import numpy as np

    from radiosity_baker.core import Settings, bake, targets
    from radiosity_baker.core.lightmap import LightmapRequest, LightmapObject
    from radiosity_baker.core.scene import Lamps, SceneData

    rng = np.random.default_rng(3)
    n = 40
    s = np.linspace(-5, 5, n + 1)
    x, y = np.meshgrid(s, s)
    floor = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], 1).astype(np.float32)
    i = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    ft = np.concatenate([np.stack([i[:-1, :-1].ravel(), i[:-1, 1:].ravel(), i[1:, 1:].ravel()], 1),
                         np.stack([i[:-1, :-1].ravel(), i[1:, 1:].ravel(), i[1:, :-1].ravel()], 1)])
    rows = []
    for count in counts:
        centre = rng.random((count, 3)) * (9.0, 9.0, 2.0) + (-4.5, -4.5, 1.0)
        tri = centre[:, None, :] + rng.normal(scale=0.05, size=(count, 3, 3))
        pos = np.concatenate([floor, tri.reshape(-1, 3)]).astype(np.float32)
        tris = np.concatenate([ft, len(floor) + np.arange(3 * count).reshape(-1, 3)]).astype(np.int32)
        nt = len(tris)
        emission = np.zeros((nt, 3), np.float32)
        emission[len(ft):] = 200.0 / count  # the same total power whatever the count
        normals = np.tile([0, 0, 1.0], (nt, 3, 1)).astype(np.float32)
        scene = SceneData(positions=pos, triangles=tris, corner_normals=normals,
                          tri_object=np.r_[np.zeros(len(ft)), np.ones(count)].astype(np.int32),
                          albedo=np.full((nt, 3), 0.5, np.float32), emission=emission, lamps=Lamps.empty(),
                          object_names=["Floor", "Emitters"])
        target = LightmapObject("Floor", "Floor", corner_vert=ft.ravel().astype(np.int32),
                                corner_triangles=np.arange(3 * len(ft), dtype=np.int32).reshape(-1, 3),
                                triangle_offset=0)
        row = {"emitters": count}
        for label, selection, shadows, size in (("tree", "tree", "fixed", 512), ("exact", "exact", "fixed", 128),
                                                ("tree adaptive", "tree", "adaptive", 512)):
            settings = Settings(method="direct", max_size=size, texel_density=1e4, atlas_pages="one",
                                light_selection=selection, texel_shadows=shadows)
            load = _load()
            r = bake(scene, settings, targets=[targets.make("lightmap", LightmapRequest(
                [target], cache_dir=Path(tempfile.mkdtemp())))])
            seconds = r.timings["texel direct"]
            row[label] = {"texels": int(r.counts["texels"]), "seconds": round(seconds, 3),
                              "microseconds_per_texel": round(1e6 * seconds / r.counts["texels"], 3),
                              "rays_per_texel": round((r.counts["rays"] - 16 * r.counts["elements"])
                                                      / r.counts["texels"], 2), "load": round(load, 2)}
        print(f"lights {count}: {json.dumps(row)}", flush=True)
        rows.append(row)
    return rows


def level(detail: float) -> dict:
    blend = ROOT / "out" / "level" / f"courtyard-{detail:g}.blend"
    subprocess.run([sys.executable, str(ROOT / "sample_blends" / "make_level.py"), str(blend), "--detail",
                    str(detail)], check=True, capture_output=True)
    out = Path(tempfile.mkdtemp(prefix="rb-level-"))
    os.environ["RADIOSITY_BAKER_CACHE"] = str(out / "unwrap")  # uncached: xatlas is timed too
    load = _load()
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "radiosity_baker", "bake", str(blend), "--method", "bunnell",
                    "--target", "lightmap", "--output", str(out / "maps"), "--report", str(out / "report.json")],
                   check=True, capture_output=True, cwd=ROOT, env=os.environ)
    wall = time.perf_counter() - t0
    report = json.loads((out / "report.json").read_text())
    counts = report["counts"]
    pages = counts["lightmap"]["pages"]
    return {"detail": detail, "load": round(load, 2), "seconds_wall": round(wall, 2),
            "seconds": {k: round(v, 3) for k, v in report["seconds"].items()},
            "objects": counts["objects"], "triangles": counts["triangles"], "elements": counts["elements"],
            "lamps": counts["lamps"], "emissive_triangles": counts["emissive_triangles"],
            "texels": counts["texels"], "pages": len(pages), "page_size": pages[0]["size"],
            "density": sorted({d["note"] for d in counts["lightmap"]["density"].values()}),
            "settings": {k: report["settings"][k] for k in ("texel_density", "max_size", "light_samples",
                                                            "shadow_budget", "texel_shadows")}}


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv and argv[0] == "page":  # one bake, in this process: page SETTINGS_JSON CACHE [SAVE.npy]
        print(json.dumps(page(json.loads(argv[1]), argv[2], argv[3] if len(argv) > 3 else None)))
        return 0
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[256, 1024])
    parser.add_argument("--shadow-size", type=int, default=512)
    parser.add_argument("--budgets", type=int, nargs="+", default=[32, 64, 128, 256])
    parser.add_argument("--reference-samples", type=int, default=2048)
    parser.add_argument("--baseline", help="a checkout of older code to measure beside (PYTHONPATH)")
    parser.add_argument("--emitters", type=int, nargs="+", default=[1, 100, 10000])
    parser.add_argument("--level-detail", type=float, default=1.0)
    parser.add_argument("--skip", nargs="*", default=[], choices=["cornell", "shadows", "lights", "level"])
    parser.add_argument("--output", type=Path, default=ROOT / "bench" / "results")
    args = parser.parse_args(argv)
    path = args.output / f"lightmap-{socket.gethostname()}.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    out = {"host": socket.gethostname(), "machine": platform.machine(), "cpus": os.cpu_count(),
           "python": platform.python_version(), "date": time.strftime("%Y-%m-%d"),
           "load_at_start": round(_load(), 2)}
    parts = {"cornell": lambda: cornell(args.sizes, args.baseline),
             "shadows": lambda: shadows(args.shadow_size, args.budgets, args.reference_samples, args.baseline),
             "lights": lambda: lights(args.emitters), "level": lambda: level(args.level_detail)}
    for name, run in parts.items():
        if name in args.skip:
            continue
        out[name] = run()
        path.write_text(json.dumps(out, indent=2) + "\n")  # after every part: the run is long
    print(f"written {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
