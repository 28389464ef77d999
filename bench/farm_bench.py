"""Baking on a farm (issue 25): wall time with 1 and 2 local Dask workers, and per-task overhead.

Runs the command line (``python -m radiosity_baker bake … --scheduler local:N``) on

- frames: ``sample_blends/animated_room.blend``, ``--frames 1:F`` (each frame a task), and
- pages: a lightmap of several pages (``--target lightmap``, default the Cornell box at
  ``--texel-density`` and ``--max-size`` small enough for several pages; ``--blend`` another,
  e.g. the benchmark level made by ``sample_blends/make_level.py``),

each with ``local:1`` and ``local:2`` (and here, without a scheduler), reading the bake report's
``counts.farm``: tasks, per-task seconds on the workers, scatter and wait seconds on the
coordinator. The cluster's start (worker processes importing Warp) is inside the wall time, as a
user sees it. Writes bench/results/farm-<machine>.json.

    .venv/bin/python bench/farm_bench.py [--frames 8] [--blend FILE] [--texel-density 64]
        [--max-size 128] [--method bunnell]
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


def run(blend: Path, options: list, scheduler: str | None) -> dict:
    """One command-line bake; returns its wall seconds and its report."""
    with tempfile.TemporaryDirectory(prefix="rb-farm-") as tmp:
        report = Path(tmp) / "report.json"
        command = [sys.executable, "-m", "radiosity_baker", "bake", str(blend), *options,
                   "--output", f"{tmp}/maps", "--save", f"{tmp}/out.blend", "--report", str(report)]
        if scheduler:
            command += ["--scheduler", scheduler]
        t0 = time.perf_counter()
        subprocess.run(command, check=True, env=os.environ, stdout=subprocess.DEVNULL)
        seconds = time.perf_counter() - t0
        data = json.loads(report.read_text())
    farm = data["counts"].get("farm", {})
    return {"scheduler": scheduler or "here", "wall_s": round(seconds, 2),
            "bake_s": round(data["seconds"]["total"], 2), "farm": farm,
            "stages": {k: round(v, 3) for k, v in data["seconds"].items()}}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=8)
    parser.add_argument("--method", default="bunnell")
    parser.add_argument("--blend", type=Path, default=ROOT / "sample_blends" / "cornell_box.blend")
    parser.add_argument("--texel-density", type=float, default=64.0)
    parser.add_argument("--max-size", type=int, default=128)
    args = parser.parse_args()
    cases = {
        "frames": (ROOT / "sample_blends" / "animated_room.blend",
                   ["--method", args.method, "--frames", f"1:{args.frames}"]),
        "pages": (args.blend, ["--method", args.method, "--target", "lightmap", "--texel-density",
                               str(args.texel_density), "--max-size", str(args.max_size)]),
    }
    out = {"cpu_count": os.cpu_count(), "load_average": os.getloadavg(), "cases": {}}
    for name, (blend, options) in cases.items():
        runs = [run(blend, options, s) for s in (None, "local:1", "local:2")]
        one, two = runs[1]["wall_s"], runs[2]["wall_s"]
        out["cases"][name] = {"options": options, "runs": runs, "speedup_2_over_1": round(one / two, 2)}
        print(f"{name}: here {runs[0]['wall_s']} s, 1 worker {one} s, 2 workers {two} s, "
              f"speedup {one / two:.2f}x; tasks {runs[2]['farm'].get('task_seconds')}")
    out["load_average_after"] = os.getloadavg()
    results_file.write("farm", out)


if __name__ == "__main__":
    main()
