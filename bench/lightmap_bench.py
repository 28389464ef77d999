"""Lightmap throughput on the Cornell box sample: unwrap, rasterisation, texels per second.

For each page size the scene is extracted once (bpy), then ``core.bake`` runs with a lightmap of
that size (``max_size`` = size, a density high enough that the atlas fills it): the xatlas unwrap
(uncached: a fresh cache folder), the raster stage, per-texel direct light (shadow rays to the
emitter, ``--samples`` per texel), the interpolation of the solver's indirect light per texel
and the final gather over the element hierarchy that adds the detail between vertices.
The reference solver's per-vertex solve is timed once (it does not depend on the page size).
Prints the results and writes bench/results/lightmap-<hostname>.json.

    python bench/lightmap_bench.py [--sizes 256 1024 4096] [--samples 16]
"""
import argparse
import json
import os
import platform
import socket
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("BLENDER_USER_RESOURCES", tempfile.mkdtemp(prefix="rb-bench-"))

import bpy  # noqa: E402

from radiosity_baker.addon.extract import extract_scene  # noqa: E402
from radiosity_baker.addon.lightmap import request  # noqa: E402
from radiosity_baker.core import Settings, bake  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[256, 1024, 4096])
    parser.add_argument("--samples", type=int, default=16, help="light samples per texel")
    args = parser.parse_args(argv)

    bpy.ops.wm.open_mainfile(filepath=str(ROOT / "sample_blends" / "cornell_box.blend"))
    extraction = extract_scene(bpy.context.evaluated_depsgraph_get())
    path = ROOT / "bench" / "results" / f"lightmap-{socket.gethostname()}.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    rows = []
    for size in args.sizes:
        settings = Settings(method="reference", target="lightmap", max_size=size, texel_density=1e4,
                            light_samples=args.samples, padding=4)
        lm_request, _ = request(extraction, settings)
        lm_request.cache_dir = Path(tempfile.mkdtemp(prefix="rb-unwrap-"))  # time xatlas itself
        t0 = time.perf_counter()
        result = bake(extraction.scene, settings, lightmap=lm_request)
        total = time.perf_counter() - t0
        t = result.timings
        texels = result.counts["texels"]
        page = result.lightmap.pages[0]
        row = {"size": list(page.size), "texels": texels, "density": round(page.density, 1),
               "seconds_total": round(total, 3),
               "seconds": {k: round(v, 4) for k, v in t.items()},
               "texels_per_second_direct": round(texels / t["texel direct"]),
               "texels_per_second_indirect": round(texels / t["texel indirect"]),
               "texels_per_second_gather": round(texels / t["texel gather"]),
               "seam_error": round(result.lightmap.seam_error, 4)}
        rows.append(row)
        print(f"{size}: {json.dumps(row)}", flush=True)
        # written after every size: the largest page takes many minutes on a CPU
        out = {"host": socket.gethostname(), "machine": platform.machine(), "cpus": os.cpu_count(),
               "device": result.device, "python": platform.python_version(), "scene": "cornell_box.blend",
               "elements": result.counts["elements"], "light_samples": args.samples, "results": rows}
        path.write_text(json.dumps(out, indent=2) + "\n")
    print(f"written {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
