"""The live preview's frame rate and where each update's time goes (issue 42), through the bpy
module.

Scene: ``bench/animation_bench.py``'s animated room (a column bent by an armature, a door
swinging, a lamp sliding) at about ``--sizes`` elements. For each size and preview method the
panel's toggle starts the preview; then ``--frames`` frames of the animation are set one after
another, each followed into the viewport as the playing timeline is (the frame handler notes it,
the timer — driven here, timers do not fire in the bpy module — extracts, the worker solves, the
timer writes the preview attribute; a frame that gives no new update is an error). Per update: extraction, solve (and the bake's own stages),
write and latency (``addon.live.Update``); the frame rate is that of warm updates (the first,
which compiles and builds what later frames move, left out): 1 / their mean work. Writes
bench/results/live-<machine>.json and prints a markdown table.

    .venv/bin/python bench/live_bench.py [--sizes 6000 26000] [--frames 8] [--methods hierarchical bunnell direct]
"""
from __future__ import annotations

import argparse
import platform
import statistics
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import animation_bench  # noqa: E402  (imports bpy with a private user folder)
import bpy  # noqa: E402
import numpy as np  # noqa: E402

import radiosity_baker  # noqa: E402
from radiosity_baker.addon import live  # noqa: E402
import results_file  # noqa: E402


def run(size: int, method: str, frames: int) -> dict:
    scene, _ = animation_bench.room(size)
    scene.radiosity_baker.method = method
    scene.frame_set(1)
    scene.radiosity_baker_live.enabled = True  # the panel's toggle
    session = live.session()
    session.settle(600.0)
    updates = []
    for frame in np.linspace(2, 48, frames).round().astype(int):
        before = session.solves
        scene.frame_set(int(frame))  # the preview's frame handler notes it, as when the timeline plays
        session.settle(600.0)
        if session.solves != before + 1:
            raise RuntimeError(f"frame {frame} gave {session.solves - before} solves, not 1")
        updates.append(session.updates[-1])
    elements = session._sequence.problem.elements.count
    scene.radiosity_baker_live.enabled = False
    if len(updates) != frames or session.error:
        raise RuntimeError(f"{len(updates)} of {frames} frames shown; {session.error}")

    def median(values):
        return round(statistics.median(values), 4)

    stages = sorted({k for u in updates for k in u.stages})
    row = {"elements": elements, "method": session.settings.method, "frames": frames,
           "frames_per_second": round(len(updates) / sum(u.work for u in updates), 3),
           "extract_s": median([u.extract for u in updates]), "solve_s": median([u.solve for u in updates]),
           "write_s": median([u.write for u in updates]), "latency_s": median([u.latency for u in updates]),
           "stages_s": {k: median([u.stages.get(k, 0.0) for u in updates]) for k in stages}}
    top = sorted(row["stages_s"].items(), key=lambda kv: -kv[1])[:5]
    print(f"| {elements} | {row['method']} | {row['frames_per_second']:.2f} | {row['extract_s']:.3f} | "
          f"{row['solve_s']:.3f} | {row['write_s']:.3f} | {row['latency_s']:.3f} | "
          + ", ".join(f"{k} {v:.3f}" for k, v in top) + " |", flush=True)
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", nargs="+", type=int, default=[6000, 26000])
    parser.add_argument("--frames", type=int, default=8)
    parser.add_argument("--methods", nargs="+", default=["hierarchical", "bunnell", "direct"])
    args = parser.parse_args()
    if hasattr(radiosity_baker, "register"):
        radiosity_baker.register()
    print("| elements | method | frames/s | extract s | solve s | write s | latency s | solve's largest stages s |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    rows = [run(size, method, args.frames) for size in args.sizes for method in args.methods]
    results_file.write("live", {"machine": platform.node(), "processor": platform.processor(),
                                "what": "live preview updates of the animated room, warm frames",
                                "rows": rows})


if __name__ == "__main__":
    main()
