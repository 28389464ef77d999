"""Lightmap encodings for engines that cannot sample float textures, and the files that hold them.

Values are linear RGB (the baked quantity, e.g. lighting = irradiance/π), float32[H,W,3], row 0
at the bottom (as pages are). Two 8-bit encodings put a float lightmap into an RGBA PNG with the
page's ``range`` (the largest value it can hold) in the file's metadata:

- ``rgbm``: value = rgb · a · range, with a rounded *up* to the next 1/255 so that rgb ≤ 1
  (a multiplier: coarse steps for dim texels of a bright page);
- ``rgbd``: value = rgb · (range/255) / a, with a rounded *down* to a 1/255 step (a divider: every
  value up to range/255 is stored with a = 1, i.e. uniform steps of range/255², brighter values
  with ever coarser steps up to range).

The range is the page's brightest texel, unless that is more than ``HEADROOM`` (16) times the
brightness (largest channel) that 99 % of its lit texels stay under (``BULK``): then it is 16 times
that, and the brighter texels — at most 1 % of them, a hot spot — are clipped to it, with a
warning giving their share (:func:`page_range`, :func:`clip_warning`). The smallest step being
range/255², a range set by one hot spot (a lamp 5 mm above a floor: 1e6 where most of the floor
holds ~0.03) would decode almost every texel to 0. ``hdr`` and the EXR formats keep every value.

RGB and A are stored as raw bytes (no sRGB curve: the texture must be sampled as linear / non-colour
data). The error of each decoded channel is at most half a step of its texel (:func:`step`):
RGBM ≤ (0.5/255)·(m + range/255), RGBD ≤ (0.5/255)·max(range/255, 2m), where m is the texel's
largest channel (tests measure it). ``hdr`` is Radiance RGBE (float decoded by the engine, an
8-bit mantissa per channel shared exponent: error < m/128); ``half``/``float`` are OpenEXR.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from . import files

# Encodings and their files: {lightmap format: file suffix}.
SUFFIX = {"half": ".exr", "float": ".exr", "hdr": ".hdr", "rgbm": ".png", "rgbd": ".png"}
EIGHT_BIT = ("rgbm", "rgbd")
# Image metadata keys written with an 8-bit encoding (PNG text chunks).
META_ENCODING, META_RANGE = "radiosity_baker:encoding", "radiosity_baker:range"
_SMALLEST = 1e-6  # the range of a black page (any positive number decodes it to 0)
# The range: at most HEADROOM × the BULK percentile of the lit texels' brightness. 16 keeps the
# samples' bright spots whole (the Cornell box's light: ~12.5 × the 99th percentile) while the
# smallest step, range/255², stays 1/4000 of the 99th percentile (RGBM: a half step is 1.2 % of a
# texel 100 × darker than it).
BULK, HEADROOM = 99.0, 16.0


def brightness(rgb: np.ndarray) -> np.ndarray:
    """float32[H,W]: the largest channel of each texel of float32[H,W,3] ``rgb``, what the 8-bit
    encodings scale by (not finite and negative values count as 0)."""
    return np.nan_to_num(rgb, nan=0.0, posinf=0.0, neginf=0.0).max(axis=2, initial=0.0)


def page_range(rgb: np.ndarray) -> float:
    """The range of an 8-bit encoding of float32[H,W,3] ``rgb``: its brightest finite texel, at
    most ``HEADROOM`` × the ``BULK`` percentile of its lit (> 0) texels' brightness, at least 1e-6.
    Texels above it are clipped (:func:`clip_warning` says how many)."""
    m = brightness(rgb)
    lit = m[m > 0]
    if not lit.size:
        return _SMALLEST
    return float(max(min(lit.max(), HEADROOM * np.percentile(lit, BULK)), _SMALLEST))


def clip_warning(rgb: np.ndarray, value_range: float, what: str) -> str | None:
    """The warning for ``what`` (e.g. "lightmap Lightmap") when texels of float32[H,W,3] ``rgb``
    are brighter than the 8-bit ``value_range`` it is encoded with (they are clipped to it);
    None when none is."""
    m = brightness(rgb)
    clipped = int(np.count_nonzero(m > value_range))
    if not clipped:
        return None
    share = 100.0 * clipped / max(int(np.count_nonzero(m > 0)), 1)
    return (f"{what}: {share:.2g} % of its lit texels ({clipped}) are brighter than the 8-bit "
            f"range {value_range:.4g} and are clipped to it (the brightest: {m.max():.4g}), so "
            f"that the others keep their precision; --lightmap-format hdr (or half, float) keeps "
            f"every value")


def encode(rgb: np.ndarray, encoding: str, value_range: float) -> np.ndarray:
    """uint8[H,W,4] RGBA of float32[H,W,3] linear ``rgb`` in ``encoding`` (``rgbm`` or ``rgbd``),
    values clamped to [0, value_range] (NaN to 0)."""
    x = np.clip(np.nan_to_num(rgb.astype(np.float64), nan=0.0), 0.0, value_range)
    m = x.max(axis=2, keepdims=True)
    if encoding == "rgbm":
        a = np.clip(np.ceil(m / value_range * 255.0), 1.0, 255.0) / 255.0
        c = x / (a * value_range)
    elif encoding == "rgbd":
        scale = value_range / 255.0
        a = np.clip(np.floor(scale / np.maximum(m, 1e-30) * 255.0), 1.0, 255.0) / 255.0
        c = x * a / scale
    else:
        raise ValueError(f"unknown 8-bit lightmap encoding {encoding!r}")
    rgba = np.concatenate([c, a], axis=2)
    return np.rint(np.clip(rgba, 0.0, 1.0) * 255.0).astype(np.uint8)


def decode(rgba: np.ndarray, encoding: str, value_range: float) -> np.ndarray:
    """float32[H,W,3] linear RGB of uint8[H,W,4] ``rgba`` (the inverse of :func:`encode`)."""
    c = rgba[..., :3].astype(np.float64) / 255.0
    a = rgba[..., 3:].astype(np.float64) / 255.0
    if encoding == "rgbm":
        return (c * a * value_range).astype(np.float32)
    if encoding == "rgbd":
        return (c * (value_range / 255.0) / np.maximum(a, 1.0 / 255.0)).astype(np.float32)
    raise ValueError(f"unknown 8-bit lightmap encoding {encoding!r}")


def step(rgba: np.ndarray, encoding: str, value_range: float) -> np.ndarray:
    """float32[H,W,1]: the quantisation step (1/255 of the colour bytes) of each encoded texel in
    decoded units; a decoded channel is within half of it of the value encoded (≤ range)."""
    a = rgba[..., 3:].astype(np.float64) / 255.0
    if encoding == "rgbm":
        return (a * value_range / 255.0).astype(np.float32)
    return ((value_range / 255.0) / np.maximum(a, 1.0 / 255.0) / 255.0).astype(np.float32)


def write(path: Path, rgb: np.ndarray, lightmap_format: str, objects=None) -> dict:
    """Write float32[H,W,3] linear ``rgb`` (row 0 bottom) in ``lightmap_format`` (a key of
    ``SUFFIX``; the path's suffix is the caller's); an EXR keeps ``objects`` (the names of the
    objects it holds, ``files.objects_of``). Returns what an engine needs to decode it:
    {"encoding": format, "range": float} for the 8-bit encodings, {"encoding": format} otherwise.
    Raises BakeError naming the path when it cannot be written."""
    if lightmap_format in ("half", "float"):
        files.write_exr(path, rgb, lightmap_format, objects)
        return {"encoding": lightmap_format}
    oiio = files._oiio()
    h, w = rgb.shape[:2]
    if lightmap_format == "hdr":
        spec = oiio.ImageSpec(w, h, 3, oiio.FLOAT)
        px = np.clip(np.nan_to_num(rgb, nan=0.0), 0.0, None)
        files._write(oiio, path, spec, np.ascontiguousarray(np.flipud(px), np.float32))
        return {"encoding": "hdr"}
    value_range = page_range(rgb)
    spec = oiio.ImageSpec(w, h, 4, oiio.UINT8)
    spec.attribute("oiio:UnassociatedAlpha", 1)  # A is data: never multiply it into RGB
    spec.attribute(META_ENCODING, lightmap_format)
    spec.attribute(META_RANGE, repr(value_range))
    rgba = encode(rgb, lightmap_format, value_range)
    files._write(oiio, path, spec, np.ascontiguousarray(np.flipud(rgba)))
    return {"encoding": lightmap_format, "range": value_range}


def read(path: Path) -> tuple[np.ndarray, dict]:
    """float32[H,W,3] linear RGB of a lightmap file :func:`write` made (row 0 bottom), decoded
    from its metadata, and that metadata ({"encoding", "range"} of an 8-bit file, else {})."""
    oiio = files._oiio()
    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)  # A is data: read the bytes as stored
    buf = oiio.ImageBuf(str(path), 0, 0, config)
    spec = buf.spec()
    encoding = spec.get_string_attribute(META_ENCODING)
    if encoding not in EIGHT_BIT:
        return files.read_exr(path)[..., :3], {}
    value_range = float(spec.get_string_attribute(META_RANGE))
    rgba = np.flipud(np.asarray(buf.get_pixels(oiio.UINT8), np.uint8))
    return decode(rgba, encoding, value_range), {"encoding": encoding, "range": value_range}
