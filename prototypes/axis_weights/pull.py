"""The pulled bar with its sides inside cells (tests/test_staggered_verification.py): `pull.py on|off`."""
import os
import sys

here = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, here)
sys.path.insert(0, os.path.join(here, "..", "..", "tests"))
import numpy as np

import axisw
import test_staggered_verification as T
from engine.grid import Grid

axisw.mode(sys.argv[1])
for h in (1 / 16, 1 / 32):
    corner = np.array([0.0, 0.2 * h, 0.1 * h])
    lo, hi = corner, corner + [1.0, 0.25, 0.25]
    grid = Grid(origin=(-h, -h, -h), spacing=h, shape=(round(1 / h) + 3, round(0.25 / h) + 3, round(0.25 / h) + 3))
    axisw.G["origin"] = np.asarray(grid.origin, float)
    axisw.G["moments"] = axisw.cutstrain.box_moments(lo, hi)
    axisw.G["edge_moments"] = axisw.box_edge_moments(lo, hi, grid)
    print(h, T._cut_side_pull({"kind": "staggered", "solver": "direct"}, h), flush=True)
