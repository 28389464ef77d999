"""Live preview: global illumination in the viewport, updated while objects, lamps and materials
change.

Switched on (``scene.radiosity_baker_live.enabled``, the panel's Live Preview toggle), a depsgraph
handler notes every change of geometry, transforms or shading; a timer on the main thread then
extracts the scene and hands it to a worker thread, which solves it with ``core.pipeline.Sequence``
(the problem moves with the scene while its topology stays, the last solution is the starting
point). A newer change cancels a solve still running. When a solve is done the timer writes it
into a color attribute ``<attribute> Preview`` of each mesh (never the baked one), which the
viewport shows in Solid mode (Attribute colour) and through a Color Attribute node. Writing it is
itself a change: a scene whose extracted content equals the last solved one is not solved again.

Switched off, the worker stops, the handlers go, and each mesh gets its preview attribute removed
(unless ``keep`` is on) and its active color attribute back. Undo and redo write the last result
again; loading a file ends the preview of the old one and starts one for the new file when its
toggle is on. Nothing blocks the UI: extraction is the only work on the main thread.
"""
from __future__ import annotations

import hashlib
import threading
import time
from dataclasses import dataclass, field, replace
from typing import Optional

import bpy
import numpy as np

from ..core import BakeCancelled, BakeError
from ..core.pipeline import Sequence
from ..core.solvers import PREVIEW, SOLVERS
from . import extract, write

# Seconds between timer ticks.
INTERVAL = 0.1
SUFFIX = " Preview"
# The frame rate is the mean over this many last updates.
RATE_OVER = 5

_session: Optional["Preview"] = None


def preview_attribute(settings) -> str:
    return settings.attribute + SUFFIX


def _signature(scene) -> bytes:
    """A hash of what a solve reads of ``scene`` (core SceneData)."""
    h = hashlib.blake2b(digest_size=16)
    for array in (scene.positions, scene.triangles, scene.corner_normals, scene.albedo, scene.emission,
                  scene.origin, *(getattr(scene.lamps, f) for f in ("kind", "position", "direction",
                                                                    "size", "power", "spot_size",
                                                                    "spot_blend"))):
        h.update(np.ascontiguousarray(array).tobytes())
    return h.digest()


@dataclass
class Update:
    """One change followed into the viewport, seconds: ``extract`` (the depsgraph read, main
    thread), ``solve`` (the worker's bake; ``stages``: its own seconds per stage, as a bake
    reports them), ``write`` (the preview attribute written, main thread) and ``latency``, from
    the extraction's start to the written attribute (the three, and the waits between them for
    the worker and the timer)."""

    extract: float
    solve: float
    write: float = 0.0
    latency: float = 0.0
    stages: dict = field(default_factory=dict)

    @property
    def work(self) -> float:
        """Seconds of work the update took (extraction, solve, write)."""
        return self.extract + self.solve + self.write


class Preview:
    """One running preview of ``scene`` (see the module docstring). ``tick()`` is the timer's work;
    ``solves`` counts finished solves, ``cancelled`` the solves a newer change stopped;
    ``updates`` the last RATE_OVER changes followed into the viewport (``Update``), of which
    ``frame_rate`` is the rate."""

    def __init__(self, scene):
        self.scene_name = scene.name
        settings = scene.radiosity_baker.to_settings()
        method = settings.method if SOLVERS[settings.solver].live else PREVIEW
        self.settings = replace(settings, method=method, target="vertex_colors", bake_copy=False,
                                frames="").validate()
        self.attribute = preview_attribute(self.settings)
        self.keep = scene.radiosity_baker_live.keep
        self._cancel = threading.Event()
        self._sequence = Sequence(self.settings, cancel=self._cancel)
        self._dirty = True
        self._rewrite = False
        self._solved = None         # signature of the last scene handed to the worker
        self._pending = None        # extraction waiting for the worker
        self._busy = False          # the worker is solving
        self._lock = threading.Lock()
        self._wake = threading.Condition(self._lock)
        self._result = None         # (extraction, values, Update) of the newest finished solve
        self._shown = None          # the result last written (for undo)
        self._active: dict = {}     # mesh name -> its active color attribute before the preview
        self._created: set = set()  # meshes whose preview attribute this preview made
        self._stop = False
        self.error: Optional[str] = None
        self.solves = 0
        self.cancelled = 0
        self.updates: list[Update] = []
        self._worker = threading.Thread(target=self._work, name="radiosity_baker preview", daemon=True)
        self._worker.start()

    # -- main thread -----------------------------------------------------------------------------

    def changed(self, depsgraph) -> None:
        """A depsgraph update: note it when it touches what the lighting depends on."""
        for update in depsgraph.updates:
            if update.is_updated_geometry or update.is_updated_transform or update.is_updated_shading:
                self._dirty = True
                return

    def frame_changed(self) -> None:
        """The scene's frame changed (the timeline played or scrubbed): animated objects, lamps and
        materials may have moved without a depsgraph update of their own (``frame_set``); the
        extraction's signature tells whether they did."""
        self._dirty = True

    def undone(self) -> None:
        self._rewrite = self._dirty = True

    def tick(self):
        """The timer: hand a changed scene to the worker, write a finished solve. Returns the
        seconds to the next tick."""
        scene = bpy.data.scenes.get(self.scene_name)
        if scene is None:
            return None
        if self._dirty:
            self._dirty = False
            self._submit(scene)
        with self._lock:
            result, self._result = self._result, None
        if result is None and self._rewrite and self._shown is not None:
            result = self._shown
        if result is not None:
            self._rewrite = False
            self._write(*result)
        return INTERVAL

    @property
    def frame_rate(self) -> float:
        """Updates per second a continuous change is followed at: 1 / the mean work of the last
        RATE_OVER updates (0 before the first)."""
        if not self.updates:
            return 0.0
        return len(self.updates) / sum(u.work for u in self.updates)

    def status(self) -> str:
        """One line for the panel: solves, frame rate and where the last update's time went."""
        text = f"{self.solves} solves ({self.settings.method})"
        if self.updates:
            u = self.updates[-1]
            text += (f", {self.frame_rate:.1f} fps: extract {u.extract:.2f} s, solve {u.solve:.2f} s, "
                     f"write {u.write:.2f} s")
        return text

    def _submit(self, scene) -> None:
        start = time.perf_counter()
        try:
            extraction = extract.extract_scene(bpy.context.evaluated_depsgraph_get())
        except extract.ExtractionError as exc:
            self.error = str(exc)
            return
        signature = _signature(extraction.scene)
        if signature == self._solved:
            return  # our own attribute write, or nothing the lighting reads
        self._solved = signature
        update = Update(extract=time.perf_counter() - start, solve=0.0, latency=start)
        with self._lock:
            if self._busy:
                self._cancel.set()  # a newer change: stop the solve that is running
            self._pending = (extraction, update)
            self._wake.notify()

    def _write(self, extraction, values, update: Optional[Update] = None) -> None:
        start = time.perf_counter()
        try:
            writes = write.prepare_color_attributes(extraction, values, self.attribute, self.settings)
        except BakeError as exc:  # a name taken, a mesh vanished or changed: the next solve follows
            self.error = str(exc)
            return
        for w in writes.writes:
            if w.mesh is not None and w.mesh.name not in self._active:
                self._active[w.mesh.name] = w.mesh.color_attributes.active_color_name
                if self.attribute not in w.mesh.color_attributes:
                    self._created.add(w.mesh.name)
        writes.apply()
        for w in writes.writes:
            if w.mesh is not None:
                w.mesh.color_attributes.active_color_name = self.attribute
        self._shown = (extraction, values)
        self.error = None
        if update is not None:  # a new solve, not undo's rewrite
            now = time.perf_counter()
            update.write, update.latency = now - start, now - update.latency
            self.updates = (self.updates + [update])[-RATE_OVER:]
        for window in bpy.context.window_manager.windows:
            for area in window.screen.areas:
                if area.type == "VIEW_3D":
                    area.tag_redraw()

    def close(self) -> None:
        """Stop the worker; remove the preview attribute (unless kept) and give each mesh its
        active color attribute back."""
        with self._lock:
            self._stop = True
            self._cancel.set()
            self._wake.notify()
        self._worker.join()
        for name, active in self._active.items():
            me = bpy.data.meshes.get(name)
            if me is None:
                continue
            attr = me.color_attributes.get(self.attribute)
            if attr is not None and not self.keep and name in self._created:
                me.color_attributes.remove(attr)
            if active and active in me.color_attributes:
                me.color_attributes.active_color_name = active
            me.update()

    # -- worker thread ---------------------------------------------------------------------------

    def _work(self) -> None:
        while True:
            with self._lock:
                while self._pending is None and not self._stop:
                    self._wake.wait()
                if self._stop:
                    return
                (extraction, update), self._pending = self._pending, None
                self._cancel.clear()
                self._busy = True
            try:
                start = time.perf_counter()
                baked = self._sequence.bake(extraction.scene)
                update.solve, update.stages = time.perf_counter() - start, dict(baked.timings)
                values = baked.output
            except BakeCancelled:
                self.cancelled += 1
                continue
            except BakeError as exc:
                self.error = str(exc)
                continue
            finally:
                with self._lock:
                    self._busy = False
            self.solves += 1
            with self._lock:
                self._result = (extraction, values, update)

    def settle(self, timeout: float = 30.0) -> None:
        """Tick (``tick``) until the worker is idle and its result written, for callers without
        the timer (the bpy module runs no timers: tests and benchmarks). Raises TimeoutError
        after ``timeout`` seconds."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            self.tick()
            if self.idle() and self._result is None:
                self.tick()
                return
            time.sleep(0.002)
        raise TimeoutError("the preview did not settle")

    def idle(self) -> bool:
        """Whether nothing waits for or runs in the worker."""
        with self._lock:
            return self._pending is None and not self._busy


def start(scene) -> Preview:
    """Start the preview of ``scene`` (stopping one that runs)."""
    global _session
    stop()
    _session = Preview(scene)
    for handlers, fn in _HANDLERS:
        if fn not in handlers:
            handlers.append(fn)
    if not bpy.app.timers.is_registered(_tick):
        bpy.app.timers.register(_tick, first_interval=INTERVAL, persistent=True)
    return _session


def stop() -> None:
    """Stop the running preview, if any (see ``Preview.close``)."""
    global _session
    if _session is not None:
        session, _session = _session, None
        session.close()
    for handlers, fn in _HANDLERS:
        if fn in handlers:
            handlers.remove(fn)
    if bpy.app.timers.is_registered(_tick):
        bpy.app.timers.unregister(_tick)


def session() -> Optional[Preview]:
    return _session


def _tick():
    return _session.tick() if _session is not None else None


@bpy.app.handlers.persistent
def _on_depsgraph(scene, depsgraph):
    if _session is not None and scene.name == _session.scene_name:
        _session.changed(depsgraph)


@bpy.app.handlers.persistent
def _on_frame(scene, *_):
    if _session is not None and scene.name == _session.scene_name:
        _session.frame_changed()


@bpy.app.handlers.persistent
def _on_undo(*_):
    if _session is not None:
        _session.undone()


@bpy.app.handlers.persistent
def _on_load_pre(*_):
    stop()


@bpy.app.handlers.persistent
def _on_load_post(*_):
    scene = bpy.context.scene
    live = getattr(scene, "radiosity_baker_live", None) if scene is not None else None
    if live is not None and live.enabled:
        start(scene)


_HANDLERS = ((bpy.app.handlers.depsgraph_update_post, _on_depsgraph),
             (bpy.app.handlers.frame_change_post, _on_frame),
             (bpy.app.handlers.undo_post, _on_undo), (bpy.app.handlers.redo_post, _on_undo))
LOAD_HANDLERS = ((bpy.app.handlers.load_pre, _on_load_pre),
                 (bpy.app.handlers.load_post, _on_load_post))


def toggle(settings, context) -> None:
    """Update callback of the panel's toggle."""
    if settings.enabled:
        start(context.scene)
    else:
        stop()


class RadiosityLiveSettings(bpy.types.PropertyGroup):
    enabled: bpy.props.BoolProperty(
        name="Live Preview", default=False, update=toggle,
        description="Solve the lighting again whenever objects, lamps or materials change, into a "
                    "'<attribute> Preview' color attribute the viewport shows (the multi-bounce "
                    "methods preview with Bunnell)")
    keep: bpy.props.BoolProperty(
        name="Keep Preview", default=False,
        description="Keep the preview attribute when the preview is switched off")


classes = (RadiosityLiveSettings,)


def register() -> None:
    for cls in classes:
        bpy.utils.register_class(cls)
    bpy.types.Scene.radiosity_baker_live = bpy.props.PointerProperty(type=RadiosityLiveSettings)
    for handlers, fn in LOAD_HANDLERS:
        if fn not in handlers:
            handlers.append(fn)


def unregister() -> None:
    stop()
    for handlers, fn in LOAD_HANDLERS:
        if fn in handlers:
            handlers.remove(fn)
    del bpy.types.Scene.radiosity_baker_live
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
