"""Error measures between a bake and a reference (per-vertex or per-texel RGB), as the manual quotes them."""
from __future__ import annotations

import numpy as np


def _norms(ours: np.ndarray, reference: np.ndarray):
    ours = np.asarray(ours, np.float64).reshape(-1, 3)
    reference = np.asarray(reference, np.float64).reshape(-1, 3)
    if ours.shape != reference.shape:
        raise ValueError(f"shapes differ: {ours.shape} vs {reference.shape}")
    return np.linalg.norm(ours - reference, axis=1), np.linalg.norm(reference, axis=1), ours, reference


def relative_rmse(ours: np.ndarray, reference: np.ndarray) -> float:
    """sqrt(mean |a − b|²) / mean |b| over samples; |·| the Euclidean norm of the RGB triple."""
    err, ref, _, _ = _norms(ours, reference)
    return float(np.sqrt(np.mean(err ** 2)) / np.mean(ref))


def mean_bias(ours: np.ndarray, reference: np.ndarray) -> float:
    """Σa / Σb − 1 over all samples and channels: + too bright, − too dark."""
    _, _, a, b = _norms(ours, reference)
    return float(a.sum() / b.sum() - 1.0)


def p95_error(ours: np.ndarray, reference: np.ndarray) -> float:
    """95th percentile of |a − b| / mean |b|: the error most samples stay under."""
    err, ref, _, _ = _norms(ours, reference)
    return float(np.percentile(err, 95) / np.mean(ref))


def summary(ours: np.ndarray, reference: np.ndarray) -> dict:
    """{relative_rmse, mean_bias, p95} rounded to 5 digits."""
    return {"relative_rmse": round(relative_rmse(ours, reference), 5),
            "mean_bias": round(mean_bias(ours, reference), 5),
            "p95": round(p95_error(ours, reference), 5)}


def scalar_summary(ours: np.ndarray, reference: np.ndarray) -> dict:
    """{mean_abs_error, mean_bias, p95_abs_error} of a scalar quantity (AO: the first channel of
    float[N,3] or float[N]), in its own units, rounded to 5 digits: absolute, not relative, since AO
    is a fraction in [0,1] whose mean says nothing about its scale."""
    a = np.asarray(ours, np.float64).reshape(len(ours), -1)[:, 0]
    b = np.asarray(reference, np.float64).reshape(len(reference), -1)[:, 0]
    if a.shape != b.shape:
        raise ValueError(f"shapes differ: {a.shape} vs {b.shape}")
    err = np.abs(a - b)
    return {"mean_abs_error": round(float(err.mean()), 5), "mean_bias": round(float((a - b).mean()), 5),
            "p95_abs_error": round(float(np.percentile(err, 95)), 5)}
