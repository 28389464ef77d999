"""Reference radiosity: all-pairs multi-bounce gather between element disks with explicit,
ray-cast visibility (O(n²) pairs; the ground truth for small scenes).

Transport ``M[i, j] = F_ij · V_ij``: F_ij the form factor from element i's point to the front face
of element j (disk approximation far away, exact triangle form factors of j's fan, a third each,
when d² < NEAR·A_j, ``core.surfels``), V_ij the unblocked fraction of rays from i to jittered
points of j's own triangles (the same for i→j and j→i, traced once). Then Jacobi sweeps
``I ← M (ρ ⊙ (D + I))`` on the device in lighting units (irradiance/π), D the direct lighting,
until the largest change is below the tolerance; the last sweep takes the elements near each
receiver as it sees them (``core.nearfield``), as the hierarchical solver's final gather does.

What is kept between sweeps depends on the memory budget (``max_pairs`` × 4 bytes): the whole
float32 matrix when it fits (``matrix``), else the visibility of every pair as one byte
(``visibility``; form factors, which cost no rays, are recomputed each sweep), else nothing
(``traced``: visibility is traced again each sweep — slow, the bake says so).
"""
from __future__ import annotations

import numpy as np
import warp as wp

from .. import device as device_mod
from ..errors import BakeError
from ..nearfield import Detail, empty, near_light, varies
from ..rays import lift
from ..surfels import Surfels, element_ff, pair_hits, ray_ends
from .base import Solution, exitance, iterate, reconstruct_with_detail

wp.set_module_options({"enable_backward": False})  # no gradients: halves compile time

MATRIX, VISIBILITY, TRACED = 0, 1, 2
MODES = ("matrix", "visibility", "traced")
# Element pairs with their visibility traced per second and CPU thread (visibility_rays = 4),
# measured on the sample Cornell box; predictions of the time a bake takes scale from it.
PAIRS_PER_SECOND_PER_THREAD = 2.0e6
CUDA_SPEEDUP = 50.0
# A bake predicted to take longer than this (s) is announced with the pair count and the time.
SLOW_SECONDS = 60.0


@wp.kernel
def _pairs_kernel(offset: int, n: int, s: Surfels, rays: int, seed: int, mode: int,
                  matrix: wp.array2d(dtype=wp.float32), visibility: wp.array2d(dtype=wp.uint8),
                  traced: wp.array(dtype=wp.int32)):
    """Thread t fills rows t and n−1−t against every later column (the same work per thread):
    M[i, j] and M[j, i] (``matrix``) or their shared visibility (``visibility``); ``traced[t]``
    counts its rays (no atomics: they are not atomic on the CPU)."""
    t = wp.tid() + offset
    count = int(0)
    for side in range(2):
        i = t
        if side == 1:
            i = n - 1 - t
        if side == 0 or i > t:
            for j in range(i + 1, n):
                if s.area[i] <= 0.0 or s.area[j] <= 0.0:
                    continue
                f_ij = element_ff(s, i, j)
                f_ji = element_ff(s, j, i)
                if f_ij <= 0.0 and f_ji <= 0.0:
                    continue
                hits = pair_hits(s, ray_ends(i, j, f_ij, f_ji), rays, seed)
                count += rays
                if mode == MATRIX:
                    v = float(hits) / float(rays)
                    matrix[i, j] = f_ij * v
                    matrix[j, i] = f_ji * v
                else:
                    visibility[i, j] = wp.uint8(hits)
                    visibility[j, i] = wp.uint8(hits)
    traced[t] = count


@wp.kernel
def _sweep_kernel(offset: int, n: int, s: Surfels, rays: int, seed: int, mode: int,
                  matrix: wp.array2d(dtype=wp.float32), visibility: wp.array2d(dtype=wp.uint8), nf: Detail,
                  direct: wp.array(dtype=wp.vec3), indirect: wp.array(dtype=wp.vec3),
                  out: wp.array(dtype=wp.vec3), traced: wp.array(dtype=wp.int32)):
    """One Jacobi sweep of row i: out_i = Σ_j M_ij ρ_j (D_j + I_j), M_ij held (MATRIX), or its
    form factors computed again with the visibility kept (VISIBILITY) or traced again (TRACED);
    each element near i as i sees it (``nearfield.near_light``; none with an empty ``nf``).
    ``traced[i]``: its rays."""
    i = wp.tid() + offset
    acc = wp.vec3(0.0)
    count = int(0)
    if s.area[i] > 0.0:
        p = s.pos[i]
        normal = s.nrm[i]
        origin = lift(p, normal, wp.sqrt(s.area[i]))
        for j in range(n):
            if j == i:
                continue
            m = float(0.0)
            if s.area[j] > 0.0:
                if mode == MATRIX:
                    m = matrix[i, j]
                else:
                    f = element_ff(s, i, j)
                    if f > 0.0:
                        if mode == VISIBILITY:
                            m = f * float(visibility[i, j]) / float(rays)
                        else:
                            # the other way's form factor decides the rays' ends only if i's is the lower
                            back = float(1.0)
                            if j < i:
                                back = element_ff(s, j, i)
                            m = f * float(pair_hits(s, ray_ends(i, j, f, back), rays, seed)) / float(rays)
                            count += rays
            if m > 0.0 or varies(nf, j):
                acc += near_light(nf, s, j, wp.cw_mul(s.albedo[j], direct[j] + indirect[j]), m, p, normal, origin)
    out[i] = acc
    traced[i] = count


@wp.kernel
def _matrix_sweep_kernel(offset: int, n: int, matrix: wp.array2d(dtype=wp.float32),
                         exitance: wp.array(dtype=wp.vec3), out: wp.array(dtype=wp.vec3)):
    """A sweep over the held matrix, row i: out_i = Σ_j M_ij B_j (the diagonal and the rows and
    columns of elements without area are 0), a plain product with no branch per entry."""
    i = wp.tid() + offset
    acc = wp.vec3(0.0)
    for j in range(n):
        acc += matrix[i, j] * exitance[j]
    out[i] = acc


class Transport:
    """The transport of ``problem``'s n elements on its device, in the mode the budget allows
    (MATRIX, VISIBILITY or TRACED, see the module docstring)."""

    def __init__(self, problem):
        settings = problem.settings
        n = problem.elements.count
        self.problem = problem
        self.n = n
        self.mode = _mode(n, settings.max_pairs)
        need = {MATRIX: 4 * n * n, VISIBILITY: n * n, TRACED: 0}[self.mode]
        free = device_mod.free_memory(problem.device)
        if free is not None and need > 0.8 * free:
            raise BakeError(f"the reference transport of {n} elements needs {need / 2**30:.2f} GiB "
                            f"({MODES[self.mode]} mode, --max-pairs {settings.max_pairs}) but only "
                            f"{free / 2**30:.2f} GiB of memory are free: lower --max-pairs")
        d = problem.device.name
        self.matrix = wp.zeros((n, n) if self.mode == MATRIX else (1, 1), dtype=wp.float32, device=d)
        self.exitance = wp.empty(n, dtype=wp.vec3, device=d)  # ρ(D + I) of a sweep over the matrix
        self.visibility = wp.zeros((n, n) if self.mode == VISIBILITY else (1, 1), dtype=wp.uint8,
                                   device=d)
        self.traced = wp.zeros(n, dtype=wp.int32, device=d)  # rays per row (thread) of a launch
        self.none = empty(d)  # no near field: the sweeps before the last
        self._rays = 0
        self.rays = int(settings.visibility_rays)
        self.seed = int(settings.seed) + 7919

    def build(self, progress=None) -> None:
        """Trace every pair's visibility once (and keep the matrix or the visibility)."""
        if self.mode == TRACED:
            return
        n = self.n
        device_mod.launch(_pairs_kernel, (n + 1) // 2,
                          [n, self.problem.surfels, self.rays, self.seed, self.mode, self.matrix,
                           self.visibility, self.traced],
                          self.problem.device, chunks=max(1, min(64, n // 128)), on_chunk=progress)
        self._count()

    def sweep(self, direct: wp.array, indirect: wp.array, out: wp.array, progress=None,
              near: Detail | None = None) -> None:
        """out ← M (ρ ⊙ (direct + indirect)) (vec3[n] device arrays), with ``near`` (the problem's
        ``Problem.near``) each element near a receiver as the receiver sees it."""
        n = self.n
        if self.mode == MATRIX and near is None:
            device = self.problem.device
            exitance(self.problem, direct, indirect, self.exitance)
            device_mod.launch(_matrix_sweep_kernel, n, [n, self.matrix, self.exitance, out], device,
                              on_chunk=progress)
            return
        device_mod.launch(_sweep_kernel, n,
                          [n, self.problem.surfels, self.rays, self.seed, self.mode, self.matrix, self.visibility,
                           near if near is not None else self.none, direct, indirect, out, self.traced],
                          self.problem.device, chunks=max(1, min(16, n // 256)),
                          on_chunk=progress)
        if self.mode == TRACED:
            self._count()

    def _count(self) -> None:
        """Add the rays the last launch traced (per-thread counts, summed in int64)."""
        self._rays += int(self.traced.numpy().astype(np.int64).sum())
        self.traced.zero_()

    @property
    def rays_traced(self) -> int:
        return self._rays


def _mode(n: int, max_pairs: int) -> int:
    """The transport mode the budget (``max_pairs`` × 4 bytes) allows for n elements."""
    budget = 4 * int(max_pairs)
    return MATRIX if 4 * n * n <= budget else VISIBILITY if n * n <= budget else TRACED


def predicted_seconds(problem) -> float:
    """How long the transport's visibility takes on ``problem``'s device (s), from the measured
    rate; in TRACED mode once per sweep, up to ``bounces`` sweeps."""
    n = problem.elements.count
    dev = problem.device
    rate = PAIRS_PER_SECOND_PER_THREAD * dev.threads * (CUDA_SPEEDUP if dev.is_cuda else 1.0)
    rate *= 4.0 / max(1, problem.settings.visibility_rays)
    seconds = 0.5 * n * n / rate
    if _mode(n, problem.settings.max_pairs) == TRACED:
        seconds *= 2 * problem.settings.bounces  # every sweep traces every row again
    return seconds


def check(problem) -> list[str]:
    """Warnings before the solve: a bake predicted to run long says so, with the pair count and
    the method to use instead (and the budget that would keep the visibility)."""
    seconds = predicted_seconds(problem)
    if seconds < SLOW_SECONDS:
        return []
    n = problem.elements.count
    message = (f"the reference solver traces {n * n / 2:.3g} element pairs for {n} elements: "
               f"predicted {_duration(seconds)} on {problem.device.name} ({problem.device.threads} "
               f"threads); use --method bunnell for scenes this large (the reference is the "
               f"yardstick for small scenes)")
    if _mode(n, problem.settings.max_pairs) == TRACED:
        message += (f"; its visibility does not fit --max-pairs {problem.settings.max_pairs} and is "
                    f"traced again every sweep: --max-pairs {-(-n * n // 4)} keeps it ({n * n / 2**30:.2f} GiB)")
    return [message]


def _duration(seconds: float) -> str:
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"


def solve(problem) -> Solution:
    """Indirect lighting per element (float32[n,3], irradiance/π) from the problem's direct
    lighting: Jacobi sweeps, from the previous frame's solution in an animation, until the
    largest change is below ``tolerance`` × the largest lighting value, or after ``bounces``
    sweeps."""
    settings, stages = problem.settings, problem.stages
    problem.direct  # noqa: B018  (traced before the transport, as the stages report it)
    transport = Transport(problem)
    stages.run("form factors", transport.build, stages.reporter("form factors"))
    n = problem.elements.count

    def sweep(direct, current, out, k):
        transport.sweep(direct, current, out, lambda f: stages.report("bounces", (k - 1 + f) / settings.bounces))

    # the last sweep sees the elements near each receiver as it sees them (``core.nearfield``)
    _, sweeps, dev_direct, current = iterate(problem, sweep, settings.bounces - 1)
    last = wp.empty(n, dtype=wp.vec3, device=problem.device.name)
    transport.sweep(dev_direct, current, last, near=problem.near)
    return Solution(last.numpy(), {"pairs": n * n, "rays": transport.rays_traced, "iterations": sweeps + 1,
                                   "transport": MODES[transport.mode]})


def evaluate(problem, solution: Solution, receivers) -> np.ndarray:
    """Indirect lighting at ``receivers``: the solution at the vertices; at other points (lightmap
    texels) interpolated, plus the detail of the tree's final gather (``texel_indirect``)."""
    return reconstruct_with_detail(problem, solution, receivers)
