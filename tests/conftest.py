"""Puts ``bench/`` on the path: the Cycles harness and the error measures (``harness``) live there,
outside the extension, and tests use them as the benchmarks do; and ``examples/threejs/`` for the
browser test's ``headless`` (the page in Chromium, shared with the manual picture's script)."""
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, "bench"))
sys.path.insert(0, os.path.join(ROOT, "examples", "threejs"))
