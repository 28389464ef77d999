"""The live preview: a depsgraph handler notes changes, the timer extracts and hands them to a worker,
results land in '<attribute> Preview' on the main thread; stale solves are cancelled; switching off
leaves the file as it was; undo and file loads are survived. Timers do not fire in the bpy module,
so the tests tick it themselves (``Preview.settle``)."""
import threading
import time

import bpy
import numpy as np
import pytest

from radiosity_baker.addon import live

from scenes import GROUND, OCCLUDER, SHADOW, lit_ground, user_data, value_at

ATTRIBUTE = "Lighting Preview"


@pytest.fixture
def preview(empty_scene):
    lit_ground(empty_scene)
    empty_scene.radiosity_baker.method = "direct"
    empty_scene.radiosity_baker.light_samples = 4
    before = user_data()
    empty_scene.radiosity_baker_live.enabled = True  # the panel's toggle
    session = live.session()
    assert session is not None
    session.settle()
    yield empty_scene, session, before
    live.stop()


def ground(name=ATTRIBUTE, xy=SHADOW):
    return value_at(bpy.data.objects[GROUND].data, name, xy)


def test_moving_an_object_updates_the_preview(preview):
    scene, session, _ = preview
    shadowed = ground()
    assert session.solves == 1 and shadowed.max() < 1.0  # the occluder's shadow
    bpy.data.objects[OCCLUDER].location.y += 3.0  # out of the way
    bpy.context.view_layer.update()  # the depsgraph handler notes it
    session.settle()
    assert session.solves == 2 and ground().max() > 5.0 * max(shadowed.max(), 1e-3)


def test_playing_the_timeline_updates_the_preview_where_something_is_animated(preview):
    """An occluder keyed out of the way at frame 10: ``frame_set`` alone (what playback and
    scrubbing do; no depsgraph update names the object) re-solves and lifts the shadow; a frame
    where nothing moved solves nothing."""
    scene, session, _ = preview
    shadowed = ground()
    occluder = bpy.data.objects[OCCLUDER]
    occluder.keyframe_insert("location", frame=1)
    occluder.location.y += 3.0
    occluder.keyframe_insert("location", frame=10)
    scene.frame_set(1)
    bpy.context.view_layer.update()
    session.settle()
    solves = session.solves
    scene.frame_set(10)
    session.settle()
    assert session.solves == solves + 1 and ground().max() > 5.0 * max(shadowed.max(), 1e-3)
    scene.frame_set(12)  # past the last key: the same scene
    session.settle()
    assert session.solves == solves + 1


def test_the_preview_reports_its_frame_rate_and_where_each_update_went(preview):
    scene, session, _ = preview
    assert len(session.updates) == 1  # the first solve
    for step in range(3):
        bpy.data.objects[OCCLUDER].location.y += 0.2
        bpy.context.view_layer.update()
        started = time.perf_counter()
        session.settle()
        waited = time.perf_counter() - started
        u = session.updates[-1]
        assert len(session.updates) == 2 + step
        assert u.extract > 0 and u.solve > 0 and u.write > 0
        assert u.work <= u.latency <= waited + u.extract  # latency runs from the extraction's start
        assert 0 < sum(u.stages.values()) <= u.solve  # the bake's own stages, within its time
        assert "direct" in u.stages  # the stages a profile needs
    assert session.frame_rate == pytest.approx(len(session.updates) / sum(u.work for u in session.updates))
    line = session.status()
    assert f"{session.frame_rate:.1f} fps" in line and "solve" in line and "4 solves" in line
    undo_before = list(session.updates)
    session.undone()
    session.settle()
    assert session.updates == undo_before  # writing the last result again is no new update


def test_a_lamp_power_change_scales_the_preview_and_own_writes_cause_no_solve(preview):
    scene, session, _ = preview
    lit = ground(xy=(-2.0, 0.0))
    bpy.data.lights["Lamp"].energy *= 2.0
    bpy.context.view_layer.update()
    session.settle()
    np.testing.assert_allclose(ground(xy=(-2.0, 0.0)), 2.0 * lit, rtol=1e-4)
    solves = session.solves
    bpy.context.view_layer.update()  # the attribute the preview wrote is no change to solve
    session.settle()
    assert session.solves == solves


def test_a_newer_change_cancels_the_solve_still_running(preview):
    scene, session, _ = preview
    real = session._sequence.bake
    started = threading.Event()

    def slow(scene_data, *args, **kwargs):  # a long solve: waits until told to stop
        started.set()
        while not session._cancel.is_set():
            time.sleep(0.005)
        return real(scene_data, *args, **kwargs)  # checks the cancel: raises BakeCancelled

    session._sequence.bake = slow
    bpy.data.objects[OCCLUDER].location.x += 0.5
    bpy.context.view_layer.update()
    session.tick()
    assert started.wait(10)
    session._sequence.bake = real
    bpy.data.objects[OCCLUDER].location.x += 0.5
    bpy.context.view_layer.update()
    session.settle()
    assert session.cancelled == 1 and session.solves == 2


def test_switching_off_leaves_the_file_as_it_was(preview):
    scene, session, before = preview
    assert ATTRIBUTE in bpy.data.objects[GROUND].data.attributes
    scene.radiosity_baker_live.enabled = False
    assert live.session() is None
    assert user_data() == before
    assert bpy.app.timers.is_registered(live._tick) is False


def test_keep_leaves_the_preview_attribute(preview):
    scene, session, _ = preview
    session.keep = True
    scene.radiosity_baker_live.enabled = False
    assert ATTRIBUTE in bpy.data.objects[GROUND].data.attributes


def test_undo_writes_the_last_result_again(preview):
    scene, session, _ = preview
    me = bpy.data.objects[GROUND].data
    me.color_attributes.remove(me.color_attributes[ATTRIBUTE])  # as an undo of the write would
    live._on_undo()
    session.settle()
    assert ATTRIBUTE in me.attributes


def test_loading_a_file_ends_the_preview_of_the_old_one(preview, tmp_path):
    scene, session, _ = preview
    path = tmp_path / "other.blend"
    scene.radiosity_baker_live.enabled = False
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    bpy.context.scene.radiosity_baker_live.enabled = True
    assert live.session() is not None
    bpy.ops.wm.open_mainfile(filepath=str(path))  # saved with the toggle off
    assert live.session() is None
