"""Lightmap encodings: each decodes back to the float lightmap within its stated error."""
import numpy as np
import pytest

from radiosity_baker.core.lightmap import encodings


def _lightmap() -> np.ndarray:
    """float32[64,96,3]: a lightmap-like page, values from 0 over five decades up to ~30 (a lamp's
    hot spot), black texels and one NaN (dropped to 0)."""
    rng = np.random.default_rng(7)
    rgb = 10.0 ** rng.uniform(-4.0, 1.5, (64, 96, 1)) * rng.uniform(0.3, 1.0, (64, 96, 3))
    rgb[:4] = 0.0
    rgb[10, 10, 1] = np.nan
    return rgb.astype(np.float32)


def _clean(rgb):
    return np.nan_to_num(rgb, nan=0.0)


@pytest.mark.parametrize("encoding", encodings.EIGHT_BIT)
def test_8bit_encodings_decode_within_half_a_step_and_the_stated_bound(encoding, tmp_path):
    rgb = _lightmap()
    path = tmp_path / f"page{encodings.SUFFIX[encoding]}"
    meta = encodings.write(path, rgb, encoding)
    decoded, read_meta = encodings.read(path)
    assert read_meta == meta and meta["range"] == pytest.approx(float(np.nanmax(rgb)))
    err = np.abs(decoded - _clean(rgb))
    rgba = encodings.encode(rgb, encoding, meta["range"])
    assert (err <= 0.5 * encodings.step(rgba, encoding, meta["range"]) * (1 + 1e-5) + 1e-7).all()
    # the bound the module docstring states, from the texel's largest channel m
    m, r = _clean(rgb).max(axis=2, keepdims=True), meta["range"]
    bound = (0.5 / 255) * ((m + r / 255) if encoding == "rgbm" else np.maximum(r / 255, 2 * m))
    assert (err <= bound * (1 + 1e-5) + 1e-7).all()
    bright = m[..., 0] > 1.0
    print(f"{encoding}: range {r:.2f}, largest error {err.max():.4f}, largest relative error "
          f"above 1: {(err.max(axis=2)[bright] / m[..., 0][bright]).max():.4f}")


@pytest.mark.parametrize("lightmap_format", ["hdr", "half", "float"])
def test_float_formats_read_back_within_their_precision(lightmap_format, tmp_path):
    rgb = _lightmap()
    path = tmp_path / f"page{encodings.SUFFIX[lightmap_format]}"
    assert encodings.write(path, rgb, lightmap_format) == {"encoding": lightmap_format}
    decoded, meta = encodings.read(path)
    assert meta == {} and decoded.shape == rgb.shape
    m = _clean(rgb).max(axis=2, keepdims=True)
    relative = {"hdr": 1 / 128, "half": 2.0 ** -11, "float": 0.0}[lightmap_format]
    tiny = {"hdr": 1e-38, "half": 6e-8, "float": 0.0}[lightmap_format]  # half: subnormal step
    # RGBE shares an exponent: its error scales with the texel's largest channel
    scale = np.broadcast_to(m if lightmap_format == "hdr" else np.abs(_clean(rgb)), rgb.shape)
    err = np.abs(_clean(decoded) - _clean(rgb))  # EXR keeps the NaN, RGBE stores 0
    assert (err <= scale * relative + tiny).all()
    print(f"{lightmap_format}: largest relative error "
          f"{(err / np.maximum(scale, 1e-30))[scale > 1e-4].max():.5f} (values above 1e-4)")


def test_a_black_page_encodes_and_decodes_to_black():
    rgb = np.zeros((4, 4, 3), np.float32)
    r = encodings.page_range(rgb)
    for encoding in encodings.EIGHT_BIT:
        assert not encodings.decode(encodings.encode(rgb, encoding, r), encoding, r).any()


def _hot_spot_floor(n: int = 257) -> np.ndarray:
    """float32[n,n,3]: lighting (irradiance/π) of a 4 m floor under a 1000 W point lamp 5 mm above
    its centre texel: 1e6 there, ~0.03 over most of the floor (seven decades)."""
    x = np.linspace(-2.0, 2.0, n)
    d2 = x[:, None] ** 2 + x[None, :] ** 2 + 0.005 ** 2
    lighting = 1000.0 / (4 * np.pi ** 2 * d2) * (0.005 / np.sqrt(d2))
    return np.repeat(lighting[..., None], 3, axis=2).astype(np.float32)


@pytest.mark.parametrize("encoding", encodings.EIGHT_BIT)
def test_a_hot_spot_is_clipped_with_a_warning_so_the_rest_of_the_page_keeps_its_precision(
        encoding, tmp_path):
    rgb = _hot_spot_floor()
    m = rgb.max(axis=2)
    meta = encodings.write(tmp_path / "page.png", rgb, encoding)
    decoded, _ = encodings.read(tmp_path / "page.png")
    r = meta["range"]
    clipped = m > r
    assert m.max() > 9e5 and 0 < clipped.mean() <= 0.01  # the hot spot alone
    assert np.all(decoded[clipped] == pytest.approx(r, rel=0.01))  # clipped to the range
    kept = decoded.max(axis=2)[~clipped]
    assert (kept > 0).all()  # the brightest texel's range decoded 98 % of them to 0
    relative = np.abs(kept - m[~clipped]) / m[~clipped]
    # seven decades in 8 bits: the bulk, three decades below the range, in steps of a few %
    assert np.median(relative) < 0.02 and np.percentile(relative, 90) < 0.1
    print(f"{encoding}: range {r:.4g} (brightest {m.max():.4g}), {100 * clipped.mean():.2f} % "
          f"clipped, relative error of the others: median {np.median(relative):.4f}, 90th "
          f"percentile {np.percentile(relative, 90):.4f}")
    message = encodings.clip_warning(rgb, r, "lightmap Floor")
    share = f"{100 * clipped.mean():.2g} %"
    assert message.startswith(f"lightmap Floor: {share} of its lit texels") and "hdr" in message
    assert encodings.clip_warning(_lightmap(), encodings.page_range(_lightmap()), "x") is None
