"""``core.device.launch``'s handling of Ctrl-C while its thread pool works."""
import os
import signal

import pytest

from radiosity_baker.core import device


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
