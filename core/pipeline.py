"""The one orchestrator: SceneData + Settings -> BakeResult, for the operator, the CLI and the tests.

It builds the problem, dispatches once to the chosen solver through the registry, and evaluates
the solution at the receivers of every target asked for (``core.targets``: shading vertices,
lightmap texels, …) through one path (``receivers.light_at``), with no branch on the target's kind.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Optional

import numpy as np

from . import direct as direct_mod
from . import solvers
from . import targets as target_registry
from .errors import BakeCancelled, BakeError
from .problem import Problem
from .receivers import light_at
from .scene import SceneData
from .settings import Settings, flag
from .stages import ProgressFn, Stages

__all__ = ["BakeResult", "BakeCancelled", "BakeError", "bake"]


@dataclass
class BakeResult:
    """What a bake made: ``targets`` {target name: its result} (the ``vertices`` target's is a
    ``core.targets.vertices.VertexLight``, the ``lightmap`` target's a ``core.lightmap.LightmapResult``;
    ``result[name]`` reads one), the device, timings (seconds per stage), counts (objects,
    triangles, elements, lamps, rays, pairs, iterations, texels …), warnings and peak memory.

    lighting, direct, indirect, output, shading: the ``vertices`` target's fields, float32[S,3]
    per shading vertex (see ``VertexLight``), for bakes that asked for it.
    """

    targets: dict
    device: str
    timings: dict = field(default_factory=dict)
    counts: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)
    peak_memory_bytes: int = 0

    def __getitem__(self, name: str):
        if name not in self.targets:
            raise KeyError(f"the bake made no {name!r} result (it made: {', '.join(self.targets)})")
        return self.targets[name]

    lighting = property(lambda self: self["vertices"].lighting)
    direct = property(lambda self: self["vertices"].direct)
    indirect = property(lambda self: self["vertices"].indirect)
    output = property(lambda self: self["vertices"].output)
    shading = property(lambda self: self["vertices"].shading)


def bake(scene: SceneData, settings: Settings, progress: Optional[ProgressFn] = None,
         cancel=None, targets: Optional[list] = None,
         notify: Optional[Callable[[str], None]] = None) -> BakeResult:
    """Bake ``scene`` with ``settings`` into ``targets`` (objects made by ``core.targets.make``;
    default: the shading vertices alone).

    progress(stage, fraction) is called as stages advance; ``cancel`` is an object with ``is_set()``
    (e.g. threading.Event) checked between kernel launches: when set, BakeCancelled is raised.
    notify(message) hears each warning as it arises (a long bake is announced before it runs).
    Raises BakeError (clear message) for input that cannot be baked.
    """
    return Sequence(settings, progress, cancel, notify).bake(scene, targets)


class Sequence:
    """Bakes the frames of an animation one after another (or one scene, as :func:`bake` does),
    reusing what carries over from one frame to the next: while the topology (and the split into
    shading vertices) stays, the problem (its device arrays updated, the BVH and the tree refitted:
    ``Problem.move``) and the previous frame's solution, which solvers that iterate start from
    (``problem.previous``).

    progress, cancel, notify: as for :func:`bake`; ``bake(scene, label=…)`` prefixes the stages it
    reports with the label (e.g. the frame).
    """

    def __init__(self, settings: Settings, progress: Optional[ProgressFn] = None, cancel=None,
                 notify: Optional[Callable[[str], None]] = None):
        self.settings = settings
        self._progress = progress
        self._cancel = cancel
        self._notify = notify
        self.problem: Optional[Problem] = None
        self._solution = None

    def bake(self, scene: SceneData, targets: Optional[list] = None, label: str = "") -> BakeResult:
        """Bake one frame into ``targets``; see :func:`bake`."""
        solved = self.solve(scene, label)
        return solved.result({target.name: solved.light(target)
                              for target in (targets if targets is not None else target_registry.default())})

    def solve(self, scene: SceneData, label: str = "") -> "Solved":
        """The frame's problem and solution, before any target (:meth:`bake` is this, then each
        target's light); label: as for :meth:`bake`."""
        progress = self._progress
        if label and progress is not None:
            progress = (lambda stage, fraction, p=progress: p(f"{label}: {stage}", fraction))
        stages = Stages(progress, self._cancel, self._notify)
        settings = self.settings
        for name in settings.unread():
            stages.warn(f"{flag(name)} is not used by method {settings.solver}")
        problem = self.problem
        shading = problem.shading_of(scene) if problem is not None else None
        if shading is not None:
            problem.stages = stages
            stages.run("move", problem.move, scene, shading)
            problem.previous = self._solution
        else:
            problem = self.problem = Problem(scene, settings, stages)
        solver = solvers.get(settings.solver)
        info = solvers.SOLVERS[settings.solver]
        for message in getattr(solver, "check", lambda p: [])(problem):
            stages.warn(message)
        if info.indirect:
            backs, rays = stages.run("lit backs", direct_mod.lit_backs, problem)
            problem.counts["rays"] += rays
            if backs:
                stages.warn(f"light reaches the back of {', '.join(backs)}, a surface without "
                            "thickness whose back is left dark: it is not reflected on to other "
                            "surfaces as Cycles would (give it thickness, e.g. a Solidify modifier)")
        solution = stages.run("solve", solver.solve, problem)
        _finite(solution.values, settings.solver)
        self._solution = solution
        problem.counts["rays"] += int(solution.counts.get("rays", 0))
        problem.counts.update({k: v for k, v in solution.counts.items() if k != "rays"})
        return Solved(problem, solver, solution)


@dataclass
class Solved:
    """A frame's ``problem`` (``core.problem.Problem``, its ``stages`` timing what follows),
    ``solver`` (a ``core.solvers`` module) and ``solution``: what every target's light comes from."""

    problem: Problem
    solver: object
    solution: object

    def light(self, target):
        """``target``'s result: its receivers, the light there (``receivers.light_at``), finished."""
        at = target.receivers(self.problem)
        light = light_at(self.problem, self.solver, self.solution, at)
        _finite(light.output, self.problem.settings.solver)
        return target.finish(self.problem, at, light)

    def result(self, targets: dict) -> BakeResult:
        """The BakeResult of the frame with ``targets`` ({name: result})."""
        problem, stages = self.problem, self.problem.stages
        return BakeResult(targets=targets, device=problem.device.name, timings=stages.timings,
                          counts=dict(problem.counts), warnings=stages.warnings,
                          peak_memory_bytes=_peak_rss_bytes())


def _finite(values: np.ndarray, method: str) -> None:
    """Raise BakeError unless every one of ``values`` is finite: NaN or infinite light is never
    written."""
    if not np.isfinite(values).all():
        raise BakeError(f"method {method} produced light that is not finite (NaN or infinite); "
                        "nothing was written")


def _peak_rss_bytes() -> int:
    """Peak resident memory of this process so far (bytes); 0 where the OS does not tell."""
    try:
        import resource
    except ImportError:  # Windows
        return 0
    return int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss) * 1024
