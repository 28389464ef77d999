"""Progress, cancellation, timings and warnings of one bake, shared by every stage."""
from __future__ import annotations

import time
from typing import Callable, Optional

from .errors import BakeCancelled

ProgressFn = Callable[[str, float], None]


class Stages:
    """Times stages, forwards progress, checks cancellation between launches and collects warnings.

    progress(stage, fraction) is called as stages advance; ``cancel`` is an object with
    ``is_set()`` (e.g. threading.Event): when set, the next check raises BakeCancelled.
    notify(message) is called at once for each warning, so a user hears of a long bake before it
    runs (warnings are also kept in ``warnings``).
    """

    def __init__(self, progress: Optional[ProgressFn] = None, cancel=None,
                 notify: Optional[Callable[[str], None]] = None):
        self._progress = progress
        self._cancel = cancel
        self._notify = notify
        self.timings: dict[str, float] = {}
        self.warnings: list[str] = []

    def check(self) -> None:
        if self._cancel is not None and self._cancel.is_set():
            raise BakeCancelled("bake cancelled")

    def report(self, stage: str, fraction: float) -> None:
        self.check()
        if self._progress is not None:
            self._progress(stage, float(fraction))

    def reporter(self, stage: str) -> Callable[[float], None]:
        """progress(fraction) of one stage, for launch helpers."""
        return lambda fraction: self.report(stage, fraction)

    def warn(self, message: str) -> None:
        if message not in self.warnings:
            self.warnings.append(message)
            if self._notify is not None:
                self._notify(message)

    def run(self, stage: str, fn, *args, **kwargs):
        self.report(stage, 0.0)
        t0 = time.perf_counter()
        out = fn(*args, **kwargs)
        self.timings[stage] = self.timings.get(stage, 0.0) + time.perf_counter() - t0
        self.report(stage, 1.0)
        return out
