"""``core.device.launch``: every thread of a launch runs once however the CPU waves are cut
(even, uneven, one range per thread, too small to split), and Ctrl-C while its thread pool
works."""
import os
import signal

import numpy as np
import pytest
import warp as wp

from radiosity_baker.core import device


@wp.kernel
def _mark_kernel(offset: int, marks: wp.array(dtype=wp.int32)):
    i = wp.tid() + offset
    marks[i] = marks[i] + 1 + i % 3  # a plain read-modify-write: a thread run twice shows


@pytest.mark.parametrize("threads", [2, 3])
@pytest.mark.parametrize("n, options", [(1, {}), (1000, {}), (100003, {"uneven": True}),
                                        (100003, {"uneven": True, "chunks": 3}),
                                        (5000, {"min_split": 4096}), (70000, {"min_split": 4096}),
                                        (37, {"one_by_one": True}), (37, {"one_by_one": True, "chunks": 4})])
def test_every_thread_of_a_launch_runs_exactly_once(threads, n, options):
    dev = device.Device("cpu", threads=threads)
    marks = wp.zeros(n, dtype=wp.int32, device="cpu")
    device.launch(_mark_kernel, n, [marks], dev, **options)
    assert np.array_equal(marks.numpy(), 1 + np.arange(n) % 3)


def test_a_ctrl_c_while_the_pool_is_handed_work_is_raised_after_it_not_inside():
    """A KeyboardInterrupt raised inside the executor's locking could leave a lock held and hang
    the process at exit: the interrupt is held back until the pool's work is handed over and
    waited for, then raised, and Python's own handler is back."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        reached = []
        with pytest.raises(KeyboardInterrupt):
            with device._interrupts_held():
                os.kill(os.getpid(), signal.SIGINT)
                reached.append("after the signal")
        assert reached == ["after the signal"]
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    finally:
        signal.signal(signal.SIGINT, previous)
