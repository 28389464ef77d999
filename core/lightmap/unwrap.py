"""UV layout of lightmaps with xatlas, run in a bpy-free subprocess and cached per mesh content.

Texel density is in texels per metre of world-space surface; an atlas is one page whose side is at
most ``max_size`` texels: where the density would need more, the worker lowers it until it fits
(the density used is returned). Charts are ``padding`` texels apart.
"""
from __future__ import annotations

import hashlib
import importlib.util
import os
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import numpy as np

from ..errors import BakeError

_WORKER = Path(__file__).with_name("_xatlas_worker.py")
# Bump when the worker's output changes meaning, so stale cache entries are not used.
_CACHE_VERSION = b"rb-unwrap-3"


@dataclass
class ChartMesh:
    """One mesh to lay out.

    name: for messages. positions: float32[N,3] world-space vertex positions (m).
    triangles: int32[T,3] vertex indices. NaN / infinite and zero-area triangles are left out.
    """

    name: str
    positions: np.ndarray
    triangles: np.ndarray


@dataclass
class Atlas:
    """One page: ``size`` (width, height) in texels, ``density`` used (texels per metre), and per
    mesh of the request float32[T,3,2] UVs of each triangle corner in [0,1] of the page (NaN for
    triangles left out)."""

    size: tuple
    density: float
    tri_uv: list


def default_cache_dir() -> Path:
    """Where unwraps are cached: ``$RADIOSITY_BAKER_CACHE`` or a folder in the system temp dir."""
    env = os.environ.get("RADIOSITY_BAKER_CACHE")
    return Path(env) if env else Path(tempfile.gettempdir()) / "radiosity_baker_unwrap"


def _clean(mesh: ChartMesh):
    """(kept triangle mask bool[T], compact float32[K,3] positions, uint32[M,3] triangles)."""
    p = np.asarray(mesh.positions, np.float64)
    t = np.asarray(mesh.triangles, np.int64).reshape(-1, 3)
    finite = np.isfinite(p).all(axis=1)[t].all(axis=1)
    q = np.where(np.isfinite(p), p, 0.0)[t]
    area = 0.5 * np.linalg.norm(np.cross(q[:, 1] - q[:, 0], q[:, 2] - q[:, 0]), axis=1)
    scale = max(float(np.abs(q).max()) if q.size else 1.0, 1e-30)
    keep = finite & (area > 1e-12 * scale * scale)
    used, inverse = np.unique(t[keep], return_inverse=True)
    return keep, p[used].astype(np.float32), inverse.reshape(-1, 3).astype(np.uint32)


def _cache_key(cleaned, density: float, max_size: int, padding: int) -> str:
    h = hashlib.sha256(_CACHE_VERSION)
    h.update(np.array([density, max_size, padding], np.float64).tobytes())
    for _, pos, idx in cleaned:
        h.update(np.array(pos.shape + idx.shape, np.int64).tobytes())
        h.update(pos.tobytes())
        h.update(idx.tobytes())
    return h.hexdigest()


def _worker_env() -> dict:
    """The environment of the worker: where numpy and xatlas are found here (inside Blender they
    live in folders a fresh interpreter would not search)."""
    paths = []
    for name in ("numpy", "xatlas"):
        spec = importlib.util.find_spec(name)
        if spec is None or spec.origin is None:
            raise BakeError(f"lightmaps need the Python package {name!r}, which is not installed")
        origin = Path(spec.origin)
        paths.append(str(origin.parent.parent if origin.name == "__init__.py" else origin.parent))
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(dict.fromkeys(paths + [p for p in
                                                               env.get("PYTHONPATH", "").split(os.pathsep) if p]))
    return env


def unwrap(groups: list[list[ChartMesh]], density: float, max_size: int, padding: int,
           python: Optional[str] = None, cache_dir: Optional[Path] = None) -> list[Atlas]:
    """Lay out each group of meshes in one shared atlas page; returns one Atlas per group.

    python: interpreter for the worker (default ``sys.executable``; inside Blender the add-on
    passes Blender's Python). Results are cached in ``cache_dir`` (default
    :func:`default_cache_dir`) keyed by positions, triangles and options, so an unchanged scene
    skips xatlas. Meshes measured in millimetres are laid out as well as metre-sized ones (the
    worker rescales them for xatlas). Raises BakeError when a mesh has no triangle with area, when
    xatlas gives a mesh no chart (one far smaller than the others of its group) or fails.
    """
    cache_dir = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    cleaned = [[_clean(m) for m in group] for group in groups]
    for group, items in zip(groups, cleaned):
        for mesh, (keep, _, _) in zip(group, items):
            if not keep.any():
                raise BakeError(f"{mesh.name} has no triangle with area: it cannot be lightmapped")
    atlases: list[Optional[Atlas]] = [None] * len(groups)
    todo = []
    for g, items in enumerate(cleaned):
        path = cache_dir / f"{_cache_key(items, density, max_size, padding)}.npz"
        if path.is_file():
            try:
                with np.load(path) as data:
                    atlases[g] = _read(data, 0, items)
                continue
            except (OSError, KeyError, ValueError):
                pass  # a damaged cache entry: unwrap again
        todo.append((g, path))
    if todo:
        _run_worker([cleaned[g] for g, _ in todo], density, max_size, padding, python, cache_dir,
                    [p for _, p in todo], atlases, [g for g, _ in todo])
    for group, atlas in zip(groups, atlases):
        for mesh, tri_uv in zip(group, atlas.tri_uv):
            if not _uv_areas(tri_uv).any():  # xatlas leaves the faces it drops at UV (0, 0)
                raise BakeError(f"UV unwrapping gave {mesh.name} no chart: it is too small next to "
                                f"the other objects of its lightmap; give it its own (per-object "
                                f"layout)")
    return atlases


def _uv_areas(tri_uv: np.ndarray) -> np.ndarray:
    """bool[T]: which triangles of float32[T,3,2] UVs cover some area of the page."""
    e1, e2 = tri_uv[:, 1] - tri_uv[:, 0], tri_uv[:, 2] - tri_uv[:, 0]
    with np.errstate(invalid="ignore"):
        return np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]) > 0


def _run_worker(items, density, max_size, padding, python, cache_dir, paths, atlases, slots):
    python = python or sys.executable
    payload = {"atlases": np.array(len(items))}
    for a, group in enumerate(items):
        payload[f"a{a}_meshes"] = np.array(len(group))
        payload[f"a{a}_density"] = np.array(float(density))
        payload[f"a{a}_max_size"] = np.array(int(max_size))
        payload[f"a{a}_padding"] = np.array(int(padding))
        for m, (_, pos, idx) in enumerate(group):
            payload[f"a{a}_m{m}_pos"] = pos
            payload[f"a{a}_m{m}_idx"] = idx
    cache_dir.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="rb-xatlas-", dir=cache_dir) as tmp:
        path_in, path_out = Path(tmp) / "in.npz", Path(tmp) / "out.npz"
        np.savez(path_in, **payload)
        try:
            proc = subprocess.run([python, str(_WORKER), str(path_in), str(path_out)],
                                  env=_worker_env(), capture_output=True, text=True)
        except OSError as exc:
            raise BakeError(f"cannot start the UV unwrapper with {python}: {exc}") from None
        if proc.returncode != 0 or not path_out.is_file():
            detail = (proc.stderr or proc.stdout).strip().splitlines()[-1:] or [f"exit status {proc.returncode}"]
            raise BakeError(f"UV unwrapping (xatlas) failed: {detail[0]}")
        with np.load(path_out) as data:
            for a, (group, path, slot) in enumerate(zip(items, paths, slots)):
                atlases[slot] = _read(data, a, group)
                np.savez(path, **{k.replace(f"a{a}_", "a0_", 1): data[k] for k in data.files
                                  if k.startswith(f"a{a}_")})


def _read(data, a: int, group) -> Atlas:
    """The Atlas of group ``a`` in the worker's output ``data`` (per-corner UVs of each triangle)."""
    tri_uv = []
    for m, (keep, _, _) in enumerate(group):
        uv = np.asarray(data[f"a{a}_m{m}_uv"], np.float32)
        idx = np.asarray(data[f"a{a}_m{m}_idx"], np.int64).reshape(-1, 3)
        if idx.shape[0] != int(keep.sum()):
            raise ValueError("unwrap result does not match the mesh")
        out = np.full((keep.shape[0], 3, 2), np.nan, np.float32)
        out[keep] = uv[idx]
        tri_uv.append(out)
    w, h = (int(x) for x in data[f"a{a}_size"])
    return Atlas(size=(w, h), density=float(data[f"a{a}_density"]), tri_uv=tri_uv)
