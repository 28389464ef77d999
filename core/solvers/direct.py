"""Direct light only: lamps and emissive surfaces with shadows (``core.direct``), no indirect
light. The pipeline adds the direct part at every receiver; this solver's part is zero."""
from __future__ import annotations

import numpy as np

from .base import Solution


def solve(problem) -> Solution:
    return Solution(np.zeros((problem.elements.count, 3), np.float32))


def evaluate(problem, solution: Solution, receivers) -> np.ndarray:
    return np.zeros((len(receivers), 3), np.float32)
