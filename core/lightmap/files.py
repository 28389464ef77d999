"""Lightmap files through OpenImageIO: float OpenEXR (zip) and a tone-mapped PNG preview.

Pages hold row 0 at the bottom (Blender's and UV v = 0's convention); image files store the top
row first, so rows are flipped on the way out and back in.
"""
from __future__ import annotations

from pathlib import Path
from typing import Optional

import numpy as np

from ..errors import BakeError


def _oiio():
    try:
        import OpenImageIO as oiio
    except ImportError:
        raise BakeError("writing lightmaps needs the OpenImageIO Python module") from None
    return oiio


# The largest finite half float: larger values would be stored as infinite.
HALF_MAX = 65504.0
# The header attribute naming the objects a lightmap file holds (one name a line).
META_OBJECTS = "radiosity_baker:objects"


def exr_precision(rgb: np.ndarray, precision: str) -> str:
    """The channels float32[H,W,3] ``rgb`` is written with: ``precision``, but ``float`` where
    ``half`` was asked and some value lies beyond ±HALF_MAX (it would become infinite)."""
    if precision == "half" and rgb.size and float(np.abs(rgb).max()) > HALF_MAX:
        return "float"
    return precision


def write_exr(path: Path, rgb: np.ndarray, precision: str = "half", objects=None) -> None:
    """Write float32[H,W,3] linear RGB (row 0 bottom) as an RGBA OpenEXR with zip compression.

    precision: ``half`` or ``float`` channels (see :func:`exr_precision`: half only where every
    value fits it); alpha is 1. ``objects``: the names of the objects the page holds, kept in
    the header (:func:`objects_of`). Raises BakeError naming the path when it cannot be written.
    """
    oiio = _oiio()
    h, w = rgb.shape[:2]
    rgba = np.concatenate([rgb, np.ones((h, w, 1), np.float32)], axis=2)
    half = exr_precision(rgb, precision) == "half"
    spec = oiio.ImageSpec(w, h, 4, oiio.HALF if half else oiio.FLOAT)
    spec.attribute("compression", "zip")
    if objects is not None:
        spec.attribute(META_OBJECTS, "\n".join(objects))
    _write(oiio, path, spec, np.ascontiguousarray(np.flipud(rgba), np.float32))


# The channels of a directional page (``write_directional_exr``), in order.
DIRECTIONAL_CHANNELS = tuple(f"{band}.{c}" for band in ("L0", "L1x", "L1y", "L1z") for c in "RGB")


def write_directional_exr(path: Path, rgb: np.ndarray, l1: np.ndarray, precision: str = "half") -> None:
    """Write a directional page (``core.sh``): float32[H,W,3] L0 and float32[H,W,9] L1 (row 0
    bottom) as an OpenEXR with the channels ``DIRECTIONAL_CHANNELS`` (zip compression)."""
    oiio = _oiio()
    h, w = rgb.shape[:2]
    spec = oiio.ImageSpec(w, h, 12, oiio.HALF if precision == "half" else oiio.FLOAT)
    spec.channelnames = DIRECTIONAL_CHANNELS
    spec.attribute("compression", "zip")
    pixels = np.concatenate([rgb, l1], axis=2)
    _write(oiio, path, spec, np.ascontiguousarray(np.flipud(pixels), np.float32))


def write_layers_exr(path: Path, layers: np.ndarray, precision: str = "half") -> None:
    """Write float32[K,H,W,3] layers (row 0 bottom) as one RGB OpenEXR K·H texels tall, layer 0
    at the top (an engine imports it as a texture array of K vertical slices)."""
    oiio = _oiio()
    k, h, w = layers.shape[:3]
    spec = oiio.ImageSpec(w, k * h, 3, oiio.HALF if exr_precision(layers, precision) == "half" else oiio.FLOAT)
    spec.attribute("compression", "zip")
    _write(oiio, path, spec, np.ascontiguousarray(np.concatenate([np.flipud(x) for x in layers]), np.float32))


def write_png8(path: Path, values: np.ndarray) -> None:
    """Write float32[H,W,C] values in [0, 1] (row 0 bottom) as a linear 8-bit PNG (no sRGB
    curve: the bytes are round(value · 255))."""
    oiio = _oiio()
    h, w, c = values.shape
    px = np.rint(np.clip(np.flipud(values), 0.0, 1.0) * 255.0).astype(np.uint8)
    _write(oiio, path, oiio.ImageSpec(w, h, c, oiio.UINT8), np.ascontiguousarray(px))


def write_preview(path: Path, rgb: np.ndarray) -> None:
    """A PNG of float32[H,W,3]: exposure scaled so the 99th percentile maps to 1, Reinhard-style
    roll-off above, sRGB encoded, 8 bits."""
    oiio = _oiio()
    h, w = rgb.shape[:2]
    lum = rgb.max(axis=2)
    white = float(np.percentile(lum[lum > 0], 99)) if (lum > 0).any() else 1.0
    x = np.clip(rgb / max(white, 1e-30), 0.0, None)
    x = x * (1.0 + x / 4.0) / (1.0 + x)  # Reinhard with white point 2: 1 → 0.625, 2 → 1
    x = np.clip(x / 0.625 * 0.8, 0.0, 1.0)
    srgb = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)
    px = np.rint(np.flipud(srgb) * 255.0).astype(np.uint8)
    _write(oiio, path, oiio.ImageSpec(w, h, 3, oiio.UINT8), np.ascontiguousarray(px))


def _write(oiio, path: Path, spec, pixels: np.ndarray) -> None:
    out = oiio.ImageOutput.create(str(path))
    if out is None:
        raise BakeError(f"cannot write {path}: {oiio.geterror() or 'unknown image format'}")
    try:
        written = out.open(str(path), spec) and out.write_image(pixels)
    finally:
        closed = out.close()  # the last data reaches the file here: a full disk may fail only now
    if not (written and closed):
        raise BakeError(f"cannot write {path}: {out.geterror() or 'write failed'}")


# The last chunk of every PNG file (length 0, type IEND, its CRC).
_PNG_END = b"\0\0\0\0IEND\xaeB`\x82"


def verify(path: Path, size: Optional[tuple] = None) -> None:
    """Raise BakeError unless the image file ``path`` reads back whole (at ``size``, width and
    height in texels, when given): a file cut short (a full disk) fails here. (A PNG decodes even
    without its closing chunk, so that is checked too.)"""
    oiio = _oiio()
    buf = oiio.ImageBuf(str(path))
    read = buf.read(force=True)
    spec = buf.spec()
    detail = buf.geterror() if not read or buf.has_error else None
    if detail is None and size is not None and (spec.width, spec.height) != tuple(size):
        detail = f"{spec.width}×{spec.height} texels, not {size[0]}×{size[1]}"
    if detail is None and Path(path).suffix.lower() == ".png":
        with open(path, "rb") as f:
            f.seek(max(0, Path(path).stat().st_size - len(_PNG_END)))
            detail = None if f.read() == _PNG_END else "the file ends early"
    if detail is not None:
        raise BakeError(f"cannot write {path}: it does not read back whole "
                        f"({(detail.strip().splitlines() or ['unknown error'])[0]})")


def objects_of(path: Path) -> Optional[list]:
    """The names of the objects a lightmap file we wrote holds (:func:`write_exr`'s ``objects``),
    or None for a file that does not say (not ours, unreadable, an older bake's)."""
    oiio = _oiio()
    image = oiio.ImageInput.open(str(path))
    if image is None:
        oiio.geterror()  # clear it: the file is simply not one of ours
        return None
    try:
        names = image.spec().get_string_attribute(META_OBJECTS, "")
    finally:
        image.close()
    return names.split("\n") if names else None


def read_exr(path: Path) -> np.ndarray:
    """float32[H,W,C] of an image file, row 0 at the bottom (the inverse of :func:`write_exr`)."""
    oiio = _oiio()
    buf = oiio.ImageBuf(str(path))
    px = buf.get_pixels(oiio.FLOAT)
    if px is None or buf.has_error:
        raise BakeError(f"cannot read {path}: {buf.geterror()}")
    return np.flipud(np.asarray(px, np.float32)).copy()
