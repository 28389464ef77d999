"""Device choice and the launch helper that spreads CPU launches over all cores.

Warp runs a CPU launch serially on the calling thread (releasing the GIL), so a large launch is split
into ranges run by one Python thread per core. Kernels launched through :func:`launch` take the
offset of their range as the first argument: ``i = wp.tid() + offset``.

Inside ``with profiling() as table:`` every launch through :func:`launch` adds its wall seconds,
process CPU seconds and thread count under its kernel's name (``module.kernel``), and blocks
wrapped in :func:`section` (scans, sorts, copies back: work that is not a launch) add theirs under
the section's name. Off (the default), a launch pays one comparison for it.
"""
from __future__ import annotations

import importlib
import os
import signal
import sys
import tempfile
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Callable, Iterator, Optional

import warp as wp

from .errors import SettingsError

_initialised = False
_load_lock = threading.RLock()
# What Warp's native library prints to stderr on wp.init() where no CUDA driver is installed; the
# device line (``Device.description``) says it in our words instead.
_NO_DRIVER = "Could not find or load the NVIDIA CUDA driver"
# The package's modules that hold kernels (relative to this package), loaded by load_kernels.
# Every module with a kernel is listed (tests/core/test_launch.py checks), so that the set-up's
# ``compile-kernels`` leaves the first bake nothing to compile.
KERNEL_MODULES = ("direct", "hierarchy", "gather", "surfels", "hits", "enclosure", "refine",
                  "solvers.base", "solvers.reference", "links", "solvers.hierarchical",
                  "directions", "solvers.implicit", "solvers.antiradiance", "lightmap.raster",
                  "targets.probes", "emitter_weights")


def init_warp() -> None:
    """Initialise Warp once, quietly (from any thread)."""
    global _initialised
    with _load_lock:
        if not _initialised:
            wp.config.log_level = wp.LOG_WARNING
            wp.config.verbose = False
            with _native_stderr_without(_NO_DRIVER):
                wp.init()
            _initialised = True


@contextmanager
def _native_stderr_without(drop: str):
    """Run the block with file descriptor 2 (where native code such as Warp's prints) going to a
    temporary file, then pass on to stderr every line of it that does not contain ``drop``. Where
    descriptor 2 cannot be redirected (no console), the block runs as it is."""
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError):
        yield
        return
    with tempfile.TemporaryFile() as caught:
        os.dup2(caught.fileno(), 2)
        try:
            yield
        finally:
            sys.stderr.flush()
            os.dup2(saved, 2)
            os.close(saved)
            caught.seek(0)
            kept = [line for line in caught.read().decode(errors="replace").splitlines(keepends=True)
                    if drop not in line]
            if kept:
                sys.stderr.write("".join(kept))
                sys.stderr.flush()


@dataclass(frozen=True)
class Device:
    """name: Warp device string ("cpu" or "cuda:0"); threads: CPU threads a launch is split over;
    why: why this device was chosen (for ``description``), empty when it was asked for."""

    name: str
    threads: int
    why: str = ""

    @property
    def is_cuda(self) -> bool:
        return self.name.startswith("cuda")

    @property
    def description(self) -> str:
        """One line for users naming the device, e.g. "the CPU (16 threads; no usable CUDA GPU
        found)" or "the GPU cuda:0 (NVIDIA H200)"."""
        if self.is_cuda:
            return f"the GPU {self.name} ({wp.get_device(self.name).name})"
        return f"the CPU ({self.threads} threads{'; ' + self.why if self.why else ''})"


def select(preference: str = "auto") -> Device:
    """Pick the device: "cuda" (SettingsError if none is usable), "cpu", or "auto" (CUDA when usable)."""
    init_warp()
    cuda = wp.get_cuda_device_count() > 0
    if preference == "cuda" and not cuda:
        raise SettingsError("device 'cuda' requested but Warp found no usable CUDA GPU "
                            "(needs an NVIDIA driver R580+ and a Turing or newer GPU); use --device cpu")
    if preference in ("cuda", "auto") and cuda:
        return Device("cuda:0", 1)
    return Device("cpu", cpu_threads(), "no usable CUDA GPU found" if preference == "auto" else "")


# Environment variable: the CPU threads a launch is split over (default: every core). Workers of
# a farm that share a machine each take their share of its cores (``core.farm``).
THREADS_VARIABLE = "RADIOSITY_BAKER_THREADS"


def cpu_threads() -> int:
    """The CPU threads a launch is split over: ``THREADS_VARIABLE`` when set, else every core."""
    given = os.environ.get(THREADS_VARIABLE, "").strip()
    if given:
        try:
            return max(1, int(given))
        except ValueError:
            raise SettingsError(f"{THREADS_VARIABLE} must be a whole number of threads, not {given!r}") from None
    return max(1, os.cpu_count() or 1)


def load_kernels(device: Device, on_compile: Optional[Callable[[], None]] = None) -> int:
    """Load (compiling the first time, then from Warp's kernel cache) every kernel module of the
    package for ``device``; ``on_compile()`` is called once before the first module that is not
    cached yet, so a caller can say why this bake takes longer. Safe to call from several threads
    (e.g. an ahead-of-time warm-up and a bake). Returns the number of modules compiled."""
    init_warp()
    package = __name__.rpartition(".")[0]
    compiled = 0
    with _load_lock:
        for name in KERNEL_MODULES:
            module = importlib.import_module(f"{package}.{name}")
            if not _cached(module, device):
                if compiled == 0 and on_compile is not None:
                    on_compile()
                compiled += 1
            wp.load_module(module, device=device.name)
    return compiled


def _cached(module, device: Device) -> bool:
    """Whether Warp's kernel cache holds ``module`` compiled for ``device`` (CPU launches load the
    block_dim 1 variant)."""
    ident = wp.get_module(module.__name__).get_module_identifier(None if device.is_cuda else 1)
    return os.path.isdir(os.path.join(wp.config.kernel_cache_dir, ident))


class Profile:
    """Where the time of a profiled block went: per kernel or section name, calls, threads (the
    launch's size, summed over calls), wall seconds and process CPU seconds (all threads; on a
    shared machine CPU seconds are the steadier measure of work)."""

    def __init__(self):
        self.rows: dict[str, dict] = {}

    def add(self, name: str, threads: int, wall: float, cpu: float) -> None:
        row = self.rows.setdefault(name, {"calls": 0, "threads": 0, "seconds": 0.0, "cpu_seconds": 0.0})
        row["calls"] += 1
        row["threads"] += threads
        row["seconds"] += wall
        row["cpu_seconds"] += cpu

    def as_dict(self) -> dict:
        """{name: {calls, threads, seconds, cpu_seconds}}, the slowest first, seconds rounded to µs."""
        order = sorted(self.rows.items(), key=lambda kv: -kv[1]["seconds"])
        return {k: {**v, "seconds": round(v["seconds"], 6), "cpu_seconds": round(v["cpu_seconds"], 6)}
                for k, v in order}


_profile: Optional[Profile] = None


@contextmanager
def profiling() -> Iterator[Profile]:
    """Collect a ``Profile`` of the launches and sections run inside the block (from the thread
    that launches; nested uses collect into their own table)."""
    global _profile
    outer = _profile
    _profile = Profile()
    try:
        yield _profile
    finally:
        _profile = outer


@contextmanager
def section(name: str, device: Device):
    """Time the block under ``name`` while profiling (synchronising ``device`` first and after, so
    a GPU's queued work is counted where it runs); nothing otherwise. For work that is not a
    launch through :func:`launch`, which times itself."""
    if _profile is None:
        yield
        return
    table = _profile
    if device.is_cuda:
        wp.synchronize_device(device.name)
    t0, c0 = time.perf_counter(), time.process_time()
    try:
        yield
    finally:
        if device.is_cuda:
            wp.synchronize_device(device.name)
        table.add(name, 0, time.perf_counter() - t0, time.process_time() - c0)


def kernel_name(kernel) -> str:
    """``module.kernel`` (the module's last component): how a profile names a launch."""
    return f"{kernel.module.name.rpartition('.')[2]}.{kernel.key}"


# An uneven CPU wave is cut into this many ranges per thread, each at least MIN_PIECE threads long,
# which the threads take in turn: an equal split left a core idle for 12–15 % of the links' oracle
# (its candidates' costs differ by 10×, a leaf pair's exact form factors against a dropped pair);
# for even work the extra launches only cost (the links' scatter on a 2.7 k-element room: +40 %).
PIECES = 4
MIN_PIECE = 64
# Launch helper threads, one pool per size, kept for the process: starting threads for each
# launch cost ~0.3 ms of CPU (measured), more than the work of many of a bake's launches. A forked
# child starts without the parent's threads, so it makes its own.
_pools: dict = {}
_pools_lock = threading.Lock()
if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_pools.clear)


def _pool(workers: int) -> ThreadPoolExecutor:
    """The process's pool of ``workers`` launch threads (made on first use)."""
    with _pools_lock:
        pool = _pools.get(workers)
        if pool is None:
            pool = _pools[workers] = ThreadPoolExecutor(workers, thread_name_prefix="radiosity-launch")
        return pool


@contextmanager
def _interrupts_held() -> Iterator[None]:
    """Ctrl-C (SIGINT) held back on the main thread while the pool is handed work and waited for,
    then raised: a KeyboardInterrupt raised inside the executor's own locking can leave one of its
    locks held, and the process then hangs at exit (seen once in a full test run: a cancelled
    command-line bake printed 'bake cancelled' and never exited). Elsewhere, or where SIGINT is
    not Python's default handler (Blender's own), nothing changes."""
    if (threading.current_thread() is not threading.main_thread()
            or signal.getsignal(signal.SIGINT) is not signal.default_int_handler):
        yield
        return
    caught = []
    signal.signal(signal.SIGINT, lambda signum, frame: caught.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    if caught:
        raise KeyboardInterrupt


def launch(kernel, n: int, inputs: list, device: Device, chunks: int = 1,
           on_chunk: Optional[Callable[[float], None]] = None, serial: bool = False,
           uneven: bool = False, min_split: int = 1, one_by_one: bool = False) -> None:
    """Launch ``kernel`` over ``n`` threads, ``kernel(offset, *inputs)``.

    The range is cut into ``chunks`` consecutive waves (progress and cancellation happen between
    waves through ``on_chunk(fraction_done)``, which may raise); on the CPU each wave is further
    split over ``device.threads`` threads — unless ``serial``: Warp's atomics are plain
    read-modify-writes on the CPU, so a kernel whose threads meet on one value through atomics
    must run its CPU waves on one thread. ``uneven``: the threads' work differs widely (the
    links' oracle), so a CPU wave is cut into PIECES ranges per thread, taken in turn.
    ``min_split``: a CPU wave with fewer threads than this per core runs on the calling thread
    alone (handing work to the pool and waiting for it costs ~80 µs, more than a small wave of
    cheap threads: a link build's first and last rounds). ``one_by_one``: each thread is a range
    of its own, taken in turn (few, long threads of unknown length: the links' depth-first runs).
    """
    if n <= 0:
        return
    table = _profile
    if table is not None:
        t0, c0 = time.perf_counter(), time.process_time()
    chunks = max(1, min(chunks, n))
    step = -(-n // chunks)
    threads = 1 if serial and not device.is_cuda else device.threads
    pool = _pool(threads - 1) if threads > 1 else None
    for start in range(0, n, step):
        count = min(step, n - start)
        if pool is None or count < threads * min_split:
            wp.launch(kernel, dim=count, inputs=[start, *inputs], device=device.name)
        else:
            # ranges taken in turn by the pool's threads and this one: with ``uneven``, PIECES per
            # thread, so a thread that drew cheap ones takes more of them
            pieces = threads * PIECES if uneven and count >= threads * PIECES * MIN_PIECE else threads
            if one_by_one:
                pieces = count
            sub = -(-count // pieces)
            ranges = iter(range(start, start + count, sub))

            def take():
                for s in ranges:  # next() on a shared range iterator hands each range out once
                    wp.launch(kernel, dim=min(sub, start + count - s), inputs=[s, *inputs],
                              device=device.name)

            with _interrupts_held():
                futures = [pool.submit(take) for _ in range(threads - 1)]
                try:
                    take()
                finally:
                    for f in futures:
                        f.result()
        if device.is_cuda:
            wp.synchronize_device(device.name)
        if on_chunk is not None:
            on_chunk((start + count) / n)
    if table is not None:
        table.add(kernel_name(kernel), n, time.perf_counter() - t0, time.process_time() - c0)


def free_memory(device: Device) -> Optional[int]:
    """Bytes of memory free for new arrays on ``device``: the GPU's free memory, or the system's
    available memory for the CPU; None where it cannot be told."""
    if device.is_cuda:
        return int(wp.get_device(device.name).free_memory)
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (AttributeError, ValueError, OSError):
        return None
