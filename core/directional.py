"""Directional lightmaps: where each texel's light comes from, as the L1 of ``core.sh``.

The plain bake says how much light arrives (``receivers.light_at``); this adds from where, for
every solver alike, from the two parts the plain bake is made of:

- direct light: the direct estimator's own samples (``direct.estimate`` with moments: each
  emitter's shadowed light over cosθ times its direction), one more pass at the texels;
- indirect light: a final gather over the cluster tree (``gather.gather`` with moments) of the
  radiance the solved elements send (ρ × their lighting, ``gather.sender_radiance``).

Each part's moment is scaled per channel so that its lighting at the texel's normal is the plain
bake's part (the solver's ``evaluate`` for the indirect part), the two are summed, and the sum is
scaled to the texel's baked value: L1 · n = L0 exactly, L0 being the plain lightmap.
"""
from __future__ import annotations

import numpy as np

from . import direct, gather, sh
from .receivers import Light, Receivers, at_elements, light_at
from .solvers import SOLVERS


def texel_l1(problem, receivers: Receivers, light: Light) -> np.ndarray:
    """float32[R,3,3] L1 at R receivers (rows R, G, B; world vectors, irradiance/π units; see
    ``core.sh``), from ``light`` (``receivers.light_at`` there: its output is L0). Stages
    ``<label> direction`` (direct) and ``<label> indirect direction`` (the gather)."""
    stages = problem.stages
    points, normals, sizes = receivers.points, receivers.normals, receivers.sizes
    parts = []
    content = problem.settings.baked_content
    if SOLVERS[problem.settings.solver].light and content != "ao":
        if content != "indirect":
            n = len(receivers)
            stage = f"{receivers.label} direction"
            _, rays, _, _, moment = stages.run(
                stage, direct.estimate, problem, points, normals, sizes,
                np.full(n, direct.MODE_FULL, np.int32), problem.settings.light_samples,
                problem.settings.seed, progress=stages.reporter(stage), with_moments=True)
            problem.counts["rays"] += int(rays.sum())
            parts.append((moment, light.direct))
        if np.any(light.indirect > 0.0):
            parts.append((stages.run(f"{receivers.label} indirect direction", _indirect_moment,
                                     problem, light, points, normals), light.indirect))
    return sh.directional_texels(light.output, parts, normals)


def _indirect_moment(problem, light: Light, points: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """float32[R,3,3]: the moment of the light the solved elements reflect to the points."""
    solver, solution = light.solved
    at = light_at(problem, solver, solution, at_elements(problem))
    radiance = gather.sender_radiance(problem, at.direct + at.indirect)
    return gather.gather(problem, points, normals, problem.far, radiance=radiance,
                         with_moment=True).moment


# Luminance weights of linear Rec.709 RGB: the one direction of Unity's layout.
LUMINANCE = np.array([0.2126, 0.7152, 0.0722], np.float32)


def godot_layers(l0: np.ndarray, l1: np.ndarray) -> np.ndarray:
    """float32[4,H,W,3]: Godot 4's four lightmap layers (LightmapGI with directional on, 4.2+) of
    a directional page, L0 float32[H,W,3] and L1 float32[H,W,9] (x, y, z rows of RGB, as the
    page holds them). Godot lights a normal n' with
    ``T0 + 4·T0·((T1, T2, T3) − 0.5)·2 · (n'y, n'z, n'x)`` per channel; the layers make that
    ``L0/2 + L1 · n'/2``: the plain lightmap at the texel's normal (L1 · n = L0) and half the tilt
    response of ``L0 + L1 · (n' − n)`` — the L1 SH whose L1 band is the texel's moment (exact for
    light spread evenly over the hemisphere)."""
    t0 = 0.5 * l0
    l1 = l1.reshape(l1.shape[:2] + (3, 3))  # [H,W,axis,channel]
    safe = np.where(t0 > 0.0, t0, 1.0)[:, :, None, :]
    g = np.where(t0[:, :, None, :] > 0.0, 0.5 * l1 / (4.0 * safe), 0.0)
    return np.stack([t0, *(g[:, :, axis] * 0.5 + 0.5 for axis in (1, 2, 0))]).astype(np.float32)


def unity_direction(l0: np.ndarray, l1: np.ndarray) -> np.ndarray:
    """float32[H,W,4] in [0, 1]: Unity's directional map beside the plain lightmap C = L0
    (float32[H,W,3]; L1 float32[H,W,9] as in :func:`godot_layers`): xyz = d · 0.5 + 0.5, w the
    rebalance factor. Unity lights a normal n' with ``C · (d · n' · 0.5 + 0.5) / w``
    (``DecodeDirectionalLightmap``); d is the luminance L1 over the luminance L0 (d · n = 1),
    shortened to unit length where longer, and w = d · n · 0.5 + 0.5, so the texel's normal gets
    C exactly and, for |d| = 1, a tilted one ``L0 + L1 · (n' − n)/2`` (luminance direction)."""
    lum = l0 @ LUMINANCE
    v = l1.reshape(l1.shape[:2] + (3, 3)) @ LUMINANCE  # [H,W,3] luminance L1
    v = np.where(lum[..., None] > 0.0, v / np.where(lum > 0.0, lum, 1.0)[..., None], 0.0)
    length = np.linalg.norm(v, axis=2, keepdims=True)
    d = v / np.maximum(length, 1.0)
    w = np.where(length > 0.0, 0.5 + 0.5 / np.maximum(length, 1.0), 0.5)
    return np.concatenate([d * 0.5 + 0.5, w], axis=2).astype(np.float32)
