"""BakeJob: one bake, shared by the operator (modal or not) and the command line.

Blender data is only touched on the main thread: extraction in ``start()``, writing in ``finish()``
in one final step, so a failed or cancelled bake leaves the file as it was. ``core.bake`` runs in
between, in a worker thread when started with ``start()`` (Warp releases the GIL, Blender stays
responsive) or in the caller's thread with ``run_sync()``. What can stop the writing (names taken
by other data, unwritable folders) is checked before baking, and again in ``finish()`` before the
first file or Blender datum is written, since the file may have changed during a modal bake.
"""
from __future__ import annotations

import threading
import time
from typing import Callable, Iterable, Optional

from .. import core
from ..core import BakeCancelled, BakeError, Settings
from . import extract, lightmap, props, write

# Errors caused by the scene, the settings (core.errors.SettingsError is a BakeError) or where the
# results go (outputs.OutputError): shown to the user as their message alone. Anything else is a
# bug, shown with its traceback.
USER_ERRORS = (extract.ExtractionError, BakeError)


class BakeJob:
    """Bake ``settings`` into the objects named ``receivers`` (None: every mesh of the scene).

    progress(stage, fraction) and notify(warning) are optional and called from the thread that
    bakes (notify as each warning of the bake arises, e.g. a long bake announced before it runs). After
    ``finish()``: ``result`` (core BakeResult), ``timings`` (seconds per stage, extraction and
    writing included), ``warnings`` (extraction, bake and writing) and ``seconds`` (wall time).
    """

    def __init__(self, settings: Settings, receivers: Optional[Iterable[str]] = None,
                 progress: Optional[Callable[[str, float], None]] = None,
                 notify: Optional[Callable[[str], None]] = None):
        self.settings = settings
        self.receivers = None if receivers is None else list(receivers)
        self._user_progress = progress
        self._notify = notify
        self._cancel = threading.Event()
        self._lock = threading.Lock()
        self._stage, self._fraction = "extract", 0.0
        self._thread: Optional[threading.Thread] = None
        self._t0 = 0.0
        self.extraction = None
        self.lightmap_request = None
        self.lightmap_files: dict = {}
        self.result = None
        self.error: Optional[BaseException] = None
        self.timings: dict[str, float] = {}
        self.warnings: list[str] = []
        self.seconds = 0.0

    # -- main thread -----------------------------------------------------------------------------

    def start(self, context) -> None:
        """Extract the scene (main thread), then bake in a worker thread.

        Raises USER_ERRORS for settings or scenes that cannot be baked; nothing was changed then.
        """
        self._extract(context)
        self._thread = threading.Thread(target=self._bake, name="radiosity_baker", daemon=True)
        self._thread.start()

    def run_sync(self, context) -> list[str]:
        """The whole bake in the calling (main) thread; returns the warnings (see ``finish``)."""
        self._extract(context)
        self._bake()
        return self.finish(context)

    def poll(self) -> tuple[str, float, bool]:
        """(stage, fraction of that stage in [0,1], done); cheap, for a UI timer."""
        with self._lock:
            stage, fraction = self._stage, self._fraction
        done = self._thread is None or not self._thread.is_alive()
        return stage, fraction, done

    def cancel(self) -> None:
        """Ask the bake to stop at its next check; ``finish()`` then raises BakeCancelled."""
        self._cancel.set()

    def finish(self, context) -> list[str]:
        """Wait for the bake, then write the results in one step; returns all warnings.

        Raises the bake's error (BakeCancelled when cancelled) and writes nothing then.
        """
        if self._thread is not None:
            self._thread.join()
        if self.error is None and self._cancel.is_set():
            self.error = BakeCancelled("bake cancelled")
        if self.error is not None:
            raise self.error
        t0 = time.perf_counter()
        # Every check first (objects resolved by name, names free): a failure writes nothing.
        colors = maps = None
        if self.settings.target in ("vertex_colors", "both"):
            colors = write.prepare_color_attributes(self.extraction, self.result.output,
                                                    self.settings.attribute, self.settings, context)
        if self.lightmap_request is not None:
            maps = lightmap.prepare(self.result.lightmap, self.lightmap_request, self.settings)
            # files next, all or none: a disk error leaves Blender untouched
            self.lightmap_files = lightmap.write_files(self.result.lightmap, self.settings)
        if colors is not None:
            self.warnings += colors.apply(context)
        if maps is not None:
            self.warnings += maps.apply(self.result.lightmap, self.lightmap_files, self.settings)
        self.timings["write"] = time.perf_counter() - t0
        self.seconds = time.perf_counter() - self._t0
        if hasattr(context.scene, "radiosity_baker"):  # the CLI may run without the add-on registered
            props.store_stats(context.scene, self.result, self.seconds)
        return self.warnings

    def _extract(self, context) -> None:
        self._t0 = time.perf_counter()
        self.settings.validate()
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
        if self.settings.target in ("vertex_colors", "both"):
            write.check_color_attributes(self.extraction, self.settings.attribute, self.settings,
                                         context)
        if self.settings.target in ("lightmap", "both"):
            lightmap.output_folder(self.settings)  # an unwritable folder fails before baking
            self.lightmap_request, warnings = lightmap.request(self.extraction, self.settings)
            self.warnings += warnings
        self.timings["extract"] = time.perf_counter() - self._t0

    # -- any thread ------------------------------------------------------------------------------

    def _bake(self) -> None:
        """core.bake; any exception is kept for ``finish()`` to raise on the main thread."""
        try:
            self.result = core.bake(self.extraction.scene, self.settings, self._on_progress,
                                    self._cancel, lightmap=self.lightmap_request, notify=self._notify)
        except BaseException as exc:  # noqa: BLE001 - re-raised by finish()
            self.error = exc
            return
        self.timings.update(self.result.timings)
        self.warnings += self.result.warnings

    def _on_progress(self, stage: str, fraction: float) -> None:
        with self._lock:
            self._stage, self._fraction = stage, fraction
        if self._user_progress is not None:
            self._user_progress(stage, fraction)
