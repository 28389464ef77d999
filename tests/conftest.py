"""Puts ``bench/`` on the path: the Cycles harness and the error measures (``harness``) live there,
outside the extension, and tests use them as the benchmarks do."""
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "bench"))
