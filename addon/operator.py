"""``object.radiosity_bake``: bake the scene's lighting into the selected (or all) meshes;
``object.radiosity_bake_clear``: remove what bakes added to them."""
from __future__ import annotations

import traceback

import bpy
from bpy.props import BoolProperty

from ..core import BakeCancelled
from . import animation, lightmap, probes
from .job import USER_ERRORS, BakeJob

# The running modal bake's progress, read by the status bar draw function: (stage, fraction).
_status: dict = {}


def _draw_status(self, context) -> None:
    if _status:
        self.layout.progress(factor=_status["fraction"], type='BAR',
                             text=f"Radiosity bake: {_status['stage']}")


def _receivers(context, use_selected: bool):
    """Names of the meshes to write, or None for every mesh of the scene."""
    if not use_selected:
        return None
    names = [ob.name for ob in context.selected_objects if ob.type == 'MESH']
    return names or None


class OBJECT_OT_radiosity_bake(bpy.types.Operator):
    """Bake global illumination of the scene into a color attribute of the meshes"""

    bl_idname = "object.radiosity_bake"
    bl_label = "Radiosity Bake"
    bl_options = {'REGISTER', 'UNDO'}

    use_selected: BoolProperty(
        name="Selected Only", default=True,
        description="Write only the selected meshes (all meshes when none is selected); the whole "
                    "scene still casts and reflects light")
    animation: BoolProperty(
        name="Animation", default=False,
        description="Bake every frame of the Frames setting (empty: the scene's frame range) into "
                    "a per-frame cache that plays back")

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._job = None
        self._timer = None

    @classmethod
    def poll(cls, context):
        if _status:
            cls.poll_message_set("A radiosity bake is already running")
            return False
        return context.scene is not None

    def execute(self, context):
        """The complete bake, synchronously (scripts, background mode)."""
        job = self._new_job(context)
        try:
            warnings = job.run_sync(context)
        except BaseException as exc:  # noqa: BLE001 - every failure becomes a report
            return self._fail(exc)
        return self._done(job, warnings)

    def invoke(self, context, event):
        """Bake in a worker thread, with progress in the status bar; Esc cancels."""
        if context.window is None:  # nothing to show progress in: behave like execute()
            return self.execute(context)
        self._job = self._new_job(context)
        try:
            self._job.start(context)
        except BaseException as exc:  # noqa: BLE001
            return self._fail(exc)
        _status.update(stage="extract", fraction=0.0)
        bpy.types.STATUSBAR_HT_header.append(_draw_status)
        self._timer = context.window_manager.event_timer_add(0.1, window=context.window)
        context.window_manager.modal_handler_add(self)
        return {'RUNNING_MODAL'}

    def modal(self, context, event):
        if event.type == 'ESC' and event.value == 'PRESS':
            self._job.cancel()
            context.workspace.status_text_set("Radiosity bake: cancelling…")
            return {'RUNNING_MODAL'}
        if event.type != 'TIMER':
            return {'PASS_THROUGH'}
        try:
            self._job.advance(context)  # an animation's next frame, extracted here (main thread)
        except BaseException as exc:  # noqa: BLE001
            self._end_modal(context)
            return self._fail(exc)
        stage, fraction, done = self._job.poll()
        if not done:
            _status.update(stage=stage, fraction=fraction)
            context.workspace.status_text_set(
                f"Radiosity bake: {stage} {fraction:.0%} (Esc to cancel)")
            for area in context.screen.areas:
                if area.type == 'STATUSBAR':
                    area.tag_redraw()
            return {'RUNNING_MODAL'}
        self._end_modal(context)
        try:
            warnings = self._job.finish(context)
        except BaseException as exc:  # noqa: BLE001
            return self._fail(exc)
        return self._done(self._job, warnings)

    def cancel(self, context):
        """Blender ends the operator (e.g. the window closes): stop the bake, write nothing."""
        self._job.cancel()
        self._end_modal(context)

    def _new_job(self, context) -> BakeJob:
        settings = context.scene.radiosity_baker.to_settings()
        frames = None
        if self.animation:
            scene = context.scene
            frames = settings.frame_list() or list(range(scene.frame_start, scene.frame_end + 1,
                                                         max(1, scene.frame_step)))
        return BakeJob(settings, _receivers(context, self.use_selected), frames=frames)

    def _end_modal(self, context) -> None:
        context.window_manager.event_timer_remove(self._timer)
        bpy.types.STATUSBAR_HT_header.remove(_draw_status)
        _status.clear()
        context.workspace.status_text_set(None)
        for area in context.screen.areas:
            if area.type == 'STATUSBAR':
                area.tag_redraw()

    def _fail(self, exc: BaseException):
        if isinstance(exc, BakeCancelled):
            self.report({'WARNING'}, "Radiosity bake cancelled: nothing was written")
            return {'CANCELLED'}
        if isinstance(exc, USER_ERRORS):
            self.report({'ERROR'}, f"Radiosity bake failed: {exc}")
        else:
            traceback.print_exception(exc)  # a bug: its traceback goes to the console
            self.report({'ERROR'}, f"Radiosity bake: internal error: {type(exc).__name__}: {exc} "
                                   f"(traceback in the console)")
        return {'CANCELLED'}

    def _done(self, job: BakeJob, warnings: list[str]):
        for message in warnings:
            self.report({'WARNING'}, message)
        self.report({'INFO'}, f"Radiosity bake: {job.result.counts.get('elements', 0)} elements "
                              f"on {job.result.device} in {job.seconds:.2f} s")
        return {'FINISHED'}


class OBJECT_OT_radiosity_bake_clear(bpy.types.Operator):
    """Remove the lightmap UV maps, images, material nodes and probe display radiosity bakes added"""

    bl_idname = "object.radiosity_bake_clear"
    bl_label = "Clear Radiosity Lightmaps"
    bl_options = {'REGISTER', 'UNDO'}

    use_selected: bpy.props.BoolProperty(
        name="Selected Only", default=True,
        description="Clear only the selected objects (all objects when none is selected)")

    def execute(self, context):
        objects = [ob for ob in context.selected_objects] if self.use_selected else []
        objects = objects or list(context.scene.objects)
        removed = lightmap.clear(objects) + animation.clear(objects) + probes.clear(objects)
        self.report({'INFO'}, f"Radiosity bake: {removed} items removed")
        return {'FINISHED'}


classes = (OBJECT_OT_radiosity_bake, OBJECT_OT_radiosity_bake_clear)
