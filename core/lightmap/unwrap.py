"""UV layout of lightmaps with xatlas, run in bpy-free subprocesses and cached per mesh content.

Two steps (``_xatlas_worker.py``): each mesh is cut into charts and laid out alone at its own
texel density (texels per metre of world-space surface) — meshes are independent, so this runs in
one process per CPU core and is cached per mesh; then the charts of a group of meshes are packed
onto pages of at most ``max_size`` texels a side, charts ``padding`` texels apart. With ``many``
pages the group takes as many as it needs, each mesh whole on one page and its density as asked
(a mesh too large for a page by itself is scaled down to fit one); otherwise everything goes onto
one page, scaled down until it fits (the density used is returned per mesh).
"""
from __future__ import annotations

import hashlib
import importlib.util
import os
import re
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Optional

import numpy as np

from ..errors import BakeError
from . import cache

_WORKER = Path(__file__).with_name("_xatlas_worker.py")
# Bump when the worker's output changes meaning, so stale cache entries are not used.
_CACHE_VERSION = b"rb-unwrap-8"
# xatlas now and then never returns (seen once in CI: a test's layout that takes 3 s here hung for
# over an hour; xatlas-python's tracker has such reports too). A worker that outlives this many
# seconds plus so many per triangle it was given is killed and started once more; a second hang
# is an error. xatlas takes ~10-50 µs a triangle here, so the limit leaves a wide margin.
WORKER_SECONDS = 120.0
WORKER_SECONDS_PER_TRIANGLE = 1e-3
WORKER_TRIES = 2


@dataclass
class ChartMesh:
    """One mesh to lay out.

    name: for messages. positions: float32[N,3] world-space vertex positions (m).
    triangles: int32[T,3] vertex indices. NaN / infinite and zero-area triangles are left out.
    density: texels per metre asked for it. corners: int[T,3] the face corner of each triangle
    corner (triangles sharing one are of one polygon, which is then kept whole in one chart, as a
    corner holds one UV), None where every triangle is a face of its own.
    """

    name: str
    positions: np.ndarray
    triangles: np.ndarray
    density: float
    corners: Optional[np.ndarray] = None


@dataclass
class Layout:
    """The pages of one group: ``sizes`` [(width, height)] in texels per page, and per mesh of
    the group its ``page`` index, the ``density`` used (texels per metre: as asked, or lower where
    it was scaled down to fit) and float32[T,3,2] UVs ``tri_uv`` of each triangle corner in [0,1]
    of its page (NaN for triangles left out)."""

    sizes: list
    page: list
    density: list
    tri_uv: list


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


def _key(*parts) -> str:
    h = hashlib.sha256(_CACHE_VERSION)
    for part in parts:
        h.update(part.tobytes() if isinstance(part, np.ndarray) else repr(part).encode())
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


def unwrap(groups: list[list[ChartMesh]], max_size: int, padding: int, many: bool = True,
           python: Optional[str] = None, cache_dir: Optional[Path] = None,
           check: Optional[Callable[[], None]] = None) -> list[Layout]:
    """Lay out each group of meshes on pages of its own; returns one Layout per group.

    python: interpreter for the workers (default ``sys.executable``; inside Blender the add-on
    passes Blender's Python). Results are cached in ``cache_dir`` (default
    ``cache.default_dir``, see ``core.lightmap.cache``): a mesh's charts by its positions, triangles, density and padding,
    a group's pages by its charts and options, so an unchanged scene skips xatlas and a changed
    mesh is cut again alone. Meshes measured in millimetres are laid out as well as metre-sized
    ones (the worker rescales them for xatlas). Raises BakeError when a mesh has no triangle with
    area or xatlas fails. ``check`` is called every 0.2 s while the workers run and raises (e.g.
    BakeCancelled) to stop them.
    """
    cache_dir = cache.prepare(Path(cache_dir) if cache_dir is not None else cache.default_dir())
    cleaned = [[_clean(m) for m in group] for group in groups]
    for group, items in zip(groups, cleaned):
        for mesh, (keep, _, _) in zip(group, items):
            if not keep.any():
                raise BakeError(f"{mesh.name} has no triangle with area: it cannot be lightmapped")
    corners = [[None if mesh.corners is None else np.asarray(mesh.corners, np.int64).reshape(-1, 3)[keep]
                for mesh, (keep, _, _) in zip(group, items)] for group, items in zip(groups, cleaned)]
    chart_keys = [[_key(pos, idx, float(mesh.density), int(padding), int(max_size), *([] if c is None else [c]))
                   for mesh, (_, pos, idx), c in zip(group, items, cs)]
                  for group, items, cs in zip(groups, cleaned, corners)]
    jobs = {}
    for group, items, keys, cs in zip(groups, cleaned, chart_keys, corners):
        for mesh, (_, pos, idx), key, c in zip(group, items, keys, cs):
            jobs[key] = {"pos": pos, "idx": idx, "density": np.array(float(mesh.density))}
            if c is not None:
                jobs[key]["corners"] = c
    charts = cache.cached(cache_dir, "c", jobs, lambda todo: _run(
        "charts", todo, {"padding": np.array(int(padding)), "max_size": np.array(int(max_size))}, python,
        cache_dir, check=check))
    packs, names = {}, {}
    for group, keys in zip(groups, chart_keys):
        packs[_key(*keys, int(max_size), int(padding), bool(many))] = keys
        names[_key(*keys, int(max_size), int(padding), bool(many))] = [mesh.name for mesh in group]
    options = {"max_size": np.array(int(max_size)), "padding": np.array(int(padding)),
               "many": np.array(int(bool(many)))}
    pack_jobs = {key: {f"m{m}_{name}": charts[k][name] for m, k in enumerate(keys)
                       for name in ("uv", "idx", "chart", "density")} | {"meshes": np.array(len(keys))}
                 for key, keys in packs.items()}
    packed = cache.cached(cache_dir, "p", pack_jobs, lambda todo: _run(
        "pack", todo, options, python, cache_dir, names=names, check=check))
    layouts = []
    for group, items, keys in zip(groups, cleaned, chart_keys):
        data = packed[_key(*keys, int(max_size), int(padding), bool(many))]
        sizes = [tuple(int(x) for x in data[f"p{p}_size"]) for p in range(int(data["pages"]))]
        pages, densities, tri_uv = [], [], []
        for m, (mesh, (keep, _, _)) in enumerate(zip(group, items)):
            uv = np.asarray(data[f"m{m}_uv"], np.float32)
            idx = np.asarray(data[f"m{m}_idx"], np.int64).reshape(-1, 3)
            out = np.full((keep.shape[0], 3, 2), np.nan, np.float32)
            out[keep] = uv[idx]
            if not _uv_areas(out).any():  # xatlas leaves the faces it drops at UV (0, 0)
                raise BakeError(f"UV unwrapping gave {mesh.name} no chart")
            pages.append(int(data[f"m{m}_page"]))
            densities.append(float(charts[keys[m]]["density"]) * float(data[f"m{m}_scale"]))
            tri_uv.append(out)
        layouts.append(Layout(sizes=sizes, page=pages, density=densities, tri_uv=tri_uv))
    return layouts


def _uv_areas(tri_uv: np.ndarray) -> np.ndarray:
    """bool[T]: which triangles of float32[T,3,2] UVs cover some area of the page."""
    e1, e2 = tri_uv[:, 1] - tri_uv[:, 0], tri_uv[:, 2] - tri_uv[:, 0]
    with np.errstate(invalid="ignore"):
        return np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]) > 0


def _failure(stderr: str, returncode: int, members: list, keys: list, names: Optional[dict]) -> str:
    """The message of a worker that failed: its last line on stderr (``failed: job J mesh M:
    why`` names the mesh, see ``_xatlas_worker.main``: the object is named when ``names`` gives
    the meshes of each group job), else its exit status."""
    last = (stderr.strip().splitlines() or [f"exit status {returncode}"])[-1]
    match = re.fullmatch(r"failed: job (\d+) mesh (-?\d+): (.*)", last)
    if match is None:
        return f"UV unwrapping (xatlas) failed: {last}"
    job, mesh, why = int(match[1]), int(match[2]), match[3]
    if names is None:
        return f"UV unwrapping (xatlas) failed: {why}"
    group = names[keys[members[job]]]
    who = group[mesh] if mesh >= 0 else ", ".join(group)
    return f"UV unwrapping (xatlas) failed for {who}: {why}"


def _run(command: str, jobs: dict, options: dict, python, cache_dir: Path,
         names: Optional[dict] = None, check: Optional[Callable[[], None]] = None) -> dict:
    """Run the worker's ``command`` on ``jobs`` ({key: inputs}) in up to one process per CPU core
    (each job a mesh, or with ``names`` — {key: object names of its meshes} — a group of meshes
    packed together); {key: outputs}. The workers are killed when this ends by an exception (a
    failed worker, ``check`` raising, KeyboardInterrupt) and die with this process (see
    ``_xatlas_worker._die_with_parent``). A worker past its time limit (``WORKER_SECONDS`` and
    ``WORKER_SECONDS_PER_TRIANGLE``) is killed and started again, up to ``WORKER_TRIES`` times in
    all, then BakeError."""
    whole = names is not None
    python = python or sys.executable
    keys = list(jobs)
    size = [sum(int(v.size) for v in jobs[k].values()) for k in keys]
    bins = [[] for _ in range(max(1, min(len(keys), os.cpu_count() or 1)))]
    load = [0] * len(bins)
    for k in sorted(range(len(keys)), key=lambda i: -size[i]):  # the largest jobs first, evenly
        b = load.index(min(load))
        bins[b].append(k)
        load[b] += size[k]
    out = {}
    env = _worker_env() | {"RADIOSITY_BAKER_PARENT": str(os.getpid())}
    with tempfile.TemporaryDirectory(prefix="rb-xatlas-", dir=cache_dir) as tmp:
        procs = []
        try:
            for b, members in enumerate(bins):
                if not members:
                    continue
                path_in, path_out = Path(tmp) / f"in{b}.npz", Path(tmp) / f"out{b}.npz"
                payload = dict(options)
                for j, k in enumerate(members):
                    if whole:
                        payload.update({f"g{j}_{name}": v for name, v in jobs[keys[k]].items()})
                    else:
                        payload.update({f"m{j}_{name}": v for name, v in jobs[keys[k]].items()})
                payload["groups" if whole else "meshes"] = np.array(len(members))
                np.savez(path_in, **payload)
                limit = WORKER_SECONDS + WORKER_SECONDS_PER_TRIANGLE * sum(
                    int(v.size) // 3 for name, v in payload.items() if name.endswith("idx"))
                procs.append([_start(python, command, path_in, path_out, env), members, path_in, path_out, limit])
            for entry in procs:
                proc, members, path_in, path_out, limit = entry
                for attempt in range(WORKER_TRIES):
                    ended = _wait(proc, check, limit)
                    if ended is not None:
                        break
                    proc.kill()
                    proc.communicate()
                    if attempt + 1 < WORKER_TRIES:
                        proc = entry[0] = _start(python, command, path_in, path_out, env)
                else:
                    raise BakeError(f"UV unwrapping (xatlas) did not finish within {limit:.0f} s, "
                                    f"{WORKER_TRIES} times, for {_who(members, keys, names)}: xatlas "
                                    "hung; bake again")
                stdout, stderr = ended
                if proc.returncode != 0 or not path_out.is_file():
                    raise BakeError(_failure(stderr or stdout, proc.returncode, members, keys, names))
                with np.load(path_out) as data:
                    for j, k in enumerate(members):
                        prefix = f"g{j}_" if whole else f"m{j}_"
                        out[keys[k]] = {name[len(prefix):]: data[name] for name in data.files
                                        if name.startswith(prefix)}
        finally:  # an error, a cancel, Ctrl-C: the workers stop with the bake
            for proc, *_ in procs:
                if proc.poll() is None:
                    proc.kill()
                    proc.communicate()
    return out


def _start(python: str, command: str, path_in: Path, path_out: Path, env: dict) -> subprocess.Popen:
    """Start one worker on ``path_in``, in a session of its own: a terminal's Ctrl-C reaches the
    bake, which stops it."""
    try:
        return subprocess.Popen([python, str(_WORKER), command, str(path_in), str(path_out)],
                                env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                text=True, start_new_session=True)
    except OSError as exc:
        raise BakeError(f"cannot start the UV unwrapper with {python}: {exc}") from None


def _who(members: list, keys: list, names: Optional[dict]) -> str:
    """The meshes of one worker's jobs for a message: their objects' names where ``names`` gives
    them, else how many meshes."""
    if names is None:
        return f"{len(members)} mesh" + ("es" if len(members) != 1 else "")
    return ", ".join(n for k in members for n in names[keys[k]])


def _wait(proc: subprocess.Popen, check: Optional[Callable[[], None]], limit: float) -> Optional[tuple]:
    """(stdout, stderr) of ``proc`` once it ends, None when it runs past ``limit`` seconds;
    ``check`` (None: none) is called every 0.2 s meanwhile and raises to stop waiting (a cancelled
    bake)."""
    end = time.monotonic() + limit
    while True:
        try:
            return proc.communicate(timeout=max(0.0, min(0.2, end - time.monotonic())))
        except subprocess.TimeoutExpired:
            if time.monotonic() >= end:
                return None
            if check is not None:
                check()
