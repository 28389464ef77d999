"""BakeJob: one bake — of the current frame or of a frame range — shared by the operator (modal or
not) and the command line.

Blender data is only touched on the main thread: extraction in ``start()`` (and, for each further
frame of an animation, in ``advance()``), writing in ``finish()`` in one final step, so a failed
or cancelled bake leaves the file as it was. The bake of each frame (``core.pipeline.Sequence``:
the problem carries over from frame to frame) runs in between, in a worker thread when started
with ``start()`` (Warp releases the GIL, Blender stays responsive) or in the caller's thread with
``run_sync()``. What can stop the writing (names taken by other data, unwritable folders) is
checked before baking, and again in ``finish()`` before the first file or Blender datum is
written, since the file may have changed during a modal bake.

With ``settings.scheduler`` the bake runs on a Dask cluster (``core.farm``, connected before
anything is extracted): an animation's frames are submitted as tasks as they are extracted (the
first one waited for when a writer lays out from it) and collected in order after the last; a
single frame is solved here and the parts of its targets that split (one page each) baked as
tasks. Writing stays here.
"""
from __future__ import annotations

import threading
import time
from typing import Callable, Iterable, Optional

from ..core import BakeCancelled, BakeError, Settings
from ..core import farm as farm_mod
from ..core.pipeline import Sequence
from . import extract, props
from .writers import WRITERS

# Errors caused by the scene, the settings (core.errors.SettingsError is a BakeError) or where the
# results go (outputs.OutputError): shown to the user as their message alone. Anything else is a
# bug, shown with its traceback.
USER_ERRORS = (extract.ExtractionError, BakeError)


class BakeJob:
    """Bake ``settings`` into the objects named ``receivers`` (None: every mesh of the scene).

    frames: the frames of an animation to bake (default ``settings.frames``; None: the current
    frame). progress(stage, fraction) and notify(warning) are optional and called from the thread
    that bakes (notify as each warning of the bake arises, e.g. a long bake announced before it
    runs). After ``finish()``: ``result`` (core BakeResult, of the last frame), ``frames`` (per
    baked frame: frame, seconds, stages, counts), ``timings`` (seconds per stage over all frames,
    extraction and writing included), ``warnings`` (extraction, bake and writing), ``seconds``
    (wall time) and ``files`` ({name: path} of the files written).

    Each core target the settings ask for (``settings.targets``) has its writer
    (``addon.writers``), which checks, stages and writes its results; the writers read the job's
    ``extraction``, ``result``, ``frame``, ``frames_left``, ``baked_frames`` and ``frame_now``.
    """

    def __init__(self, settings: Settings, receivers: Optional[Iterable[str]] = None,
                 progress: Optional[Callable[[str, float], None]] = None,
                 notify: Optional[Callable[[str], None]] = None,
                 frames: Optional[list[int]] = None):
        self.settings = settings
        self.receivers = None if receivers is None else list(receivers)
        self._user_progress = progress
        self._notify = notify
        self.frames_left = list(frames) if frames is not None else settings.frame_list()
        self.animation = self.frames_left is not None
        self._sequence = None
        self.frame = None           # the frame being baked (None: the current one, no animation)
        self.frame_now = None       # the scene's frame when the bake started
        self.baked_frames: list = []  # (frame, extraction, result) per baked frame
        self.writers = [WRITERS[name](self) for name in settings.targets]
        self.frames: list = []
        self._cancel = threading.Event()
        self._lock = threading.Lock()
        self._stage, self._fraction = "extract", 0.0
        self._thread: Optional[threading.Thread] = None
        self._t0 = 0.0
        self.extraction = None
        self.result = None
        self.error: Optional[BaseException] = None
        self.timings: dict[str, float] = {}
        self.warnings: list[str] = []
        self.seconds = 0.0
        self.farm: Optional[farm_mod.Farm] = None
        self._submitted: list = []  # farm frames: (frame, extraction, future) not yet collected

    # -- main thread -----------------------------------------------------------------------------

    def start(self, context) -> None:
        """Extract the scene (main thread), then bake in a worker thread; an animation's further
        frames follow through ``advance``.

        Raises USER_ERRORS for settings or scenes that cannot be baked; nothing was changed then.
        """
        try:
            self._begin(context)
            self._extract(context)
        except BaseException:
            self._close_farm()
            raise
        self._launch()

    def advance(self, context) -> None:
        """Main thread, from a UI timer: once a frame is baked, extract the next one (if any) and
        bake it in a worker thread. Does nothing while a frame bakes, after an error or a cancel."""
        if self._thread is not None and self._thread.is_alive():
            return
        if self.error is None and not self._cancel.is_set() and self.frames_left:
            self._extract(context)
            self._launch()

    def run_sync(self, context) -> list[str]:
        """The whole bake in the calling (main) thread; returns the warnings (see ``finish``)."""
        try:
            self._begin(context)
            while True:
                self._extract(context)
                self._bake()
                if self.error is not None or not self.frames_left:
                    break
        except BaseException:
            self._discard()
            raise
        return self.finish(context)

    def poll(self) -> tuple[str, float, bool]:
        """(stage, fraction of that stage in [0,1], done); cheap, for a UI timer."""
        with self._lock:
            stage, fraction = self._stage, self._fraction
        idle = self._thread is None or not self._thread.is_alive()
        done = idle and (self.error is not None or self._cancel.is_set() or not self.frames_left)
        return stage, fraction, done

    def stop_soon(self) -> None:
        """Ask the bake to stop at its next check, and nothing else: safe from a signal handler
        that interrupts this job's own code. ``run_sync``/``finish`` then raise BakeCancelled."""
        self._cancel.set()

    @property
    def stopping(self) -> bool:
        """Whether the bake was asked to stop."""
        return self._cancel.is_set()

    def cancel(self) -> None:
        """Ask the bake to stop at its next check; ``finish()`` then raises BakeCancelled (and
        removes what was staged; so does this call when no frame is baking)."""
        self.stop_soon()
        if self._thread is None or not self._thread.is_alive():
            self._discard()

    def finish(self, context) -> list[str]:
        """Wait for the bake, then write the results in one step; returns all warnings.

        Raises the bake's error (BakeCancelled when cancelled) and writes nothing then.
        """
        if self._thread is not None:
            self._thread.join()
        if self.error is None and self._cancel.is_set():
            self.error = BakeCancelled("bake cancelled")
        if self.error is not None:
            self._discard()
            raise self.error
        try:
            return self._write(context)
        finally:
            self._discard()

    def _close_farm(self) -> None:
        if self.farm is not None:
            self.farm.close()
            self.farm = None

    @property
    def files(self) -> dict:
        """{name: path} of the files the writers put on disk."""
        return {name: path for w in self.writers for name, path in w.files.items()}

    def _write(self, context) -> list[str]:
        t0 = time.perf_counter()
        self.progress("write", 0.0)
        # Every check first (objects resolved by name, names free), files next: a failure leaves
        # Blender's data untouched.
        pending = [w.prepare(context) for w in self.writers]
        for apply in pending:
            self.warnings += apply()
        self.progress("write", 1.0)
        self.timings["write"] = time.perf_counter() - t0
        self.seconds = time.perf_counter() - self._t0
        if hasattr(context.scene, "radiosity_baker"):  # the CLI may run without the add-on registered
            props.store_stats(context.scene, self.result, self.seconds)
        return self.warnings

    def _begin(self, context) -> None:
        self._t0 = time.perf_counter()
        self.settings.validate()
        self.frame_now = context.scene.frame_current
        self._sequence = Sequence(self.settings, self.progress, self._cancel, self._notify)
        if self.animation and self.settings.bake_copy:
            raise BakeError("--bake-copy bakes one frame's evaluated mesh: it does not go with a "
                            "frame range")
        for w in self.writers:
            w.begin(context)
        if self.settings.scheduler.strip():
            self.farm = farm_mod.Farm(self.settings.scheduler.strip())
            for message in self.farm.warnings:
                self.warn(message)

    def _extract(self, context) -> None:
        """Extract the next frame (the current one for a still bake), the scene's frame restored."""
        t0 = time.perf_counter()
        self.frame = self.frames_left.pop(0) if self.animation else None
        scene = context.scene
        if self.frame is not None and self.frame != scene.frame_current:
            scene.frame_set(self.frame)
            try:
                self._extract_current(context)
            finally:
                scene.frame_set(self.frame_now)
        else:
            self._extract_current(context)
        self.timings["extract"] = self.timings.get("extract", 0.0) + time.perf_counter() - t0

    def _extract_current(self, context) -> None:
        receivers = None
        if self.receivers is not None:
            missing = [n for n in self.receivers if n not in context.scene.objects]
            if missing:
                raise extract.ExtractionError(
                    f"no object named {', '.join(map(repr, missing))} in scene {context.scene.name!r}")
            receivers = [context.scene.objects[n] for n in self.receivers]
        self.extraction = extract.extract_scene(context.evaluated_depsgraph_get(), receivers)
        self.warnings += self.extraction.warnings
        if not self.extraction.targets:  # a bake that writes nothing is no success
            if self.receivers is None:
                where = "in the scene"
            else:
                where = f"among {', '.join(self.receivers)}" if self.receivers else "named"
            raise extract.ExtractionError(f"nothing to write: no visible mesh with faces {where}")
        for w in self.writers:
            w.check(context)

    # -- any thread ------------------------------------------------------------------------------

    def _launch(self) -> None:
        self._thread = threading.Thread(target=self._bake, name="radiosity_baker", daemon=True)
        self._thread.start()

    def _bake(self) -> None:
        """Bake the extracted frame (on a farm: submit it, or bake its pages as tasks); any
        exception is kept for ``finish()`` to raise on the main thread."""
        label = f"frame {self.frame}" if self.frame is not None else ""
        t0 = time.perf_counter()
        try:
            targets = [w.target() for w in self.writers]
            if self.farm is not None and self.animation:
                self._submitted.append((self.frame, self.extraction, self.farm.submit_frame(
                    self.extraction.scene, self.settings, targets, self.frame)))
                first = not self.baked_frames and any(w.from_first_frame for w in self.writers)
                if first or not self.frames_left:
                    self._collect()
                return
            if self.farm is not None:
                result = farm_mod.bake_split(self.farm, self.extraction.scene, self.settings, targets,
                                             self.progress, self._cancel, self._notify)
            else:
                result = self._sequence.bake(self.extraction.scene, targets, label)
            self._baked(result, time.perf_counter() - t0)
        except BaseException as exc:  # noqa: BLE001 - re-raised by finish()
            self.error = exc

    def _collect(self) -> None:
        """The farm's submitted frames, in order, handed to the writers as if baked here (each
        seeing the frames after it as still to come); the last result's counts get the farm's
        report."""
        submitted, self._submitted = self._submitted, []
        results = self.farm.gather([future for _, _, future in submitted], self._cancel)
        left, now = self.frames_left, self.frame
        try:
            for k, ((frame, extraction, _), result) in enumerate(zip(submitted, results)):
                self.frame, self.extraction = frame, extraction
                self.frames_left = [f for f, _, _ in submitted[k + 1:]] + left
                self._baked(result, sum(result.timings.values()))
        finally:
            self.frames_left, self.frame = left, now
        self.result.counts["farm"] = self.farm.report()

    def _baked(self, result, seconds: float) -> None:
        """Hand the frame's result to the writers and note its timings, warnings and counts."""
        self.result = result
        for w in self.writers:
            w.baked(result)
        for stage, secs in result.timings.items():
            self.timings[stage] = self.timings.get(stage, 0.0) + secs
        self.warnings += [w for w in result.warnings if w not in self.warnings]
        if self.animation:
            self.baked_frames.append((self.frame, self.extraction, result))
            self.frames.append({"frame": self.frame, "seconds": round(seconds, 4),
                                "stages": {k: round(v, 4) for k, v in result.timings.items()},
                                "counts": result.counts})

    def _discard(self) -> None:
        self._close_farm()
        for w in self.writers:
            w.discard()

    def warn(self, message: Optional[str]) -> None:
        """Keep a warning (None: none) and tell it now, before the bake runs."""
        if message is not None and message not in self.warnings:
            self.warnings.append(message)
            if self._notify is not None:
                self._notify(message)

    def progress(self, stage: str, fraction: float) -> None:
        with self._lock:
            self._stage, self._fraction = stage, fraction
        if self._user_progress is not None:
            self._user_progress(stage, fraction)
