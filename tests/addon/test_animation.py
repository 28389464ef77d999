"""Frame-range bakes: each frame as a single bake of that frame gives it, a per-frame attribute cache
that plays back through Geometry Nodes, the current frame in the named attribute, progress per
frame, nothing written when cancelled, the report's frames, and clearing."""
import json

import bpy
import numpy as np
import pytest

from radiosity_baker.addon import animation, cli
from radiosity_baker.addon.job import BakeJob
from radiosity_baker.core import BakeCancelled, Settings
from harness import metrics

from scenes import script, snapshot

FRAMES = (1, 9, 17)


@pytest.fixture
def room(empty_scene):
    """The sample animated room, coarse (0.25 m cells), over frames 1–17."""
    script("sample_blends/make_samples.py").animated_room(empty_scene, cell=0.25, frames=(1, 17))
    return empty_scene


def colors(name_or_mesh, attribute):
    me = bpy.data.objects[name_or_mesh].data if isinstance(name_or_mesh, str) else name_or_mesh
    out = np.empty(len(me.vertices) * 4, np.float32)
    me.attributes[attribute].data.foreach_get("color", out)
    return out.reshape(-1, 4)[:, :3]


SETTINGS = dict(method="reference", light_samples=4, visibility_rays=2, device="cpu")


def test_each_frame_of_an_armature_animation_is_what_a_single_bake_of_that_frame_gives(room):
    room.frame_set(9)
    job = BakeJob(Settings(frames="1:17:8", **SETTINGS))
    job.run_sync(bpy.context)
    assert [f["frame"] for f in job.frames] == list(FRAMES) and room.frame_current == 9
    # the problem carried over where the split into shading vertices stayed (the column's flat
    # faces stop being coplanar as it starts to bend: its elements change once)
    assert "move" in job.frames[-1]["stages"]
    for frame in FRAMES:
        room.frame_set(frame)
        BakeJob(Settings(attribute="Single", **SETTINGS)).run_sync(bpy.context)
        for name in ("Column", "Floor", "Door"):
            cached = colors(name, animation.frame_attribute("Lighting", frame))
            single = colors(name, "Single")
            assert metrics.relative_rmse(cached, single) <= 0.01, (name, frame)
    first, last = colors("Column", "Lighting.0001"), colors("Column", "Lighting.0017")
    assert metrics.relative_rmse(first, last) > 0.05  # the column bent: frames differ
    # the named attribute holds the frame that was current when the bake ran
    np.testing.assert_array_equal(colors("Column", "Lighting"), colors("Column", "Lighting.0009"))


def test_the_cache_plays_back_the_current_frame_and_clears(room):
    BakeJob(Settings(frames="1:17:8", method="bunnell", light_samples=2, device="cpu")).run_sync(bpy.context)
    column = bpy.data.objects["Column"]
    assert column.modifiers[-1].name == animation.PLAYBACK
    for frame, shown in ((1, 1), (9, 9), (17, 17), (12, 9), (30, 17)):
        room.frame_set(frame)
        evaluated = column.evaluated_get(bpy.context.evaluated_depsgraph_get()).data
        np.testing.assert_allclose(colors(evaluated, "Lighting"),
                                   colors("Column", animation.frame_attribute("Lighting", shown)))
    bpy.context.view_layer.objects.active = column
    assert bpy.ops.object.radiosity_bake_clear(use_selected=False) == {'FINISHED'}
    assert animation.PLAYBACK not in column.modifiers
    assert not any(a.name.startswith("Lighting.") for a in column.data.attributes)
    assert not any(g.name.startswith(animation.PLAYBACK) for g in bpy.data.node_groups)


def test_cancel_between_frames_writes_nothing(room):
    before = snapshot()

    def progress(stage, fraction):
        if stage.startswith("frame 9:"):
            job.cancel()

    job = BakeJob(Settings(frames="1:17:8", method="direct", device="cpu"), progress=progress)
    with pytest.raises(BakeCancelled):
        job.run_sync(bpy.context)
    assert snapshot() == before and room.frame_current == 1


def test_a_modal_animation_bake_extracts_each_frame_on_the_main_thread(room):
    job = BakeJob(Settings(frames="1:17:8", method="direct", device="cpu"))
    job.start(bpy.context)
    while not job.poll()[2]:
        job.advance(bpy.context)  # what the modal operator's timer does
        bpy.app.timers  # keep the loop honest: nothing else drives it
        import time
        time.sleep(0.01)
    job.finish(bpy.context)
    assert [f["frame"] for f in job.frames] == list(FRAMES)
    assert all(animation.frame_attribute("Lighting", f) in bpy.data.objects["Floor"].data.attributes
               for f in FRAMES)


def test_cli_frames_reports_each_frame_and_saves_the_cache(room, tmp_path):
    blend, out, report = tmp_path / "room.blend", tmp_path / "baked.blend", tmp_path / "r.json"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    assert cli.main(["bake", str(blend), "--method", "bunnell", "--frames", "1:17:8", "--samples", "2",
                     "--save", str(out), "--report", str(report)]) == 0
    frames = json.loads(report.read_text())["frames"]
    assert [f["frame"] for f in frames] == list(FRAMES)
    assert all(f["seconds"] > 0 and f["counts"]["elements"] > 0 for f in frames)
    bpy.ops.wm.open_mainfile(filepath=str(out))
    attributes = bpy.data.objects["Column"].data.attributes
    assert {"Lighting", "Lighting.0001", "Lighting.0009", "Lighting.0017"} <= set(attributes.keys())


@pytest.mark.parametrize("frames", ["5", "9:1", "1:9:0", "a:b"])
def test_a_bad_frame_range_is_a_usage_error(room, tmp_path, frames):
    blend = tmp_path / "room.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    assert cli.main(["bake", str(blend), "--frames", frames]) == 2


def test_a_lightmap_animation_is_an_image_sequence_with_a_file_per_frame(room, tmp_path):
    from radiosity_baker.core.lightmap import files

    settings = Settings(frames="1:17:8", method="bunnell", light_samples=2, device="cpu",
                        target="lightmap", texel_density=6.0, output=str(tmp_path / "maps"),
                        hookup="node")
    BakeJob(settings, receivers=["Floor", "Column"]).run_sync(bpy.context)
    written = sorted(p.name for p in (tmp_path / "maps").glob("*.exr"))
    assert written == [f"Lightmap.{f:04d}.exr" for f in range(1, 18)]  # held between baked frames
    pages = {f: files.read_exr(tmp_path / "maps" / f"Lightmap.{f:04d}.exr") for f in (1, 5, 9, 17)}
    np.testing.assert_array_equal(pages[1], pages[5])  # frame 5 holds frame 1
    assert pages[1].shape == pages[17].shape and np.abs(pages[1] - pages[17]).max() > 0.01
    image = next(im for im in bpy.data.images if im.get("radiosity_baker_lightmap"))
    assert image.source == "SEQUENCE"
    mat = bpy.data.objects["Column"].material_slots[0].material
    user = mat.node_tree.nodes["RB Lightmap"].image_user
    assert (user.frame_start, user.frame_duration, user.use_auto_refresh) == (1, 17, True)
    assert "Lightmap" in bpy.data.objects["Column"].data.uv_layers


def test_a_cancelled_lightmap_animation_leaves_the_output_folder_as_it_was(room, tmp_path):
    maps = tmp_path / "maps"
    maps.mkdir()
    (maps / "mine.txt").write_text("user file")
    settings = Settings(frames="1:17:8", method="direct", device="cpu", target="lightmap",
                        texel_density=6.0, output=str(maps))

    def progress(stage, fraction):
        if stage.startswith("frame 17:"):
            job.cancel()

    job = BakeJob(settings, receivers=["Floor"], progress=progress)
    with pytest.raises(BakeCancelled):
        job.run_sync(bpy.context)
    assert sorted(p.name for p in maps.iterdir()) == ["mine.txt"]


def test_the_panels_bake_animation_button_bakes_the_scenes_frame_range(room):
    room.frame_start, room.frame_end, room.frame_step = 1, 17, 8
    room.radiosity_baker.method = "direct"
    assert room.radiosity_baker.frames == ""  # the scene's range, then
    assert bpy.ops.object.radiosity_bake(animation=True, use_selected=False) == {'FINISHED'}
    names = set(bpy.data.objects["Door"].data.attributes.keys())
    assert {animation.frame_attribute("Lighting", f) for f in FRAMES} <= names


@pytest.fixture
def static_square(empty_scene):
    """A 3×3-vertex square under a sun: the cheapest scene a frame range can bake."""
    from scenes import grid

    grid(empty_scene, "Square", 2.0, 3)
    sun = bpy.data.objects.new("Sun", bpy.data.lights.new("Sun", "SUN"))
    empty_scene.collection.objects.link(sun)
    return empty_scene


def _write_seconds(frames: int, progress=None) -> float:
    bpy.ops.object.radiosity_bake_clear(use_selected=False)
    job = BakeJob(Settings(frames=f"1:{frames}", method="direct", light_samples=1, device="cpu"),
                  progress=progress)
    job.run_sync(bpy.context)
    return job.timings["write"]


def test_writing_a_frame_range_takes_time_linear_in_frames_and_reports_progress(static_square):
    """50 and 400 frames: 8× the frames take far less than the 64× a quadratic write would (one
    node per frame in the playback group made it so); the write reports its progress."""
    seen = []
    short = _write_seconds(50)
    long = _write_seconds(400, lambda stage, fraction: seen.append(fraction) if stage == "write" else None)
    assert long < 24 * max(short, 0.005), (short, long)
    assert seen[0] == 0.0 and seen[-1] == 1.0 and seen == sorted(seen)
    assert sum(0.0 < f < 1.0 for f in seen) >= 400  # each frame, prepared and written
    names = bpy.data.objects["Square"].data.attributes.keys()
    assert {"Lighting.0001", "Lighting.0400"} <= set(names)


def test_a_large_attribute_cache_is_announced_before_baking(static_square, monkeypatch):
    monkeypatch.setattr(animation, "CACHE_WARN_BYTES", 20 * 9 * 16 - 1)  # 20 frames of 9 vertices
    events = []
    job = BakeJob(Settings(frames="1:20", method="direct", light_samples=1, device="cpu"),
                  progress=lambda stage, fraction: events.append(stage),
                  notify=lambda message: events.append(message))
    job.run_sync(bpy.context)
    warning = next(i for i, e in enumerate(events) if "20 frames × 9 vertices" in e)
    assert warning < events.index("frame 1: direct")
    assert any("20 frames × 9 vertices" in w for w in job.warnings)
