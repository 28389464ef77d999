"""Supersampled texels gathered once per texel, and at every sub-sample where the texels around
disagree (``core.lightmap.sparse``)."""
import numpy as np

import shapes
from radiosity_baker.core import Settings, bake
from radiosity_baker.core.lightmap import LightmapRequest, raster, sparse
from test_lightmap_pages import _targets, _wall_and_floor


def _grid(texels: int, s: int) -> raster.Texels:
    """A fully covered page of texels² texels at s² sub-samples each, in index order."""
    n = (texels * s) ** 2
    return raster.Texels(index=np.arange(n, dtype=np.int64), triangle=np.zeros(n, np.int32),
                         bary=np.full((n, 3), 1 / 3, np.float32), width=texels * s, height=texels * s)


def test_detail_is_gathered_once_per_texel_and_at_every_sub_sample_beside_a_step():
    texels, s = 8, 2
    grid = _grid(texels, s)
    x = (grid.index % grid.width) // s  # the texel column of each sub-sample
    truth = np.where(x >= 4, 1.0, 0.0)[:, None].repeat(3, axis=1).astype(np.float32)
    asked = []

    def detail_at(index, progress):
        asked.append(np.asarray(index))
        return truth[index]

    base = np.ones_like(truth)
    detail, again = sparse.gather([grid], s, detail_at, base, lambda f: None)
    np.testing.assert_array_equal(detail, truth)
    texel = x + texels * ((grid.index // grid.width) // s)
    assert np.array_equal(np.sort(texel[asked[0]]), np.arange(texels ** 2))  # one sub-sample each
    # the two columns beside the step are gathered again, at their other sub-samples only
    assert set(np.unique(x[asked[1]])) == {3, 4}
    assert asked[1].size == 2 * texels * (s * s - 1)
    assert again == 2 / texels


def test_a_smooth_detail_is_shared_within_each_texel():
    texels, s = 8, 2
    grid = _grid(texels, s)
    x = (grid.index % grid.width).astype(np.float32)
    truth = np.stack([0.1 + 0.001 * x] * 3, axis=1)
    detail, again = sparse.gather([grid], s, lambda index, progress: truth[index], np.ones_like(truth),
                                  lambda f: None)
    assert again == 0.0
    assert np.abs(detail - truth).max() <= 0.001 * (s - 1) + 1e-7


def test_supersampled_lightmap_gathered_sparsely_matches_every_sub_sample_gathered(tmp_path, monkeypatch):
    """The wall's bounce light on a coarse floor: the page gathered sparsely against the page
    gathered at every sub-sample (SPREAD below 0)."""
    sc, parts = _wall_and_floor(2)
    settings = Settings(method="reference", content="indirect", light_samples=4, texel_density=32.0,
                        padding=2, device="cpu", supersample=2, target="lightmap")
    pages, shares = {}, {}
    for label, spread in (("sparse", sparse.SPREAD), ("every", -1.0)):
        monkeypatch.setattr(sparse, "SPREAD", spread)
        r = bake(sc, settings, targets=shapes.with_lightmap(LightmapRequest(_targets(sc, parts),
                                                                            cache_dir=tmp_path / "cache")))
        pages[label], shares[label] = r["lightmap"].pages[0], r.counts["texels_gathered_whole"]
    covered = pages["every"].covered
    a, b = pages["sparse"].rgb[covered], pages["every"].rgb[covered]
    print(f"\nshare gathered at every sub-sample: {shares}; relative RMS difference "
          f"{np.sqrt(((a - b) ** 2).mean() / (b ** 2).mean()):.4f}, largest {np.abs(a - b).max() / b.max():.4f}")
    assert shares["every"] == 1.0 and 0.0 < shares["sparse"] < 0.5
    assert np.sqrt(((a - b) ** 2).mean()) < 0.01 * np.sqrt((b ** 2).mean())
    assert np.abs(a - b).max() < 0.05 * b.max()
