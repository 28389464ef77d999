"""The unwrap cache: xatlas results (``unwrap``) stored per content key as ``.npz`` files in a
folder of the user's own, written atomically and held to a size.

- Where: ``$RADIOSITY_BAKER_CACHE``, else the user's cache folder (``$XDG_CACHE_HOME`` or
  ``~/.cache`` on Linux, ``~/Library/Caches`` on macOS, ``%LOCALAPPDATA%`` on Windows) under
  ``radiosity_baker/unwrap``, made readable by its owner only: never a folder every user of the
  machine can write into (another user could plant layouts there, or fill it).
- Writes: each entry is written under a temporary name in the folder and renamed over its name,
  so a reader (another bake at the same time) sees the whole entry or none, and a bake killed
  while writing leaves no damaged entry (a damaged one is computed again anyway).
- Size: after writing, the entries least recently used are removed until the folder holds at most
  MAX_BYTES; temporary files and worker folders (``rb-xatlas-*``) left by a killed bake are
  removed once older than STALE seconds.
"""
from __future__ import annotations

import os
import shutil
import sys
import tempfile
import time
from pathlib import Path
from typing import Optional

import numpy as np

# The most the cache folder holds (bytes), and the age (s) after which another bake's leftovers
# are taken as abandoned.
MAX_BYTES = 1 << 30
STALE = 24 * 3600.0
_TEMP_PREFIX = ".rb-entry-"


def default_dir() -> Path:
    """Where unwraps are cached: ``$RADIOSITY_BAKER_CACHE``, else the user's cache folder."""
    env = os.environ.get("RADIOSITY_BAKER_CACHE")
    if env:
        return Path(env)
    if sys.platform == "win32":
        base = Path(os.environ.get("LOCALAPPDATA") or Path.home() / "AppData" / "Local")
    elif sys.platform == "darwin":
        base = Path.home() / "Library" / "Caches"
    else:
        base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return base / "radiosity_baker" / "unwrap"


def prepare(folder: Path) -> Path:
    """``folder`` made (its owner only may enter it) and returned."""
    folder.mkdir(parents=True, exist_ok=True, mode=0o700)
    return folder


def cached(folder: Path, kind: str, jobs: dict, compute) -> dict:
    """{key: result dict of arrays} for ``jobs`` ({key: inputs}): read from ``folder`` where
    cached (``<kind>-<key>.npz``), the rest from ``compute({key: inputs}) -> {key: result}``,
    stored, and the folder then held to MAX_BYTES."""
    out, todo = {}, {}
    for key, job in jobs.items():
        path = folder / f"{kind}-{key}.npz"
        if path.is_file():
            try:
                with np.load(path) as data:
                    out[key] = {name: data[name] for name in data.files}
                os.utime(path)  # recently used: kept longest
                continue
            except (OSError, KeyError, ValueError):
                pass  # a damaged cache entry: compute again
        todo[key] = job
    if todo:
        for key, result in compute(todo).items():
            out[key] = result
            _store(folder / f"{kind}-{key}.npz", result)
        prune(folder)
    return out


def _store(path: Path, arrays: dict) -> None:
    """Write ``arrays`` to ``path`` whole or not at all (a temporary file renamed over it)."""
    handle, temp = tempfile.mkstemp(prefix=_TEMP_PREFIX, suffix=".npz", dir=path.parent)
    try:
        with os.fdopen(handle, "wb") as file:
            np.savez(file, **arrays)
        os.replace(temp, path)
    except BaseException:
        Path(temp).unlink(missing_ok=True)
        raise


def prune(folder: Path, max_bytes: Optional[int] = None, now: Optional[float] = None) -> None:
    """Remove the least recently used entries of ``folder`` until it holds at most ``max_bytes``
    (default MAX_BYTES), and leftovers of killed bakes older than STALE. Entries another bake
    removes at the same time are skipped."""
    max_bytes = MAX_BYTES if max_bytes is None else max_bytes
    now = time.time() if now is None else now
    entries = []
    for path in folder.iterdir():
        try:
            stat = path.stat()
        except OSError:
            continue
        if path.name.startswith((_TEMP_PREFIX, "rb-xatlas-")):
            if now - stat.st_mtime <= STALE:
                continue
            if path.is_dir():
                shutil.rmtree(path, ignore_errors=True)
            else:
                path.unlink(missing_ok=True)
        elif path.suffix == ".npz":
            entries.append((stat.st_mtime, stat.st_size, path))
    total = sum(size for _, size, _ in entries)
    for _, size, path in sorted(entries):
        if total <= max_bytes:
            break
        path.unlink(missing_ok=True)
        total -= size
