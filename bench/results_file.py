"""Where benchmarks leave their figures: ``bench/results/<name>-<machine>.json``."""
from __future__ import annotations

import json
import platform
from pathlib import Path

FOLDER = Path(__file__).resolve().parent / "results"


def write(name: str, data) -> Path:
    """Write ``data`` as ``bench/results/<name>-<machine>.json``; returns the path (and says it)."""
    FOLDER.mkdir(parents=True, exist_ok=True)
    path = FOLDER / f"{name}-{platform.node() or 'machine'}.json"
    path.write_text(json.dumps(data, indent=2) + "\n")
    print(f"wrote {path}")
    return path
