"""Baking on a real Dask cluster on this machine (127.0.0.1 only): lightmap pages and animation
frames as tasks come back equal to a bake here, a worker killed in the middle of a task costs
nothing but its retry, and a scheduler that cannot be reached stops the bake before any work.
Every process a test starts is stopped by it, also when it fails (and by a watchdog when it hangs).
"""
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import shapes
from radiosity_baker.core import Settings, bake, device, farm
from radiosity_baker.core.errors import SettingsError
from radiosity_baker.core.lightmap import LightmapRequest
from radiosity_baker.core.scene import LAMP_POINT

distributed = pytest.importorskip("distributed")

# Seconds a cluster test may take before its processes are killed under it.
WATCHDOG = 100
SETTINGS = dict(method="bunnell", light_samples=4, texel_density=30.0, max_size=128, padding=2,
                device="cpu")


def _crates_request(tmp_path):
    scene, objects = shapes.crates(4)
    return scene, LightmapRequest(objects, cache_dir=tmp_path / "unwrap")


def _same_pages(a, b):
    assert [p.stem for p in a.pages] == [p.stem for p in b.pages] and len(a.pages) > 1
    for pa, pb in zip(a.pages, b.pages):
        assert np.array_equal(pa.rgb, pb.rgb) and np.array_equal(pa.covered, pb.covered)
    assert a.seam_error == b.seam_error and a.texels == b.texels


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def dask_processes(tmp_path):
    """A ``dask scheduler`` and a ``dask worker --nworkers 2`` on 127.0.0.1 as processes of their
    own (inheriting PYTHONPATH, so workers import this package); yields the scheduler's address.
    Both are stopped at the end, and killed by a watchdog after WATCHDOG seconds."""
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    dask = [sys.executable, "-m", "distributed.cli"]
    env = dict(os.environ, DASK_DISTRIBUTED__WORKER__DAEMON="False")
    procs = []

    def stop():
        for p in reversed(procs):
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGTERM)
        for p in procs:
            try:
                p.wait(10)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)
                p.wait(10)

    watchdog = threading.Timer(WATCHDOG, stop)
    watchdog.start()
    try:
        log = open(tmp_path / "dask.log", "w")
        procs.append(subprocess.Popen([*dask[:2], "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
                                       "--port", str(port), "--dashboard-address", ":0"],
                                      env=env, stdout=log, stderr=log, start_new_session=True))
        procs.append(subprocess.Popen([*dask[:2], "distributed.cli.dask_worker", address, "--nworkers", "2",
                                       "--nthreads", "1", "--host", "127.0.0.1", "--no-dashboard"],
                                      env=env, stdout=log, stderr=log, start_new_session=True))
        yield address
    finally:
        watchdog.cancel()
        stop()


def test_lightmap_pages_baked_on_a_local_cluster_equal_a_bake_here_bit_for_bit(tmp_path):
    scene, request = _crates_request(tmp_path)
    settings = Settings(**SETTINGS)
    here = bake(scene, settings, targets=shapes.with_lightmap(request))
    with farm.Farm("local:2") as f:
        done = farm.bake_split(f, scene, settings, shapes.with_lightmap(request))
        report = done.counts["farm"]
        shares = set(f.client.run(device.cpu_threads).values())  # the cores shared out
    assert shares == {max(1, device.cpu_threads() // 2)}
    _same_pages(here["lightmap"], done["lightmap"])
    assert np.array_equal(here.output, done.output)  # vertices baked on the coordinator
    assert report["tasks"] == len(here["lightmap"].pages) and report["retried"] == []
    assert len(set(report["task_workers"]["lightmap"])) == 2  # both workers took pages
    assert "farm scatter" in done.timings and "texel direct" in done.timings


def _moving_lamp_frames(count: int):
    p, n, t = shapes.grid(2.0, 6)
    return [shapes.scene([(p, n, t, (0.5, 0.4, 0.3), (0,) * 3)],
                         shapes.lamp(LAMP_POINT, (0.2 * k, 0, 1.5), power=(80.0,) * 3)) for k in range(count)]


def test_frames_on_dask_scheduler_and_worker_processes_equal_each_frame_baked_here(dask_processes):
    frames = _moving_lamp_frames(3)
    settings = Settings(method="bunnell", light_samples=4, device="cpu")
    with farm.Farm(dask_processes, worker_timeout=60) as f:
        futures = [f.submit_frame(scene, settings, None, k) for k, scene in enumerate(frames)]
        results = f.gather(futures)
    for scene, result in zip(frames, results):
        assert np.array_equal(result.output, bake(scene, settings).output)


def test_a_worker_killed_in_the_middle_of_a_page_is_retried_and_the_pages_equal_a_bake_here(
        dask_processes, tmp_path):
    scene, request = _crates_request(tmp_path)
    settings = Settings(**SETTINGS)
    here = bake(scene, settings, targets=[shapes.with_lightmap(request)[1]])
    with farm.Farm(dask_processes, worker_timeout=60) as f:
        f.client.wait_for_workers(2, timeout=60)
        pids = f.client.run(os.getpid)
        killed = []

        def kill_a_busy_worker():
            deadline = time.monotonic() + 60
            while not killed and time.monotonic() < deadline:
                busy = [w for w, keys in f.client.processing().items()
                        if any("-page-" in str(k) for k in keys)]  # in the middle of a page
                if busy:
                    os.kill(pids[busy[0]], signal.SIGKILL)
                    killed.append(busy[0])
                time.sleep(0.05)

        killer = threading.Thread(target=kill_a_busy_worker)
        killer.start()
        done = farm.bake_split(f, scene, settings, [shapes.with_lightmap(request)[1]])
        killer.join()
    assert killed, "no worker was seen busy"
    _same_pages(here["lightmap"], done["lightmap"])
    assert done.counts["farm"]["retried"], "the killed worker's page is named as retried"


def test_a_scheduler_that_cannot_be_reached_stops_the_bake_before_any_work():
    address = f"tcp://127.0.0.1:{_free_port()}"
    t0 = time.monotonic()
    with pytest.raises(SettingsError, match=f"cannot reach the Dask scheduler at {address}"):
        farm.Farm(address, connect_timeout=2)
    assert time.monotonic() - t0 < 15


@pytest.mark.parametrize("address", ["localhost", "local:0", "8786"])
def test_a_scheduler_address_of_the_wrong_form_is_a_settings_error(address):
    with pytest.raises(SettingsError, match="scheduler"):
        Settings(scheduler=address).validate()


def test_the_threads_a_launch_is_split_over_can_be_set_for_workers_sharing_a_machine(monkeypatch):
    monkeypatch.setenv(device.THREADS_VARIABLE, "3")
    assert device.cpu_threads() == 3 and device.select("cpu").threads == 3
    monkeypatch.setenv(device.THREADS_VARIABLE, "many")
    with pytest.raises(SettingsError, match="whole number of threads"):
        device.cpu_threads()


def test_a_local_cluster_of_more_workers_than_the_machine_runs_is_capped_with_a_warning(monkeypatch):
    """``local:1000`` on this machine starts one worker per core at most (before: 1000 processes,
    51 of them within 10 s on 2 cores, and counting). The cluster is recorded, not started."""
    started = []

    class Cluster:
        def __init__(self, n_workers, **kwargs):
            started.append((n_workers, kwargs["env"][device.THREADS_VARIABLE]))

        def close(self):
            pass

    class Client:
        def __init__(self, *args, **kwargs):
            pass

        def wait_for_workers(self, n, timeout):
            pass

        def close(self):
            pass

    monkeypatch.setattr(distributed, "LocalCluster", Cluster)
    monkeypatch.setattr(distributed, "Client", Client)
    cores = len(os.sched_getaffinity(0))
    with farm.Farm("local:1000") as f:
        pass
    workers = farm.local_workers(1000)[0]
    assert 1 <= workers <= cores
    assert started == [(workers, str(max(1, device.cpu_threads() // workers)))]
    assert len(f.warnings) == 1 and "local:1000 asks for 1000 worker processes" in f.warnings[0]
    with farm.Farm("local:1") as f:
        pass
    assert started[-1][0] == 1 and f.warnings == []


def test_local_workers_are_bounded_by_cores_and_by_memory(monkeypatch):
    import radiosity_baker.core.lightmap.budget as budget

    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: set(range(8)))
    monkeypatch.setattr(budget, "memory_budget", lambda: 64 * farm.WORKER_MEMORY)
    assert farm.local_workers(8) == (8, None)
    workers, warning = farm.local_workers(9)
    assert workers == 8 and "this machine runs 8 (8 cores" in warning
    monkeypatch.setattr(budget, "memory_budget", lambda: 3 * farm.WORKER_MEMORY + 1)
    workers, warning = farm.local_workers(8)
    assert workers == 3 and "8 worker processes" in warning and "3 workers instead" in warning
