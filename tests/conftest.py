"""Puts ``bench/`` on the path: the Cycles harness and the error measures (``harness``) live there,
outside the extension, and tests use them as the benchmarks do; and ``examples/threejs/`` for the
browser test's ``headless`` (the page in Chromium, shared with the manual picture's script).
A test that hangs stops the run with every thread's stack printed."""
import faulthandler
import os
import sys
import threading

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "bench"))
sys.path.insert(0, os.path.join(ROOT, "examples", "threejs"))

# A test that runs this long has hung (the slowest takes about a minute): every thread's stack is
# printed and the run stops with an error, instead of CI waiting out its own limit with nothing to
# show (seen once: a hang inside the suite that ended only at CI's limit).
TEST_LIMIT_S = 600


def _stop_hung_run(config, test: str) -> None:
    """Print every thread's stack past pytest's capture (os._exit drops what it holds) and end."""
    capture = config.pluginmanager.getplugin("capturemanager")
    if capture is not None:
        capture.suspend_global_capture(in_=True)
    sys.stdout.flush()
    sys.stderr.write(f"\n{test} ran past {TEST_LIMIT_S} s: it hung. Every thread's stack:\n")
    sys.stderr.flush()
    faulthandler.dump_traceback(file=sys.stderr, all_threads=True)
    sys.stderr.flush()
    os._exit(1)


@pytest.fixture(autouse=True)
def _hang_watchdog(request):
    timer = threading.Timer(TEST_LIMIT_S, _stop_hung_run, (request.config, request.node.nodeid))
    timer.daemon = True
    timer.start()
    faulthandler.dump_traceback_later(TEST_LIMIT_S + 60, exit=True)  # should the GIL never come free
    yield
    faulthandler.cancel_dump_traceback_later()
    timer.cancel()
