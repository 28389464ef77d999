"""What solvers share: their solution and the mapping of per-element values to receivers."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import warp as wp

from .. import device as device_mod
from ..errors import BakeError

# A sweep whose added light (its change, as power: Σ area × |change|) exceeds this many times the
# larger of the direct light's power and the first sweep's change is diverging: with albedo in
# [0, 1] each bounce carries at most the power of the one before it.
GROWTH = 8.0

wp.set_module_options({"enable_backward": False})  # no gradients: halves compile time


@dataclass
class Solution:
    """values: float32[n,3] per element (indirect lighting, irradiance/π, for light solvers;
    accessibility in all three channels for AO); counts: what the solve made and traced
    (iterations, rays, pairs …) for the report; cache: what ``evaluate`` computes once per
    solution and reuses (e.g. a final gather's sender radiance)."""

    values: np.ndarray
    counts: dict = field(default_factory=dict)
    cache: dict = field(default_factory=dict)


@wp.kernel
def _exitance_kernel(offset: int, albedo: wp.array(dtype=wp.vec3), direct: wp.array(dtype=wp.vec3),
                     indirect: wp.array(dtype=wp.vec3), out: wp.array(dtype=wp.vec3)):
    e = wp.tid() + offset
    out[e] = wp.cw_mul(albedo[e], direct[e] + indirect[e])


def exitance(problem, direct: wp.array, indirect: wp.array, out: wp.array) -> wp.array:
    """out ← ρ ⊙ (direct + indirect) (vec3[n] device arrays): what each element reflects, the
    radiance a sweep sends."""
    device_mod.launch(_exitance_kernel, problem.elements.count,
                      [problem.surfels.albedo, direct, indirect, out], problem.device)
    return out


def iterate(problem, sweep, sweeps: int, changes: list | None = None,
            start: np.ndarray | None = None) -> tuple[np.ndarray, int, wp.array, wp.array]:
    """Jacobi sweeps ``sweep(direct, current, out, k)`` (vec3[n] device arrays: the problem's
    direct lighting, the indirect lighting so far, the next; k the sweep's number from 1) until the
    largest change is below ``tolerance`` × the largest lighting value, or ``sweeps`` of them.
    Returns (float32[n,3] the last indirect lighting, sweeps made, the direct lighting and the
    last indirect lighting on the device). ``start`` (float32[n,3]) is the starting point, else
    an animation's previous frame (``problem.previous``): its light has mostly converged already.
    ``changes``, when given, gets each sweep's largest change over the largest lighting value
    (the convergence measure).
    Raises BakeError when the sweeps diverge (the change grows past ``GROWTH``, or a value is not
    finite), so that no NaN or infinite lighting is ever written."""
    settings, stages, direct = problem.settings, problem.stages, problem.direct
    d = problem.device.name
    n = problem.elements.count
    dev_direct = wp.array(direct, dtype=wp.vec3, device=d)
    if start is not None:
        before = np.asarray(start, np.float32)
    elif problem.previous is not None:
        before = problem.previous.values
    else:
        before = np.zeros((n, 3), np.float32)
    current = wp.array(before, dtype=wp.vec3, device=d)
    nxt = wp.zeros(n, dtype=wp.vec3, device=d)
    scale_direct = float(np.abs(direct).max(initial=0.0))
    area = problem.elements.area.astype(np.float64)
    floor = power(area, direct)
    made = 0
    for made in range(1, sweeps + 1):
        sweep(dev_direct, current, nxt, made)
        current, nxt = nxt, current
        now = current.numpy()
        added = power(area, now - before)
        if made == 1:
            floor = max(floor, added)
        if not (np.isfinite(now).all() and added <= GROWTH * floor):
            raise BakeError(f"method {settings.solver} diverged at bounce {made}: the indirect light "
                            "grew with each bounce instead of converging (a surface reflecting more "
                            "than it receives?); nothing was written")
        change = float(np.abs(now - before).max(initial=0.0))
        scale = max(float(np.abs(now).max(initial=0.0)), scale_direct, 1e-30)
        before = now
        if changes is not None:
            changes.append(change / scale)
        stages.report("bounces", made / settings.bounces)
        if change <= settings.tolerance * scale:
            break
    return before, made, dev_direct, current


def power(area: np.ndarray, values: np.ndarray) -> float:
    """Σ area × |values| over elements and channels (area float[n] m², values float[n,3]
    irradiance/π): the power the values stand for, up to π; inf or NaN where a value is."""
    with np.errstate(invalid="ignore", over="ignore"):
        return float(area @ np.abs(values.astype(np.float64)).sum(axis=1))


def reconstruct(problem, solution: Solution, receivers) -> np.ndarray:
    """float32[R,3]: the solution interpolated at ``receivers`` (their element weights)."""
    return receivers.reconstruct(solution.values)


def reconstruct_with_detail(problem, solution: Solution, receivers) -> np.ndarray:
    """float32[R,3] indirect lighting at ``receivers``: the solution itself where they are the
    elements; elsewhere (lightmap texels) interpolated from the elements, plus — with
    ``texel_indirect`` ``gather`` — what a final gather over the tree finds at each receiver beyond
    the same gather interpolated from the elements: detail finer than the mesh (contact shadows,
    bleeding), while the solver's accuracy at the elements is kept (the gather's own error,
    mostly smooth, cancels)."""
    values = receivers.reconstruct(solution.values)
    if receivers.aligned or problem.settings.texel_indirect != "gather" or not len(values):
        return values
    from .. import gather
    from ..lightmap import sparse

    stages = problem.stages
    if "final_gather" not in solution.cache:
        lighting = problem.direct + solution.values
        radiance = stages.run("final gather", gather.sender_radiance, problem, lighting)
        els = problem.elements
        at_elements = stages.run("final gather", gather.light_at, problem, radiance, els.position,
                                 els.normal)
        solution.cache["final_gather"] = (radiance, at_elements)
    radiance, at_elements = solution.cache["final_gather"]

    def detail_at(index, progress):
        light = gather.light_at(problem, radiance, receivers.points[index], receivers.normals[index],
                                progress)
        return light - receivers.reconstruct(at_elements, index)

    report, s = stages.reporter("texel gather"), problem.settings.supersample
    if receivers.grids is not None and s > 1:  # supersampled texels: sparsely
        detail, again = stages.run("texel gather", sparse.gather, receivers.grids, s, detail_at,
                                   values, report)
        problem.counts["texels_gathered_whole"] = round(again, 4)
    else:
        detail = stages.run("texel gather", detail_at, slice(None), report)
    return np.maximum(values + detail, 0.0).astype(np.float32)
