"""Settings: one source of truth for range, default and help; the manual's reference follows from it;
the traps of a bad combination are errors or warnings, not black bakes."""
from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest

import shapes
from radiosity_baker.core import Settings, bake
from radiosity_baker.core.errors import BakeError, SettingsError
from radiosity_baker.core.scene import LAMP_POINT
from radiosity_baker.core.settings import REFERENCE_PAGE, option, reads, reference_page

PAGE = Path(__file__).resolve().parents[2] / REFERENCE_PAGE


def test_the_manuals_settings_reference_is_the_one_the_settings_make():
    assert PAGE.read_text(encoding="utf-8") == reference_page(), (
        f"{REFERENCE_PAGE} is out of date: run .venv/bin/python -c "
        "'from radiosity_baker.core import settings; settings.write_reference_page()'")


@pytest.mark.parametrize("f", fields(Settings), ids=lambda f: f.name)
def test_every_default_is_within_its_own_range(f):
    opt = option(f.name)
    value = f.default
    assert opt.choices is None or value in opt.choices
    assert opt.low is None or value >= opt.low
    assert opt.high is None or value <= opt.high
    assert opt.help and opt.label and opt.group in ("solver", "lightmap", "output")


@pytest.mark.parametrize("name, value", [("light_samples", 0), ("visibility_rays", 256),
                                         ("tolerance", 0.9), ("supersample", 9), ("seed", -1),
                                         ("max_size", 8), ("max_size", 16385), ("method", "magic")])
def test_out_of_range_values_are_refused_naming_the_setting(name, value):
    with pytest.raises(SettingsError, match=name):
        Settings(**{name: value}).validate()
    assert issubclass(SettingsError, BakeError) and issubclass(SettingsError, ValueError)


def lit_plane():
    p, n, t = shapes.grid(2.0, 4)
    return shapes.scene([(p, n, t, (0.5,) * 3, (0,) * 3)], shapes.lamp(LAMP_POINT, (0, 0, 1), power=(50,) * 3))


def test_indirect_content_with_a_method_without_indirect_light_is_an_error_not_black():
    with pytest.raises(SettingsError, match="indirect"):
        bake(lit_plane(), Settings(method="direct", content="indirect"))


def test_any_sample_count_is_used_as_given():
    """8 samples are 8 (not rounded down to a square): the ray count says so."""
    p, n, t = shapes.grid(2.0, 2)
    lamp = shapes.lamp(LAMP_POINT, (0, 0, 1), size=(0.1, 0.0), power=(50,) * 3)
    counts = {k: bake(shapes.scene([(p, n, t, (0.5,) * 3, (0,) * 3)], lamp),
                      Settings(method="direct", light_samples=k)).counts["rays"] for k in (4, 8, 9)}
    assert counts[8] == 2 * counts[4] and counts[9] * 4 == counts[4] * 9


def test_settings_the_method_does_not_read_are_greyed_and_warned_about():
    assert reads("reference", "bounces") and not reads("bunnell", "bounces")
    assert not reads("bunnell", "visibility_rays") and not reads("bunnell", "tolerance")
    assert reads("ao", "ao_distance") and not reads("reference", "ao_distance")
    assert not reads("ao", "light_samples") and reads("direct", "light_samples")
    r = bake(lit_plane(), Settings(method="bunnell", bounces=3, device="cpu"))
    assert any("--bounces is not used by method bunnell" in w for w in r.warnings)


def test_ao_content_bakes_with_the_ao_solver_whatever_the_method():
    a = bake(lit_plane(), Settings(content="ao", method="reference", device="cpu"))
    b = bake(lit_plane(), Settings(method="ao", device="cpu"))
    np.testing.assert_array_equal(a.output, b.output)
    assert a.counts["rays"] == 0  # no light traced for AO
