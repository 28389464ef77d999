"""Baking on a farm (issue 25): wall time with 1 and 2 local Dask workers, and per-task overhead.

Runs the command line (``python -m radiosity_baker bake … --scheduler local:N``) on

- frames: ``sample_blends/animated_room.blend``, ``--frames 1:F`` (each frame a task), and
- pages: a lightmap of several pages (``--target lightmap``, default the Cornell box with a page
  per object at ``--texel-density`` and ``--max-size``; ``--blend`` another,
  e.g. the benchmark level made by ``sample_blends/make_level.py``),

each with ``local:1`` and ``local:2`` (and here, without a scheduler), reading the bake report's
``counts.farm``: tasks, per-task seconds on the workers, scatter and wait seconds on the
coordinator. The cluster's start (worker processes importing Warp) is inside the wall time, as a
user sees it. Writes bench/results/farm-<machine>.json.

    .venv/bin/python bench/farm_bench.py [--frames 8] [--blend FILE] [--texel-density 64]
        [--max-size 128] [--layout per_object] [--method bunnell]
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import results_file  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def run(blend: Path, options: list, scheduler: str | None, threads: str | None = None) -> dict:
    """One command-line bake (``threads``: RADIOSITY_BAKER_THREADS, None for every core); returns
    its wall seconds and its report."""
    with tempfile.TemporaryDirectory(prefix="rb-farm-") as tmp:
        report = Path(tmp) / "report.json"
        command = [sys.executable, "-m", "radiosity_baker", "bake", str(blend), *options,
                   "--output", f"{tmp}/maps", "--save", f"{tmp}/out.blend", "--report", str(report)]
        if scheduler:
            command += ["--scheduler", scheduler]
        t0 = time.perf_counter()
        env = dict(os.environ, **({"RADIOSITY_BAKER_THREADS": threads} if threads else {}))
        subprocess.run(command, check=True, env=env, stdout=subprocess.DEVNULL)
        seconds = time.perf_counter() - t0
        data = json.loads(report.read_text())
    farm = data["counts"].get("farm", {})
    return {"scheduler": scheduler or "here", "threads": threads or "all", "wall_s": round(seconds, 2),
            "bake_s": round(data["seconds"]["total"], 2), "farm": farm,
            "stages": {k: round(v, 3) for k, v in data["seconds"].items()}}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=8)
    parser.add_argument("--method", default="bunnell")
    parser.add_argument("--blend", type=Path, default=ROOT / "sample_blends" / "cornell_box.blend")
    parser.add_argument("--texel-density", type=float, default=64.0)
    parser.add_argument("--max-size", type=int, default=128)
    parser.add_argument("--layout", default="per_object", help="per_object: a page per object")
    args = parser.parse_args()
    cases = {
        "frames": (ROOT / "sample_blends" / "animated_room.blend",
                   ["--method", args.method, "--frames", f"1:{args.frames}"]),
        "pages": (args.blend, ["--method", args.method, "--target", "lightmap", "--texel-density",
                               str(args.texel_density), "--max-size", str(args.max_size),
                               "--layout", args.layout]),
    }
    out = {"cpu_count": os.cpu_count(), "load_average": os.getloadavg(), "cases": {}}
    for name, (blend, options) in cases.items():
        # the machine's cores shared out among its workers, and one core per worker (as workers on
        # machines of one core each would scale)
        runs = [run(blend, options, s, t) for t in (None, "1") for s in (None, "local:1", "local:2")]
        shared = runs[1]["wall_s"] / runs[2]["wall_s"]
        single = runs[4]["wall_s"] / runs[5]["wall_s"]
        out["cases"][name] = {"options": options, "runs": runs, "speedup_2_over_1": round(shared, 2),
                              "speedup_2_over_1_one_core_each": round(single, 2)}
        print(f"{name}: here {runs[0]['wall_s']} s, 1 / 2 workers sharing the cores "
              f"{runs[1]['wall_s']} / {runs[2]['wall_s']} s ({shared:.2f}x); one core each: here "
              f"{runs[3]['wall_s']} s, 1 / 2 workers {runs[4]['wall_s']} / {runs[5]['wall_s']} s "
              f"({single:.2f}x); tasks {runs[2]['farm'].get('task_seconds')}")
    out["load_average_after"] = os.getloadavg()
    results_file.write("farm", out)


if __name__ == "__main__":
    main()
