"""Where the Cycles comparison tests leave their measured figures: ``out/test-figures/`` (ignored by
git; ``RB_TEST_FIGURES`` names another folder), never the tracked ``bench/results``, which only
benchmarks write."""
import json
import os
from pathlib import Path

FOLDER = Path(os.environ.get("RB_TEST_FIGURES", Path(__file__).resolve().parents[2] / "out" / "test-figures"))


def record(name: str, key, figures) -> Path:
    """Merge ``figures`` under ``key`` (None: the whole file) into ``<FOLDER>/<name>.json``."""
    FOLDER.mkdir(parents=True, exist_ok=True)
    path = FOLDER / f"{name}.json"
    table = json.loads(path.read_text()) if path.is_file() and key is not None else {}
    if key is None:
        table = figures
    else:
        table[key] = figures
    path.write_text(json.dumps(table, indent=2, sort_keys=True) + "\n")
    return path
