"""Baking on a Dask cluster (``distributed``): the frames of an animation, and the pages of a
frame's lightmaps, as tasks. No bpy: a worker is an ordinary ``dask worker`` with this package
installed.

- **Frames** (:meth:`Farm.submit_frame`): each frame is one task, ``pipeline.bake`` of the frame's
  extracted SceneData on a worker, cold (no warm start from the frame before: frames run apart).
- **Pages** (:func:`bake_split`): the coordinator solves the frame once and lays out the pages
  (unwrapping is global); the solved problem goes to the workers once (``Farm.share``) as a
  :class:`Snapshot` of host arrays, and each page of every target that can be split (one with a
  ``split`` method: the lightmap) is a task — its raster, texel direct light, the solver's
  ``evaluate``, dilation — returning the page's arrays. A worker builds the problem of a snapshot
  once for all its pages (:func:`_solved`). Targets that cannot be split bake on the coordinator.

Results are arrays; files are written by the caller (the add-on's writers stage them and move
them into place together), so a worker that dies leaves no file. A task whose worker died is run
again on another (Dask reschedules it; ``RETRIES`` more attempts for a task that raises), and the
report names it. Pages come out bit-identical to a bake on one machine: each page's texels are
seeded as among all pages' (``receivers.Part``) and the problem a worker rebuilds is the
coordinator's (same scene, settings, direct light per element, solution).
"""
from __future__ import annotations

import os
import time
import uuid
from dataclasses import dataclass, field
from typing import Callable, Optional

import numpy as np

from . import device as device_mod
from . import targets as target_registry
from .errors import BakeCancelled, BakeError, SettingsError
from .pipeline import BakeResult, Sequence, Solved, bake
from .problem import Problem
from .scene import SceneData
from .settings import Settings
from .solvers import get as get_solver
from .solvers.base import Solution
from .stages import Stages

# More attempts for a task that raises (a worker that dies is Dask's own: its tasks go to others,
# up to ``distributed.scheduler.allowed-failures`` deaths).
RETRIES = 2
# Seconds to reach a scheduler, and for its first worker to join.
CONNECT_TIMEOUT = 10.0
WORKER_TIMEOUT = 60.0
# The resource a task asks for on a CUDA bake (workers started with --resources GPU=1).
GPU = "GPU"
# Memory a local worker process needs at least: measured 100 MB idle and 250 MB after baking the
# pages of a small scene (tests/core/test_farm.py's crates); larger scenes need more.
WORKER_MEMORY = 512 << 20


def local_workers(asked: int) -> tuple[int, Optional[str]]:
    """(the worker processes a ``local:asked`` cluster starts: at most one per core and one per
    WORKER_MEMORY of the bake's memory budget, a warning when that is fewer than asked, else
    None)."""
    from .lightmap.budget import memory_budget

    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    budget = memory_budget()
    most = max(1, min(cores, budget // WORKER_MEMORY))
    if asked <= most:
        return asked, None
    return most, (f"--scheduler local:{asked} asks for {asked} worker processes; this machine runs "
                  f"{most} ({cores} cores, {budget / 2**30:.1f} GB for the bake at "
                  f"{WORKER_MEMORY >> 20} MB a worker at least): {most} workers instead")


def _distributed():
    try:
        import distributed
    except ImportError:
        raise BakeError("baking on a farm needs the Python package 'distributed' "
                        "(pip install distributed, or the set-up command in README.md)") from None
    return distributed


class Farm:
    """A connection to a Dask scheduler: ``tcp://HOST:PORT`` (a running ``dask scheduler``) or
    ``local:N`` (a cluster of N worker processes on this machine, made here and closed with the
    farm; at most what the machine can run, see :func:`local_workers`, with a warning in
    ``warnings``). Use as a context manager or call ``close()``.

    Raises SettingsError (a BakeError), before any work, when the scheduler cannot be reached or
    no worker joins it within WORKER_TIMEOUT seconds; BakeError without ``distributed``.
    """

    def __init__(self, address: str, connect_timeout: float = CONNECT_TIMEOUT,
                 worker_timeout: float = WORKER_TIMEOUT):
        distributed = _distributed()
        self.address = address
        self.cluster = None
        self.tasks: list = []       # keys of the tasks submitted, for the report
        self.timings: dict = {}     # scatter, wait …: seconds on the coordinator
        self.warnings: list = []    # e.g. a local cluster smaller than asked
        try:
            if address.startswith("local:"):
                workers, capped = local_workers(int(address.partition(":")[2]))
                self.warnings += [capped] if capped else []
                # the workers share this machine's cores: each splits its launches over its share
                share = str(max(1, device_mod.cpu_threads() // workers))
                self.cluster = distributed.LocalCluster(
                    n_workers=workers, threads_per_worker=1, processes=True, host="127.0.0.1",
                    dashboard_address=None, silence_logs=40, env={device_mod.THREADS_VARIABLE: share})
                self.client = distributed.Client(self.cluster, timeout=connect_timeout)
            else:
                self.client = distributed.Client(address, timeout=connect_timeout)
        except (OSError, TimeoutError, ValueError) as exc:
            self.close()
            raise SettingsError(f"cannot reach the Dask scheduler at {address}: {exc}") from None
        try:
            self.client.wait_for_workers(1, timeout=worker_timeout)
        except (OSError, TimeoutError) as exc:
            self.close()
            raise SettingsError(f"no worker joined the Dask scheduler at {address} within "
                            f"{worker_timeout:g} s ({exc})") from None

    def __enter__(self) -> "Farm":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """Disconnect (and stop a ``local:`` cluster's processes)."""
        client = getattr(self, "client", None)
        if client is not None:
            client.close()
        if self.cluster is not None:
            self.cluster.close()

    @property
    def workers(self) -> int:
        return len(self.client.scheduler_info(n_workers=-1)["workers"])

    def submit(self, fn, *args, key: str, settings: Settings):
        """A future of ``fn(*args)`` as the task ``key`` (unique per farm), asking for a GPU on a
        CUDA bake."""
        key = f"{key}-{uuid.uuid4().hex[:8]}"
        self.tasks.append(key)
        gpu = {GPU: 1} if settings.device == "cuda" else None
        return self.client.submit(fn, *args, key=key, retries=RETRIES, resources=gpu, pure=False)

    def share(self, value):
        """A future holding ``value`` on every worker, sent once: the result of a task whose spec
        holds it, made on one worker and copied to the others (so the scheduler can place the
        tasks that need it anywhere). Unlike scattered data, a task's result lost with its workers
        is made again, so the tasks that need it are retried instead of cancelled."""
        future = self.client.submit(_held, value, key=f"shared-{uuid.uuid4().hex[:8]}", pure=False)
        _distributed().wait([future])
        self.client.replicate([future])
        return future

    def submit_frame(self, scene: SceneData, settings: Settings, targets: list, frame: int):
        """A future of ``pipeline.bake(scene, settings, targets=targets)`` (a BakeResult): one
        frame of an animation, on a worker, from its extracted scene."""
        return self.submit(bake, scene, settings, None, None, targets, key=f"frame-{frame}",
                           settings=settings)

    def gather(self, futures: list, cancel=None) -> list:
        """The results of ``futures`` in order, waiting (``cancel.is_set()`` checked each second:
        BakeCancelled, the tasks cancelled). A task that failed for good raises its error."""
        distributed = _distributed()
        t0 = time.perf_counter()
        pending = list(futures)
        while pending:
            if cancel is not None and cancel.is_set():
                self.client.cancel(futures)
                raise BakeCancelled("bake cancelled")
            try:
                distributed.wait(pending, timeout=1.0, return_when="FIRST_COMPLETED")
            except TimeoutError:
                pass
            pending = [f for f in pending if not f.done()]
        self.timings["farm wait"] = self.timings.get("farm wait", 0.0) + time.perf_counter() - t0
        return self.client.gather(futures)

    def retried(self) -> list[str]:
        """Keys of this farm's tasks that went to a worker more than once (its worker died, or
        it raised and was retried), from the scheduler's log."""
        story = self.client.story(*self.tasks) if self.tasks else []
        starts: dict = {}
        for event in story:  # ("scheduler", key, from state, to state, …) on the scheduler
            if len(event) >= 4 and event[0] == "scheduler" and event[3] == "processing":
                starts[event[1]] = starts.get(event[1], 0) + 1
        return sorted(k for k, n in starts.items() if n > 1)

    def report(self) -> dict:
        """What a bake report says of the farm: scheduler, workers, tasks, retried tasks, seconds."""
        return {"scheduler": self.address, "workers": self.workers, "tasks": len(self.tasks),
                "retried": self.retried(), "seconds": {k: round(v, 4) for k, v in self.timings.items()}}


@dataclass
class Snapshot:
    """A solved frame as host arrays, sent to the workers once (``Farm.share``): ``key`` (unique per
    bake: a worker's cache key), the ``scene`` as given to the bake (not recentred) and its
    ``settings``; ``direct`` float32[n,3] direct lighting per element and ``values`` float32[n,3]
    the solution per element (irradiance/π); per split target name, what its parts need
    (``parts``: the lightmap's layout and texel counts)."""

    key: str
    scene: SceneData
    settings: Settings
    direct: np.ndarray
    values: np.ndarray
    parts: dict = field(default_factory=dict)


@dataclass
class PartDone:
    """What a part task returns: the target part's ``result``, its stage ``timings`` (s), the
    shadow ``rays`` it traced, its wall ``seconds`` and the ``worker`` process (host:pid)."""

    result: object
    timings: dict
    rays: int
    seconds: float
    worker: str


# Per worker process: the problem of the last snapshot it baked parts of (key, Solved).
_CACHE: dict = {}


def _solved(snapshot: Snapshot) -> Solved:
    """The solved problem of ``snapshot``, built the first time a worker process sees it (the
    problem from the same scene and settings as the coordinator's, its direct light and solution
    taken as they are) and kept for its other parts; a new snapshot replaces the last."""
    if _CACHE.get("key") != snapshot.key:
        _CACHE.clear()
        problem = Problem(snapshot.scene, snapshot.settings)
        problem.direct = snapshot.direct
        _CACHE.update(key=snapshot.key, solved=Solved(problem, get_solver(snapshot.settings.solver),
                                                      Solution(snapshot.values)))
    return _CACHE["solved"]


def bake_part(snapshot: Snapshot, name: str, index: int) -> PartDone:
    """Task: part ``index`` of the split target ``name`` of ``snapshot`` (a lightmap page)."""
    t0 = time.perf_counter()
    solved = _solved(snapshot)
    problem = solved.problem
    problem.stages, problem.counts["rays"] = Stages(), 0
    target = target_registry.make(name, None, *snapshot.parts[name], range(index, index + 1))
    result = solved.light(target)
    return PartDone(result, problem.stages.timings, int(problem.counts["rays"]),
                    time.perf_counter() - t0, f"{os.uname().nodename}:{os.getpid()}")


def _held(value):
    """A task's result that is ``value`` itself (``Farm.share``)."""
    return value


def bake_split(farm: Farm, scene: SceneData, settings: Settings, targets: list,
               progress: Optional[Callable[[str, float], None]] = None, cancel=None,
               notify: Optional[Callable[[str], None]] = None) -> BakeResult:
    """Bake one frame into ``targets`` as ``pipeline.bake`` does, the parts of targets that can be
    split (``target.split(problem)`` → (layout, counts); ``target.join``) as tasks on ``farm``:
    the solve runs here once, the snapshot is sent to the workers once (``Farm.share``). The result's counts get ``farm``
    (scheduler, workers, tasks, retried tasks, per-task seconds) and its timings the tasks'
    stages summed over them (CPU seconds on the workers) and ``farm scatter`` / ``farm wait``
    (here)."""
    solved = Sequence(settings, progress, cancel, notify).solve(scene)
    problem, stages = solved.problem, solved.problem.stages
    split = {t.name: t for t in targets if hasattr(t, "split")}
    parts = {name: stages.run("farm split", t.split, problem) for name, t in split.items()}
    results = {t.name: solved.light(t) for t in targets if t.name not in split}
    if split:
        t0 = time.perf_counter()
        snapshot = Snapshot(uuid.uuid4().hex, scene, settings, problem.direct, solved.solution.values, parts)
        shared = farm.share(snapshot)
        farm.timings["farm scatter"] = time.perf_counter() - t0
        futures = {name: [farm.submit(bake_part, shared, name, k, key=f"{name}-page-{k}", settings=settings)
                          for k in range(len(parts[name][1]))] for name in split}
        stages.report("farm", 0.0)
        done = dict(zip(futures, (farm.gather(f, cancel) for f in futures.values())))
        for name, target in split.items():
            results[name] = target.join(problem, parts[name][0], [d.result for d in done[name]])
            for d in done[name]:
                for stage, seconds in d.timings.items():
                    stages.timings[stage] = stages.timings.get(stage, 0.0) + seconds
                problem.counts["rays"] += d.rays
        stages.timings.update(farm.timings)
        problem.counts["farm"] = dict(farm.report(), task_seconds={
            name: [round(d.seconds, 4) for d in ds] for name, ds in done.items()},
            task_workers={name: [d.worker for d in ds] for name, ds in done.items()})
    return solved.result(results)
