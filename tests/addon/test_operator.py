"""The operator, the BakeJob behind it, the scene properties and the panel, on the real pipeline."""
import threading
from dataclasses import fields
from types import SimpleNamespace

import bpy
import pytest

from radiosity_baker.addon.job import BakeJob
from radiosity_baker.core import BakeCancelled, Settings
from radiosity_baker.core import settings as core_settings
from radiosity_baker.core.solvers import SOLVERS

from scenes import (GROUND, LIT, OCCLUDER, SHADOW, UNDER_LAMP, expected_point_lighting,
                    fast_settings, lit_ground, snapshot, value_at, vertex_colors)


@pytest.fixture
def lit_scene(empty_scene):
    lit_ground(empty_scene)
    fast_settings(empty_scene)
    return empty_scene


def test_execute_bakes_lit_plane_into_float_color_point_attribute(lit_scene):
    assert bpy.ops.object.radiosity_bake() == {'FINISHED'}
    mesh = bpy.data.objects[GROUND].data
    attr = mesh.attributes["Lighting"]
    assert (attr.domain, attr.data_type) == ('POINT', 'FLOAT_COLOR')
    under, lit, shadow = (value_at(mesh, "Lighting", xy) for xy in (UNDER_LAMP, LIT, SHADOW))
    assert under == pytest.approx([expected_point_lighting(*UNDER_LAMP)] * 3, rel=0.1)
    assert lit == pytest.approx([expected_point_lighting(*LIT)] * 3, rel=0.1)
    assert under.mean() > lit.mean()  # nearer the lamp, less slanted
    assert shadow.mean() < 0.05 * lit.mean()  # same distance as LIT, behind the occluder
    stats = lit_scene.radiosity_baker.last_bake
    assert stats.device and stats.elements > 0 and stats.seconds > 0


def test_invoke_without_a_window_bakes_synchronously(lit_scene):
    assert bpy.ops.object.radiosity_bake('INVOKE_DEFAULT') == {'FINISHED'}
    assert "Lighting" in bpy.data.objects[GROUND].data.attributes


def test_execute_with_selection_writes_only_selected_meshes(lit_scene):
    bpy.data.objects[OCCLUDER].select_set(True)
    assert bpy.ops.object.radiosity_bake(use_selected=True) == {'FINISHED'}
    assert "Lighting" in bpy.data.objects[OCCLUDER].data.attributes
    assert "Lighting" not in bpy.data.objects[GROUND].data.attributes


@pytest.mark.parametrize("method", [m for m, info in SOLVERS.items() if info.indirect])
def test_execute_bakes_light_reflected_by_the_ground(lit_scene, method):
    # Turned to face the ground, the occluder sees no lamp: all its light bounced off the ground.
    bpy.data.objects[OCCLUDER].data.flip_normals()
    fast_settings(lit_scene, method=method, content="indirect", attribute="Indirect", bounces=2,
                  visibility_rays=1)
    assert bpy.ops.object.radiosity_bake() == {'FINISHED'}
    underside = vertex_colors(bpy.data.objects[OCCLUDER].data, "Indirect")[:, :3]
    # Grey 0.8 ground, lit about 1 to 3 over the part the underside sees.
    assert 0.2 < underside.mean() < 3.0


def test_job_cancelled_before_start_writes_nothing(lit_scene):
    before = snapshot()
    job = BakeJob(lit_scene.radiosity_baker.to_settings())
    job.cancel()
    with pytest.raises(BakeCancelled):
        job.run_sync(bpy.context)
    assert snapshot() == before


def test_job_cancelled_while_baking_in_thread_writes_nothing(lit_scene):
    before = snapshot()
    stages = []

    def progress(stage, fraction):
        stages.append(stage)
        if stage == "direct":
            job.cancel()

    job = BakeJob(lit_scene.radiosity_baker.to_settings(), progress=progress)
    job.start(bpy.context)
    while not job.poll()[2]:
        threading.Event().wait(0.01)
    with pytest.raises(BakeCancelled):
        job.finish(bpy.context)
    assert "direct" in stages
    assert snapshot() == before
    assert not lit_scene.radiosity_baker.last_bake.device


def test_job_in_thread_reports_progress_and_writes_once_finished(lit_scene):
    job = BakeJob(lit_scene.radiosity_baker.to_settings(), receivers=[GROUND])
    job.start(bpy.context)
    assert "Lighting" not in bpy.data.objects[GROUND].data.attributes  # written by finish() only
    while not job.poll()[2]:
        threading.Event().wait(0.01)
    stage, fraction, done = job.poll()
    assert done and fraction == 1.0
    job.finish(bpy.context)
    assert "Lighting" in bpy.data.objects[GROUND].data.attributes
    assert {"extract", "direct", "write"} <= job.timings.keys()


def test_properties_mirror_every_settings_field():
    props = bpy.types.Scene.bl_rna.properties["radiosity_baker"].fixed_type.properties
    for f in fields(Settings):
        assert f.name in props, f"scene.radiosity_baker lacks {f.name}"
    for name, choices in (("method", tuple(SOLVERS)), ("content", core_settings.CONTENTS),
                          ("target", core_settings.TARGETS), ("device", core_settings.DEVICES)):
        assert tuple(i.identifier for i in props[name].enum_items) == choices


def assert_same_settings(a: Settings, b: Settings) -> None:
    a, b = a.as_dict(), b.as_dict()
    # Blender keeps float properties in single precision.
    for name in [k for k, v in b.items() if isinstance(v, float)]:
        assert a.pop(name) == pytest.approx(b.pop(name), rel=1e-6)
    assert a == b


def test_to_settings_defaults_and_changes_round_trip(empty_scene):
    s = empty_scene.radiosity_baker
    assert_same_settings(s.to_settings(), Settings())
    changed = Settings(method="direct", content="combined", attribute="GI", device="cpu",
                       light_samples=3, visibility_rays=2, bounces=5, tolerance=0.01,
                       max_pairs=1000, seed=7, bake_copy=True)
    for f in fields(Settings):
        setattr(s, f.name, getattr(changed, f.name))
    assert_same_settings(s.to_settings(), changed)


def test_panel_is_in_render_properties_for_every_engine(empty_scene):
    panel = bpy.types.RENDER_PT_radiosity_bake
    assert (panel.bl_space_type, panel.bl_context) == ('PROPERTIES', "render")
    shown = []
    for engine in ("BLENDER_EEVEE", "BLENDER_EEVEE_NEXT", "CYCLES", "BLENDER_WORKBENCH"):
        try:
            empty_scene.render.engine = engine
        except TypeError:  # EEVEE's identifier differs between Blender versions
            continue
        assert panel.poll(bpy.context), engine
        shown.append(engine)
    assert {"CYCLES", "BLENDER_WORKBENCH"} <= set(shown) and len(shown) >= 3


class RecordingLayout:
    """Stands in for UILayout (the bpy module cannot draw): records what a panel asks to show."""

    def __init__(self, shown):
        self.shown = shown

    def column(self, **kwargs):
        return self

    row = box = column

    def prop(self, data, name, **kwargs):
        assert hasattr(data, name), name
        self.shown.append(name)

    def operator(self, idname, **kwargs):
        self.shown.append(idname)
        return SimpleNamespace()  # the operator's properties, which a panel may set

    def label(self, text="", **kwargs):
        self.shown.append(text)


def test_panels_draw_every_setting_the_bake_button_and_last_stats(lit_scene):
    assert bpy.ops.object.radiosity_bake() == {'FINISHED'}
    shown = []
    for panel in (bpy.types.RENDER_PT_radiosity_bake, bpy.types.RENDER_PT_radiosity_bake_advanced):
        panel.draw(SimpleNamespace(layout=RecordingLayout(shown)), bpy.context)
    assert {f.name for f in fields(Settings)} <= set(shown)
    assert "object.radiosity_bake" in shown
    assert any(line.startswith("Last bake:") for line in shown)


def test_operator_refuses_to_start_without_changing_anything_on_bad_settings(lit_scene):
    lit_scene.radiosity_baker.attribute = "  "
    before = snapshot()
    with pytest.raises(RuntimeError, match="attribute name must not be empty"):
        bpy.ops.object.radiosity_bake()
    assert snapshot() == before
