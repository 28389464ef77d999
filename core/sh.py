"""Where light comes from: the first moment of arriving light and real spherical harmonics (SH).

Conventions (docs/directional-probes.md):

- **Moment** of the light arriving at a surface point with unit normal n: m = (1/π) ∫ L(ω) ω dω
  over the directions light arrives from (W m⁻² sr⁻¹, per RGB channel; world space; it points
  towards where the light comes from). Where all of it arrives in front of a normal n', the
  lighting there (irradiance/π, the unit of every bake) is m · n' exactly; at n it is the plain
  lighting.
- **Directional lightmap texel** (``--directional sh``): L0 = the plain lightmap's value, L1 = the
  moment scaled per channel so that L1 · n = L0 (so L0 is the plain lightmap exactly); decoded at
  a normal n' (a normal map's): lighting(n') ≈ L0 + L1 · (n' − n). In standard L1 SH of the
  arriving radiance, L₁ₘ = 0.488603 · π · L1 (x, y, z).
- **SH of radiance** (probes): real SH, Y00 = 0.282095, (Y1,-1, Y10, Y11) = 0.488603 (y, z, x),
  then the five L2 terms, in the order of ``sh9``; coefficients c_lm = ∫ L(ω) Y_lm(ω) dω. The
  lighting at a normal n' (irradiance/π) is Σ a_l c_lm Y_lm(n') with a = (1, 2/3, 1/4)
  (Ramamoorthi & Hanrahan's Â_l / π): ``lighting_from_sh``.
"""
from __future__ import annotations

import numpy as np
import warp as wp

wp.set_module_options({"enable_backward": False})  # no gradients: halves compile time

# Below this cosine to the receiver's normal, a contribution's direction counts as if at it (its
# light over cosθ would blow up at the horizon).
GRAZING = wp.constant(0.05)

# Irradiance convolution per band, over π: lighting(n) = Σ_l BAND[l] Σ_m c_lm Y_lm(n).
BAND = np.array([1.0, 2.0 / 3.0, 0.25])
# The band of each of the nine coefficients.
BAND_OF = np.array([0, 1, 1, 1, 2, 2, 2, 2, 2])

sh9_vec = wp.types.vector(length=9, dtype=wp.float32)


@wp.func
def moment_of(light: wp.vec3, w: wp.vec3, n: wp.vec3) -> wp.mat33:
    """The moment of lighting ``light`` (irradiance/π at unit normal n) arriving from unit
    direction w: rows R, G, B of light/cosθ · w, so that its rows dotted with n give ``light`` back
    (cosθ clamped at GRAZING)."""
    return wp.outer(light / wp.max(wp.dot(w, n), GRAZING), w)


@wp.func
def sh9(w: wp.vec3) -> sh9_vec:
    """The nine real SH basis functions at unit direction w (order: see the module)."""
    x = w[0]
    y = w[1]
    z = w[2]
    return sh9_vec(0.282095, 0.488603 * y, 0.488603 * z, 0.488603 * x, 1.092548 * x * y,
                   1.092548 * y * z, 0.315392 * (3.0 * z * z - 1.0), 1.092548 * x * z,
                   0.546274 * (x * x - y * y))


def sh9_numpy(w: np.ndarray) -> np.ndarray:
    """float64[N,9]: ``sh9`` at unit directions float[N,3]."""
    x, y, z = np.asarray(w, np.float64).T
    return np.stack([np.full_like(x, 0.282095), 0.488603 * y, 0.488603 * z, 0.488603 * x,
                     1.092548 * x * y, 1.092548 * y * z, 0.315392 * (3 * z * z - 1),
                     1.092548 * x * z, 0.546274 * (x * x - y * y)], axis=1)


def lighting_from_sh(coefficients: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """float32[...,D,3]: lighting (irradiance/π) at unit normals float[D,3] from SH of radiance
    float[...,K,3] (K = 4: L1, or 9: L2; channels last)."""
    k = coefficients.shape[-2]
    basis = sh9_numpy(normals)[:, :k] * BAND[BAND_OF[:k]]
    return np.einsum("dk,...kc->...dc", basis, coefficients).astype(np.float32)


def scaled_moment(moment: np.ndarray, value: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """float32[R,3,3]: ``moment`` (rows R, G, B of world vectors per receiver) scaled per channel
    so that each row · the receiver's normal (float32[R,3]) equals ``value`` float32[R,3]; a row
    with nothing in front of the normal becomes value · normal."""
    along = np.einsum("rcj,rj->rc", moment, normals)
    ok = along > 1e-12 * np.maximum(np.abs(value), 1e-30)
    scale = np.where(ok, value / np.where(ok, along, 1.0), 0.0)
    out = moment * scale[..., None] + np.where(ok, 0.0, value)[..., None] * normals[:, None, :]
    return out.astype(np.float32)


def directional_texels(value: np.ndarray, moments: list, normals: np.ndarray) -> np.ndarray:
    """float32[R,3,3] L1 per receiver (rows R, G, B; L1 · n = value): the parts' moments, each a
    (moment float32[R,3,3], its lighting float32[R,3]) pair, scaled to their lighting and summed
    (the direction of each part, the balance of the plain bake), then scaled to ``value``."""
    total = sum((scaled_moment(m, light, normals) for m, light in moments),
                np.zeros((len(value), 3, 3), np.float32))
    return scaled_moment(total, value, normals)
